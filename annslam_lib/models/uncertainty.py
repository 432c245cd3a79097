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

from .. import _checks
from .geometry import wrap_angle

__all__ = ["propagate", "ellipse_points", "ellipse_curves", "monte_carlo", "mahalanobis2",
           "coverage", "expected_coverage", "chi2_quantile", "chi2_cdf", "draw_ellipse"]

def propagate(J, P, R=None) -> np.ndarray:
    """Linearised covariance of y = f(x) + noise: J P J^T (+ R), symmetrised.

    Parameters
    ----------
    J : array_like, shape (m, n)
        The Jacobian of f at the mean.
    P : array_like, shape (n, n)
        The covariance of x (symmetric, positive semi-definite).
    R : array_like, shape (m, m), optional
        An additive noise covariance (e.g. the measurement noise in the innovation
        covariance S = H P H^T + R, notebook 03).

    Returns
    -------
    ndarray, shape (m, m)
        J P J^T (+ R), symmetrised.

    Raises
    ------
    ValueError
        If ``J`` is not 2-D, the shapes do not match, or ``P`` or ``R`` is not a
        covariance.
    """
    J = _checks.array("J", J)
    if J.ndim != 2:
        raise ValueError(f"J must be a 2-D (m, n) matrix, got shape {J.shape}")
    P = _checks.covariance("P", P)
    if J.shape[1] != P.shape[0]:
        raise ValueError(f"J has {J.shape[1]} columns but P is {P.shape[0]} x {P.shape[0]}")
    S = J @ P @ J.T
    if R is not None:
        S = S + _checks.covariance("R", R, J.shape[0])
    return 0.5 * (S + S.T)


def ellipse_points(mean, cov, n_sigma: float = 1.0, n_points: int = 100) -> np.ndarray:
    """Closed curve (n_points, 2) of the ``n_sigma`` ellipse of a 2-D Gaussian:
    {x : (x - mean)^T cov^-1 (x - mean) = n_sigma^2}.

    Built from the symmetric square root of ``cov`` (eigen-decomposition), so a
    singular covariance gives a flat ellipse (a segment) instead of failing.
    The first and last points coincide.
    """
    mean = _checks.array("mean", mean, (2,))
    if mean.ndim != 1:
        raise ValueError(f"mean must have shape (2,), got {mean.shape}")
    cov = _checks.covariance("cov", cov, 2)
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

    Parameters
    ----------
    f : callable
        Maps an (n, d) array of inputs to an (n, m) array of outputs.
    mean : array_like, shape (d,)
        Mean of the input Gaussian.
    cov : array_like, shape (d, d)
        Covariance of the input Gaussian.
    n : int, optional
        Number of samples, >= 2.
    seed : int, optional
        Seed of the random generator (``numpy.random.default_rng``).
    angle_outputs : sequence of int, optional
        Output columns that are angles, rad.

    Returns
    -------
    mean : ndarray, shape (m,)
        Sample mean of the outputs.
    cov : ndarray, shape (m, m)
        Sample covariance of the outputs.
    samples : ndarray, shape (n, m)
        The outputs, angle columns unwrapped around f(mean).

    Raises
    ------
    ValueError
        If ``mean`` is not 1-D, ``cov`` is not a (d, d) covariance, n < 2, or ``f``
        does not return an (n, m) array.
    """
    mean = _checks.array("mean", mean)
    if mean.ndim != 1:
        raise ValueError(f"mean must be one-dimensional, got shape {mean.shape}")
    cov = _checks.covariance("cov", cov, mean.size)
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
    x = _checks.array("x", x)
    mean = _checks.array("mean", mean)
    if x.ndim != 2 or mean.ndim != 1 or x.shape[1] != mean.size:
        raise ValueError(f"x must be (n, d) and mean (d,), got {x.shape} and {mean.shape}")
    cov = _checks.covariance("cov", cov, mean.size)
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
    covariance that is too small, too large, or centred wrongly gives less.

    Parameters
    ----------
    x : array_like, shape (n, d)
        Samples, one per row.
    mean : array_like, shape (d,)
        Centre of the ellipsoid.
    cov : array_like, shape (d, d)
        Its covariance (non-singular).
    n_sigma : float, optional
        Size of the ellipsoid, in standard deviations (Mahalanobis distance).
    angle_columns : sequence of int, optional
        Columns that are angles, rad: their differences are wrapped.

    Returns
    -------
    float
        The fraction of rows with squared Mahalanobis distance <= n_sigma^2.

    Raises
    ------
    ValueError
        If the shapes do not match or ``cov`` is singular or not a covariance.
    """
    return float(np.mean(mahalanobis2(x, mean, cov, angle_columns=angle_columns) <= n_sigma**2))


def expected_coverage(n_sigma: float = 2.0, dim: int = 2) -> float:
    """Probability that a dim-dimensional Gaussian sample lies within n_sigma
    (Mahalanobis): the chi-square CDF with ``dim`` degrees of freedom at n_sigma^2."""
    if not (np.isfinite(n_sigma) and n_sigma > 0) or int(dim) != dim or dim < 1:
        raise ValueError(f"need n_sigma > 0 and an integer dim >= 1, got {n_sigma!r}, {dim!r}")
    return float(chi2_cdf(n_sigma**2, int(dim)))


def chi2_quantile(p, dof):
    """The chi-square quantile chi2.ppf(p, dof), elementwise. At 2 dof it has the closed
    form -2 ln(1 - p) (the exponential distribution), which the filter's gates use, so
    that importing the filter does not import ``scipy.stats`` (0.4 s); other dof use it.

    Parameters
    ----------
    p : float or array_like
        Probabilities in [0, 1).
    dof : int or array_like
        Degrees of freedom, broadcast with ``p``.

    Returns
    -------
    float or ndarray
        The quantiles: a float for scalar inputs, else an array of the broadcast shape.
    """
    p_arr, d_arr = np.asarray(p, dtype=float), np.asarray(dof, dtype=float)
    if np.all(d_arr == 2):
        with np.errstate(divide="ignore"):
            q = -2.0 * np.log1p(-p_arr) + 0.0 * d_arr
        return float(q) if q.ndim == 0 else q
    from scipy import stats

    q = stats.chi2.ppf(p_arr, d_arr)
    return float(q) if np.ndim(q) == 0 else q


def chi2_cdf(x, dof):
    """The chi-square CDF, elementwise (closed form 1 - exp(-x/2) at 2 dof)."""
    x_arr, d_arr = np.asarray(x, dtype=float), np.asarray(dof, dtype=float)
    if np.all(d_arr == 2):
        c = -np.expm1(-0.5 * x_arr) + 0.0 * d_arr
    else:
        from scipy import stats

        c = stats.chi2.cdf(x_arr, d_arr)
    return float(c) if np.ndim(c) == 0 else c


def draw_ellipse(ax, mean, cov, n_sigma: float = 2.0, **style):
    """Draw the ``n_sigma`` ellipse of a 2-D Gaussian on ``ax``; returns the line."""
    pts = ellipse_points(mean, cov, n_sigma)
    (line,) = ax.plot(pts[:, 0], pts[:, 1], **style)
    return line


def ellipse_curves(means, covs, n_sigma: float = 2.0, n_points: int = 40) -> np.ndarray:
    """(N, n_points, 2) closed ``n_sigma`` ellipses of N 2-D Gaussians at once: the same
    curve as ``uncertainty.ellipse_points`` (symmetric square root of each covariance),
    vectorised for a map of hundreds of landmarks."""
    means = np.asarray(means, dtype=float).reshape(-1, 2)
    covs = np.asarray(covs, dtype=float).reshape(-1, 2, 2)
    if means.shape[0] != covs.shape[0]:
        raise ValueError(f"{means.shape[0]} means but {covs.shape[0]} covariances")
    if not (np.isfinite(n_sigma) and n_sigma > 0):
        raise ValueError(f"n_sigma must be a positive number, got {n_sigma!r}")
    if int(n_points) != n_points or n_points < 3:
        raise ValueError(f"n_points must be an integer >= 3, got {n_points!r}")
    w, V = np.linalg.eigh(0.5 * (covs + np.swapaxes(covs, 1, 2)))
    root = V * np.sqrt(np.clip(w, 0.0, None))[:, None, :]
    t = np.linspace(0.0, 2.0 * np.pi, int(n_points))
    circle = np.stack([np.cos(t), np.sin(t)], -1)
    return means[:, None, :] + n_sigma * np.einsum("pj,nij->npi", circle, root)
