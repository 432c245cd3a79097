"""Graph-SLAM from scratch (``smoothing.gauss_newton``) against what we did not write:
finite differences for its Jacobians, GTSAM's ``Pose2.Logmap`` for Log, GTSAM's batch
Levenberg-Marquardt on the same Car Park graph for the solution, and the gauge's three free
directions for the information matrix without a prior."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from annslam_lib.data import load, simulate
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig
from annslam_lib.smoothing import gauss_newton as gn
from annslam_lib.smoothing import problem as gp
from annslam_lib.smoothing import solve as gs

gtsam = pytest.importorskip("gtsam")


@pytest.fixture(scope="module")
def car_park():
    car = load("car_park")
    result = runner.run(car, SlamConfig.for_dataset("car_park"), progress=False)
    return gp.build_problem(car, result)


@pytest.fixture(scope="module")
def simulated():
    ds = simulate.simulate(seed=400, laps=1, raw_laser=False)
    r = runner.run(ds, SlamConfig.for_dataset("simulated", association="truth"), progress=False)
    return gp.build_problem(ds, r)


@pytest.mark.parametrize("theta", [0.0, 3e-5, -2e-4, 0.7, -2.5, 3.14159])
def test_log_is_gtsams_and_its_derivative_its_finite_difference(theta):
    u = np.array([1.3, -0.4])
    xi, d = gn.se2_log_jacobian(u, theta)
    np.testing.assert_allclose(xi, gtsam.Pose2.Logmap(gtsam.Pose2(u[0], u[1], theta)), atol=1e-12)
    h = 1e-6
    fd = (gn.se2_log_jacobian(u, theta + h)[0][:2] - gn.se2_log_jacobian(u, theta - h)[0][:2]) / (2 * h)
    np.testing.assert_allclose(d, fd, atol=1e-7)


def test_the_jacobian_is_the_errors_derivative(simulated):
    """Every column of J against central differences of the whitened errors, at a
    perturbed estimate (so no residual is zero)."""
    P = simulated
    rng = np.random.default_rng(3)
    x = P.initial_poses + rng.normal(0, 0.05, P.initial_poses.shape)
    m = P.initial_landmarks + rng.normal(0, 0.05, P.initial_landmarks.shape)
    e, J = gn.linearise(P, x, m)
    K = P.n_poses
    v = np.concatenate([x.ravel(), m.ravel()])

    def errors(w):
        return gn.linearise(P, w[:3 * K].reshape(K, 3), w[3 * K:].reshape(-1, 2))[0]

    cols = np.concatenate([rng.choice(3 * K, 60, replace=False), 3 * K + np.arange(2 * P.n_landmarks)])
    J = J.tocsc()
    for i in cols:
        h = 1e-6
        vp, vm = v.copy(), v.copy()
        vp[i] += h
        vm[i] -= h
        fd = (errors(vp) - errors(vm)) / (2 * h)
        col = J[:, i].toarray().ravel()
        assert np.abs(fd - col).max() <= 1e-5 * max(1.0, np.abs(col).max()), i


def test_the_cost_is_gtsams_graph_error(simulated):
    graph, values = gs.build_graph(simulated)
    assert gn.cost(simulated, simulated.initial_poses, simulated.initial_landmarks) == \
        pytest.approx(graph.error(values), rel=1e-12)


def test_gauss_newton_agrees_with_gtsams_batch_solution_on_the_car_park(car_park):
    """Both from the EKF's estimate: poses within 0.1 mm and 1e-5 rad, landmarks within
    0.1 mm, and Gauss-Newton's cost no higher than LM's (LM stops at a relative decrease of
    1e-6, Gauss-Newton at 1e-10)."""
    g = gn.solve_gauss_newton(car_park)
    b = gs.solve_batch(car_park)
    assert g.iterations <= 10
    d = g.poses - b.poses
    assert np.abs(d[:, :2]).max() < 1e-4
    assert np.abs(np.angle(np.exp(1j * d[:, 2]))).max() < 1e-5
    assert np.abs(g.landmarks - b.landmarks).max() < 1e-4
    assert g.error_final <= b.error_final * (1 + 1e-9)
    assert g.error_final < 0.01 * g.error_initial          # the EKF's estimate was far off


def test_without_a_prior_the_information_matrix_has_the_three_gauge_directions(car_park):
    """Without a prior and GPS: J^T J N = 0 for N the whole map moved in x, in y, and
    turned about the origin; with the prior, no such direction."""
    free = dataclasses.replace(car_park, prior_pose=None, prior_cov=None,
                               gps_node=np.empty(0, np.int64), gps_xy=np.empty((0, 2)))
    g = gn.solve_gauss_newton(car_park)
    H = gn.information_matrix(free, g.poses, g.landmarks)
    K, L = car_park.n_poses, car_park.n_landmarks
    N = np.zeros((3 * K + 2 * L, 3))
    N[0:3 * K:3, 0] = N[3 * K::2, 0] = 1.0
    N[1:3 * K:3, 1] = N[3 * K + 1::2, 1] = 1.0
    N[0:3 * K:3, 2], N[1:3 * K:3, 2], N[2:3 * K:3, 2] = -g.poses[:, 1], g.poses[:, 0], 1.0
    N[3 * K::2, 2], N[3 * K + 1::2, 2] = -g.landmarks[:, 1], g.landmarks[:, 0]
    scale = abs(H).max()
    assert np.abs(H @ N).max() < 1e-8 * scale * np.abs(N).max()
    Hp = gn.information_matrix(car_park, g.poses, g.landmarks)
    # the prior and the GPS fixes hold each direction: information > 1 along all three
    assert np.linalg.eigvalsh(N.T @ (Hp @ N)).min() > 1.0
    assert np.abs(np.linalg.eigvalsh(N.T @ (H @ N))).max() < 1e-6


def test_an_under_determined_graph_is_refused(car_park):
    free = dataclasses.replace(car_park, prior_pose=None, prior_cov=None,
                               gps_node=np.empty(0, np.int64), gps_xy=np.empty((0, 2)))
    with pytest.raises(ValueError, match="missing prior"):
        gn.solve_gauss_newton(free)
    with pytest.raises(gs.SolverError, match="singular"):
        gn.solve_gauss_newton(free, check=False)
    keep = car_park.obs_landmark != 3                        # landmark 3 loses its sightings
    unseen = dataclasses.replace(car_park, obs_node=car_park.obs_node[keep],
                                 obs_landmark=car_park.obs_landmark[keep],
                                 obs_z=car_park.obs_z[keep])
    with pytest.raises(ValueError, match="landmark 3 has no bearing-range factor"):
        gn.solve_gauss_newton(unseen)
    with pytest.raises(gs.SolverError, match="singular at landmark 3"):
        gn.solve_gauss_newton(unseen, check=False)


def test_a_robust_kernel_resists_wrong_associations_as_gtsams_does(car_park):
    """5 % of the Car Park's detections given to a wrong landmark (a fixed draw): plain
    least squares moves the map by metres; with Huber's loss (k = 1) the map stays within
    0.15 m of the clean solution, and the from-scratch solution is GTSAM's robust batch
    solution (poses and landmarks within 1 mm, the same cost to 1e-6)."""
    clean = gn.solve_gauss_newton(car_park)
    rng = np.random.default_rng(11)
    lm = car_park.obs_landmark.copy()
    bad = rng.choice(lm.size, int(0.05 * lm.size), replace=False)
    lm[bad] = (lm[bad] + rng.integers(1, car_park.n_landmarks, bad.size)) % car_park.n_landmarks
    wrong = dataclasses.replace(car_park, obs_landmark=lm)
    plain = gn.solve_gauss_newton(wrong, max_iterations=100)
    robust = gn.solve_gauss_newton(wrong, huber_k=1.0)
    moved = {name: np.abs(s.landmarks - clean.landmarks).max()
             for name, s in (("plain", plain), ("robust", robust))}
    assert moved["plain"] > 2.0 and moved["robust"] < 0.15, moved
    b = gs.solve_batch(wrong, huber_k=1.0, max_iterations=200)
    assert np.abs(robust.poses[:, :2] - b.poses[:, :2]).max() < 1e-3
    assert np.abs(robust.landmarks - b.landmarks).max() < 1e-3
    assert robust.error_final == pytest.approx(b.error_final, rel=1e-6)
    assert gn.cost(wrong, b.poses, b.landmarks, huber_k=1.0) == pytest.approx(b.error_final,
                                                                             rel=1e-9)


def test_huber_is_quadratic_then_linear():
    rho, w = gn.huber([0.5, 1.0, 3.0], 1.0)
    np.testing.assert_allclose(rho, [0.125, 0.5, 2.5])
    np.testing.assert_allclose(w, [1.0, 1.0, 1 / 3])
    with pytest.raises(ValueError, match="huber_k must be positive"):
        gn.solve_gauss_newton(None, huber_k=0.0)
