"""The Kalman filter of chapter 01a (annslam_lib.slam.kalman) against references it does not
share code with: the Bayes filter on a grid (no Gaussian assumption), Gaussian conditioning
written out from the joint covariance, Monte Carlo, iterating the filter to its fixed
point, and scipy's chi-square; bad input raises."""
import math

import numpy as np
import pytest
from scipy.stats import binomtest, chi2

from annslam_lib.slam import dense, kalman
from annslam_lib.chapters import ch01a_kalman_filter as ch


def test_1d_update_is_the_grid_bayes_posterior_for_asymmetric_cases():
    g = np.linspace(-20, 30, 5001)
    for mu, var, z, r in [(0.0, 4.0, 3.0, 1.0), (10.0, 0.01, 8.0, 2.0), (-3.0, 2.5, 5.0, 0.3)]:
        post = kalman.grid_update(kalman.gaussian_pdf(g, mu, var), g, z, r)
        m = kalman.grid_moments(post, g)
        mu_k, var_k, K = kalman.update_1d(mu, var, z, r)
        assert m["mean"] == pytest.approx(mu_k, abs=1e-6)
        assert m["var"] == pytest.approx(var_k, rel=1e-5)
        assert 1 / var_k == pytest.approx(1 / var + 1 / r)       # information adds
        assert 0 < K < 1


def test_grid_prediction_is_the_convolution_and_loses_mass_only_past_the_edge():
    g = np.linspace(-5, 5, 1001)
    p = kalman.grid_predict(kalman.gaussian_pdf(g, 0.0, 0.2), g, 1.0, 0.3)
    m = kalman.grid_moments(p, g)
    assert (m["mean"], m["var"]) == (pytest.approx(1.0, abs=1e-6), pytest.approx(0.5, abs=1e-6))
    edge = kalman.grid_predict(kalman.gaussian_pdf(g, 4.0, 0.2), g, 1.0, 0.3)
    lost = 1 - kalman.grid_moments(edge, g)["mass"]
    assert lost == pytest.approx(0.5, abs=0.01)                 # half of N(5, 0.5) is past x = 5


def test_nd_update_equals_gaussian_conditioning_of_the_joint():
    rng = np.random.default_rng(0)
    for n, m in [(2, 1), (3, 2), (5, 3)]:
        A = rng.normal(size=(n, n))
        P = A @ A.T + 0.1 * np.eye(n)
        H = rng.normal(size=(m, n))
        B = rng.normal(size=(m, m))
        R = B @ B.T + 0.1 * np.eye(m)
        x, z = rng.normal(size=n), rng.normal(size=m)
        # the joint of (x, z) and the conditional of its first block, written out
        J = np.block([[P, P @ H.T], [H @ P, H @ P @ H.T + R]])
        Sxz, Szz = J[:n, n:], J[n:, n:]
        mean = x + Sxz @ np.linalg.solve(Szz, z - H @ x)
        cov = J[:n, :n] - Sxz @ np.linalg.solve(Szz, Sxz.T)
        for form in ("joseph", "simple"):
            xk, Pk = kalman.kf_update(x, P, z, H, R, form=form)
            np.testing.assert_allclose(xk, mean, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(Pk, cov, rtol=1e-8, atol=1e-12)


def test_joseph_form_is_the_covariance_of_any_gain_and_the_simple_form_is_not():
    so = ch.suboptimal_gain(scale=0.5, n_draws=200_000, seed=11)
    assert np.max(np.abs(so["joseph_z"])) < 4                   # within sampling error
    assert np.max(np.abs(so["simple_z"])) > 20                  # far outside it
    at_opt = ch.suboptimal_gain(scale=1.0, n_draws=50_000, seed=12)
    np.testing.assert_allclose(at_opt["simple"], at_opt["joseph"], rtol=1e-9)


def test_covariance_never_depends_on_the_measurements():
    same = ch.same_covariance(n_steps=15, seed=9)
    assert same["mean_difference"] > 1.0 and same["covariance_difference"] == 0.0


@pytest.mark.parametrize("q, r", [(0.09, 0.16), (1e-3, 10.0), (5.0, 0.01), (0.0, 1.0), (1.0, 0.0)])
def test_steady_state_is_the_fixed_point_of_the_filter(q, r):
    p = 1.0
    for _ in range(20_000):
        _, p, _ = kalman.update_1d(0.0, p + q, 0.0, r) if p + q + r > 0 else (0, 0, 0)
    p_minus, p_plus = kalman.steady_state_variance(q, r)
    assert p_plus == pytest.approx(p, abs=1e-4 if q == 0 else 1e-12, rel=1e-9)
    assert p_minus == pytest.approx(p_plus + q)


def test_gate_keeps_the_share_p_in_every_dimension():
    rng = np.random.default_rng(3)
    for m in (1, 2, 4):
        A = rng.normal(size=(m, m))
        S = A @ A.T + 0.2 * np.eye(m)
        nu = rng.multivariate_normal(np.zeros(m), S, 4000)
        kept = sum(kalman.innovation_gate(v, S, 0.9)[2] for v in nu)
        assert binomtest(int(kept), 4000, 0.9).pvalue > 0.001
        d2, t, ok = kalman.innovation_gate(nu[0], S, 0.9)
        assert t == pytest.approx(chi2.ppf(0.9, m)) and ok == (d2 <= t)


def test_random_walk_agrees_with_the_grid_and_settles_at_the_closed_form():
    w = ch.random_walk(n_steps=40, seed=5)
    assert w["max_grid_difference"] < 1e-9
    assert w["var"][-1] == pytest.approx(w["p_plus"], rel=1e-9)


def test_ekf_matches_the_exact_posterior_only_where_the_model_is_nearly_linear():
    far = ch.range_example(6.5, 1.0, z=math.hypot(6.0, 5.0))
    near = ch.range_example(0.5, 4.0, z=math.hypot(1.5, 5.0))
    assert far["ekf"][0] == pytest.approx(far["exact"][0], abs=0.05)
    assert far["ekf"][1] == pytest.approx(far["exact"][1], rel=0.1)
    assert len(near["modes"]) == 2 and near["modes"][0] < 0 < near["modes"][1]
    assert abs(near["ekf"][0] - near["exact"][0]) > 1.0 and near["ekf"][1] < near["exact"][1]


@pytest.mark.parametrize("call, match", [
    (lambda: kalman.update_1d(0, -1, 0, 1), "var"),
    (lambda: kalman.update_1d(0, 0, 0, 0), "var \\+ r = 0"),
    (lambda: kalman.update_1d(float("nan"), 1, 0, 1), "mu"),
    (lambda: kalman.predict_1d(0, 1, 0, -0.1), "q"),
    (lambda: kalman.steady_state_variance(0, 0), "q = r = 0"),
    (lambda: kalman.innovation_gate([1.0, 2.0], np.eye(2), 1.5), "p"),
    (lambda: kalman.innovation_gate([1.0, 2.0], np.zeros((2, 2)), 0.9), "positive definite"),
    (lambda: kalman.innovation_gate([1.0, 2.0], np.eye(3), 0.9), "S"),
    (lambda: kalman.kf_update([0, 0], np.eye(2), [1.0], [[1.0, 0.0]], [[0.0]], form="fast"), "form"),
    (lambda: kalman.kf_update([0, 0], np.zeros((2, 2)), [1.0], [[1.0, 0.0]], [[0.0]]), "singular"),
    (lambda: kalman.kf_update([0, 0], np.eye(2), [1.0, 2.0], [[1.0, 0.0]], np.eye(2)), "H must be"),
    (lambda: kalman.kf_predict([0, 0], np.eye(2), np.eye(3), np.eye(2)), "F must be"),
    (lambda: kalman.kf_predict([0, 0], [[1, 2], [0, 1]], np.eye(2), np.eye(2)), "symmetric"),
    (lambda: kalman.grid_update(np.ones(5), np.array([0, 1, 2, 4, 5.0]), 0, 1), "evenly"),
    (lambda: kalman.grid_update(np.ones(5), np.arange(5.0), 1e6, 1e-6), "zero likelihood"),
    (lambda: kalman.grid_predict(-np.ones(5), np.arange(5.0), 0, 1), "negative"),
])
def test_bad_input_raises_a_clear_error(call, match):
    with pytest.raises((ValueError, TypeError), match=match):
        call()


def test_kf_update_uses_the_course_filter_functions():
    P, H, R = np.diag([1.0, 2.0]), np.array([[1.0, 1.0]]), np.array([[0.5]])
    K, _ = dense.kalman_gain(P, H, R)
    _, Pk = kalman.kf_update([0, 0], P, [1.0], H, R)
    np.testing.assert_array_equal(Pk, dense.joseph_covariance(P, H, R, K))
