"""Gaussian uncertainty: propagation through a Jacobian, ellipses, Monte-Carlo checks.

The EKF pushes covariances through Jacobians, P -> J P J^T, which is exact only
for a linear function. Notebook 03 ("what happens if" experiments on the
observation model) compares that linearisation with Monte Carlo: sample the
input Gaussian, push every sample through the true nonlinear function, and
look at the spread of the outputs. The functions here do those steps and
nothing else, so the notebooks, the widgets and the filter share one tested
implementation.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from .geometry import as_array, wrap_angle

__all__ = ["check_covariance", "propagate", "ellipse_points", "monte_carlo",
           "mahalanobis2", "coverage", "expected_coverage", "draw_ellipse"]

#: Relative tolerance for "symmetric" and "positive semi-definite".
COV_RTOL = 1e-9


def check_covariance(name: str, P, n: int | None = None) -> np.ndarray:
    """``P`` as a float (n, n) covariance matrix, or ValueError naming ``name``.

    Checks: square, finite, symmetric to ``COV_RTOL`` relative to its largest
    entry, no eigenvalue below ``-COV_RTOL`` times that scale. Returns the
    symmetrised matrix (P + P^T) / 2.
    """
    P = as_array(name, P)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {P.shape}")
    if n is not None and P.shape[0] != n:
        raise ValueError(f"{name} must be {n} x {n}, got {P.shape}")
    scale = max(float(np.max(np.abs(P))), 1e-300)
    if np.max(np.abs(P - P.T)) > COV_RTOL * scale:
        raise ValueError(f"{name} is not symmetric (largest asymmetry "
                         f"{np.max(np.abs(P - P.T)):.3g})")
    P = 0.5 * (P + P.T)
    lowest = float(np.min(np.linalg.eigvalsh(P)))
    if lowest < -COV_RTOL * scale:
        raise ValueError(f"{name} is not positive semi-definite (eigenvalue {lowest:.3g})")
    return P


def propagate(J, P, R=None) -> np.ndarray:
    """Linearised covariance of y = f(x) + noise: J P J^T (+ R), symmetrised.

    J (m, n) is the Jacobian of f at the mean, P (n, n) the covariance of x,
    R (m, m) an optional additive noise covariance (e.g. the measurement noise in
    the innovation covariance S = H P H^T + R, notebook 03).
    """
    J = as_array("J", J)
    if J.ndim != 2:
        raise ValueError(f"J must be a 2-D (m, n) matrix, got shape {J.shape}")
    P = check_covariance("P", P)
    if J.shape[1] != P.shape[0]:
        raise ValueError(f"J has {J.shape[1]} columns but P is {P.shape[0]} x {P.shape[0]}")
    S = J @ P @ J.T
    if R is not None:
        S = S + check_covariance("R", R, J.shape[0])
    return 0.5 * (S + S.T)


def ellipse_points(mean, cov, n_sigma: float = 1.0, n_points: int = 100) -> np.ndarray:
    """Closed curve (n_points, 2) of the ``n_sigma`` ellipse of a 2-D Gaussian:
    {x : (x - mean)^T cov^-1 (x - mean) = n_sigma^2}.

    Built from the symmetric square root of ``cov`` (eigen-decomposition), so a
    singular covariance gives a flat ellipse (a segment) instead of failing.
    The first and last points coincide.
    """
    mean = as_array("mean", mean, (2,))
    if mean.ndim != 1:
        raise ValueError(f"mean must have shape (2,), got {mean.shape}")
    cov = check_covariance("cov", cov, 2)
    if not (np.isfinite(n_sigma) and n_sigma > 0):
        raise ValueError(f"n_sigma must be a positive number, got {n_sigma!r}")
    if int(n_points) != n_points or n_points < 3:
        raise ValueError(f"n_points must be an integer >= 3, got {n_points!r}")
    w, V = np.linalg.eigh(cov)
    root = V * np.sqrt(np.clip(w, 0.0, None))          # root @ root.T = cov
    t = np.linspace(0.0, 2.0 * np.pi, int(n_points))
    circle = np.stack([np.cos(t), np.sin(t)], -1)
    return mean + n_sigma * circle @ root.T


def monte_carlo(f, mean, cov, n: int = 20000, *, seed: int = 0, angle_outputs=()):
    """Sample x ~ N(mean, cov), push the samples through ``f``, return the outputs'
    (mean, covariance, samples).

    ``f`` maps an (n, d) array of inputs to an (n, m) array of outputs. Output
    columns listed in ``angle_outputs`` are unwrapped around f(mean) before the
    statistics, so a bearing spread across +-pi is not torn in two (the reported
    mean of such a column is wrapped to (-pi, pi] again). The covariance uses the
    unbiased 1/(n - 1) normalisation.
    """
    mean = as_array("mean", mean)
    if mean.ndim != 1:
        raise ValueError(f"mean must be one-dimensional, got shape {mean.shape}")
    cov = check_covariance("cov", cov, mean.size)
    if int(n) != n or n < 2:
        raise ValueError(f"n must be an integer >= 2, got {n!r}")
    rng = np.random.default_rng(seed)
    w, V = np.linalg.eigh(cov)
    root = V * np.sqrt(np.clip(w, 0.0, None))
    x = mean + rng.standard_normal((int(n), mean.size)) @ root.T
    y = np.asarray(f(x), dtype=float)
    if y.ndim != 2 or y.shape[0] != n:
        raise ValueError(f"f must return an (n, m) array for n = {n} inputs, got {y.shape}")
    y = y.copy()
    centre = np.asarray(f(mean[None, :]), dtype=float)[0]
    for i in angle_outputs:
        y[:, i] = centre[i] + wrap_angle(y[:, i] - centre[i])
    m = y.mean(axis=0)
    C = np.cov(y, rowvar=False).reshape(y.shape[1], y.shape[1])
    for i in angle_outputs:
        m[i] = wrap_angle(m[i])
    return m, C, y


def mahalanobis2(x, mean, cov, *, angle_columns=()) -> np.ndarray:
    """Squared Mahalanobis distances (n,) of the rows of ``x`` (n, d) from ``mean``
    under ``cov`` (non-singular); differences in ``angle_columns`` are wrapped."""
    x = as_array("x", x)
    mean = as_array("mean", mean)
    if x.ndim != 2 or mean.ndim != 1 or x.shape[1] != mean.size:
        raise ValueError(f"x must be (n, d) and mean (d,), got {x.shape} and {mean.shape}")
    cov = check_covariance("cov", cov, mean.size)
    d = x - mean
    for i in angle_columns:
        d[:, i] = wrap_angle(d[:, i])
    try:
        L = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError as exc:
        raise ValueError("cov is singular: Mahalanobis distance undefined") from exc
    u = np.linalg.solve(L, d.T)
    return np.sum(u * u, axis=0)


def coverage(x, mean, cov, n_sigma: float = 2.0, *, angle_columns=()) -> float:
    """Fraction of the rows of ``x`` inside the ``n_sigma`` ellipsoid of N(mean, cov).

    For samples that really are N(mean, cov) this tends to
    :func:`expected_coverage` (86.5 % for 2 sigma in 2-D); a linearised
    covariance that is too small, too large, or centred wrongly gives less."""
    return float(np.mean(mahalanobis2(x, mean, cov, angle_columns=angle_columns) <= n_sigma**2))


def expected_coverage(n_sigma: float = 2.0, dim: int = 2) -> float:
    """Probability that a dim-dimensional Gaussian sample lies within n_sigma
    (Mahalanobis): the chi-square CDF with ``dim`` degrees of freedom at n_sigma^2."""
    if not (np.isfinite(n_sigma) and n_sigma > 0) or int(dim) != dim or dim < 1:
        raise ValueError(f"need n_sigma > 0 and an integer dim >= 1, got {n_sigma!r}, {dim!r}")
    return float(stats.chi2.cdf(n_sigma**2, int(dim)))


def draw_ellipse(ax, mean, cov, n_sigma: float = 2.0, **style):
    """Draw the ``n_sigma`` ellipse of a 2-D Gaussian on ``ax``; returns the line."""
    pts = ellipse_points(mean, cov, n_sigma)
    (line,) = ax.plot(pts[:, 0], pts[:, 1], **style)
    return line
