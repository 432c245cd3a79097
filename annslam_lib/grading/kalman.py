"""Checks for the graded exercises of chapter 01a (the Kalman filter).

``check_update_1d``: the 1-D update (posterior mean and variance), with a ValueError for
negative variances and for var = r = 0. ``check_kalman_gain``: K = P H^T S^-1 for any
state and measurement size, with a ValueError when S is not positive definite.
``check_gate``: the chi-square gate of an innovation of any dimension.
``check_steady_state``: the stationary posterior variance of a 1-D filter, derived from
the scalar Riccati equation. References: :mod:`annslam_lib.slam.kalman` and
:func:`annslam_lib.slam.kalman.kalman_gain`.
"""
from __future__ import annotations

import functools
import math

import numpy as np
from scipy.stats import chi2

from ..slam import kalman
from ..slam.kalman import kalman_gain
from .core import GradingError, Mistake, passed, call, check_function, check_raises, describe, fail, forbids, prefetch

__all__ = ["check_update_1d", "check_kalman_gain", "check_gate", "check_steady_state"]



# ----------------------------------------------------------------------------- 1a.1 1-D update

_U_ARGS = ("mu", "var", "z", "r")


def _update_reference(mu, var, z, r):
    m, v, _ = kalman.update_1d(mu, var, z, r)
    return m, v


def _update_cases(seed: int, n: int) -> list[tuple]:
    """The chapter's numbers, a very precise and a very vague measurement, an exact prior
    (var = 0) and a noiseless measurement (r = 0), then ``n`` seeded random cases with
    var and r spread over four decades (so that no fixed weight passes)."""
    cases = [(12.0, 0.34, 12.4, 0.16), (0.0, 1.0, 2.0, 1.0), (5.0, 4.0, -1.0, 0.01),
             (5.0, 0.01, -1.0, 4.0), (3.0, 0.0, 7.0, 0.5), (3.0, 0.5, 7.0, 0.0),
             (-20.0, 2.5, -18.0, 0.3)]
    rng = np.random.default_rng(seed)
    for _ in range(n):
        var, r = 10.0 ** rng.uniform(-2, 2, size=2)
        mu = float(rng.uniform(-50, 50))
        cases.append((mu, float(var), mu + float(rng.normal(0, 2 * math.sqrt(var + r))), float(r)))
    return cases


def _weights(f):
    """A wrong gain used consistently: in the mean and in (1 - K) var."""
    def wrong(mu, var, z, r):
        K = f(var, r)
        return mu + K * (z - mu), (1.0 - K) * var
    return wrong


@forbids(kalman.update_1d)
def check_update_1d(fn, *, seed: int = 0, n: int = 40, name: str = "my_update_1d",
                    quiet: bool = False) -> str:
    """Grade ``fn(mu, var, z, r) -> (mu_post, var_post)``, chapter 01a eq. 1a.4:
    K = var / (var + r), mu+ = mu + K (z − mu), var+ = (1 − K) var; ValueError for a
    negative variance and for var = r = 0. Reference: ``kalman.update_1d``.

    Catches the weights swapped (K = r / (var + r)), the innovation's sign, the variances
    added or averaged, the posterior variance K var, the prior variance returned
    unchanged, and the standard deviations combined instead of the variances.
    """
    cases = _update_cases(seed, n)
    mistakes = [
        Mistake(f"{name} gives the weight to the wrong side: the prior and the measurement "
                "have swapped weights. An uncertain prior (large var) should move a long way "
                "towards z, a precise one hardly at all: check which variance makes the gain "
                "grow.",
                _weights(lambda var, r: r / (var + r)),
                answer="The gain grows with the PRIOR's variance: K = var / (var + r), "
                       "mu+ = mu + K (z − mu)."),
        Mistake(f"{name} moves the mean away from the measurement: the innovation has the "
                "wrong sign.",
                lambda mu, var, z, r: (mu - var / (var + r) * (z - mu),
                                       _update_reference(mu, var, z, r)[1]),
                answer="The innovation is z − mu, so mu+ = mu + K (z − mu)."),
        Mistake(f"{name}'s posterior variance is the share of the prior's variance that the "
                "measurement REMOVES, not the share that is left. It must be smaller than both "
                "var and r: two independent pieces of information add up.",
                lambda mu, var, z, r: (_update_reference(mu, var, z, r)[0], var * var / (var + r)),
                answer="var+ = (1 − K)·var = var·r / (var + r), i.e. 1/var+ = 1/var + 1/r."),
        Mistake(f"{name} adds the variances: that is the variance of a PREDICTION (two "
                "independent errors added); a measurement brings information, so the "
                "posterior variance is smaller than both.",
                lambda mu, var, z, r: (_update_reference(mu, var, z, r)[0], var + r),
                answer="var+ = var·r / (var + r)."),
        Mistake(f"{name} returns the prior's variance unchanged: the update must also shrink "
                "it.",
                lambda mu, var, z, r: (_update_reference(mu, var, z, r)[0], var),
                answer="var+ = (1 − K) var."),
        Mistake(f"{name} weights by the standard deviations: the product of two Gaussians "
                "weights by another power of them (look at the exponents you add).",
                _weights(lambda var, r: math.sqrt(var) / (math.sqrt(var) + math.sqrt(r))),
                answer="It weights by the VARIANCES, K = var / (var + r)."),
    ]
    check_function(fn, _update_reference, cases, name=name, arg_names=_U_ARGS,
                   labels=("mu_post", "var_post"), mistakes=mistakes, what="kalman.update_1d",
                   quiet=True)
    bad = [((1.0, -0.5, 2.0, 0.1), "var < 0 is no variance"),
           ((1.0, 0.5, 2.0, -0.1), "r < 0 is no variance"),
           ((1.0, 0.0, 2.0, 0.0), "var = r = 0: a state known exactly, measured exactly "
            "somewhere else, has no posterior (K = 0 / 0)")]
    for args, why in bad:
        check_raises(fn, args, name=name, why=why, arg_names=_U_ARGS)
    return passed(f"✓ {name} agrees with kalman.update_1d on {len(cases)} inputs and raises "
                  f"ValueError for all {len(bad)} impossible ones.", quiet)


# ----------------------------------------------------------------------------- 1a.2 the gain

_K_ARGS = ("P", "H", "R")


def _gain_reference(P, H, R):
    return kalman_gain(P, H, R)[0]


def _random_cov(rng, n, scale=1.0):
    A = rng.normal(size=(n, n)) * scale
    return A @ A.T / n + 1e-3 * scale**2 * np.eye(n)


def _gain_cases(seed: int, n: int) -> list[tuple]:
    """Shapes 1x1, 2-state/1-measurement (the chapter's position-velocity example),
    3-state/2-measurement (the car's pose seen by range and bearing), 5x2 and 4x3, with
    correlated P and R, then ``n`` seeded random ones."""
    rng = np.random.default_rng(seed)
    cases = [(np.array([[0.34]]), np.array([[1.0]]), np.array([[0.16]])),
             (np.array([[1.0, 0.5], [0.5, 2.0]]), np.array([[1.0, 0.0]]), np.array([[0.25]]))]
    for (ns, m) in [(3, 2), (5, 2), (4, 3), (2, 2), (6, 1)]:
        cases.append((_random_cov(rng, ns), rng.normal(size=(m, ns)), _random_cov(rng, m, 0.5)))
    for _ in range(n):
        ns = int(rng.integers(1, 7))
        m = int(rng.integers(1, ns + 1))
        cases.append((_random_cov(rng, ns, 10 ** rng.uniform(-1, 1)), rng.normal(size=(m, ns)),
                      _random_cov(rng, m, 10 ** rng.uniform(-1, 0.5))))
    return cases


def _elementwise(P, H, R):
    S = H @ P @ H.T + R
    return P @ H.T / S


@forbids(kalman_gain)
def check_kalman_gain(fn, *, seed: int = 0, n: int = 30, name: str = "my_kalman_gain",
                      quiet: bool = False) -> str:
    """Grade ``fn(P, H, R) -> K``, chapter 01a eq. 1a.6: K = P H^T S^-1 with
    S = H P H^T + R, for any state size n and measurement size m (K is n x m); ValueError
    when S is not positive definite. Reference: ``kalman.kalman_gain``.

    Catches R^-1 instead of S^-1, S instead of S^-1, S without R, an elementwise division
    by S (right only when m = 1), only S's diagonal, and H^T S^-1 without P.
    """
    cases = _gain_cases(seed, n)
    inv = np.linalg.inv
    mistakes = [
        Mistake(f"{name} divides by S elementwise. That is right when the measurement is a "
                "single number (m = 1), and wrong as soon as it has two correlated components: "
                "'dividing' by a matrix means its matrix inverse.", _elementwise,
                answer="K = P Hᵀ S⁻¹: np.linalg.solve(S, H @ P).T or P @ H.T @ np.linalg.inv(S)."),
        Mistake(f"{name} uses R⁻¹ instead of S⁻¹. With R alone the filter forgets that the "
                "prediction H x is itself uncertain.",
                lambda P, H, R: P @ H.T @ inv(R), answer="K = P Hᵀ (H P Hᵀ + R)⁻¹."),
        Mistake(f"{name} multiplies by S instead of its inverse.",
                lambda P, H, R: P @ H.T @ (H @ P @ H.T + R), answer="K = P Hᵀ S⁻¹."),
        Mistake(f"{name} leaves R out of S: the measurement's own noise is what keeps the "
                "gain below 1.", lambda P, H, R: P @ H.T @ inv(H @ P @ H.T),
                answer="S = H P Hᵀ + R."),
        Mistake(f"{name} inverts only the diagonal of S: the measurement components are "
                "correlated through H P Hᵀ, so S⁻¹ needs the full inverse.",
                lambda P, H, R: P @ H.T @ np.diag(1 / np.diag(H @ P @ H.T + R))),
        Mistake(f"{name} forgets P in front (the gain carries the state's uncertainty back "
                "from measurement space to state space).",
                lambda P, H, R: H.T @ inv(H @ P @ H.T + R), answer="K = P Hᵀ S⁻¹."),
    ]
    shapes: dict[tuple, list] = {}
    for c in cases:                  # check_function compares outputs of one shape at a time
        shapes.setdefault(c[1].shape, []).append(c)
    # single measurements first: a gain right for m = 1 only is then named as such
    for H_shape, group in sorted(shapes.items(), key=lambda kv: kv[0][0] > 1):
        _check_shapes(fn, group, name=name, scalar_ok=H_shape[0] > 1)
        check_function(fn, _gain_reference, group, name=name, arg_names=_K_ARGS,
                       mistakes=mistakes, what="kalman.kalman_gain", quiet=True, rtol=1e-6,
                       atol=1e-9)
    v = np.array([[1.0, 2.0, 0.5]])
    bad = [((np.zeros((2, 2)), np.eye(2), np.zeros((2, 2))), "P = 0 and R = 0 make S = 0: a "
            "known state measured without noise has no gain (S⁻¹ does not exist)"),
           ((v.T @ v, np.eye(3)[:2], np.zeros((2, 2))), "S = H P Hᵀ + R is singular here "
            "(P has rank 1 and R = 0); its inverse is rounding noise. Test that S is "
            "positive definite (np.linalg.eigvalsh(S)[0] > 0, or catch "
            "np.linalg.LinAlgError from np.linalg.cholesky) and raise ValueError"),
           ((np.eye(2), np.eye(2), -2 * np.eye(2)), "S = P + R = -I is negative definite: "
            "no covariance")]
    for args, why in bad:
        check_raises(fn, args, name=name, why=why, arg_names=_K_ARGS)
    return passed(f"✓ {name} agrees with kalman.kalman_gain on {len(cases)} inputs (states of 1 "
                  f"to 6 entries, measurements of 1 to 6) and raises ValueError for all "
                  f"{len(bad)} S that are not positive definite.", quiet)


def _check_shapes(fn, cases, *, name, scalar_ok: bool) -> None:
    """K must be n x m: say so with the shapes (a transposed gain is the common slip).
    ``scalar_ok``: every single-measurement case has passed, so an error here is the
    mistake of a gain written for m = 1 only."""
    prefetch(fn, cases)
    for c in cases:
        try:
            out = call(fn, c, name=name, arg_names=_K_ARGS)
        except GradingError as e:
            if not scalar_ok or "raised" not in str(e):
                raise
            fail(f"{e}\nYour gain is right for every single measurement (m = 1) and fails "
                 f"for m = {c[1].shape[0]}: there S is an m x m matrix, and 'dividing' by it "
                 f"means multiplying by its inverse (np.linalg.solve or np.linalg.inv), not the "
                 f"elementwise '/' or float(S).")
        try:
            shape = np.shape(np.asarray(out, dtype=float))
        except (TypeError, ValueError):
            return                                # check_function reports what it is
        n, m = c[0].shape[0], c[1].shape[0]
        if shape == (n, m):
            continue
        hint = (" It looks transposed: K maps an innovation (m entries) to a state correction "
                "(n entries), so K = P Hᵀ S⁻¹ is n x m." if shape == (m, n) else "")
        fail(f"{name}({describe(c, _K_ARGS)}) returned an array of shape {shape}; a state of "
             f"{n} and a measurement of {m} need K of shape ({n}, {m}).{hint}")


# ----------------------------------------------------------------------------- 1a.3 the gate

_G_ARGS = ("nu", "S", "p")
_PROBS = (0.9, 0.95, 0.99, 0.999)


@functools.lru_cache(maxsize=None)
def chi2_ppf(p: float, dof: float) -> float:
    """chi2.ppf as a float, cached: the gate checks (here, ``localisation``,
    ``association``) evaluate a few quantiles many times."""
    # not models.uncertainty.chi2_quantile: its closed form at 2 dof differs in the last bits
    return float(chi2.ppf(p, dof))


def _gate_reference(nu, S, p) -> bool:
    return kalman.innovation_gate(nu, S, p)[2]


def _gate_cases(seed: int, n: int) -> list[tuple]:
    """Innovations of 1, 2 and 3 entries placed at 0.5, 0.9, 1.1 and 2 times the threshold
    of each probability (so a wrong dof or quantile flips some decisions), including the
    1-D '3 sigma' point and correlated S, then ``n`` seeded random ones."""
    rng = np.random.default_rng(seed)
    cases = [(np.array([2.9]), np.array([[1.0]]), 0.997), (np.array([3.1]), np.array([[1.0]]), 0.997)]
    for dof in (1, 2, 3):
        for p in _PROBS:
            for f in (0.5, 0.9, 1.1, 2.0):
                S = _random_cov(rng, dof, 0.5)
                u = rng.normal(size=dof)
                u /= math.sqrt(u @ np.linalg.solve(S, u))       # d2(u) = 1
                cases.append((u * math.sqrt(f * chi2_ppf(p, dof)), S, p))
    for _ in range(n):
        dof = int(rng.integers(1, 4))
        S = _random_cov(rng, dof, 10 ** rng.uniform(-1, 1))
        nu = rng.multivariate_normal(np.zeros(dof), S) * rng.choice([1.0, 2.0, 3.0])
        d2 = nu @ np.linalg.solve(S, nu)
        p = float(rng.choice(_PROBS))
        if abs(d2 - chi2_ppf(p, dof)) > 1e-6 * chi2_ppf(p, dof):
            cases.append((nu, S, p))
    return cases


def _d2(nu, S):
    return float(nu @ np.linalg.solve(S, nu))


def _gate_mistakes(name: str) -> list[Mistake]:
    return [
        Mistake(f"{name} always uses 2 degrees of freedom. d2 = νᵀ S⁻¹ ν has as many "
                "degrees of freedom as ν has entries: a GPS height alone has 1, a "
                "range-bearing pair 2, a 3-D position 3.",
                lambda nu, S, p: _d2(nu, S) <= chi2_ppf(p, 2), answer="Use chi2.ppf(p, len(nu))."),
        Mistake(f"{name} always uses 1 degree of freedom, whatever the size of ν.",
                lambda nu, S, p: _d2(nu, S) <= chi2_ppf(p, 1), answer="Use chi2.ppf(p, len(nu))."),
        Mistake(f"{name} uses the quantile of 1 − p: that threshold keeps only 1 − p of the "
                "right measurements, and the gate must keep the share p.",
                lambda nu, S, p: _d2(nu, S) <= chi2_ppf(1 - p, len(nu)),
                answer="The threshold is chi2.ppf(p, dof)."),
        Mistake(f"{name} compares the distance √d2 with the chi-square quantile: the "
                "quantile is for the squared distance d2 = νᵀ S⁻¹ ν.",
                lambda nu, S, p: math.sqrt(_d2(nu, S)) <= chi2_ppf(p, len(nu))),
        Mistake(f"{name} computes νᵀ S ν: the Mahalanobis distance divides by the "
                "uncertainty, it does not multiply by it.",
                lambda nu, S, p: float(nu @ S @ nu) <= chi2_ppf(p, len(nu)),
                answer="d2 = νᵀ S⁻¹ ν."),
        Mistake(f"{name} uses only the diagonal of S: the components of ν are correlated "
                "(S has off-diagonal terms), so d2 needs the full inverse.",
                lambda nu, S, p: float(np.sum(nu**2 / np.diag(S))) <= chi2_ppf(p, len(nu))),
        Mistake(f"{name} is inverted: it must return True when the innovation is INSIDE the "
                "gate (d2 <= threshold), i.e. when the measurement is accepted.",
                lambda nu, S, p: _d2(nu, S) > chi2_ppf(p, len(nu))),
    ]


def _bool(out, name, where) -> bool:
    if isinstance(out, (bool, np.bool_)) or (isinstance(out, (int, np.integer)) and out in (0, 1)):
        return bool(out)
    if isinstance(out, np.ndarray) and out.size == 1 and out.dtype == bool:
        return bool(out.ravel()[0])
    fail(f"{name}({where}) returned {out!r:.60}; it should return True (accepted, inside the "
         f"gate) or False.")


@forbids(kalman.innovation_gate)
def check_gate(fn, *, seed: int = 0, n: int = 40, name: str = "my_gate",
               quiet: bool = False) -> str:
    """Grade ``fn(nu, S, p) -> bool``, chapter 01a eq. 1a.8: True iff
    νᵀ S⁻¹ ν <= chi2.ppf(p, len(ν)), for innovations of 1, 2 and 3 entries.
    Reference: ``kalman.innovation_gate``.

    Catches a fixed number of degrees of freedom (2 or 1), chi2.ppf(1 − p), √d2 against
    the quantile, νᵀ S ν, only S's diagonal, an inverted decision.
    """
    cases = _gate_cases(seed, n)
    prefetch(fn, cases)
    got = [_bool(call(fn, c, name=name, arg_names=_G_ARGS), name, describe(c, _G_ARGS))
           for c in cases]
    exp = [_gate_reference(*c) for c in cases]
    if got != exp:
        for m in _gate_mistakes(name):
            if [bool(m.wrong(*c)) for c in cases] == got:
                fail(m.text)
        k = next(i for i in range(len(cases)) if got[i] != exp[i])
        nu, S, p = cases[k]
        d2, t = _d2(nu, S), chi2_ppf(p, len(nu))
        fail(f"{name}({describe(cases[k], _G_ARGS)}) returned {got[k]}, expected {exp[k]}: "
             f"d2 = νᵀ S⁻¹ ν = {d2:.4g} against chi2.ppf({p}, {len(nu)}) = {t:.4g}. "
             f"{sum(g != e for g, e in zip(got, exp))} of {len(cases)} decisions differ.")
    return passed(f"✓ {name} agrees with kalman.innovation_gate on {len(cases)} innovations of "
                  f"1 to 3 entries.", quiet)


# ----------------------------------------------------------------------------- 1a.4 steady state

_S_ARGS = ("q", "r")


def _steady_reference(q, r) -> float:
    return kalman.steady_state_variance(q, r)[1]


def _steady_cases(seed: int, n: int) -> list[tuple]:
    """The chapter's (q, r), q = r, q much smaller and much larger than r, q = 0 (nothing
    moves: the variance goes to 0) and r = 0, then ``n`` seeded random pairs over six
    decades."""
    rng = np.random.default_rng(seed)
    cases = [(0.09, 0.16), (1.0, 1.0), (1e-4, 1.0), (1.0, 1e-4), (0.0, 0.5), (0.5, 0.0),
             (2.0, 0.3)]
    cases += [(float(10 ** rng.uniform(-3, 3)), float(10 ** rng.uniform(-3, 3))) for _ in range(n)]
    return cases


def _p_minus(q, r):
    return 0.5 * (q + math.sqrt(q * q + 4 * q * r))


@forbids(kalman.steady_state_variance)
def check_steady_state(fn, *, seed: int = 0, n: int = 40, name: str = "my_steady_state",
                       quiet: bool = False) -> str:
    """Grade ``fn(q, r) -> p_plus``, chapter 01a eq. 1a.9: the posterior variance a 1-D
    filter settles at when each step adds process noise q and then updates with a
    measurement of noise r. Reference: ``kalman.steady_state_variance``.

    Catches the prior's variance p− returned instead of p+, the other root of the quadratic,
    q and r swapped, and the standard deviation returned instead of the variance.
    """
    cases = _steady_cases(seed, n)
    mistakes = [
        Mistake(f"{name} returns the PRIOR's stationary variance p− (just before each "
                "update). The question asks for the posterior, just after the update.",
                _p_minus, answer="p+ = p− − q, or equally p− r / (p− + r)."),
        Mistake(f"{name} takes the negative root of the quadratic: that is no variance. Keep "
                "the positive root.",
                lambda q, r: 0.5 * (q - math.sqrt(q * q + 4 * q * r)) - q,
                answer="p− = (q + √(q² + 4 q r)) / 2 is the root of p−² − q p− − q r = 0 to keep."),
        Mistake(f"{name} has q and r swapped: check which variance the prediction adds "
                "(q) and which the measurement has (r).", lambda q, r: _steady_reference(r, q)),
        Mistake(f"{name} returns a standard deviation: the question asks for the variance "
                "p+ (its square).", lambda q, r: math.sqrt(_steady_reference(q, r))),
    ]
    check_function(fn, _steady_reference, cases, name=name, arg_names=_S_ARGS,
                   mistakes=mistakes, what="kalman.steady_state_variance", quiet=True,
                   rtol=1e-6, atol=1e-12)
    return passed(f"✓ {name} agrees with kalman.steady_state_variance on {len(cases)} (q, r) "
                  f"pairs from 1e-3 to 1e3.", quiet)
