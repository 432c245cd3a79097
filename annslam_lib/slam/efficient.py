"""EKF-SLAM for the car-like vehicle, written to scale (notebook 05 "EKF-SLAM", notebook 06
"Victoria Park at scale").

State and covariance
    x = [x, y, phi, l1x, l1y, l2x, l2y, ...]: the LASER pose (``kinematics``) and the
    landmarks in the world frame; P its (n, n) covariance, n = 3 + 2 N, kept as ONE
    C-contiguous array whose UPPER triangle holds the symmetric P (symmetric by
    construction; the lower triangle is filled in only when P is handed out). Its
    transpose is Fortran-contiguous, which lets the BLAS rank-k correction work in place
    (:meth:`EkfSlam._correct`).

Cost (``benchmarks/bench_ekf_slam.py`` measures it against the dense reference)
    - Prediction touches only the 3x3 vehicle block and the 3 x 2N cross covariance.
      The motion Jacobian of one Euler step is F = [[1, 0, f0], [0, 1, f1], [0, 0, 1]], and a
      product of such matrices is again of that form with f0, f1 summed, so consecutive
      odometry steps are COMPOUNDED exactly: each step updates the pose and the 3x3 block
      (plain ``math``, a few microseconds), the sums (f0, f1) accumulate, and the cross
      covariance is multiplied by F_total once, when something next reads it (a scan, a
      GPS fix, a checkpoint). ``tests/test_ekf_slam.py`` proves it equal to step-by-step
      prediction.
    - An update touches only the columns its Jacobian touches: the vehicle and the
      observed landmarks. With H_c (2m x c) the nonzero columns of H,

          HP = H_c P[c, :]                  (2m x n; the rows of P, P symmetric)
          S  = HP[:, c] H_c^T + R,  symmetrised, S = L L^T (Cholesky)
          W^T = L^{-1} HP,  x += W (L^{-1} nu),  P -= W W^T

      The last line is the optimal-gain covariance update P - P H^T S^{-1} H P written as
      a symmetric rank-2m correction, done in place on the upper triangle by BLAS
      ``dsyrk`` (no n x n temporary, no n x n Jacobian; half the memory traffic of a
      full ``dgemm``, which matters because the update is memory-bound). All
      observations of a scan go into ONE update.
    - Landmark augmentation (``observation.inverse_observe``): for new landmarks
      l = g(pose, z), P_ll = J_pose P_vv J_pose^T + J_z R J_z^T, P_l* = J_pose P_v*.

Process noise (notebook 05 "process noise")
    The odometry sample k, taken at t_k, is the control held over [t_k, t_{k+1})
    (``dead_reckoning`` convention). Its error is modelled on what is measured: the
    encoder speed (``sigma_speed``) and the steering angle (``sigma_steer``), mapped to
    the controls (v_c, alpha) by the Jacobian of ``motion.axle_speed``:
    Q_c = M diag(sigma_speed^2, sigma_steer^2) M^T. A full Euler step of length
    Delta_k = t_{k+1} - t_k adds G Q_c G^T = Delta_k^2 B Q_c B^T (B = d rate / d control),
    the ACFR discrete model. Scans and GPS fixes fall inside odometry intervals, so the
    filter predicts to every event time in partial steps tau; each partial step adds
    tau Delta_k B Q_c B^T, so the noise added over one odometry interval does not depend
    on how many events split it (and equals the ACFR value when none does).

First-estimates Jacobians (``fej=True``; Huang, Mourikis & Roumeliotis 2008, 2010)
    SLAM cannot observe where the whole scene lies: moving the vehicle and every landmark
    by one rigid motion changes no odometry and no measurement. The EKF linearises each
    observation at the current landmark estimate and each prediction at the latest pose;
    because these estimates change between steps, the linearised model of the filter sees
    the global heading as observable and gains information it cannot have: it becomes
    over-confident. FEJ evaluates every observation Jacobian at the landmark's FIRST
    estimate (kept from :meth:`augment`) and the motion Jacobian of the first prediction
    after an update at the pose predicted before it, F = [[1, 0, -(y' - y)], [0, 1, x' - x],
    [0, 0, 1]] with (x, y) the prior and (x', y') the predicted laser position: the
    shear by the update's position correction (``_cx``, ``_cy``) is applied once before the
    next step (:meth:`_prediction_start`, for :meth:`predict_many` and
    :meth:`predict_stretch`), and the heading column of a new landmark's Jacobian
    takes the same correction (:meth:`augment`). Gating, update and
    the innovation covariance use the same Jacobians; innovations use the current estimates.
    Why it matters, measured: with FEJ and no GPS, the heading's variance never falls below
    its initial value (nothing observes the global heading); the standard filter's does
    (``tests/test_fej.py``).

Models used here as fast, unchecked copies (each beside its model, with the list of places
to change together): the Euler and midpoint step and its noise (``models.motion``,
"fast copies"), the range-bearing prediction (``models.observation.observe_fast``), the
angle wrap of differences (``models.geometry.wrap_difference``). The gating of
:meth:`EkfSlam.innovation_d2` has a compiled copy, ``slam.compiled``, that long runs use
(``gating='compiled'``, chosen by ``runner.run``); this numpy code stays the reference.
"""
from __future__ import annotations

import math

import numpy as np

from .. import _checks
from . import compiled
from ..models.geometry import wrap_angle, wrap_difference
from ..models.observation import inverse_observe, observe_fast
from ..perception.association import mahalanobis
from ..models.vehicle import Vehicle
from .base import (InnovationError, with_known_landmarks, check_dt, check_initial, check_remove, check_sigmas,
                   check_z)

__all__ = ["EkfSlam", "diag_blocks"]

_PI, _TWO_PI = math.pi, 2.0 * math.pi

# scipy.linalg (0.18 s to import) is bound on the first filter's construction, so that
# importing the run loop or a chapter that never filters does not pay for it.
eigh = dsyrk = dtrsm = dpotrf = dtrtrs = None


def _load_linalg() -> None:
    global eigh, dsyrk, dtrsm, dpotrf, dtrtrs
    if dsyrk is None:
        from scipy.linalg import eigh
        from scipy.linalg.blas import dsyrk, dtrsm
        from scipy.linalg.lapack import dpotrf, dtrtrs


class EkfSlam:
    """The efficient EKF-SLAM state (x, P) and its operations (module docstring).

    ``slam.dense.DenseEkfSlam`` has the same interface with textbook dense algebra.
    Read the state through :meth:`state` (or ``pose``, ``pose_cov``,
    :meth:`landmark_covs`): between calls the vehicle block lives in Python floats, the
    cross covariance may await its compounded prediction, and ``self.P`` holds only
    its upper triangle up to date.

    Parameters
    ----------
    x0 : array_like, shape (3,)
        Initial laser pose (x, y, phi) (m, m, rad); the map starts empty.
    P0 : array_like, shape (3, 3)
        Its covariance (symmetric, PSD, finite).
    vehicle : Vehicle
        The car (``L``, ``a``, ``b``) of the motion model.
    motion_model : {'euler', 'midpoint'}, optional
        The prediction's discretisation (:class:`SlamConfig`).
    fej : bool, optional
        First-estimates Jacobians (module docstring).
    gating : {'numpy', 'compiled'}, optional
        'numpy' (:meth:`innovation_d2` as derived) or 'compiled' (the same as one
        numba-compiled loop, ``slam.compiled``: what ``runner.run`` chooses for long
        runs).

    Raises
    ------
    TypeError
        If ``x0`` or ``P0`` is not numeric, ``vehicle`` is not a Vehicle or ``fej`` is
        not a bool.
    ValueError
        If ``x0`` is not a finite (3,) array, ``P0`` not a finite symmetric positive
        semi-definite (3, 3) matrix, or ``motion_model`` or ``gating`` is unknown.
    RuntimeError
        For ``gating='compiled'`` when the compiled loop is not available.
    """

    def __init__(self, x0, P0, vehicle: Vehicle, motion_model: str = "euler", *,
                 fej: bool = False, gating: str = "numpy") -> None:
        x0, P0 = check_initial(x0, P0, vehicle, motion_model)
        if gating not in ("numpy", "compiled"):
            raise ValueError(f"EkfSlam gating must be 'numpy' or 'compiled', got {gating!r}")
        self._gate = None                  # slam.compiled's loop, for gating='compiled'
        if gating == "compiled":
            self._gate = compiled.gating_kernel()
            if self._gate is None:
                raise RuntimeError("EkfSlam gating='compiled': the compiled gating is not "
                                   f"available ({compiled.unavailable_reason()})")
        self.gating = gating
        _load_linalg()
        self._mid = motion_model == "midpoint"
        self.fej = _checks.flag("EkfSlam fej", fej)
        self._first = np.empty((0, 2))     # the landmarks' first estimates (fej)
        self._cx = self._cy = 0.0          # position corrections since the last prediction
        self.vehicle = vehicle
        self._a, self._b, self._L = vehicle.a, vehicle.b, vehicle.L
        self.x = x0.copy()
        self.x[2] = float(wrap_angle(self.x[2]))
        self.P = np.ascontiguousarray(0.5 * (P0 + P0.T))
        self._load_vehicle()

    # ---- vehicle block held as Python floats between flushes
    def _load_vehicle(self) -> None:
        self._px, self._py, self._pphi = self.x[:3].tolist()
        b = self.P[:3, :3].ravel().tolist()
        self._p = [b[0], b[1], b[2], b[4], b[5], b[8]]
        self._f0 = self._f1 = 0.0
        self._dirty = False
        self._om = None                    # cached gating Jacobians are stale

    def flush(self) -> None:
        """Write the compounded prediction into (x, P): the pose, the 3x3 block, and
        the cross covariance multiplied ONCE by F_total = [[1,0,f0],[0,1,f1],[0,0,1]]."""
        if not self._dirty:
            return
        P, x = self.P, self.x
        x[:3] = (self._px, self._py, self._pphi)
        f0, f1 = self._f0, self._f1
        if P.shape[0] > 3:                 # the upper triangle holds P (see _correct)
            P[:2, 3:] += np.multiply.outer((f0, f1), P[2, 3:])
        p00, p01, p02, p11, p12, p22 = self._p
        n, f = P.shape[0], P.reshape(-1)
        f[0], f[1], f[2], f[n + 1], f[n + 2], f[2 * n + 2] = p00, p01, p02, p11, p12, p22
        f[n], f[2 * n], f[2 * n + 1] = p01, p02, p12
        self._f0 = self._f1 = 0.0
        self._dirty = False

    def predict(self, u, dt: float) -> None:
        """One Euler step of ``motion.predict`` of length ``dt`` with the control row
        ``u`` of :func:`~annslam_lib.models.motion.control_table`, process noise
        dt * Delta B Q_c B^T (scalar code: the vehicle block only; the cross covariance
        waits for :meth:`flush`). A step of dt = 0 does nothing; a negative or non-finite
        dt raises ValueError."""
        if check_dt(dt) > 0.0:
            self.predict_many(u, 0.0, (dt,), (u,), record=False)

    def predict_many(self, u, t: float, times, rows, *, record: bool = True):
        """Advance over a stretch of odometry samples in one call, step by step (the
        reference :meth:`predict_stretch` is tested against, and :meth:`predict`'s one
        step; the run loop applies stretches compounded beforehand, ``slam.stretches``):
        holding control ``u`` from time ``t``, for each sample
        k predict to ``times[k]`` (steps of dt <= 0 skipped), then hold ``rows[k]``.
        ``u`` may be None (no control yet: nothing is predicted). Returns (u, t, n, poses):
        the control held and the time reached after the last sample, the number of steps
        taken and, with ``record``, the pose (t, x, y, phi) at every sample.

        The scalar step (the fast copy of ``models.motion.predict`` and its noise; the
        midpoint variant evaluates the rate at phi + dt w / 2) runs on local floats, and the
        motion Jacobians compound into (f0, f1) for :meth:`flush`."""
        a, b, L, mid = self._a, self._b, self._L, self._mid
        px, py, phi = self._px, self._py, self._pphi
        p00, p01, p02, p11, p12, p22, F0, F1 = self._prediction_start()
        cos, sin = math.cos, math.sin
        n = 0
        poses = [] if record else None
        for tk, row in zip(times, rows):
            dt = tk - t
            if dt > 0.0 and u is not None:
                v, _, ta, w, dw, q00, q01, q11, span = u
                if mid:
                    c, s = cos(phi + 0.5 * dt * w), sin(phi + 0.5 * dt * w)
                else:
                    c, s = cos(phi), sin(phi)
                lx = a * s + b * c
                ly = a * c - b * s
                vx = v * c - w * lx
                f0 = dt * (-v * s - w * ly)
                f1 = dt * vx
                px += dt * vx
                py += dt * (v * s + w * ly)
                phi += dt * w
                if not -_PI < phi <= _PI:
                    phi = _PI - (_PI - phi) % _TWO_PI
                # B = d rate / d (v_c, alpha); noise N = k B Q_c B^T with k = dt * Delta.
                tl = ta / L
                b00, b01 = c - tl * lx, -dw * lx
                b10, b11 = s + tl * ly, dw * ly
                k = dt * span
                g00, g01 = b00 * q00 + b01 * q01, b00 * q01 + b01 * q11   # rows of B Q
                g10, g11 = b10 * q00 + b11 * q01, b10 * q01 + b11 * q11
                g20, g21 = tl * q00 + dw * q01, tl * q01 + dw * q11
                p00, p01, p02, p11, p12, p22 = (
                    p00 + 2.0 * f0 * p02 + f0 * f0 * p22 + k * (g00 * b00 + g01 * b01),
                    p01 + f0 * p12 + f1 * p02 + f0 * f1 * p22 + k * (g00 * b10 + g01 * b11),
                    p02 + f0 * p22 + k * (g00 * tl + g01 * dw),
                    p11 + 2.0 * f1 * p12 + f1 * f1 * p22 + k * (g10 * b10 + g11 * b11),
                    p12 + f1 * p22 + k * (g10 * tl + g11 * dw),
                    p22 + k * (g20 * tl + g21 * dw))
                F0 += f0
                F1 += f1
                n += 1
            if record:
                poses.append((tk, px, py, phi))
            u, t = row, tk
        if n:
            self._px, self._py, self._pphi = px, py, phi
            self._p = [p00, p01, p02, p11, p12, p22]
            self._f0, self._f1 = F0, F1
            self._cx = self._cy = 0.0
            self._dirty = True
        return u, t, n, poses

    def _prediction_start(self) -> tuple:
        """The vehicle block's six entries and the compounded shear (F0, F1) a prediction
        starts from. With fej, after an update (module docstring), the first step's
        Jacobian at the prior position is F(step) E with the shear
        E = [[1, 0, e0], [0, 1, e1], [0, 0, 1]], (e0, e1) = (-cy, cx): E is applied here, to
        the copies returned; the caller clears (cx, cy) once it has taken a step (until
        then the correction waits)."""
        if self._cx or self._cy:
            e0, e1 = -self._cy, self._cx
            return (*_sheared(self._p, e0, e1), self._f0 + e0, self._f1 + e1)
        return (*self._p, self._f0, self._f1)

    def predict_stretch(self, row) -> int:
        """Advance over one stretch of odometry compounded beforehand (``slam.stretches``:
        the run loop's step between two events, equal to :meth:`predict_many` over it):
        ``row`` = (dx, dy, dtheta, q00, q01, q02, q11, q12, q22, steps), the displacement
        and turn in the frame of the stretch's start and the noise Q gathered there. The
        pose moves by R(phi) (dx, dy) and dtheta, the vehicle block becomes
        F P F^T + R0 Q R0^T, and F, a shear by the perpendicular of the displacement,
        compounds for :meth:`flush`. Returns the number of steps (0: nothing changes)."""
        dx, dy, dth, q00, q01, q02, q11, q12, q22, steps = row
        if not steps:
            return 0
        *p, F0, F1 = self._prediction_start()
        self._cx = self._cy = 0.0
        phi = self._pphi
        c, s = math.cos(phi), math.sin(phi)
        wx, wy = c * dx - s * dy, s * dx + c * dy        # the displacement in the world
        f0, f1 = -wy, wx
        cc, ss, cs = c * c, s * s, c * s                 # R0 Q R0^T
        r00 = cc * q00 - 2.0 * cs * q01 + ss * q11
        r01 = cs * (q00 - q11) + (cc - ss) * q01
        r11 = ss * q00 + 2.0 * cs * q01 + cc * q11
        r02, r12 = c * q02 - s * q12, s * q02 + c * q12
        p00, p01, p02, p11, p12, p22 = _sheared(p, f0, f1)
        self._p = [p00 + r00, p01 + r01, p02 + r02, p11 + r11, p12 + r12, p22 + q22]
        self._px += wx
        self._py += wy
        phi += dth
        if not -_PI < phi <= _PI:
            phi = _PI - (_PI - phi) % _TWO_PI
        self._pphi = phi
        self._f0, self._f1 = F0 + f0, F1 + f1
        self._dirty = True
        return steps

    # ---- read access
    @property
    def n_landmarks(self) -> int:
        return (self.x.size - 3) // 2

    @property
    def pose(self) -> np.ndarray:
        return np.array([self._px, self._py, self._pphi])

    def pose_tuple(self) -> tuple[float, float, float]:
        """The laser pose (x, y, phi) as floats (cheap: no array)."""
        return self._px, self._py, self._pphi

    def pose_cov_entries(self) -> tuple:
        """The six unique entries (p00, p01, p02, p11, p12, p22) of the pose covariance."""
        return tuple(self._p)

    @property
    def pose_cov(self) -> np.ndarray:
        p00, p01, p02, p11, p12, p22 = self._p
        return np.array([[p00, p01, p02], [p01, p11, p12], [p02, p12, p22]])

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, P) after a flush, P made whole (the arrays themselves, not copies)."""
        self.flush()
        self._symmetrize()
        return self.x, self.P

    def landmarks(self) -> np.ndarray:
        return self.x[3:].reshape(-1, 2)

    def landmark_covs(self) -> np.ndarray:
        """(N, 2, 2) marginal covariances of the landmarks (a strided view of P)."""
        self.flush()
        self._symmetrize()
        return diag_blocks(self.P)

    # ---- observations
    def observation_model(self, sigma_range: float, sigma_bearing: float):
        """Predicted (range, bearing) of every landmark, zhat (N, 2), and the innovation
        covariances S (N, 2, 2) for gating, elementwise over the landmarks.

        With u = (dx, dy) / r the unit vector to the landmark and w = (-u_y, u_x), the
        Jacobians are H_landmark = J = [u^T; w^T / r] = -H_pose[:, :2] and a heading
        column (0, -1), so H e = J (e_l - e_p) - (0, e_phi) and

            S = [[u'Mu, u'Mw / r - u'm], [., w'Mw / r^2 - 2 w'm / r + P_phiphi]] + R

        with M = Cov(l - p) and m = Cov(l - p, phi). In terms of cos 2theta = u_x^2 - u_y^2
        and sin 2theta = 2 u_x u_y: u'Mu, w'Mw = tr M / 2 -+ A, u'Mw = B with
        A + iB = (cos2 + i sin2) ((m11 - m00) / 2 + i m01) = u^2 C, and u'm + i w'm =
        conj(u) (m_x + i m_y), writing u as the complex number u_x + i u_y. About forty
        vector operations over the N landmarks instead of N small matrix products; the
        Jacobians are kept for an :meth:`update` from the same state."""
        self.flush()
        if self.n_landmarks == 0:
            return np.empty((0, 2)), np.empty((0, 2, 2))
        r, bearing, a, b, c = self._model(sigma_range, sigma_bearing)
        zhat = np.empty((r.size, 2))
        zhat[:, 0] = r
        zhat[:, 1] = bearing
        S = np.empty((r.size, 2, 2))
        S[:, 0, 0] = a
        S[:, 0, 1] = S[:, 1, 0] = b
        S[:, 1, 1] = c
        return zhat, S

    def _model(self, sigma_range: float, sigma_bearing: float):
        """Predicted range and bearing of every landmark and the entries (S00, S01, S11)
        of its innovation covariance (the closed form of :meth:`observation_model`, in
        complex arithmetic: a 2-vector (x, y) is x + iy, which halves the operations);
        the Jacobians are cached for an :meth:`update` from the same state."""
        P = self.P
        d = self.x[3:].view(complex) - complex(self._px, self._py)   # landmark - laser
        J = np.empty((5, d.size))                          # cached for update(), below
        r = np.abs(d, out=J[0])
        if not r.min() >= 1e-9:                            # NaN fails too
            if np.isnan(r).any():
                raise ValueError("the state holds NaN (a landmark position is not finite)")
            raise ValueError("a landmark coincides with the sensor position (range < 1e-9 m)")
        bearing = J[1]
        bearing[:] = wrap_difference(np.arctan2(d.imag, d.real) + (_PI / 2 - self._pphi))
        if self.fej:                                       # Jacobians at the first estimates
            d, J[4] = self._first_estimates()
            ir = J[4]
        else:
            ir = np.divide(1.0, r, out=J[4])
        u = d * ir                                         # unit vector u_x + i u_y
        J[2], J[3] = u.real, u.imag
        p00, p01, p02, p11, p12, p22 = self._p
        n = P.shape[0]
        cx, cy, flat = P[0, 3:], P[1, 3:], P.reshape(-1)   # Cov(x | y, landmarks)
        # The landmarks' marginal blocks are read where they lie, on P's diagonal and
        # superdiagonal (strided views: 1.5 us at n = 673, cheaper than keeping copies).
        m00 = flat[3 * n + 3::2 * n + 2] - 2.0 * cx[0::2] + p00     # M = Cov(l - p)
        m11 = flat[4 * n + 4::2 * n + 2] - 2.0 * cy[1::2] + p11
        half_tr = 0.5 * (m00 + m11)
        C = np.empty(r.size, complex)
        np.subtract(m11, m00, out=C.real)
        C.real *= 0.5
        np.subtract(flat[3 * n + 4::2 * n + 2] - cx[1::2], cy[0::2] - p01, out=C.imag)  # m01
        AB = u * u * C                                     # A + iB
        mv = u.conjugate() * (P[2, 3:].view(complex) - complex(p02, p12))   # u'm + i w'm
        s00 = half_tr - AB.real + sigma_range**2
        s01 = AB.imag * ir - mv.real
        s11 = ((half_tr + AB.real) * ir - 2.0 * mv.imag) * ir + (p22 + sigma_bearing**2)
        # Cached for update(): rows r, bearing, u_x, u_y, 1 / r.
        self._om = [self._px, self._py, self._pphi, self.n_landmarks, J]
        return r, bearing, s00, s01, s11

    def innovation_d2(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        """Squared Mahalanobis distances d2 (n, N) of the detections z (n, 2) to every
        landmark's predicted measurement: :meth:`observation_model` followed by
        ``perception.association.mahalanobis_fast`` (the same formulas, equal to rounding),
        in one pass without building zhat and S (the scan's gating is its costliest step
        after the update). With ``gating='compiled'`` the same formulas run as one compiled
        loop (``slam.compiled.gate_loop``); a state it finds bad is handed to this code,
        which raises its own error."""
        check_sigmas("innovation_d2", sigma_range, sigma_bearing)
        z = check_z("innovation_d2", z)
        self.flush()
        N = self.n_landmarks
        if N == 0:
            return np.empty((z.shape[0], 0))
        status = 0
        if self._gate is not None:                         # the same, as one compiled loop
            if self._first.shape != (N, 2) or not self.P.flags.c_contiguous:
                raise RuntimeError("EkfSlam: the state's arrays do not fit together "
                                   f"({N} landmarks, {self._first.shape[0]} first estimates)")
            J, d2 = np.empty((5, N)), np.empty((z.shape[0], N))
            status = self._gate(self.x[3:].reshape(N, 2), self.P, self._px, self._py,
                                self._pphi, *self._p, self._first, self.fej,
                                np.ascontiguousarray(z), float(sigma_range**2),
                                float(sigma_bearing**2), J, d2)
            if not status:
                self._om = [self._px, self._py, self._pphi, N, J]
                return d2
            # a problem (NaN, a coincident landmark, S not positive definite): the numpy
            # code below finds it again and raises its own error, naming it
        r, bearing, a, b, c = self._model(sigma_range, sigma_bearing)
        det = a * c - b * b
        if not (det.min() > 0.0 and a.min() > 0.0):        # NaN fails too
            S = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
            mahalanobis(z, np.column_stack([r, bearing]), S)    # raises, naming the landmark
        if status:                                         # the two codes disagree
            raise RuntimeError(f"EkfSlam: the compiled gating reported problem {status} "
                               "(slam.compiled) where the numpy gating finds none; "
                               "ANNSLAM_KERNEL=numpy avoids the compiled loop")
        idet = 1.0 / det
        nu_r = z[:, 0, None] - r
        nu_b = wrap_difference(z[:, 1, None] - bearing)
        return ((c * idet) * nu_r - (2.0 * b * idet) * nu_b) * nu_r + (a * idet) * (nu_b * nu_b)

    def update(self, z, lm, sigma_range: float, sigma_bearing: float) -> tuple[float, int]:
        """One batch update with observations z (m, 2) of landmarks lm (m,) (indices;
        a landmark may appear twice). Returns (NIS, dof = 2m)."""
        check_sigmas("update", sigma_range, sigma_bearing)
        z = check_z("update", z)
        self.flush()
        lm_list = lm if type(lm) is list else np.asarray(lm, dtype=np.int64).ravel().tolist()
        m = len(lm_list)
        if m != z.shape[0]:
            raise ValueError(f"update: {z.shape[0]} observations but {m} landmark indices")
        if m and not 0 <= min(lm_list) <= max(lm_list) < self.n_landmarks:
            raise ValueError(f"update: landmark index out of range 0..{self.n_landmarks - 1}")
        if m == 0:
            return 0.0, 0
        uniq = list(dict.fromkeys(lm_list))                # first-seen order
        pos = [uniq.index(j) for j in lm_list] if len(uniq) < m else list(range(m))
        cols = [0, 1, 2]
        for j in uniq:
            cols += (3 + 2 * j, 4 + 2 * j)
        om = self._om
        if om is not None and om[:4] == [self._px, self._py, self._pphi, self.n_landmarks]:
            J = om[4][:, lm_list].tolist()                 # from the gating, same state
        else:
            zhat, _, Hl = observe_fast(self.x[:3], self.landmarks()[lm_list])
            J = np.vstack([zhat.T, Hl[:, 0].T, 1.0 / zhat[:, 0]])
            if self.fej:                                   # u and 1/r at the first estimates
                d, ir = self._first_estimates(lm_list)
                u = d * ir
                J[2], J[3], J[4] = u.real, u.imag, ir
            J = J.tolist()
        # H restricted to the columns cols, filled as a flat list (m is a handful: Python
        # floats beat a dozen small numpy calls): per observation a range row
        # [-u^T, 0 | u^T at its landmark] and a bearing row [-w^T/r, -1 | w^T/r].
        r, bearing, ux, uy, ir = J
        c = len(cols)
        Hc = [0.0] * (2 * m * c)
        nu = []
        for i, (zr, zb) in enumerate(z.tolist()):
            o, q = 2 * i * c, 3 + 2 * pos[i]
            Hc[o], Hc[o + 1], Hc[o + q], Hc[o + q + 1] = -ux[i], -uy[i], ux[i], uy[i]
            o += c
            wx, wy = -uy[i] * ir[i], ux[i] * ir[i]
            Hc[o], Hc[o + 1], Hc[o + 2], Hc[o + q], Hc[o + q + 1] = -wx, -wy, -1.0, wx, wy
            nu += (zr - r[i], (zb - bearing[i] + _PI) % _TWO_PI - _PI)
        return self._correct(cols, np.array(Hc).reshape(2 * m, c), np.array(nu),
                             np.array([sigma_range**2, sigma_bearing**2] * m))

    def _first_estimates(self, idx=slice(None)):
        """(d, 1 / |d|) with d = l_first - (x, y) as complex numbers, for the landmarks ``idx``
        (fej: the observation Jacobians' linearisation points)."""
        d = self._first[idx].view(complex).ravel() - complex(self._px, self._py)
        r = np.abs(d)
        if not r.min() >= 1e-9:
            raise ValueError("a landmark's first estimate coincides with the sensor position "
                             "(range < 1e-9 m): its first-estimates Jacobian is undefined")
        return d, 1.0 / r

    def joint_prediction(self, lm) -> tuple[np.ndarray, np.ndarray]:
        """Predicted measurements zhat (L, 2) of the distinct landmarks ``lm`` and the joint
        covariance C = H P H^T (2L, 2L) of those predictions, with every correlation (no R):
        what joint compatibility (``perception.jcbb``) tests hypotheses against. Uses the
        Jacobians of the last gating from this state (as :meth:`update` does)."""
        self.flush()
        lm_list = np.asarray(lm, dtype=np.int64).ravel().tolist()
        if len(set(lm_list)) != len(lm_list) or (
                lm_list and not 0 <= min(lm_list) <= max(lm_list) < self.n_landmarks):
            raise ValueError(f"joint_prediction: landmark indices must be distinct, in "
                             f"0..{self.n_landmarks - 1}")
        m = len(lm_list)
        if m == 0:
            return np.empty((0, 2)), np.empty((0, 0))
        om = self._om
        if om is None or om[:4] != [self._px, self._py, self._pphi, self.n_landmarks]:
            raise RuntimeError("joint_prediction needs the gating of this state first "
                               "(innovation_d2 or observation_model)")
        r, bearing, ux, uy, ir = om[4][:, lm_list]
        cols = [0, 1, 2] + [c for j in lm_list for c in (3 + 2 * j, 4 + 2 * j)]
        Hc = np.zeros((2 * m, 3 + 2 * m))
        k = np.arange(m)
        wx, wy = -uy * ir, ux * ir
        Hc[2 * k, 0], Hc[2 * k, 1], Hc[2 * k, 3 + 2 * k], Hc[2 * k, 4 + 2 * k] = -ux, -uy, ux, uy
        Hc[2 * k + 1, 0], Hc[2 * k + 1, 1], Hc[2 * k + 1, 2] = -wx, -wy, -1.0
        Hc[2 * k + 1, 3 + 2 * k], Hc[2 * k + 1, 4 + 2 * k] = wx, wy
        c = np.array(cols)                                 # P[cols, cols] from the upper triangle
        C = Hc @ self.P[np.minimum.outer(c, c), np.maximum.outer(c, c)] @ Hc.T
        return np.column_stack([r, bearing]), 0.5 * (C + C.T)

    def gps_update(self, xy, sigma_gps: float, gate: float = math.inf) -> tuple[float, bool]:
        """Position fix of the laser point: H = [I2 0 ...]. Rejected (no change) if its NIS
        exceeds ``gate``. Returns (NIS, accepted)."""
        check_sigmas("gps_update", sigma_gps)
        xy = np.asarray(xy, dtype=float)
        if xy.shape != (2,) or not np.isfinite(xy).all():
            raise ValueError(f"gps_update: xy must be a finite (2,) position, got {xy!r}")
        self.flush()
        nu = xy - self.x[:2]
        nis, _ = self._correct([0, 1], np.eye(2), nu, np.full(2, sigma_gps**2), gate)
        return nis, nis <= gate

    def _rows(self, cols) -> np.ndarray:
        """Full rows ``cols`` of the symmetric P from its upper triangle: row c is the
        column above the diagonal, P[:c, c], then the row from the diagonal on, P[c, c:]."""
        P = self.P
        G = P[cols]                                        # right from the diagonal on
        for r, c in enumerate(cols):
            G[r, :c] = P[:c, c]
        return G

    def _symmetrize(self) -> None:
        """Copy the upper triangle (the stored covariance) into the lower one, so that P
        can be read as a whole (checkpoints and results; O(n^2), never per scan)."""
        P = self.P
        lower = np.tril_indices(P.shape[0], -1)
        P[lower] = P.T[lower]

    def _correct(self, cols, Hc, nu, Rd, gate: float = math.inf):
        P = self.P
        HP = Hc @ self._rows(cols)                         # (k, n) = H P
        S = HP[:, cols] @ Hc.T                             # dpotrf reads its lower triangle
        S.flat[::S.shape[0] + 1] += Rd
        Lc, info = dpotrf(S, lower=1, clean=1)             # S = L L^T
        if info != 0:
            raise InnovationError(
                "innovation covariance S is not positive definite (singular): eigenvalues "
                f"{np.linalg.eigvalsh(S)}; check for zero measurement noise")
        e, info = dtrtrs(Lc, nu, lower=1)                  # e = L^-1 nu
        nis = float(e @ e)
        if not math.isfinite(nis):
            raise ValueError("update produced a non-finite innovation (NaN in the state?)")
        if nis > gate:
            return nis, nu.size
        # W = P H^T L^-T (n, k), Fortran-contiguous: solve W L^T = (HP)^T in place.
        W = dtrsm(1.0, Lc, HP.T, side=1, lower=1, trans_a=1, overwrite_b=1)
        dx = W @ e
        self.x += dx
        if self.fej:                       # the next prediction's Jacobian starts at the prior
            self._cx += float(dx[0])
            self._cy += float(dx[1])
        # P -= W W^T in place, on the upper triangle only (half the flops and traffic of a
        # full dgemm; dsyrk runs near the core's peak at n = 673): P.T is F-contiguous, so dsyrk
        # writes into P itself, and the Fortran lower triangle of P.T is P's upper one.
        PT = P.T
        if dsyrk(-1.0, W, beta=1.0, c=PT, lower=1, overwrite_c=1) is not PT:
            # the silent-copy pitfall (f2py copies an input it cannot use): never let it pass
            raise RuntimeError("in-place covariance update worked on a copy")
        x2 = float(self.x[2])
        if not -_PI < x2 <= _PI:
            self.x[2] = _PI - (_PI - x2) % _TWO_PI
        self._load_vehicle()
        return nis, nu.size

    def add_known_landmarks(self, xy, sigma: float = 0.0) -> np.ndarray:
        """Append landmarks at known positions ``xy`` (k, 2) with covariance sigma^2 I each
        (:func:`slam.base.with_known_landmarks`; EKF localisation, chapter 04a). Returns
        their indices."""
        self.flush()
        N0 = self.n_landmarks
        self.x, self.P = with_known_landmarks(self.x, self.P, xy, sigma)
        self._first = self.x[3:].reshape(-1, 2).copy()
        self._om = None
        return np.arange(N0, self.n_landmarks)

    def augment(self, z, sigma_range: float, sigma_bearing: float) -> np.ndarray:
        """Add landmarks for observations z (k, 2) from the current pose
        (``observation.inverse_observe``). Returns their indices."""
        check_sigmas("augment", sigma_range, sigma_bearing)
        z = check_z("augment", z)
        self.flush()
        k = z.shape[0]
        N0 = self.n_landmarks
        if k == 0:
            return np.empty(0, dtype=np.int64)
        lm, Jp, Jz = inverse_observe(self.x[:3], z)
        if self.fej and (self._cx or self._cy):
            # the heading column at the prior position, as the prediction's (module docstring):
            # d l / d phi = (-(l_y - y), l_x - x) with (x, y) before this scan's update
            Jp[:, 0, 2] -= self._cy
            Jp[:, 1, 2] += self._cx
        n = self.x.size
        P = self.P
        Jp2 = Jp.reshape(2 * k, 3)
        A = Jp2 @ self._rows([0, 1, 2])                   # (2k, n) = J_pose P_v*
        Pn = np.empty((n + 2 * k, n + 2 * k))
        Pn[:n, :n] = P
        Pn[n:, :n] = A
        Pn[:n, n:] = A.T
        Pnn = A[:, :3] @ Jp2.T
        R = np.diag([sigma_range**2, sigma_bearing**2])
        JRJ = Jz @ R @ Jz.transpose(0, 2, 1)
        for i in range(k):
            Pnn[2 * i:2 * i + 2, 2 * i:2 * i + 2] += JRJ[i]
        Pn[n:, n:] = 0.5 * (Pnn + Pnn.T)
        self.P = Pn
        self.x = np.concatenate([self.x, lm.ravel()])
        self._first = np.concatenate([self._first, lm.reshape(-1, 2)])
        self._om = None
        return np.arange(N0, N0 + k)

    def remove(self, idx) -> None:
        """Delete landmarks ``idx`` (marginalise them out: drop their rows and columns).
        Copied block by block between the removed rows: about one copy of P."""
        idx = np.unique(check_remove(idx, self.n_landmarks))
        if idx.size == 0:
            return
        self.flush()
        n = self.x.size
        drop = np.sort(np.concatenate([3 + 2 * idx, 4 + 2 * idx]))
        keep = np.ones(n, dtype=bool)
        keep[drop] = False
        starts = np.concatenate([[0], drop + 1])
        ends = np.concatenate([drop, [n]])
        runs = [(a, b) for a, b in zip(starts.tolist(), ends.tolist()) if b > a]
        m = n - drop.size
        Pn = np.empty((m, m))
        P = self.P
        r0 = 0
        for a, b in runs:
            c0 = 0
            for c, d in runs:
                Pn[r0:r0 + b - a, c0:c0 + d - c] = P[a:b, c:d]
                c0 += d - c
            r0 += b - a
        self.P = Pn
        self.x = self.x[keep]
        self._first = np.delete(self._first, idx, axis=0)
        self._om = None

    def health(self) -> tuple[float, float]:
        """(smallest eigenvalue of P, max |P - P^T|). P is stored as its upper triangle
        (symmetric by construction), so the asymmetry is that of the matrix made whole,
        i.e. zero; the dense reference's is a real measurement."""
        self.flush()
        self._symmetrize()
        P = self.P
        lo = float(eigh(P, eigvals_only=True, subset_by_index=[0, 0], check_finite=False)[0])
        return lo, float(np.max(np.abs(P - P.T)))



def _sheared(p, e0: float, e1: float) -> tuple:
    """The six entries (00, 01, 02, 11, 12, 22) of E P E^T for the pose block P given by
    ``p`` and the shear E = [[1, 0, e0], [0, 1, e1], [0, 0, 1]] (a compounded motion
    Jacobian, or the FEJ correction). The per-sample loop of ``predict_many`` writes the
    same products inline, with the step's noise folded in."""
    p00, p01, p02, p11, p12, p22 = p
    return (p00 + 2.0 * e0 * p02 + e0 * e0 * p22,
            p01 + e0 * p12 + e1 * p02 + e0 * e1 * p22,
            p02 + e0 * p22,
            p11 + 2.0 * e1 * p12 + e1 * e1 * p22,
            p12 + e1 * p22,
            p22)


def diag_blocks(P) -> np.ndarray:
    """The landmarks' 2x2 diagonal blocks of the C-contiguous P as a (N, 2, 2) strided view."""
    n = P.shape[0]
    N = (n - 3) // 2
    s = P.strides[1]
    return np.lib.stride_tricks.as_strided(P[3:, 3:], shape=(N, 2, 2),
                                           strides=((2 * n + 2) * s, n * s, s), writeable=False)
