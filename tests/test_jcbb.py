"""JCBB (``perception.jcbb``) against a brute-force enumeration of every hypothesis, a scan
where gated nearest neighbour pairs wrongly and JCBB does not, its bound and bad input."""
import itertools
import math

import numpy as np
import pytest
from scipy.stats import chi2

from annslam_lib.perception import association, jcbb

R = np.diag([0.1**2, math.radians(1.0)**2])


def brute_force(z, zhat, C, R, gate_prob=0.99, joint_prob=0.99):
    """Every hypothesis, written plainly: the individually and jointly compatible one with the
    most pairings, then the smallest joint NIS; and every compatible one as many pairings."""
    n, L = z.shape[0], zhat.shape[0]
    best, best_key, hyps = None, None, []
    for pairs in itertools.product(range(-1, L), repeat=n):
        used = [j for j in pairs if j >= 0]
        if len(used) != len(set(used)):
            continue
        ok = True
        for i, j in enumerate(pairs):
            if j >= 0:
                nu = z[i] - zhat[j]
                nu[1] = (nu[1] + math.pi) % (2 * math.pi) - math.pi
                d2 = nu @ np.linalg.solve(C[2 * j:2 * j + 2, 2 * j:2 * j + 2] + R, nu)
                ok &= d2 <= chi2.ppf(gate_prob, 2)
        if not ok:
            continue
        nis = jcbb.joint_nis(z, zhat, C, R, pairs)
        if used and nis > chi2.ppf(joint_prob, 2 * len(used)):
            continue
        key = (-len(used), nis)
        hyps.append((len(used), np.array(pairs)))
        if best_key is None or key < best_key:
            best, best_key = np.array(pairs), key
    ties = [p for k, p in hyps if k == -best_key[0]]
    return best, -best_key[0], best_key[1], ties


def scene(rng, n_lm=4, n_z=4, pose_sigma=(0.3, 0.3, 0.05)):
    """Landmarks close together seen from an uncertain pose: H P H^T from a sampled P."""
    lm = rng.uniform([5, -3], [12, 3], (n_lm, 2))
    pose = np.zeros(3)
    d = lm - pose[:2]
    r = np.hypot(d[:, 0], d[:, 1])
    zhat = np.column_stack([r, np.arctan2(d[:, 1], d[:, 0]) + math.pi / 2])
    # H for (pose, landmarks) and a P with a correlated pose and landmark block
    n = 3 + 2 * n_lm
    A = rng.normal(0, 0.05, (n, n))
    P = A @ A.T + np.diag(np.concatenate([np.square(pose_sigma), np.full(2 * n_lm, 0.01)]))
    H = np.zeros((2 * n_lm, n))
    for j in range(n_lm):
        u = d[j] / r[j]
        w = np.array([-u[1], u[0]]) / r[j]
        H[2 * j, :2], H[2 * j, 3 + 2 * j:5 + 2 * j] = -u, u
        H[2 * j + 1, :2], H[2 * j + 1, 2], H[2 * j + 1, 3 + 2 * j:5 + 2 * j] = -w, -1.0, w
    C = H @ P @ H.T
    truth = rng.permutation(n_lm)[:n_z]
    err = rng.multivariate_normal(np.zeros(2 * n_lm), C + np.kron(np.eye(n_lm), R)).reshape(n_lm, 2)
    z = zhat[truth] + err[truth]
    z[rng.random(z.shape[0]) < 0.25] += rng.normal(0, [1.0, 0.1], 2)     # some clutter
    return z, zhat, C, truth


@pytest.mark.parametrize("seed", range(25))
def test_jcbb_finds_the_hypothesis_brute_force_finds(seed):
    rng = np.random.default_rng(seed)
    z, zhat, C, _ = scene(rng, n_lm=int(rng.integers(2, 5)), n_z=int(rng.integers(1, 4)))
    ref, pairings, nis, ties = brute_force(z, zhat, C, R)
    got = jcbb.jcbb(z, zhat, C, R)
    assert got.complete and got.pairings == pairings
    np.testing.assert_array_equal(got.pairs, ref)     # the smallest joint NIS among the ties
    assert got.nis == pytest.approx(nis, rel=1e-9, abs=1e-12)
    assert len(ties) >= 1


@pytest.mark.parametrize("seed", range(100, 108))
def test_the_incremental_search_agrees_with_brute_force_on_deeper_scenes(seed):
    """Five measurements and five landmarks, an uncertain pose: branches five pairings deep,
    where the search's extended Cholesky factor is used four times over."""
    rng = np.random.default_rng(seed)
    z, zhat, C, _ = scene(rng, n_lm=5, n_z=5, pose_sigma=(0.6, 0.6, 0.1))
    ref, pairings, nis, _ = brute_force(z, zhat, C, R)
    got = jcbb.jcbb(z, zhat, C, R)
    assert got.complete and got.pairings == pairings
    np.testing.assert_array_equal(got.pairs, ref)
    assert got.nis == pytest.approx(nis, rel=1e-9, abs=1e-12)
    assert got.nis == pytest.approx(jcbb.joint_nis(z, zhat, C, R, got.pairs), rel=1e-12, abs=1e-12)


def test_a_joint_covariance_that_is_not_positive_definite_is_refused():
    """Each prediction alone is fine, the pair is not: the cross covariance is larger than
    the variances (a correlation above 1), so the pair's 4x4 block is indefinite even with R
    added."""
    zhat = np.array([[10.0, 1.0], [10.0, 1.1]])
    C = np.eye(4) * 0.01
    C[0, 2] = C[2, 0] = C[1, 3] = C[3, 1] = 0.05          # |correlation| > 1: not a covariance
    z = zhat.copy()
    with pytest.raises(ValueError, match="not positive definite"):
        jcbb.jcbb(z, zhat, C, R)


def test_a_singular_measurement_noise_is_refused():
    """With R = 0 a joint covariance of rank below its size would be accepted or refused by
    rounding (an exactly singular block is not detected reliably): R must be positive
    definite."""
    zhat = np.array([[10.0, 1.0]])
    for bad in (np.zeros((2, 2)), np.diag([0.01, 0.0])):
        with pytest.raises(ValueError, match="R must be positive definite"):
            jcbb.jcbb(zhat.copy(), zhat, np.eye(2) * 0.01, bad)


def test_jcbb_rejects_what_nearest_neighbour_pairs_wrongly():
    """Two landmarks 1 m apart, the vehicle's heading uncertain: both measurements are shifted
    by the same heading error, so each falls nearest to the other landmark's neighbour. NN
    pairs the first with the wrong landmark; the joint test sees the shared error."""
    lm = np.array([[10.0, 0.0], [10.0, 1.2], [10.0, 2.4]])
    d = lm
    r = np.hypot(d[:, 0], d[:, 1])
    zhat = np.column_stack([r, np.arctan2(d[:, 1], d[:, 0]) + math.pi / 2])
    P = np.zeros((9, 9))
    P[2, 2] = math.radians(4.0) ** 2                  # only the heading is uncertain
    H = np.zeros((6, 9))
    for j in range(3):
        H[2 * j + 1, 2] = -1.0                         # bearing rows: -1 in the heading column
        u = d[j] / r[j]
        H[2 * j, 3 + 2 * j:5 + 2 * j] = u
    C = H @ P @ H.T
    shift = math.radians(6.3)                          # a 1.6-sigma heading error, shared
    z = zhat[[0, 1]] - np.array([0.0, shift])          # landmarks 0 and 1 seen, both rotated
    d2 = association.mahalanobis(z, zhat, C.reshape(3, 2, 3, 2)[np.arange(3), :, np.arange(3), :] + R)
    nn = association.associate(d2, association.gate_threshold(0.99), association.gate_threshold(0.99999))
    got = jcbb.jcbb(z, zhat, C, R)
    assert got.complete and got.pairs.tolist() == [0, 1]
    assert nn.tolist() != [0, 1], nn


def test_the_node_limit_returns_the_best_so_far_flagged():
    rng = np.random.default_rng(3)
    z, zhat, C, _ = scene(rng, n_lm=4, n_z=4, pose_sigma=(1.0, 1.0, 0.3))
    full = jcbb.jcbb(z, zhat, C, R)
    cut = jcbb.jcbb(z, zhat, C, R, max_nodes=3)
    assert full.complete and full.nodes > 3
    assert not cut.complete and cut.nodes == 3 and cut.pairings <= full.pairings
    if cut.pairings:                                   # what it returns is jointly compatible
        assert cut.nis <= chi2.ppf(0.99, 2 * cut.pairings)


def test_bad_input_is_a_clear_error():
    zhat, C = np.array([[10.0, 1.0]]), np.eye(2) * 0.01
    with pytest.raises(ValueError, match="joint covariance"):
        jcbb.jcbb(np.array([[10.0, 1.0]]), zhat, np.eye(4), R)
    with pytest.raises(ValueError):
        jcbb.jcbb(np.array([[np.nan, 1.0]]), zhat, C, R)
    with pytest.raises(ValueError, match="max_nodes"):
        jcbb.jcbb(np.array([[10.0, 1.0]]), zhat, C, R, max_nodes=0)
    with pytest.raises(ValueError, match="two measurements"):
        jcbb.joint_nis(np.array([[10.0, 1.0], [10.0, 1.0]]), zhat, C, R, [0, 0])
    empty = jcbb.jcbb(np.empty((0, 2)), zhat, C, R)
    assert empty.pairings == 0 and empty.pairs.size == 0


def test_joint_prediction_is_the_dense_H_P_Ht_and_the_run_loop_uses_jcbb():
    from annslam_lib.data import simulate
    from annslam_lib.models.observation import observe
    from annslam_lib.models.vehicle import ACFR_UTE
    from annslam_lib.slam import runner
    from annslam_lib.slam.config import SlamConfig
    from annslam_lib.slam.efficient import EkfSlam

    f = EkfSlam(np.array([1.0, 2.0, 0.4]), np.diag([0.04, 0.03, 0.01]), ACFR_UTE, "euler")
    f.augment(np.array([[8.0, 1.2], [12.0, 2.0], [6.0, 0.5]]), 0.1, math.radians(1.0))
    with pytest.raises(RuntimeError, match="gating"):
        f.joint_prediction([0, 2])
    f.innovation_d2(np.array([[8.0, 1.2]]), 0.1, math.radians(1.0))
    zhat, C = f.joint_prediction([2, 0])
    x, P = f.state()
    lms = x[3:].reshape(-1, 2)[[2, 0]]
    z_ref, Hp, Hl = observe(x[:3], lms)
    H = np.zeros((4, x.size))
    for k, j in enumerate([2, 0]):
        H[2 * k:2 * k + 2, :3], H[2 * k:2 * k + 2, 3 + 2 * j:5 + 2 * j] = Hp[k], Hl[k]
    np.testing.assert_allclose(zhat, z_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(C, H @ P @ H.T, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="distinct"):
        f.joint_prediction([0, 0])

    ds = simulate.simulate(seed=401, laps=1, raw_laser=False)
    cfg = SlamConfig.for_dataset("simulated", association="jcbb", motion_model="midpoint")
    r = runner.run(ds, cfg, progress=False)
    o = r.observations
    a = (o.status == 0) & (o.landmark >= 0)
    assert r.counts["jcbb_truncated"] == 0 and a.sum() > 1000
    assert np.all(r.landmark_true_id[o.landmark[a]] == o.true_id[a])   # every pairing right
    assert r.counts["landmarks"] == np.unique(ds.detections.landmark_id).size
    with pytest.raises(ValueError, match="efficient backend only"):
        runner.run(ds, cfg, progress=False, backend="dense")
    with pytest.raises(ValueError, match="jcbb_max_nodes"):
        SlamConfig(jcbb_max_nodes=0)
