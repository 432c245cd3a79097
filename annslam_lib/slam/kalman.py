"""The Kalman filter in its general form (chapter 01a, "The Kalman filter").

The 1-D filter (:func:`predict_1d`, :func:`update_1d`), the n-D linear filter
(:func:`kf_predict`, :func:`kf_update`, with the gain :func:`kalman_gain` and the Joseph
covariance :func:`joseph_covariance`, the same functions every filter of the course uses,
EKF-SLAM included), the chi-square gate of one innovation (:func:`innovation_gate`), the stationary
variance of a 1-D random walk (:func:`steady_state_variance`), and the Bayes filter on a
grid (:func:`grid_predict`, :func:`grid_update`, :func:`grid_moments`), which makes no
Gaussian assumption and is the independent reference the chapter checks the closed forms
against.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .. import _checks
from .base import InnovationError, check_measurement

__all__ = ["predict_1d", "update_1d", "kf_predict", "kf_update", "kalman_gain",
           "joseph_covariance", "innovation_gate", "steady_state_variance", "grid_predict",
           "grid_update", "grid_moments", "gaussian_pdf"]


def kalman_gain(P, H, R) -> tuple[np.ndarray, np.ndarray]:
    """Optimal gain K = P H^T S^-1 and innovation covariance S = H P H^T + R (notebook 05
    section 3).

    Parameters
    ----------
    P : array_like, shape (n, n)
        State covariance.
    H : array_like, shape (m, n)
        Measurement Jacobian.
    R : array_like, shape (m, m)
        Measurement noise covariance.

    Returns
    -------
    K : ndarray, shape (n, m)
        The gain.
    S : ndarray, shape (m, m)
        The innovation covariance.

    Raises
    ------
    slam.base.InnovationError
        (a ValueError) If S is singular or not positive definite (smallest eigenvalue
        <= 1e-12 of its largest): no gain exists, e.g. a perfectly known state measured
        without noise.
    ValueError
        If the shapes do not match or a value is not finite.
    """
    P = _checks.array("P", P)
    H, R = check_measurement(P, H, R)
    S = H @ P @ H.T + R
    w = np.linalg.eigvalsh(0.5 * (S + S.T))
    if not w[0] > 1e-12 * max(abs(w[-1]), 1e-300):
        raise InnovationError(f"the innovation covariance S = H P H^T + R is singular or not "
                              f"positive definite (eigenvalues {w[0]:.3g} .. {w[-1]:.3g}): "
                              f"no Kalman gain exists")
    return P @ H.T @ np.linalg.inv(S), S


def joseph_covariance(P, H, R, K) -> np.ndarray:
    """Joseph form of the covariance update, P+ = (I - K H) P (I - K H)^T + K R K^T
    (notebook 05 section 3): the covariance of x + K (z - H x) for ANY gain K, symmetric
    and positive semi-definite by construction. The short forms (I - K H) P and
    P - K S K^T equal it only for the optimal gain of :func:`kalman_gain`.

    Parameters
    ----------
    P : array_like, shape (n, n)
        Prior covariance.
    H : array_like, shape (m, n)
        Measurement Jacobian.
    R : array_like, shape (m, m)
        Measurement noise covariance.
    K : array_like, shape (n, m)
        The gain used, optimal or not.

    Returns
    -------
    ndarray, shape (n, n)
        P+.

    Raises
    ------
    ValueError
        If ``P`` is not square, the shapes do not match or a value is not finite.
    """
    P = _checks.array("P", P)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"P must be square, got {P.shape}")
    H, R = check_measurement(P, H, R)
    K = _checks.array("K", K)
    if K.shape != H.T.shape:
        raise ValueError(f"K must be {H.shape[1]} x {H.shape[0]} (state x measurement), "
                         f"got {K.shape}")
    IKH = np.eye(P.shape[0]) - K @ H
    return IKH @ P @ IKH.T + K @ R @ K.T


def _variance(name: str, v) -> float:
    return _checks.real(name, v, lo=0.0)


def predict_1d(mu, var, u, q) -> tuple[float, float]:
    """Prediction of a 1-D Kalman filter (chapter 01a, eq. 1a.3): the state moves by ``u``
    with a zero-mean error of variance ``q`` independent of the state, so the means add and
    the variances add: (mu + u, var + q)."""
    mu, u = _checks.real("mu", mu), _checks.real("u", u)
    return mu + u, _variance("var", var) + _variance("q", q)


def update_1d(mu, var, z, r) -> tuple[float, float, float]:
    """Update of a 1-D Kalman filter (chapter 01a, eq. 1a.4): the product of the prior
    N(mu, var) and the likelihood N(z; x, r), normalised. With the gain K = var / (var + r),

        mu+ = mu + K (z - mu),   var+ = (1 - K) var = var r / (var + r).

    Returns (mu+, var+, K). ValueError for a negative variance or var = r = 0 (no
    distribution to condition on)."""
    mu, z = _checks.real("mu", mu), _checks.real("z", z)
    var, r = _variance("var", var), _variance("r", r)
    if var + r == 0.0:
        raise ValueError("var + r = 0: a known state measured without noise has no update "
                         "(the gain var / (var + r) is 0 / 0)")
    K = var / (var + r)
    return mu + K * (z - mu), var * r / (var + r), K


def kf_predict(x, P, F, Q, u=None) -> tuple[np.ndarray, np.ndarray]:
    """Linear prediction (chapter 01a, eq. 1a.5): x- = F x + u, P- = F P F^T + Q."""
    x = _checks.array("x", x).ravel()
    P = _checks.covariance("P", P, x.size)
    F = _checks.array("F", F)
    if F.shape != (x.size, x.size):
        raise ValueError(f"F must be {x.size} x {x.size}, got {F.shape}")
    Q = _checks.covariance("Q", Q, x.size)
    x_new = F @ x if u is None else F @ x + _checks.array("u", u, (x.size,))
    P_new = F @ P @ F.T + Q
    return x_new, 0.5 * (P_new + P_new.T)


def kf_update(x, P, z, H, R, *, form: str = "joseph") -> tuple[np.ndarray, np.ndarray]:
    """Linear update (chapter 01a, eq. 1a.6-1a.7): nu = z - H x, S = H P H^T + R,
    K = P H^T S^-1, x+ = x + K nu; P+ in the Joseph form (I - K H) P (I - K H)^T + K R K^T
    (``form="joseph"``, valid for any gain) or the simple form (I - K H) P (``"simple"``,
    equal only for this optimal K, and not symmetric after rounding). P+ does not depend
    on z. Raises InnovationError (a ValueError) when S is not positive definite."""
    form = _checks.choice("form", form, ("joseph", "simple"))
    x = _checks.array("x", x).ravel()
    P = _checks.covariance("P", P, x.size)
    z = _checks.array("z", z).ravel()
    H = _checks.array("H", H).reshape(z.size, -1) if np.ndim(H) == 1 else _checks.array("H", H)
    if H.shape != (z.size, x.size):
        raise ValueError(f"H must be {z.size} x {x.size} (measurement x state), got {H.shape}")
    R = _checks.covariance("R", R, z.size)
    K, _ = kalman_gain(P, H, R)
    x_new = x + K @ (z - H @ x)
    if form == "joseph":
        return x_new, joseph_covariance(P, H, R, K)
    return x_new, (np.eye(x.size) - K @ H) @ P


def innovation_gate(nu, S, p) -> tuple[float, float, bool]:
    """The chi-square gate of one innovation (chapter 01a, eq. 1a.8): d2 = nu^T S^-1 nu
    has a chi-square distribution with dim(nu) degrees of freedom when the filter is right,
    so the innovation is accepted when d2 <= chi2.ppf(p, dim(nu)), which keeps a share p of
    the right measurements. Returns (d2, threshold, accepted); ValueError when S is not
    positive definite."""
    nu = np.atleast_1d(_checks.array("nu", nu)).ravel()
    S = _checks.covariance("S", np.atleast_2d(S), nu.size)
    p = _checks.probability("p", p)
    w = np.linalg.eigvalsh(S)
    if not w[0] > 1e-12 * max(abs(w[-1]), 1e-300):
        raise ValueError(f"S is not positive definite (eigenvalues {w[0]:.3g} .. "
                         f"{w[-1]:.3g}): no Mahalanobis distance")
    d2 = float(nu @ np.linalg.solve(S, nu))
    from scipy.stats import chi2          # scipy.stats loads only when a gate is asked for

    threshold = float(chi2.ppf(p, nu.size))
    return d2, threshold, d2 <= threshold


def steady_state_variance(q, r) -> tuple[float, float]:
    """Stationary variances of a 1-D filter that predicts with process noise ``q`` and
    updates with measurement noise ``r`` every step (chapter 01a, eq. 1a.9). The prior
    variance p- solves p- = p- r / (p- + r) + q, i.e. p-^2 - q p- - q r = 0, so

        p- = (q + sqrt(q^2 + 4 q r)) / 2,   p+ = p- - q = p- r / (p- + r).

    Parameters
    ----------
    q : float
        Process noise variance per step, >= 0.
    r : float
        Measurement noise variance, >= 0.

    Returns
    -------
    p_minus : float
        Stationary variance after the prediction, p-.
    p_plus : float
        Stationary variance after the update, p+.

    Raises
    ------
    ValueError
        For a negative variance or q = 0 with r = 0.
    """
    q, r = _variance("q", q), _variance("r", r)
    if q == 0.0 and r == 0.0:
        raise ValueError("q = r = 0: nothing moves and nothing is measured; the variance "
                         "stays wherever it started")
    p_minus = 0.5 * (q + math.sqrt(q * q + 4.0 * q * r))
    return p_minus, p_minus - q


# ------------------------------------------------------------ the Bayes filter on a grid

def gaussian_pdf(x, mu, var) -> np.ndarray:
    """N(x; mu, var) evaluated at ``x``."""
    var = _checks.real("var", var, lo=0.0, strict=True)
    x = np.asarray(x, float)
    return np.exp(-0.5 * (x - mu) ** 2 / var) / math.sqrt(2.0 * math.pi * var)


def _grid(grid) -> tuple[np.ndarray, float]:
    g = _checks.array("grid", grid)
    if g.ndim != 1 or g.size < 3:
        raise ValueError(f"grid must be a 1-D array of at least 3 points, got shape {g.shape}")
    dx = np.diff(g)
    if not np.all(dx > 0) or not np.allclose(dx, dx[0], rtol=1e-9, atol=0.0):
        raise ValueError("grid must be evenly spaced and increasing")
    return g, float(dx[0])


def _density(name: str, p, n: int) -> np.ndarray:
    p = _checks.array(name, p)
    if p.shape != (n,):
        raise ValueError(f"{name} must have one value per grid point ({n}), got {p.shape}")
    if np.any(p < 0):
        raise ValueError(f"{name} has negative values: not a density")
    return p


def grid_predict(p, grid, u, q) -> np.ndarray:
    """Bayes prediction on an even grid (chapter 01a, eq. 1a.1): the density of x + w,
    w ~ N(u, q), as the convolution of ``p`` with that Gaussian (mass beyond the grid is
    lost and reported by :func:`grid_moments`'s ``mass``). Returns the density."""
    g, dx = _grid(grid)
    p = _density("p", p, g.size)
    q = _checks.real("q", q, lo=0.0, strict=True)
    # p-(x_i) = sum_j p(x_j) N(x_i - x_j; u, q) dx: a discrete convolution over offsets k dx
    n = g.size
    kernel = gaussian_pdf(dx * np.arange(-(n - 1), n), _checks.real("u", u), q)
    return np.convolve(p, kernel)[n - 1:2 * n - 1] * dx


def grid_update(p, grid, z, r, h: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
    """Bayes update on a grid (chapter 01a, eq. 1a.2): prior ``p`` times the likelihood
    N(z; h(x), r) (``h`` the identity when None), normalised to integrate to 1. ValueError
    when the measurement is impossible under the prior (the product underflows to 0)."""
    g, dx = _grid(grid)
    p = _density("p", p, g.size)
    hx = g if h is None else np.asarray(h(g), float)
    post = p * gaussian_pdf(_checks.real("z", z), hx, _checks.real("r", r, lo=0.0, strict=True))
    total = float(post.sum() * dx)
    if not total > 0.0:
        raise ValueError("the measurement has zero likelihood everywhere the prior lives")
    return post / total


def grid_moments(p, grid) -> dict:
    """Mass, mean and variance of a density on a grid (rectangle rule)."""
    g, dx = _grid(grid)
    p = _density("p", p, g.size)
    mass = float(p.sum() * dx)
    if not mass > 0.0:
        raise ValueError("the density has no mass on the grid")
    mean = float((g * p).sum() * dx / mass)
    return {"mass": mass, "mean": mean, "var": float(((g - mean) ** 2 * p).sum() * dx / mass)}
