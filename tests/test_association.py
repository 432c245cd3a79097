"""Chi-square gating and nearest-neighbour association with mutual exclusion, on crafted cases."""
import dataclasses
import math

import numpy as np
import pytest
from scipy.stats import chi2


from annslam_lib.perception.association import NEW, REJECTED, associate, gate_threshold, mahalanobis
from annslam_lib.data import simulate
from annslam_lib.perception import association


def test_thresholds_are_the_chi_square_quantiles():
    # For 2 degrees of freedom the chi-square CDF is 1 - exp(-x/2): ppf(p) = -2 ln(1 - p).
    for p in (0.5, 0.95, 0.99, 0.9999):
        assert gate_threshold(p) == pytest.approx(-2.0 * math.log(1.0 - p), rel=1e-12)
    assert association.GATE == pytest.approx(-2.0 * math.log(0.01), rel=1e-12)          # 9.21
    assert association.NEW_LANDMARK == pytest.approx(-2.0 * math.log(1e-5), rel=1e-12)  # 23.03
    assert gate_threshold(0.95, dof=1) == pytest.approx(1.959963984540054**2, rel=1e-9)
    for p, dof in ((0.99, 2), (0.9999, 2), (0.95, 3)):
        assert gate_threshold(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-12)
    for bad in (0.0, 1.0, -0.5):
        with pytest.raises(ValueError, match="prob"):
            gate_threshold(bad)
    for bad in (True, "0.9"):
        with pytest.raises(TypeError, match="prob"):
            gate_threshold(bad)
    with pytest.raises(ValueError, match="dof"):
        gate_threshold(0.9, dof=0)


def test_mahalanobis_matches_a_solve_loop_on_random_inputs():
    rng = np.random.default_rng(4)
    n, m = 7, 5
    z = np.column_stack([rng.uniform(1, 30, n), rng.uniform(-np.pi, np.pi, n)])
    zhat = np.column_stack([rng.uniform(1, 30, m), rng.uniform(-np.pi, np.pi, m)])
    A = rng.normal(size=(m, 2, 2))
    S = A @ np.swapaxes(A, 1, 2) + 0.01 * np.eye(2)
    d2 = mahalanobis(z, zhat, S)
    assert d2.shape == (n, m)
    for i in range(n):
        for j in range(m):
            nu = z[i] - zhat[j]
            nu[1] = (nu[1] + np.pi) % (2 * np.pi) - np.pi
            assert d2[i, j] == pytest.approx(nu @ np.linalg.solve(S[j], nu), rel=1e-9)


def test_bearing_innovation_is_wrapped_across_plus_minus_pi():
    s_b = math.radians(1.0)
    S = np.diag([0.1**2, s_b**2])[None]
    z = np.array([[10.0, np.pi - 0.01]])
    zhat = np.array([[10.0, -np.pi + 0.01]])          # 0.02 rad away, the short way round
    assert mahalanobis(z, zhat, S)[0, 0] == pytest.approx((0.02 / s_b) ** 2, rel=1e-9)
    assert associate(mahalanobis(z, zhat, S)).tolist() == [0]


def test_singular_or_asymmetric_S_raises_naming_the_landmark():
    z, zhat = np.zeros((1, 2)) + 5.0, np.full((3, 2), 5.0)
    good = np.diag([0.01, 0.001])
    for bad, word in (([[1.0, 1.0], [1.0, 1.0]], "positive definite"),
                      ([[-1.0, 0.0], [0.0, 1.0]], "positive definite"),
                      (np.zeros((2, 2)), "positive definite"),
                      ([[1.0, 0.2], [0.1, 1.0]], "not symmetric")):
        S = np.stack([good, np.asarray(bad, float), good])
        with pytest.raises(ValueError, match=f"landmark 1 is {word}|landmark 1 .*{word}"):
            mahalanobis(z, zhat, S)
    with pytest.raises(ValueError, match="NaN"):
        mahalanobis(z, zhat, np.stack([good, good, good * np.nan]))
    with pytest.raises(ValueError, match="S \\(m, 2, 2\\)"):
        mahalanobis(z, zhat, np.stack([good, good]))


def test_nearest_in_mahalanobis_not_in_euclidean_distance():
    # Landmark 0 is 0.3 m away in range but very certain (sigma 0.1 m): d2 = 9.0, inside the
    # 9.21 gate. Landmark 1 is 0.6 m away but uncertain (sigma 0.5 m): d2 = 1.44.
    z = np.array([[10.0, 1.0]])
    zhat = np.array([[10.3, 1.0], [10.6, 1.0]])
    S = np.stack([np.diag([0.1**2, 1e-4]), np.diag([0.5**2, 1e-4])])
    d2 = mahalanobis(z, zhat, S)
    np.testing.assert_allclose(d2, [[9.0, 1.44]], rtol=1e-9)
    assert np.all(d2 <= association.GATE)                  # both in the gate
    assert np.argmin(np.linalg.norm(z - zhat, axis=1)) == 0  # Euclidean would pick landmark 0
    assert associate(d2).tolist() == [1]


def test_correlated_S_changes_the_nearest_landmark():
    # Same Euclidean innovation (0.5 m, 0.5 deg) for both landmarks; landmark 0's S is
    # correlated along that direction, landmark 1's against it.
    b = math.radians(0.5)
    z = np.array([[10.5, 1.0 + b]])
    zhat = np.array([[10.0, 1.0], [10.0, 1.0]])
    sr, sb = 0.5, math.radians(0.5)
    S = np.stack([[[sr**2, 0.9 * sr * sb], [0.9 * sr * sb, sb**2]],
                  [[sr**2, -0.9 * sr * sb], [-0.9 * sr * sb, sb**2]]])
    d2 = mahalanobis(z, zhat, S)
    # nu = (1 sigma, 1 sigma): d2 = 2 / (1 + rho) along the correlation, 2 / (1 - rho) against.
    np.testing.assert_allclose(d2, [[2 / 1.9, 2 / 0.1]], rtol=1e-9)
    assert associate(d2).tolist() == [0]


def test_new_landmark_outlier_and_accepted():
    # d2 to the only landmark: 2 (accepted), 12 (between the gates: rejected), 40 (new).
    d2 = np.array([[2.0], [12.0], [40.0]])
    assert associate(d2).tolist() == [0, REJECTED, NEW]
    # A too-small gate turns the good one into a reject; a huge new-landmark threshold
    # keeps the far one out of the map.
    assert associate(d2, gate=1.0).tolist() == [REJECTED, REJECTED, NEW]
    assert associate(d2, new_landmark=100.0).tolist() == [0, REJECTED, REJECTED]


def test_two_observations_compete_for_one_landmark():
    d2 = np.array([[4.0], [1.0]])                     # observation 1 is nearer
    assert associate(d2).tolist() == [REJECTED, 0]
    # With a second landmark inside observation 0's gate, it falls back to that one.
    d2 = np.array([[4.0, 6.0], [1.0, 50.0]])
    assert associate(d2).tolist() == [1, 0]
    # Greedy in increasing d2: (1,0)=1 first, then (0,1)=3; (0,0)=2 loses its landmark.
    d2 = np.array([[2.0, 3.0], [1.0, 50.0]])
    assert associate(d2).tolist() == [1, 0]
    # Ties are broken by the lower observation, then the lower landmark index.
    assert associate(np.array([[1.0], [1.0]])).tolist() == [0, REJECTED]
    assert associate(np.array([[1.0, 1.0]])).tolist() == [0]


def test_every_landmark_receives_at_most_one_observation():
    rng = np.random.default_rng(0)
    d2 = rng.chisquare(2, size=(30, 12)) * rng.uniform(0.2, 3, size=(30, 1))
    a = associate(d2)
    taken = a[a >= 0]
    assert taken.size == np.unique(taken).size > 5
    assert np.all(d2[np.flatnonzero(a >= 0), taken] <= association.GATE)
    assert np.all(np.min(d2[a == NEW], axis=1) > association.NEW_LANDMARK)
    # Each rejected observation either has no landmark in its gate or lost all of them.
    for i in np.flatnonzero(a == REJECTED):
        inside = np.flatnonzero(d2[i] <= association.GATE)
        assert np.min(d2[i]) <= association.NEW_LANDMARK
        assert np.all(np.isin(inside, taken))


def test_empty_maps_and_empty_scans():
    assert associate(np.zeros((3, 0))).tolist() == [NEW, NEW, NEW]
    assert associate(np.zeros((0, 4))).shape == (0,)
    assert mahalanobis(np.zeros((0, 2)), np.ones((2, 2)), np.stack([np.eye(2)] * 2)).shape == (0, 2)
    assert mahalanobis(np.ones((3, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2))).shape == (3, 0)
    assert associate(np.array([[np.inf, 3.0]])).tolist() == [1]      # +inf: never matched


def test_associate_rejects_bad_input():
    with pytest.raises(ValueError, match="NaN"):
        associate(np.array([[np.nan]]))
    with pytest.raises(ValueError, match="non-negative"):
        associate(np.array([[-1.0]]))
    with pytest.raises(ValueError, match="\\(n, m\\)"):
        associate(np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="must be >= gate"):
        associate(np.array([[1.0]]), gate=10.0, new_landmark=5.0)
    with pytest.raises(ValueError, match="gate"):
        associate(np.array([[1.0]]), gate=0.0)


def test_score_association_counts_each_outcome():
    # Map holds true landmarks 7 and 3; measurements come from 7, 3, 3, 9 (unmapped), 9, 7.
    predicted = np.array([7, 3])
    true = np.array([7, 3, 3, 9, 9, 7])
    assign = np.array([0, 0, REJECTED, NEW, 1, NEW])
    s = association.score_association(assign, predicted, true)
    assert s == {"correct": 1, "wrong": 2, "missed": 1, "false_new": 1, "new_ok": 1,
                 "new_rejected": 0}
    assert association.score_association(np.array([NEW]), np.array([], dtype=int), np.array([4]))["new_ok"] == 1
    with pytest.raises(ValueError, match="outside"):
        association.score_association(np.array([2]), predicted, np.array([7]))


def test_a_simulated_scan_is_associated_correctly():
    """End to end on the simulator: true pose with a known error covariance, S = H P H^T + R,
    the 99 % gate catches the true landmark of almost every detection."""
    
    from annslam_lib.models.observation import observe

    ds = simulate.simulate(seed=1, laps=1)
    rng = np.random.default_rng(1)
    P = np.diag([0.2**2, 0.2**2, math.radians(2.0) ** 2])
    R = np.diag([0.1**2, math.radians(1.0) ** 2])
    det, scores = ds.detections, []
    for k in range(0, len(det), 3):
        z = det[k]
        if not len(z):
            continue
        pose = ds.info["scan_poses"][k] + rng.multivariate_normal(np.zeros(3), P)
        zhat, Hp, _ = observe(pose, ds.beacons)
        S = Hp @ P @ Hp.transpose(0, 2, 1) + R
        a = associate(mahalanobis(z, zhat, S))
        ids = det.landmark_id[det.offsets[k]:det.offsets[k + 1]]
        scores.append(association.score_association(a, np.arange(len(ds.beacons)), ids))
    total = {key: sum(s[key] for s in scores) for key in scores[0]}
    n = sum(total.values())
    assert n > 300 and total["wrong"] == 0
    assert total["correct"] / n > 0.97


def test_gate_experiment_shows_the_trade_off_of_the_gate_size():
    

    ds = simulate.simulate(seed=3, n_beacons=60, beacon_min_sep=1.5, beacon_max_dist=10, laps=1)
    mapped = np.arange(0, 60, 2)                   # half the beacons are on the map
    P = np.diag([0.3**2, 0.3**2, math.radians(3.0) ** 2])
    R = np.diag([0.1**2, math.radians(1.0) ** 2])
    rows = association.gate_experiment(ds, mapped, P, R, [0.5, 0.99, 1 - 1e-8])
    small, mid, big = rows
    known = sum(mid[k] for k in ("correct", "wrong", "missed", "false_new"))
    assert [r["gate"] for r in rows] == pytest.approx([gate_threshold(p) for p in (0.5, 0.99, 1 - 1e-8)])
    assert small["missed"] > 10 * mid["missed"]    # too small: true matches rejected
    assert big["wrong"] > 2 * mid["wrong"]         # too large: unmapped beacons grabbed
    assert mid["correct"] > 0.9 * known and mid["false_new"] <= 2
    over = association.gate_experiment(ds, mapped, P, R, [0.99], S_scale=0.25)[0]
    assert over["false_new"] > 50                  # an over-confident filter makes duplicates
    with pytest.raises(ValueError, match="simulated dataset"):
        association.gate_experiment(dataclasses.replace(ds, info={}), mapped, P, R, [0.99])
