"""The EKF-SLAM steps as plain functions of (x, P) (annslam_lib.ekf_dense, notebook 05's
exercise references): equal to the dense filter's methods, the Joseph form equal to the
sampled covariance of the update for any gain, the short forms only for the optimal one,
and clear errors for bad input."""
import math

import numpy as np
import pytest


from annslam_lib.slam.base import InnovationError
from annslam_lib.models.observation import inverse_observe, observe
from annslam_lib.models.uncertainty import monte_carlo
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.slam import dense


def _filter(seed=0, N=4):
    """A dense filter with N landmarks, after a drive and an update (correlated P)."""
    rng = np.random.default_rng(seed)
    f = dense.DenseEkfSlam([1.0, -2.0, 2.9], np.diag([0.02, 0.03, 0.002]), ACFR_UTE)
    f.augment(np.c_[rng.uniform(3, 25, N), rng.uniform(0.1, 3.0, N)], 0.1, math.radians(1))
    u = (2.0, 0.1, 0.0, 2.0 * math.tan(0.1) / ACFR_UTE.L, 0.0, 0.05, 0.0, 0.01, 0.025)
    for _ in range(20):
        f.predict(u, 0.025)
    return f, rng


def test_augment_landmark_is_the_dense_filters_augment():
    f, _ = _filter()
    x, P = f.state()
    z = np.array([[9.0, 0.7], [4.0, 3.1]])
    R = np.diag([0.1**2, math.radians(1)**2])
    x1, P1 = dense.augment_landmark(x, P, z, R)
    f.augment(z, 0.1, math.radians(1))
    np.testing.assert_allclose(x1, f.x, rtol=0, atol=1e-13)
    np.testing.assert_allclose(P1, f.P, rtol=0, atol=1e-15)
    x2, P2 = dense.augment_landmark(x, P, z[0], R)           # one landmark as (2,)
    np.testing.assert_allclose(P2, P1[:-2, :-2], rtol=0, atol=1e-15)


def test_augmented_covariance_matches_monte_carlo():
    """The new blocks are the linearised covariance of [X; g(X_v, z)]: sampled pose and
    measurement pushed through inverse_observe give the same matrix (small noise)."""
    f, _ = _filter(N=1)
    x, P = f.state()
    z = np.array([10.0, 1.0])
    R = np.diag([0.05**2, math.radians(0.5)**2])
    _, P1 = dense.augment_landmark(x, P, z, R)
    mean = np.concatenate([x, z])
    cov = np.zeros((7, 7))
    cov[:5, :5], cov[5:, 5:] = P, R

    def g(s):
        return np.c_[s[:, :5], inverse_observe(s[:, :3], s[:, 5:])[0]]

    _, C, _ = monte_carlo(g, mean, cov, n=100_000, seed=1)
    scale = np.sqrt(np.outer(np.diag(P1), np.diag(P1)))
    assert np.max(np.abs(C - P1) / scale) < 0.02


def test_update_is_the_dense_filters_update_and_wraps():
    f, _ = _filter(seed=3)
    x, P = f.state()
    lm = [1, 3]
    z_hat, Hp, Hl = observe(x[:3], f.landmarks()[lm])
    H = np.zeros((4, x.size))
    for i, j in enumerate(lm):
        H[2 * i:2 * i + 2, :3], H[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] = Hp[i], Hl[i]
    z = z_hat.ravel() + np.array([0.05, 0.01, -0.08, -0.02])
    z[1::2] = (z[1::2] + np.pi) % (2 * np.pi) - np.pi
    R = np.diag(np.tile([0.1**2, math.radians(1)**2], 2))
    x1, P1 = dense.range_bearing_update(x, P, z.ravel(), z_hat.ravel(), H, R)
    f.update(z.reshape(-1, 2), lm, 0.1, math.radians(1))
    np.testing.assert_allclose(x1, f.x, rtol=0, atol=1e-13)
    np.testing.assert_allclose(P1, f.P, rtol=0, atol=1e-15)
    # A bearing across +-pi: the innovation is the short way round.
    nu = dense.innovation([5.0, -math.pi + 0.006], [5.1, math.pi - 0.004])
    np.testing.assert_allclose(nu, [-0.1, 0.01], atol=1e-12)
    # The heading after the update is wrapped into (-pi, pi].
    x_wrap = x.copy()
    x_wrap[2] = math.pi - 1e-4
    K, _ = dense.kalman_gain(P, H, R)
    push = K[2] / (K[2] @ K[2]) * 0.01                 # (K nu)[2] = +0.01
    x2, _ = dense.joseph_update(x_wrap, P, push, H, R)
    assert x2[2] == pytest.approx(-math.pi + 0.0099, abs=1e-12)


def test_joseph_form_is_the_covariance_for_any_gain():
    """For a linear measurement z = H X + v the updated estimate x + K (z - H x) has error
    (I - K H) e - K v: its sampled covariance equals the Joseph form for an arbitrary K,
    the short forms only for the optimal gain (where they agree with it)."""
    f, rng = _filter(seed=5, N=2)
    x, P = f.state()
    H = rng.normal(size=(2, x.size))
    R = np.diag([0.04, 0.01])
    K_opt, S = dense.kalman_gain(P, H, R)
    K = K_opt * 0.5 + rng.normal(scale=0.05, size=K_opt.shape)
    n = 100_000
    e = rng.multivariate_normal(np.zeros(x.size), P, n)
    v = rng.multivariate_normal(np.zeros(2), R, n)
    after = e - (e @ H.T + v) @ K.T
    C = np.cov(after, rowvar=False)
    J = dense.joseph_covariance(P, H, R, K)
    scale = np.sqrt(np.outer(np.diag(J), np.diag(J)))
    assert np.max(np.abs(C - J) / scale) < 0.02
    short = (np.eye(x.size) - K @ H) @ P
    assert np.max(np.abs(short - J) / scale) > 0.1 and np.max(np.abs(short - short.T)) > 1e-4
    J_opt = dense.joseph_covariance(P, H, R, K_opt)
    np.testing.assert_allclose((np.eye(x.size) - K_opt @ H) @ P, J_opt, atol=1e-14)
    np.testing.assert_allclose(P - K_opt @ S @ K_opt.T, J_opt, atol=1e-14)
    # the optimal gain gives the smallest trace
    assert np.trace(J_opt) < np.trace(J)


def test_singular_innovation_covariance_is_an_innovation_error():
    f, _ = _filter()
    x, P = f.state()
    z_hat, Hp, Hl = observe(x[:3], f.landmarks()[0])
    H = np.zeros((2, x.size))
    H[:, :3], H[:, 3:5] = Hp, Hl
    with pytest.raises(InnovationError, match="singular"):
        dense.kalman_gain(np.zeros_like(P), H, np.zeros((2, 2)))
    b = np.arange(1.0, x.size + 1)[:, None] * 0.1
    with pytest.raises(ValueError, match="no Kalman gain"):            # rank 1, not exact
        dense.range_bearing_update(x, b @ b.T, z_hat, z_hat, H, np.zeros((2, 2)))
    with pytest.raises(ValueError, match="singular"):
        dense.joseph_update(x, P, [0.0, 0.0, 0.0, 0.0], np.vstack([H, H]), np.zeros((4, 4)))


def test_bad_input_is_a_clear_error():
    f, _ = _filter()
    x, P = f.state()
    R = np.eye(2) * 0.01
    with pytest.raises(ValueError, match="size 3 \\+ 2N"):
        dense.augment_landmark(x[:-1], P[:-1, :-1], [5.0, 1.0], R)
    with pytest.raises(ValueError, match="P must be 11 x 11"):
        dense.augment_landmark(x, P[:-2, :-2], [5.0, 1.0], R)
    with pytest.raises(ValueError, match="range must be > 0"):
        dense.augment_landmark(x, P, [0.0, 1.0], R)
    with pytest.raises(ValueError, match="R must be the 2 x 2"):
        dense.augment_landmark(x, P, [5.0, 1.0], np.eye(3))
    with pytest.raises(ValueError, match="H must be"):
        dense.joseph_update(x, P, [0.1, 0.0], np.zeros((2, 5)), R)
    with pytest.raises(ValueError, match="nu has 3 entries"):
        dense.joseph_update(x, P, [0.1, 0.0, 0.0], np.eye(2, x.size), R)
    with pytest.raises(ValueError, match="K must be"):
        dense.joseph_covariance(P, np.eye(2, x.size), R, np.zeros((2, x.size)))
    with pytest.raises(ValueError, match="same \\(range, bearing\\) pairs"):
        dense.innovation([1.0, 0.0], [1.0, 0.0, 2.0, 0.0])
    with pytest.raises(ValueError, match="NaN"):
        dense.joseph_covariance(P, np.eye(2, x.size), [[np.nan, 0], [0, 1]], np.zeros((x.size, 2)))
