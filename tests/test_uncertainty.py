"""Covariance propagation, ellipses and Monte-Carlo helpers (annslam_lib.uncertainty)."""
import math

import numpy as np
import pytest
from scipy import special
from annslam_lib.models import observation
from annslam_lib.models import uncertainty


def random_cov(n, rng):
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


# ------------------------------------------------------------------ propagate

def test_propagate_is_J_P_JT_plus_R():
    rng = np.random.default_rng(0)
    J, P, R = rng.normal(size=(2, 5)), random_cov(5, rng), random_cov(2, rng)
    explicit = np.einsum("ij,jk,lk->il", J, P, J)
    np.testing.assert_allclose(uncertainty.propagate(J, P), explicit, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uncertainty.propagate(J, P, R), explicit + R, rtol=1e-12, atol=1e-12)
    S = uncertainty.propagate(J, P, R)
    assert np.array_equal(S, S.T)


def test_propagate_matches_monte_carlo_for_a_linear_map():
    """For y = A x + b linearisation is exact: the sample covariance must agree
    with A P A^T to sampling accuracy (~sqrt(2/n) relative)."""
    rng = np.random.default_rng(1)
    A, b, P = rng.normal(size=(3, 4)), rng.normal(size=3), random_cov(4, rng)
    mean = rng.normal(size=4)
    m, C, y = uncertainty.monte_carlo(lambda x: x @ A.T + b, mean, P, 100_000, seed=5)
    S = uncertainty.propagate(A, P)
    assert y.shape == (100_000, 3)
    sd = np.sqrt(np.diag(S))
    np.testing.assert_allclose(m, A @ mean + b, atol=0.02 * sd.max())
    np.testing.assert_allclose(C / np.outer(sd, sd), S / np.outer(sd, sd), atol=0.02)


@pytest.mark.parametrize("J, P, R, match", [
    (np.ones((2, 3)), np.eye(2), None, "columns"),
    (np.ones(3), np.eye(3), None, "2-D"),
    (np.ones((2, 3)), np.ones((3, 2)), None, "square"),
    (np.ones((2, 3)), [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], None, "symmetric"),
    (np.ones((2, 3)), np.diag([1.0, -1.0, 1.0]), None, "positive semi-definite"),
    (np.ones((2, 3)), np.diag([1.0, np.nan, 1.0]), None, "NaN"),
    (np.ones((2, 3)), np.eye(3), np.eye(3), "2 x 2"),
    (np.ones((2, 3)), "P", None, "numeric"),
])
def test_propagate_rejects_bad_input(J, P, R, match):
    with pytest.raises(TypeError if match == "numeric" else ValueError, match=match):
        uncertainty.propagate(J, P, R)


# ------------------------------------------------------------------- ellipses

@pytest.mark.parametrize("n_sigma", [1.0, 2.0, 3.0])
def test_ellipse_points_lie_on_the_mahalanobis_contour(n_sigma):
    rng = np.random.default_rng(2)
    mean, cov = rng.normal(size=2), random_cov(2, rng)
    pts = uncertainty.ellipse_points(mean, cov, n_sigma, n_points=64)
    assert pts.shape == (64, 2)
    np.testing.assert_allclose(pts[0], pts[-1], atol=1e-12)
    d2 = uncertainty.mahalanobis2(pts, mean, cov)
    np.testing.assert_allclose(d2, n_sigma**2, rtol=1e-9)
    # the ellipse's x extent is n_sigma times the x standard deviation
    half_width = 0.5 * (pts[:, 0].max() - pts[:, 0].min())
    assert half_width == pytest.approx(n_sigma * math.sqrt(cov[0, 0]), rel=2e-3)


def test_ellipse_of_singular_covariance_is_a_segment():
    pts = uncertainty.ellipse_points([1.0, 2.0], [[4.0, 0.0], [0.0, 0.0]], 2.0, n_points=101)  # t = pi included
    np.testing.assert_allclose(pts[:, 1], 2.0, atol=1e-12)
    assert pts[:, 0].min() == pytest.approx(-3.0) and pts[:, 0].max() == pytest.approx(5.0)


@pytest.mark.parametrize("kw, match", [
    (dict(mean=[0, 0, 0], cov=np.eye(2)), "shape"),
    (dict(mean=[0, 0], cov=np.eye(3)), "2 x 2"),
    (dict(mean=[0, 0], cov=np.eye(2), n_sigma=0), "n_sigma"),
    (dict(mean=[0, 0], cov=np.eye(2), n_points=2), "n_points"),
])
def test_ellipse_points_rejects_bad_input(kw, match):
    with pytest.raises(ValueError, match=match):
        uncertainty.ellipse_points(**kw)


# ---------------------------------------------------------------- Monte Carlo

def test_monte_carlo_unwraps_angles_near_pi():
    """A bearing spread across +-pi has a small variance, not ~pi^2."""
    sigma = 0.05
    m, C, y = uncertainty.monte_carlo(lambda x: np.c_[np.angle(np.exp(1j * x[:, 0]))], [np.pi], [[sigma**2]],
                              50_000, seed=3, angle_outputs=[0])
    assert C[0, 0] == pytest.approx(sigma**2, rel=0.03)
    assert abs(abs(m[0]) - np.pi) < 1e-3
    # without unwrapping the same samples are torn in two
    _, C_raw, _ = uncertainty.monte_carlo(lambda x: np.c_[np.angle(np.exp(1j * x[:, 0]))], [np.pi],
                                  [[sigma**2]], 50_000, seed=3)
    assert C_raw[0, 0] > 1.0


def test_monte_carlo_mean_of_an_uncertain_heading_shrinks_towards_the_sensor():
    """Analytic check on a nonlinear map: a landmark put at range r with heading
    noise N(0, s^2) has mean along the heading r E[cos] = r exp(-s^2 / 2)."""
    r, s = 20.0, math.radians(30.0)
    mean = np.array([0.0, 0.0, 0.0, r, np.pi / 2])        # straight ahead
    P = np.diag([0.0, 0.0, s**2, 0.0, 0.0])
    m, C, _ = uncertainty.monte_carlo(lambda x: observation.inverse_observe(x[:, :3], x[:, 3:])[0], mean, P,
                              100_000, seed=4)
    assert m[0] == pytest.approx(r * math.exp(-s**2 / 2), abs=0.02)
    assert m[1] == pytest.approx(0.0, abs=0.05)
    # Var(r sin(e)) = r^2 (1 - exp(-2 s^2)) / 2
    assert C[1, 1] == pytest.approx(r**2 * (1 - math.exp(-2 * s**2)) / 2, rel=0.02)


def test_monte_carlo_rejects_bad_input():
    with pytest.raises(ValueError, match="n must be"):
        uncertainty.monte_carlo(lambda x: x, [0.0], [[1.0]], 1)
    with pytest.raises(ValueError, match="1 x 1"):
        uncertainty.monte_carlo(lambda x: x, [0.0], np.eye(2))
    with pytest.raises(ValueError, match=r"\(n, m\)"):
        uncertainty.monte_carlo(lambda x: x[:, 0], [0.0], [[1.0]], 10)


# ------------------------------------------------------------------- coverage

def test_expected_coverage_matches_closed_forms():
    assert uncertainty.expected_coverage(1.0, 2) == pytest.approx(1 - math.exp(-0.5), rel=1e-12)
    assert uncertainty.expected_coverage(2.0, 2) == pytest.approx(1 - math.exp(-2.0), rel=1e-12)
    assert uncertainty.expected_coverage(2.0, 1) == pytest.approx(special.erf(2 / math.sqrt(2)), rel=1e-12)
    with pytest.raises(ValueError):
        uncertainty.expected_coverage(-1.0)


def test_coverage_of_gaussian_samples_is_the_chi_square_probability():
    rng = np.random.default_rng(6)
    mean, cov = rng.normal(size=2), random_cov(2, rng)
    x = rng.multivariate_normal(mean, cov, size=40_000)
    for k in (1.0, 2.0, 3.0):
        assert uncertainty.coverage(x, mean, cov, k) == pytest.approx(uncertainty.expected_coverage(k), abs=0.01)
    # a covariance half as wide covers far less
    assert uncertainty.coverage(x, mean, cov / 4, 2.0) < 0.5


def test_mahalanobis_wraps_angle_columns_and_rejects_singular():
    d2 = uncertainty.mahalanobis2([[np.pi - 0.1, 0.0]], [-np.pi + 0.1, 0.0], np.eye(2) * 0.01,
                          angle_columns=[0])
    assert d2[0] == pytest.approx(0.2**2 / 0.01)
    with pytest.raises(ValueError, match="singular"):
        uncertainty.mahalanobis2([[0.0, 0.0]], [0.0, 0.0], [[1.0, 0.0], [0.0, 0.0]])
