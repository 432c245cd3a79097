"""The unscented transform and the UKF (``slam.unscented``) against what we did not write:
exact Gaussian moments of linear maps, a Monte-Carlo truth for the polar-to-Cartesian
"banana", the linear Kalman filter for a linear measurement, and the EKF to first order."""
from __future__ import annotations

import numpy as np
import pytest

from annslam_lib.models.motion import predict
from annslam_lib.models.observation import observe
from annslam_lib.models.vehicle import Vehicle
from annslam_lib.slam import unscented as uk
from annslam_lib.slam.kalman import kf_update


@pytest.mark.parametrize("alpha, kappa", [(1.0, 0.0), (0.5, 1.0), (1e-3, 0.0)])
def test_sigma_points_reproduce_the_mean_and_covariance(alpha, kappa):
    rng = np.random.default_rng(1)
    A = rng.normal(size=(4, 4))
    P = A @ A.T + 0.1 * np.eye(4)
    mean = rng.normal(size=4)
    sp = uk.sigma_points(mean, P, alpha=alpha, kappa=kappa)
    assert sp.points.shape == (9, 4)
    np.testing.assert_allclose(sp.wm.sum(), 1.0, atol=1e-12)
    np.testing.assert_allclose(sp.wm @ sp.points, mean, atol=1e-9)
    D = sp.points - mean
    np.testing.assert_allclose((D * sp.wc[:, None]).T @ D - (1 - alpha**2 + 2) * np.outer(
        D[0], D[0]), P, atol=1e-9 * max(1.0, 1 / alpha**2))


def test_a_linear_map_is_transformed_exactly():
    rng = np.random.default_rng(2)
    A, b = rng.normal(size=(2, 3)), rng.normal(size=2)
    P = np.diag([0.3, 0.2, 0.05])
    mean = np.array([1.0, -2.0, 0.4])
    m, C, _, _ = uk.unscented_transform(uk.sigma_points(mean, P), lambda X: X @ A.T + b)
    np.testing.assert_allclose(m, A @ mean + b, atol=1e-12)
    np.testing.assert_allclose(C, A @ P @ A.T, atol=1e-12)


def test_the_banana_mean_is_closer_to_monte_carlo_than_the_linearised_one():
    """Range 10 m (sigma 0.1 m), bearing 0 (sigma 0.5 rad) to Cartesian: the true mean
    lies 1.18 m short of the linearised one (x = r cos b, E[cos b] = exp(-sigma^2/2)); the
    unscented mean within 0.2 m of the Monte-Carlo mean of 10^6 draws, the linearised one
    more than 1 m off."""
    mean, P = np.array([10.0, 0.0]), np.diag([0.1**2, 0.5**2])

    def polar(X):
        return np.stack([X[:, 0] * np.cos(X[:, 1]), X[:, 0] * np.sin(X[:, 1])], -1)

    draws = np.random.default_rng(3).multivariate_normal(mean, P, 1_000_000)
    truth = polar(draws).mean(0)
    np.testing.assert_allclose(truth[0], 10 * np.exp(-0.125), atol=0.01)   # E[cos b]
    m, _, _, _ = uk.unscented_transform(uk.sigma_points(mean, P, kappa=1.0), polar)
    linear = polar(mean[None])[0]
    assert np.abs(m - truth).max() < 0.2
    assert np.abs(linear - truth).max() > 1.0


def test_the_update_of_a_linear_measurement_is_the_kalman_filters():
    """Range and bearing of a landmark far ahead are nearly linear in a small pose
    uncertainty; against the EKF (linear KF with the Jacobian) the UKF's update agrees to
    the size of the neglected curvature."""
    pose = np.array([0.0, 0.0, 0.3])
    P = np.diag([1e-4, 1e-4, 1e-6])
    lm = np.array([40.0, 30.0])
    R = np.diag([0.05**2, 0.01**2])
    z = np.array([50.2, np.pi / 2 + 0.01])
    new, Pn, info = uk.ukf_update(pose, P, z, lm, R)
    zhat, H, _ = observe(pose, lm)
    nu = z - zhat
    x_kf, P_kf = kf_update(pose, P, nu + H @ pose, H, R)
    np.testing.assert_allclose(new, x_kf, atol=1e-5)
    np.testing.assert_allclose(Pn, P_kf, rtol=1e-3, atol=1e-12)


def test_the_prediction_agrees_with_the_ekf_to_first_order():
    veh = Vehicle()
    pose, P = np.array([1.0, 2.0, 0.2]), np.diag([1e-4, 1e-4, 1e-5])
    u, Q, dt = np.array([3.0, 0.05]), np.diag([0.01**2, 1e-4**2]), 0.025
    m, C = uk.ukf_predict(pose, P, u, dt, veh, Q)
    nxt, F, G = predict(pose, u, dt, veh)
    # the means differ by the second-order term, about v dt sigma_phi^2 / 2 = 3.8e-7 m
    np.testing.assert_allclose(m, nxt, atol=2 * 0.5 * u[0] * dt * P[2, 2])
    np.testing.assert_allclose(C, F @ P @ F.T + G @ Q @ G.T, rtol=1e-4, atol=1e-12)


def test_headings_across_pi_average_on_the_circle():
    sp = uk.sigma_points(np.array([0.0, 0.0, np.pi - 0.01]), np.diag([0.01, 0.01, 0.05**2]))
    m, C, _, _ = uk.unscented_transform(sp, lambda X: X, angles=(2,))
    assert abs(abs(m[2]) - (np.pi - 0.01)) < 1e-9          # not near 0
    assert C[2, 2] == pytest.approx(0.05**2, rel=1e-6)


def test_bad_covariances_are_refused_saying_where():
    with pytest.raises(uk.UnscentedError, match="not positive semi-definite"):
        uk.sigma_points(np.zeros(2), np.array([[1.0, 2.0], [2.0, 1.0]]))
    # a semi-definite covariance (one component known exactly) has sigma points
    sp = uk.sigma_points(np.zeros(2), np.diag([1.0, 0.0]))
    D = sp.points
    np.testing.assert_allclose((D * sp.wc[:, None]).T @ D - 3.0 * np.outer(D[0], D[0]),
                               np.diag([1.0, 0.0]), atol=1e-12)
    with pytest.raises(ValueError, match="must have shape"):
        uk.sigma_points(np.zeros(2), np.eye(3))
    with pytest.raises(ValueError):
        uk.ukf_update([0, 0, np.nan], np.eye(3), [1.0, 0.0], [1.0, 0.0], np.eye(2))
    # a negative-definite "noise" makes the update's covariance indefinite: refused
    with pytest.raises(uk.UnscentedError, match="lost its definiteness"):
        uk.ukf_update(np.zeros(3), np.eye(3) * 0.01, [10.0, 1.6], [0.0, 10.0],
                      -np.eye(2) * 0.0099)


def test_a_ukf_run_follows_the_dense_ekf_where_the_models_are_nearly_linear():
    """The run loop with ``backend='ukf'`` on a seeded simulation (noise small against
    the models' curvature): the same associations and landmarks as the dense EKF, the path
    within 5 mm, the map within 5 mm, the final pose variances within 2 %."""
    import dataclasses

    from annslam_lib.data import simulate
    from annslam_lib.slam import runner
    from annslam_lib.slam.config import SlamConfig

    ds = simulate.simulate(seed=400, laps=1, raw_laser=False)
    cfg = SlamConfig.for_dataset("simulated", association="truth")
    ekf = runner.run(ds, cfg, progress=False, backend="dense")
    ukf = runner.run(ds, cfg, progress=False, backend="ukf")
    assert (ukf.counts["associated"], ukf.counts["new"]) == (ekf.counts["associated"],
                                                             ekf.counts["new"])
    assert np.abs(ukf.trajectory[:, 1:3] - ekf.trajectory[:, 1:3]).max() < 0.005
    assert np.abs(ukf.landmarks - ekf.landmarks).max() < 0.005
    np.testing.assert_allclose(np.diag(ukf.pose_cov[-1]), np.diag(ekf.pose_cov[-1]), rtol=0.02)
    with pytest.raises(ValueError, match="'efficient', 'dense' or 'ukf'"):
        runner.run(ds, dataclasses.replace(cfg), progress=False, backend="particles")


def test_ukf_localisation_on_the_car_park_agrees_with_the_ekfs():
    """The Car Park on its surveyed map: the UKF makes the EKF's 883 associations and 50
    GPS updates, and its path stays within 5 cm of the EKF's (1.4 cm measured)."""
    import dataclasses

    from annslam_lib.data import load
    from annslam_lib.slam import runner
    from annslam_lib.slam.config import SlamConfig

    car = load("car_park")
    cfg = dataclasses.replace(SlamConfig.for_dataset("car_park"), map_mode="known")
    ekf = runner.run(car, cfg, progress=False)
    ukf = runner.run(car, cfg, progress=False, backend="ukf")
    for key in ("associated", "gps_updates", "rejected"):
        assert ukf.counts[key] == ekf.counts[key], key
    assert np.abs(ukf.trajectory[:, 1:3] - ekf.trajectory[:, 1:3]).max() < 0.05
