"""The scan's gating as one loop over the landmarks, compiled with numba for long runs
(notebook 06 "Victoria Park at scale", its cost section).

What it computes is :meth:`EkfSlam.innovation_d2 <annslam_lib.slam.efficient.EkfSlam.innovation_d2>`:
for every landmark its predicted range and bearing (``models.observation``, paper 4.1,
corrected), its innovation covariance S = H P H^T + R in the closed form derived in
:meth:`EkfSlam.observation_model` (chapter 05), and the squared Mahalanobis distance of every
detection to it; it also leaves the Jacobians' ingredients (r, bearing, u_x, u_y, 1/r) that
:meth:`EkfSlam.update` reads. That numpy code stays the reference and what the chapters
teach; this loop is a fast copy of it, listed with the other copies in
``models.observation``'s docstring (change them together), held to it by
``tests/test_compiled.py``.

Why a compiled loop: the numpy gating does about fifty vector operations per scan over a
few hundred landmarks, each costing its call overhead (about a microsecond) more than its
arithmetic: on Victoria Park (7248 scans, 335 landmarks) about a quarter of the run. One
compiled loop does the same arithmetic in one call. Measured on a 2-core Xeon, one thread
(for Victoria Park, ``benchmarks/bench_ekf_slam.py --against HEAD`` times the whole run with
the loop and, in its ``numpy`` row, without it): the loop saves 55-65 us a scan on Victoria
Park (up to 335 landmarks) and about 35-45 us on the Car Park (15), while a process pays
about 0.27 s CPU once to import numba (0.12-0.14 s) and load the cached machine code
(0.14-0.15 s), about 0.3 s more the first time on a machine (compiling it). Break-even is
thus near 5000 scans of a Victoria Park-sized map (more for smaller maps: the saving grows
with the landmarks): :func:`use_compiled` switches the loop on for runs at least
:data:`MIN_SCANS` long (Victoria Park; not the Car Park's 586 scans nor one simulated
run), so that a chapter without such a run never imports numba; a Monte-Carlo study
(``evaluation.consistency.monte_carlo``) asks for all its runs' scans together, since one
process pays the loading once for all of them.

``ANNSLAM_KERNEL=numpy`` in the environment switches it off everywhere (the grader's sandbox
does: it runs student code, which must not share a cache of compiled code with the course;
``course.grader`` also deletes any numba cache file that appears in the course's folders
while a submission runs); ``ANNSLAM_KERNEL=auto`` or unset leaves it on.
"""
from __future__ import annotations

import math
import threading
import warnings

from .. import _settings

__all__ = ["gate_loop", "gating_kernel", "use_compiled", "unavailable_reason", "MIN_SCANS"]

# A run with fewer scans than this keeps the numpy gating (measured break-even: module
# docstring; benchmarks/bench_ekf_slam.py prints the figures).
MIN_SCANS = 5000

_PI = math.pi
_TWO_PI = 2.0 * math.pi

# Status codes of gate_loop: 0 fine; otherwise the numpy path is run to raise its own error.
OK, BAD_RANGE, BAD_FIRST, BAD_S = 0, 1, 2, 3


def gate_loop(lm, P, px, py, pphi, p00, p01, p02, p11, p12, p22, first, fej,
              z, sr2, sb2, J, d2):
    """Gating of the detections ``z`` (m, 2) against the landmarks ``lm`` (N, 2) of the state
    with covariance ``P`` (its UPPER triangle is read), laser pose (px, py, pphi) and pose
    block entries p00..p22 (as held by the filter between flushes); measurement variances
    sr2, sb2. With ``fej`` the Jacobians are taken at the first estimates ``first`` (N, 2).

    Writes J (5, N): rows r, bearing, u_x, u_y, 1/r (u the unit vector from the laser to the
    landmark, at the first estimate with ``fej``), and d2 (m, N). Returns a status: 0, or
    the first problem found (a range under 1e-9 m or NaN, the same at a first estimate, an
    S not positive definite or NaN), in which case J and d2 are incomplete.

    The arithmetic follows ``EkfSlam._model`` and ``innovation_d2`` operation by operation
    (their complex products written out in real and imaginary parts), so both give the same
    numbers up to the last bits that a fused multiply-add or a different libm may change.
    Plain Python: compiled by :func:`gating_kernel`, or run as it is (slowly) by the tests.
    """
    N = lm.shape[0]
    m = z.shape[0]
    off = _PI / 2 - pphi
    for j in range(N):
        dx = lm[j, 0] - px
        dy = lm[j, 1] - py
        r = math.hypot(dx, dy)
        if not r >= 1e-9:
            return BAD_RANGE
        b = math.atan2(dy, dx) + off
        b = b - _TWO_PI * math.floor((b + _PI) / _TWO_PI)       # geometry.wrap_difference
        if fej:
            dx = first[j, 0] - px
            dy = first[j, 1] - py
            rf = math.hypot(dx, dy)
            if not rf >= 1e-9:
                return BAD_FIRST
            ir = 1.0 / rf
        else:
            ir = 1.0 / r
        ux = dx * ir
        uy = dy * ir
        J[0, j] = r
        J[1, j] = b
        J[2, j] = ux
        J[3, j] = uy
        J[4, j] = ir
        k = 3 + 2 * j
        m00 = P[k, k] - 2.0 * P[0, k] + p00                     # M = Cov(l - p)
        m11 = P[k + 1, k + 1] - 2.0 * P[1, k + 1] + p11
        m01 = (P[k, k + 1] - P[0, k + 1]) - (P[1, k] - p01)
        half_tr = 0.5 * (m00 + m11)
        cr = 0.5 * (m11 - m00)
        u2r = ux * ux - uy * uy                                 # u^2 (complex)
        u2i = 2.0 * ux * uy
        A = u2r * cr - u2i * m01                                # A + iB = u^2 C
        B = u2r * m01 + u2i * cr
        mx = P[2, k] - p02                                      # m = Cov(l - p, phi)
        my = P[2, k + 1] - p12
        mvr = ux * mx + uy * my                                 # u'm + i w'm = conj(u) m
        mvi = ux * my - uy * mx
        s00 = half_tr - A + sr2
        s01 = B * ir - mvr
        s11 = ((half_tr + A) * ir - 2.0 * mvi) * ir + (p22 + sb2)
        det = s00 * s11 - s01 * s01
        if not (det > 0.0 and s00 > 0.0):
            return BAD_S
        idet = 1.0 / det
        c0 = s11 * idet
        c1 = 2.0 * s01 * idet
        c2 = s00 * idet
        for i in range(m):
            nr = z[i, 0] - r
            nb = z[i, 1] - b
            nb = nb - _TWO_PI * math.floor((nb + _PI) / _TWO_PI)
            d2[i, j] = (c0 * nr - c1 * nb) * nr + c2 * (nb * nb)
    return OK


_kernel = None          # the compiled gate_loop, once built
_failed = None          # why it could not be built (str), once tried
_lock = threading.Lock()


def _switched_off() -> bool:
    """``ANNSLAM_KERNEL``: 'numpy' switches the compiled loop off, 'auto' or unset leaves it;
    anything else is refused (a typo must not leave it silently on)."""
    return _settings.kernel() == "numpy"


def gating_kernel():
    """The compiled :func:`gate_loop`, or None when numba is not installed or cannot be
    loaded, cannot compile here, or ``ANNSLAM_KERNEL=numpy``. Built once per process, on
    first use; numba caches its machine code on disk (in ``NUMBA_CACHE_DIR`` if set, else
    next to this file, else in the user's cache folder) and the next process loads it; where
    that fails (no writable folder, a damaged cache file) it is compiled in memory, with a
    warning that says why."""
    global _kernel, _failed
    if _switched_off():
        return None
    with _lock:
        if _kernel is not None or _failed is not None:
            return _kernel
        try:
            import numba
        except Exception as exc:           # not installed, or its LLVM library fails to load
            _failed = f"numba cannot be imported ({type(exc).__name__}: {exc})"
            return None
        try:
            _kernel = _compiled(numba, cache=True)
        except Exception as exc:
            warnings.warn(f"annslam: the compiled gating is not cached on disk ({type(exc).__name__}: "
                          f"{exc}); compiling it in memory for this process", RuntimeWarning,
                          stacklevel=2)
            try:
                _kernel = _compiled(numba, cache=False)
            except Exception as exc2:      # pragma: no cover - numba installed but broken
                _failed = (f"numba could not compile the gating ({type(exc2).__name__}: "
                           f"{exc2})")
        return _kernel


def _compiled(numba, cache: bool):
    import numpy as np
    f = numba.njit(cache=cache, nogil=True, error_model="numpy")(gate_loop)
    lm = np.zeros((1, 2))
    lm[0, 0] = 1.0
    P = np.eye(5)
    J = np.empty((5, 1))
    d2 = np.empty((2, 1))
    z = np.zeros((2, 2))
    # compile (or load) now, so that a failure surfaces here and not inside a run
    f(lm, P, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 1.0, lm, False, z, 1.0, 1.0, J, d2)
    return f


def use_compiled(n_scans: int) -> bool:
    """Whether a run of ``n_scans`` scans gates with the compiled loop: long enough to win
    back loading it (:data:`MIN_SCANS`), and the loop available (:func:`gating_kernel`)."""
    return n_scans >= MIN_SCANS and gating_kernel() is not None


def unavailable_reason() -> str | None:
    """Why :func:`gating_kernel` returned None (after it was asked), else None."""
    if _switched_off():
        return "ANNSLAM_KERNEL=numpy"
    return _failed
