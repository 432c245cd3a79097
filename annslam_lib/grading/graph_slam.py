"""Checks for the graded exercises of chapter 11 (graph-SLAM from scratch).

``check_whitened_range_bearing``: a detection's whitened error and its Jacobians, eq. (11.2).
``check_gauss_newton_step``: one Gauss-Newton step from the sparse normal equations, eq. (11.4).
``check_huber_weights``: the weights that make a least-squares step minimise Huber's loss,
eq. (11.6).
References: :mod:`annslam_lib.smoothing.gauss_newton` (itself tested against GTSAM).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from ..models.geometry import wrap_angle
from ..models.observation import observe
from ..smoothing import gauss_newton
from .core import Mistake, check_function, forbids, passed

__all__ = ["check_whitened_range_bearing", "check_gauss_newton_step", "check_huber_weights",
           "whitened_range_bearing", "gauss_newton_step", "huber_weights"]


# --------------------------------------------------------- 11.1 one detection's rows

def whitened_range_bearing(pose, landmark, z, sigma_range, sigma_bearing):
    """Reference of exercise 11.1, eq. (11.2): e_w = (wrap(beta_hat - beta) / sigma_beta,
    (r_hat - r) / sigma_r) and its Jacobians with respect to the pose (2, 3) and the
    landmark (2, 2), rows in the same (bearing, range) order."""
    zhat, Hp, Hl = observe(np.asarray(pose, float), np.asarray(landmark, float))
    w = np.array([1.0 / sigma_bearing, 1.0 / sigma_range])
    e = np.array([float(wrap_angle(zhat[1] - z[1])), zhat[0] - z[0]]) * w
    return e, Hp[[1, 0]] * w[:, None], Hl[[1, 0]] * w[:, None]


def _flat(out):
    e, jp, jl = out
    return np.concatenate([np.ravel(np.asarray(e, float)), np.ravel(np.asarray(jp, float)),
                           np.ravel(np.asarray(jl, float))])


_WR_LABELS = ("e_bearing", "e_range",
              *(f"d e_{r} / d {c}" for r in ("bearing", "range") for c in ("x", "y", "phi")),
              *(f"d e_{r} / d m_{c}" for r in ("bearing", "range") for c in ("x", "y")))


def _wr_cases(seed: int, n: int) -> list[tuple]:
    rng = np.random.default_rng(seed)
    cases = []
    pose = np.array([0.0, 0.0, 0.0])
    a = -math.pi / 2 + math.pi - 0.003                   # laser bearing pi - 0.003
    cases.append((pose, 10 * np.array([math.cos(a), math.sin(a)]),
                  np.array([10.2, -math.pi + 0.004]), 0.1, 0.01))
    for _ in range(n):
        pose = np.array([rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-math.pi, math.pi)])
        ang, r = rng.uniform(-math.pi, math.pi), rng.uniform(2, 40)
        lm = pose[:2] + r * np.array([math.cos(ang), math.sin(ang)])
        z = observe(pose, lm)[0] + rng.normal(0, [0.3, 0.05])
        z[1] = wrap_angle(z[1])
        cases.append((pose, lm, z, float(rng.uniform(0.02, 0.5)), float(rng.uniform(0.002, 0.05))))
    return cases


def _wr_mistakes(name: str) -> list[Mistake]:
    def not_whitened(pose, lm, z, sr, sb):
        e, jp, jl = whitened_range_bearing(pose, lm, z, 1.0, 1.0)
        return e, jp, jl

    def by_variance(pose, lm, z, sr, sb):
        return whitened_range_bearing(pose, lm, z, sr * sr, sb * sb)

    def range_first(pose, lm, z, sr, sb):
        e, jp, jl = whitened_range_bearing(pose, lm, z, sr, sb)
        return e[::-1], jp[::-1], jl[::-1]

    def measured_minus_predicted(pose, lm, z, sr, sb):
        e, jp, jl = whitened_range_bearing(pose, lm, z, sr, sb)
        return -e, jp, jl

    def unwrapped(pose, lm, z, sr, sb):
        zhat = observe(np.asarray(pose, float), np.asarray(lm, float))[0]
        e, jp, jl = whitened_range_bearing(pose, lm, z, sr, sb)
        e = e.copy()
        e[0] = (zhat[1] - z[1]) / sb
        return e, jp, jl

    def flat(f):
        return lambda *a: _flat(f(*a))

    return [
        Mistake(f"{name} does not whiten: each error row is divided by its own standard "
                "deviation, so that a 1 m range error and a 1 rad bearing error weigh what "
                "their noise says.", flat(not_whitened), "e_w = L⁻¹ e with R = L Lᵀ: divide "
                "by σ_β and σ_r."),
        Mistake(f"{name} divides by the variances: whitening divides by the standard "
                "deviations (the square root of R's diagonal).", flat(by_variance),
                "σ, not σ²."),
        Mistake(f"{name} puts the range first: the rows are ordered (bearing, range), as the "
                "factor's noise model of chapter 10.", flat(range_first),
                "Bearing row first, in e and in both Jacobians."),
        Mistake(f"{name} returns measured − predicted in the error but the Jacobians of the "
                "prediction: the error and its Jacobian must be of the same function.",
                flat(measured_minus_predicted), "e = h(x) ⊖ z, and J = ∂e/∂x = ∂h/∂x."),
        Mistake(f"{name} does not wrap the bearing error.", flat(unwrapped),
                "Wrap β̂ − β into (−π, π] before dividing by σ_β."),
    ]


@forbids(gauss_newton.linearise, gauss_newton.cost, whitened_range_bearing)
def check_whitened_range_bearing(fn, *, seed: int = 0, n: int = 30,
                                 name: str = "my_whitened_range_bearing",
                                 quiet: bool = False) -> str:
    """Grade ``fn(pose, landmark, z, sigma_range, sigma_bearing) -> (e_w (2,), J_pose (2, 3),
    J_landmark (2, 2))``, chapter 11 eq. (11.2). Reference: :func:`whitened_range_bearing`
    (the rows :func:`~annslam_lib.smoothing.gauss_newton.linearise` builds)."""
    cases = _wr_cases(seed, n)
    check_function(fn, whitened_range_bearing, cases, name=name,
                   arg_names=("pose", "landmark", "z", "sigma_range", "sigma_bearing"),
                   labels=_WR_LABELS, output=_flat, wrap=False, mistakes=_wr_mistakes(name),
                   what="the whitened rows of smoothing.gauss_newton", quiet=True,
                   rtol=1e-5, atol=1e-6)
    return passed(f"✓ {name} agrees with the whitened rows of smoothing.gauss_newton on "
                  f"{len(cases)} sightings (one across the bearing seam).", quiet)


# ------------------------------------------------------------------ 11.2 a Gauss-Newton step

def gauss_newton_step(J, e):
    """Reference of exercise 11.2, eq. (11.4): dx solving (J^T J) dx = -J^T e."""
    J = sp.csc_matrix(J)
    H = (J.T @ J).tocsc()
    from scipy.sparse.linalg import spsolve

    return spsolve(H, -(J.T @ np.asarray(e, float)))


def _gn_cases(seed: int, n: int) -> list[tuple]:
    """Sparse Jacobians of chains of 4 poses and 2 landmarks (12 unknowns, 3 to 5 nonzero
    entries a row) and their errors; a tall dense one."""
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n):
        m = int(rng.integers(20, 40))
        rows = []
        for _r in range(m):
            row = np.zeros(12)
            cols = rng.choice(12, int(rng.integers(3, 6)), replace=False)
            row[cols] = rng.normal(0, 3, cols.size)
            rows.append(row)
        J = np.vstack(rows + [np.eye(12) * 0.5])            # a prior on every unknown
        cases.append((sp.csr_matrix(J), rng.normal(0, 2, J.shape[0])))
    return cases


def _gn_mistakes(name: str) -> list[Mistake]:
    def uphill(J, e):
        return -gauss_newton_step(J, e)

    def gradient(J, e):
        return -(sp.csr_matrix(J).T @ np.asarray(e, float))

    def damped(J, e):
        J = sp.csc_matrix(J)
        from scipy.sparse.linalg import spsolve

        H = (J.T @ J + sp.identity(J.shape[1])).tocsc()
        return spsolve(H, -(J.T @ np.asarray(e, float)))

    return [
        Mistake(f"{name} steps uphill: the step solves H dx = −Jᵀe (the minus sign makes "
                "the cost fall).", uphill, "dx = −(JᵀJ)⁻¹ Jᵀ e."),
        Mistake(f"{name} returns the gradient's direction −Jᵀe without solving with the "
                "information matrix: that is gradient descent, whose step has the wrong "
                "length and direction.", gradient, "Solve (JᵀJ) dx = −Jᵀe."),
        Mistake(f"{name} adds a damping term (JᵀJ + I): that is Levenberg-Marquardt, not "
                "Gauss-Newton.", damped, "H = JᵀJ, no added diagonal."),
    ]


@forbids(gauss_newton.solve_gauss_newton, gauss_newton.step, gauss_newton_step)
def check_gauss_newton_step(fn, *, seed: int = 0, n: int = 12,
                            name: str = "my_gauss_newton_step", quiet: bool = False) -> str:
    """Grade ``fn(J, e) -> dx``, chapter 11 eq. (11.4): one Gauss-Newton step from the
    sparse Jacobian J (a scipy.sparse matrix) and the whitened errors e. Reference:
    :func:`gauss_newton_step`."""
    cases = _gn_cases(seed, n)
    check_function(fn, gauss_newton_step, cases, name=name, arg_names=("J", "e"),
                   labels=tuple(f"dx[{i}]" for i in range(12)),
                   output=lambda out: np.ravel(np.asarray(out, dtype=float)),
                   mistakes=_gn_mistakes(name), what="the normal equations' solution",
                   quiet=True, rtol=1e-6, atol=1e-9)
    return passed(f"✓ {name} solves the normal equations on {len(cases)} sparse problems.",
                  quiet)


# ------------------------------------------------------------------ 11.3 Huber's weights

def huber_weights(r, k):
    """Reference of exercise 11.3, eq. (11.6): w = 1 where r <= k, k / r beyond."""
    return gauss_newton.huber(np.asarray(r, float), float(k))[1]


def _hw_cases(seed: int, n: int) -> list[tuple]:
    rng = np.random.default_rng(seed)
    cases = [(np.array([0.01, 0.5, 1.0, 1.5, 4.0, 100.0]), 1.0),
             (np.array([1e-3, 2.0, 2.0 + 1e-9, 3.0, 0.1, 50.0]), 2.0)]
    for _ in range(n):
        cases.append((np.abs(rng.normal(0, 3, 6)) + 1e-3, float(rng.uniform(0.5, 3.0))))
    return cases


def _hw_mistakes(name: str) -> list[Mistake]:
    def everywhere(r, k):
        return k / np.asarray(r, float)

    def inverted(r, k):
        r = np.asarray(r, float)
        return np.where(r > k, r / k, 1.0)

    def squared_threshold(r, k):
        r = np.asarray(r, float)
        return np.where(r * r > k, k / r, 1.0)

    def square_root(r, k):
        return np.sqrt(huber_weights(r, k))

    return [
        Mistake(f"{name} uses k/r for every error: within the threshold Huber's loss is the "
                "ordinary square, weight 1.", everywhere, "w = 1 for r ≤ k."),
        Mistake(f"{name} gives large errors MORE weight (r/k): a robust loss must trust them "
                "less.", inverted, "w = k/r for r > k."),
        Mistake(f"{name} compares r² with k: the threshold is on the whitened error's norm r.",
                squared_threshold, "r > k, not r² > k."),
        Mistake(f"{name} returns √w, the factor each row is scaled by: the weight itself is "
                "w = ρ'(r)/r.", square_root, "Rows are scaled by √w; the weight is w."),
    ]


@forbids(gauss_newton.huber, huber_weights)
def check_huber_weights(fn, *, seed: int = 0, n: int = 20, name: str = "my_huber_weights",
                        quiet: bool = False) -> str:
    """Grade ``fn(r, k) -> w`` (arrays), chapter 11 eq. (11.6): the iteratively reweighted
    least-squares weights of Huber's loss, for error norms r > 0. Reference:
    :func:`huber_weights`."""
    cases = _hw_cases(seed, n)
    check_function(fn, huber_weights, cases, name=name, arg_names=("r", "k"),
                   labels=tuple(f"w[{i}]" for i in range(6)),
                   output=lambda out: np.ravel(np.asarray(out, dtype=float)),
                   mistakes=_hw_mistakes(name), what="Huber's weights", quiet=True,
                   rtol=1e-9, atol=1e-12)
    return passed(f"✓ {name} gives Huber's weights on {len(cases)} sets of errors (at and "
                  "around the threshold).", quiet)
