"""EKF-SLAM (annslam_lib.ekf_slam): the efficient filter against the dense textbook
reference, compounding, consistency on the simulator, the Car Park targets, Victoria Park
covariance health, and bad input."""
import math

import numpy as np
import pytest
from scipy.stats import chi2


from annslam_lib.slam.dense import DenseEkfSlam
from annslam_lib.slam.efficient import EkfSlam
from annslam_lib.slam.base import InnovationError
from annslam_lib.slam.config import SlamConfig
from annslam_lib.models.observation import observe
from annslam_lib.data.records import Odometry
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.data import simulate
from annslam_lib.evaluation import consistency
from annslam_lib.evaluation import map as map_eval
from annslam_lib.evaluation import trajectory
from annslam_lib.models import motion
from annslam_lib.perception import association
from annslam_lib.slam import runner
from annslam_lib.slam import threads


@pytest.fixture(scope="module")
def sim_short():
    return simulate.simulate(seed=3, raw_laser=False, laps=1)


def _filter_with_landmarks(n_landmarks=20, seed=0, motion_model="euler"):
    """An efficient and a dense filter in the same non-trivial state (landmarks added from
    a pose with some uncertainty, one update so that everything is correlated)."""
    rng = np.random.default_rng(seed)
    P0 = np.diag([0.04, 0.09, 0.002])
    P0[0, 1] = P0[1, 0] = 0.01
    x0 = np.array([1.0, -2.0, 0.3])
    z = np.column_stack([rng.uniform(3, 25, n_landmarks), rng.uniform(0.1, 3.0, n_landmarks)])
    filters = []
    for cls in (EkfSlam, DenseEkfSlam):
        f = cls(x0, P0, ACFR_UTE, motion_model)
        f.augment(z, 0.1, math.radians(1))
        f.update(z[:3] + [[0.05, 0.01], [-0.03, 0.0], [0.02, -0.02]], [0, 1, 2], 0.1, math.radians(1))
        filters.append(f)
    return filters


def _controls(n=40, seed=1):
    rng = np.random.default_rng(seed)
    odo = Odometry(t=np.cumsum(np.full(n, 0.025)), speed=rng.uniform(1.0, 3.0, n),
                   steering=rng.uniform(-0.4, 0.4, n))
    return motion.control_table(odo, ACFR_UTE, 0.7, math.radians(7))


# --------------------------------------------------------------------------- the models

def test_scalar_predict_is_kinematics_predict():
    """The per-step scalar code = kinematics.predict (pose, F) and the documented noise
    dt * Delta * B Q_c B^T with B = G / dt."""
    f = EkfSlam([2.0, 1.0, 3.1], np.diag([0.01, 0.02, 0.003]), ACFR_UTE)
    u = _controls()[5]
    dt = 0.0137
    pose, F, G = motion.predict(np.array([2.0, 1.0, 3.1]), np.array(u[:2]), dt, ACFR_UTE)
    P = np.diag([0.01, 0.02, 0.003])
    Q = np.array([[u[5], u[6]], [u[6], u[7]]])
    f.predict(u, dt)
    np.testing.assert_allclose(f.pose, pose, rtol=0, atol=1e-14)
    np.testing.assert_allclose(f.pose_cov, F @ P @ F.T + (u[8] / dt) * G @ Q @ G.T, rtol=1e-13)


def test_control_noise_maps_encoder_noise_through_axle_speed():
    odo = Odometry(t=[0.0, 0.025], speed=[2.0, 2.0], steering=[0.3, 0.3])
    u = motion.control_table(odo, ACFR_UTE, 0.7, 0.1)[0]
    _, J = motion.axle_speed(2.0, 0.3, ACFR_UTE)
    M = np.array([[J[0], J[1]], [0.0, 1.0]])
    Qc = M @ np.diag([0.7**2, 0.1**2]) @ M.T
    np.testing.assert_allclose([u[5], u[6], u[7]], [Qc[0, 0], Qc[0, 1], Qc[1, 1]], rtol=1e-14)
    assert u[8] == pytest.approx(0.025)


def test_compounded_prediction_equals_step_by_step():
    """Many predict steps, the cross covariance multiplied once by F_total, equal the
    dense full-state G P G^T step by step, and the efficient filter flushed every step."""
    eff, dense = _filter_with_landmarks()
    each, _ = _filter_with_landmarks()
    controls = _controls()
    for k, u in enumerate(controls):
        for dt in (0.011, 0.014):                 # partial steps, as around a scan
            eff.predict(u, dt)
            dense.predict(u, dt)
            each.predict(u, dt)
            each.flush()
        assert eff._dirty                          # nothing touched the cross covariance yet
    x, P = eff.state()
    np.testing.assert_allclose(x, dense.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(P, dense.P, rtol=0, atol=1e-12)
    np.testing.assert_allclose(P, each.state()[1], rtol=0, atol=1e-13)
    np.testing.assert_array_equal(P, P.T)
    # the compounding really skipped the work: the landmark block never changed
    np.testing.assert_array_equal(P[3:, 3:], each.state()[1][3:, 3:])


def test_partial_steps_add_the_noise_of_one_interval():
    """Splitting an odometry interval at event times does not change the added noise
    (to first order): tau * Delta B Q B^T summed over the pieces."""
    u = _controls()[3]
    one = EkfSlam([0, 0, 0.2], np.zeros((3, 3)), ACFR_UTE)
    split = EkfSlam([0, 0, 0.2], np.zeros((3, 3)), ACFR_UTE)
    one.predict(u, 0.025)
    for dt in (0.005, 0.012, 0.008):
        split.predict(u, dt)
    np.testing.assert_allclose(split.pose_cov, one.pose_cov, rtol=0.05)


def test_observation_model_matches_dense_and_observe():
    eff, dense = _filter_with_landmarks(30)
    eff.predict(_controls()[0], 0.02)
    dense.predict(_controls()[0], 0.02)
    zhat, S = eff.observation_model(0.1, 0.02)
    zd, Sd = dense.observation_model(0.1, 0.02)
    np.testing.assert_allclose(zhat, zd, rtol=0, atol=1e-12)
    np.testing.assert_allclose(S, Sd, rtol=1e-11, atol=1e-15)
    z_ref, _, _ = observe(eff.pose, eff.landmarks())
    np.testing.assert_allclose(zhat, z_ref, atol=1e-12)


def test_batch_update_in_place_equals_dense_joseph():
    """One batch update (a landmark observed twice included): x and P equal the dense
    (I - KH) P (I - KH)^T + K R K^T, and P really changed in memory (the in-place BLAS
    call did not silently work on a copy)."""
    eff, dense = _filter_with_landmarks(25)
    before = eff.state()[1].copy()
    buffer = eff.P
    z = np.array([[10.0, 1.0], [7.0, 2.0], [12.0, 0.5], [10.1, 1.01]])
    lm = [4, 9, 17, 4]
    zh, _, _ = observe(eff.pose, eff.landmarks()[lm])
    z = zh + [[0.1, 0.01], [-0.05, -0.02], [0.0, 0.015], [0.03, 0.0]]
    nis_e, dof = eff.update(z, lm, 0.1, 0.02)
    nis_d, _ = dense.update(z, lm, 0.1, 0.02)
    assert dof == 8 and nis_e == pytest.approx(nis_d, rel=1e-10)
    assert eff.P is buffer                             # corrected in place
    assert np.max(np.abs(np.triu(eff.P) - np.triu(before))) > 1e-4   # the stored triangle
    np.testing.assert_allclose(eff.state()[1], dense.P, rtol=0, atol=1e-12)
    np.testing.assert_allclose(eff.x, dense.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(eff.landmark_covs(), dense.landmark_covs(), atol=1e-12)


def test_gps_update_gate_and_remove_match_dense():
    eff, dense = _filter_with_landmarks(12)
    nis_e, ok_e = eff.gps_update([1.2, -2.1], 0.05)
    nis_d, ok_d = dense.gps_update([1.2, -2.1], 0.05)
    assert ok_e and ok_d and nis_e == pytest.approx(nis_d, rel=1e-10)
    far, ok = eff.gps_update([50.0, 50.0], 0.05, gate=13.8)
    assert not ok and far > 13.8                        # a GPS jump is rejected, no change
    eff.remove([3, 7])
    dense.remove([3, 7])
    np.testing.assert_allclose(eff.state()[1], dense.P, atol=1e-12)
    np.testing.assert_allclose(eff.x, dense.x, atol=1e-12)
    assert eff.n_landmarks == 10 and eff.P.flags.c_contiguous


def test_fast_gating_helpers_equal_association_module():
    eff, _ = _filter_with_landmarks(40, seed=4)
    zhat, S = eff.observation_model(0.1, 0.02)
    rng = np.random.default_rng(5)
    z = np.column_stack([rng.uniform(1, 30, 9), rng.uniform(-0.2, 3.3, 9)])
    np.testing.assert_allclose(association.mahalanobis_fast(z, zhat, S),
                               association.mahalanobis(z, zhat, S), rtol=1e-12)
    for trial in range(300):
        d2 = rng.exponential(8.0, size=(rng.integers(1, 6), rng.integers(1, 6)))
        np.testing.assert_array_equal(association.associate_fast(d2, 9.21, 18.4),
                                      association.associate(d2, 9.21, 18.4))


# --------------------------------------------------------------------------- whole runs

@pytest.mark.parametrize("overrides", [
    dict(association="truth", gps_mode="init", gps_init_seconds=5.0, landmark_min_observations=5,
         landmark_probation=0.7, max_range=15.0),
    dict(association="nn", gps_mode="all", sigma_gps=0.3, gps_gate_prob=0.99,
         motion_model="midpoint"),
])
def test_efficient_run_equals_dense_reference(sim_short, overrides):
    """The whole seeded run, efficient vs textbook dense: same decisions, same numbers
    to 1e-9 (GPS updates, tentative landmarks deleted, both motion models included)."""
    cfg = SlamConfig.for_dataset("simulated", **overrides)
    eff = runner.run(sim_short, cfg, progress=False)
    ref = runner.run(sim_short, cfg, progress=False, backend="dense")
    assert eff.counts == ref.counts
    if overrides["association"] == "truth":
        assert eff.counts["landmarks_removed"] >= 1
    assert eff.counts["gps_updates"] > 0 and eff.counts["updates"] > 200
    np.testing.assert_array_equal(eff.observations.status, ref.observations.status)
    np.testing.assert_array_equal(eff.observations.landmark, ref.observations.landmark)
    np.testing.assert_allclose(eff.trajectory, ref.trajectory, rtol=0, atol=1e-9)
    np.testing.assert_allclose(eff.pose_cov, ref.pose_cov, rtol=0, atol=1e-9)
    np.testing.assert_allclose(eff.state, ref.state, rtol=0, atol=1e-9)
    np.testing.assert_allclose(eff.covariance, ref.covariance, rtol=0, atol=1e-9)
    np.testing.assert_allclose(eff.nis["nis"], ref.nis["nis"], rtol=1e-9, atol=1e-9)


def test_result_bookkeeping_on_simulation(sim_short):
    r = runner.run(sim_short, SlamConfig.for_dataset("simulated"), progress=False)
    log, c = r.observations, r.counts
    assert len(log) == c["observations"] == sim_short.detections.count
    assert c["associated"] + c["new"] + c["rejected"] + c["out_of_range"] == c["observations"]
    assert np.sum(r.nis["dof"][r.nis["kind"] == 0]) == 2 * c["associated"]
    assert r.landmarks.shape == (c["landmarks"], 2) and r.landmark_cov.shape == (c["landmarks"], 2, 2)
    # every mapped landmark is a different true beacon, and lies near it
    assert sorted(r.landmark_true_id.tolist()) == list(range(15))
    err = np.hypot(*(r.landmarks - sim_short.beacons[r.landmark_true_id]).T)
    assert err.max() < 0.3
    for j, scans in enumerate(r.landmark_observations):
        mine = log.landmark == j
        np.testing.assert_array_equal(scans, log.scan[mine])
        assert np.all(log.true_id[mine & (log.status == 0)] == r.landmark_true_id[j])
    # the logged pose is the trajectory's pose after the scan
    rows = np.searchsorted(r.scan_index, log.scan)
    np.testing.assert_array_equal(log.pose, r.trajectory[rows, 1:])
    assert r.odometry_trajectory.shape == (len(sim_short.odometry), 4)
    np.testing.assert_array_equal(r.state[3:].reshape(-1, 2), r.landmarks)


def test_nees_and_nis_inside_chi_square_bands():
    """10 seeded Monte Carlo runs (random layouts too): the average pose NEES (3 dof) and
    the normalised NIS inside their 95 % bands for an average of 10 runs. Time-indexed:
    at each scan the mean over runs; the band of a mean of N chi2(d) values is
    chi2.ppf([0.025, 0.975], N d) / N. The test asserts the time average inside the
    band and at least 80 % (NEES) / 90 % (NIS) of the scans inside it (a consistent
    filter: 95 %; Euler's model error costs some, see notebook 05)."""
    n_runs = 10
    cfg = SlamConfig.for_dataset("simulated")
    nees, nis, dof = [], [], []
    for seed in range(n_runs):
        ds = simulate.simulate(seed=100 + seed, raw_laser=False)
        r = runner.run(ds, cfg, progress=False)
        assert r.counts["landmarks"] == 15
        nees.append(consistency.pose_nees(r, ds))
        k = r.nis["kind"] == 0
        row, d = np.zeros(len(ds.detections)), np.zeros(len(ds.detections))
        row[r.nis["scan"][k]], d[r.nis["scan"][k]] = r.nis["nis"][k], r.nis["dof"][k]
        nis.append(row)
        dof.append(d)
    K = min(map(len, nees))
    anees = np.mean([x[:K] for x in nees], axis=0)
    lo, hi = chi2.ppf([0.025, 0.975], n_runs * 3) / n_runs
    assert lo <= anees.mean() <= hi, anees.mean()
    assert np.mean((anees >= lo) & (anees <= hi)) >= 0.80
    K = min(map(len, nis))
    s, D = np.sum([x[:K] for x in nis], axis=0), np.sum([x[:K] for x in dof], axis=0)
    s, D = s[D > 0], D[D > 0]
    lo_k, hi_k = chi2.ppf(0.025, D) / D, chi2.ppf(0.975, D) / D
    assert lo_k.mean() <= np.mean(s / D) <= hi_k.mean(), np.mean(s / D)
    assert np.mean((s >= lo_k * D) & (s <= hi_k * D)) >= 0.90


def test_car_park_targets(car_park):
    """Default configuration: all 15 surveyed beacons mapped once, nothing spurious, map
    RMSE <= 0.05 m after the best rigid alignment and <= 0.15 m as mapped, trajectory
    RMSE against GPS <= 0.6 m, covariance symmetric PSD."""
    r = runner.run(car_park, progress=False)
    assert r.config == SlamConfig.for_dataset("car_park")
    m = map_eval.map_errors(r.landmarks, car_park.beacons, max_distance=1.0)
    assert r.counts["landmarks"] == 15
    assert m.missed == 0 and m.spurious == 0 and m.duplicates == 0
    assert m.rmse_aligned <= 0.05, m.summary()
    assert m.rmse <= 0.15, m.summary()
    e = trajectory.trajectory_errors(r.odometry_trajectory, car_park.gps)
    assert e.rmse <= 0.6, e.summary()
    assert np.all(r.health["min_eig"] >= -1e-9)
    # the start did not need a hand-tuned heading: fitted to GPS, ~127 deg from East
    assert r.initial_info["policy"] == "gps"
    assert abs(math.degrees(r.initial_pose[2]) + 127.0) < 3.0


@pytest.fixture(scope="module")
def victoria_run(victoria_park):
    """The whole Victoria Park run, once (about 4 s; benchmarks/bench_ekf_slam.py times it)."""
    return runner.run(victoria_park, progress=False)


def test_victoria_park_covariance_healthy_at_every_checkpoint(victoria_park, victoria_run):
    """Symmetric PSD covariance at every checkpoint (every 500 scans and the end), a
    plausible map and a track that follows GPS (its median error; GPS itself jumps)."""
    r = victoria_run
    h = r.health
    assert h["min_eig"].size == r.counts["scans"] // 500 + 1
    assert np.all(h["min_eig"] >= -1e-9)
    assert np.all(h["asymmetry"] <= 1e-12 * np.max(np.abs(r.covariance)))
    assert r.counts["scans"] >= 7200 and r.counts["predicts"] > 60000
    assert 200 <= r.counts["landmarks"] <= 500
    assert r.counts["landmarks_removed"] > 0            # tentative trees were dropped
    e = trajectory.trajectory_errors(r.odometry_trajectory, victoria_park.gps)
    assert np.median(e.error) < 2.5, e.summary()


# --------------------------------------------------------------------------- bad input

def test_unknown_dataset_name():
    with pytest.raises(ValueError, match="unknown dataset 'parking_lot'"):
        runner.run("parking_lot", progress=False)
    with pytest.raises(TypeError, match="records.Dataset"):
        runner.run(42, progress=False)


@pytest.mark.parametrize("field, value", [
    ("sigma_range", -0.1), ("sigma_steer", float("nan")), ("gps_mode", "sometimes"),
    ("association", "magic"), ("gate_prob", 1.5), ("landmark_min_observations", 0),
    ("initial_pose", (1.0, float("nan"), 0.0)), ("initial_pose", "guess"),
    ("max_range", 0.5), ("motion_model", "rk4"), ("gps_gate_prob", 0.0),
])
def test_invalid_config_names_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        SlamConfig(**{field: value})


def test_config_defaults_and_unknown_names():
    assert SlamConfig.for_dataset("car_park").sigma_speed == 0.7
    assert SlamConfig.for_dataset("simulated").gps_mode == "none"
    assert SlamConfig.for_dataset("victoria_park", max_range=25.0).max_range == 25.0
    with pytest.raises(ValueError, match="no SlamConfig defaults for dataset 'mars'"):
        SlamConfig.for_dataset("mars")
    with pytest.raises(ValueError, match="unknown SlamConfig field.*sigma_rang"):
        SlamConfig.for_dataset("car_park", sigma_rang=0.1)
    with pytest.raises(ValueError, match="unknown SlamConfig field.*foo"):
        SlamConfig().replace(foo=1)
    with pytest.raises(ValueError, match="SlamConfig.new_landmark_prob"):
        SlamConfig(gate_prob=0.999, new_landmark_prob=0.99)


def test_bad_run_arguments(sim_short, car_park):
    with pytest.raises(TypeError, match="config must be a SlamConfig"):
        runner.run(sim_short, {"sigma_range": 0.1}, progress=False)
    with pytest.raises(ValueError, match="backend"):
        runner.run(sim_short, progress=False, backend="gpu")
    with pytest.raises(ValueError, match="true landmark ids"):
        runner.run(car_park, SlamConfig(association="truth"), progress=False)
    with pytest.raises(ValueError, match="initial_pose = 'truth'"):
        runner.run(car_park, SlamConfig(initial_pose="truth"), progress=False)


def test_nan_state_is_rejected():
    with pytest.raises(ValueError, match="NaN"):
        EkfSlam([0.0, np.nan, 0.0], np.eye(3), ACFR_UTE)
    with pytest.raises(ValueError, match="NaN"):
        EkfSlam([0.0, 0.0, 0.0], np.full((3, 3), np.inf), ACFR_UTE)
    with pytest.raises(ValueError, match="symmetric"):
        EkfSlam([0.0, 0.0, 0.0], [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], ACFR_UTE)
    f = EkfSlam([0.0, 0.0, 0.0], np.eye(3) * 0.01, ACFR_UTE)
    f.augment([[5.0, 1.0]], 0.1, 0.01)
    f.x[3] = np.nan                                  # corrupted state: no silent answer
    with pytest.raises(ValueError):
        f.update([[5.0, 1.0]], [0], 0.1, 0.01)


def test_singular_innovation_covariance_is_a_clear_error():
    """Zero uncertainty everywhere and a noise whose square underflows to 0: S = 0, no
    gain exists (a noise of exactly 0 is refused on entry)."""
    f = EkfSlam([0.0, 0.0, 0.0], np.zeros((3, 3)), ACFR_UTE)
    f.augment([[5.0, 1.0]], 1e-200, 1e-200)
    with pytest.raises(InnovationError, match="not positive definite"):
        f.update([[5.0, 1.0]], [0], 1e-200, 1e-200)
    with pytest.raises(ValueError, match="sigma must be finite and > 0"):
        f.update([[5.0, 1.0]], [0], 0.0, 0.0)
    assert issubclass(InnovationError, ValueError)


def test_progress_bar_and_explicit_initial_pose(sim_short):
    cfg = SlamConfig.for_dataset("simulated")
    quiet = runner.run(sim_short, cfg, progress=False)
    pose0 = tuple(sim_short.truth.poses[0, 1:])
    shown = runner.run(sim_short, cfg.replace(initial_pose=pose0), progress=True)
    assert shown.initial_info["policy"] == "given"
    np.testing.assert_array_equal(shown.trajectory, quiet.trajectory)


def test_gating_rejects_a_non_positive_definite_innovation_covariance():
    S = np.array([[[1.0, 0.0], [0.0, 1.0]], [[1.0, 2.0], [2.0, 1.0]]])
    with pytest.raises(ValueError, match="landmark 1 is not positive definite"):
        association.mahalanobis_fast(np.array([[5.0, 1.0]]), np.array([[5.0, 1.0], [6.0, 1.2]]), S)


def test_run_uses_one_blas_thread_and_restores_the_setting():
    """With two BLAS threads and a busy machine a Victoria Park run took 54 s instead of
    4 s: ``run`` limits BLAS to one thread while it runs, whatever OMP_NUM_THREADS says."""
    controls = threads.openblas_thread_controls()
    if not controls:
        pytest.skip("no OpenBLAS thread control found in this process")
    before = [get() for _, get in controls]
    with threads.one_blas_thread():
        assert [get() for _, get in controls] == [1] * len(controls)
    assert [get() for _, get in controls] == before


# ------------------------------------------------------------------ arguments checked on entry

_SR, _SB = 0.1, math.radians(1)
BAD_CALLS = [
    ("remove([-1]) would delete the pose's rows", lambda f: f.remove([-1]), ValueError, "out of range"),
    ("remove past the last landmark", lambda f: f.remove([20]), ValueError, "out of range"),
    ("remove with float indices", lambda f: f.remove([1.5]), TypeError, "integers"),
    ("predict with dt NaN", lambda f: f.predict(_controls()[0], math.nan), ValueError, "dt"),
    ("predict with dt inf", lambda f: f.predict(_controls()[0], math.inf), ValueError, "dt"),
    ("predict backwards in time", lambda f: f.predict(_controls()[0], -0.1), ValueError, "dt"),
    ("update with sigma NaN", lambda f: f.update([[10.0, 1.0]], [0], math.nan, _SB), ValueError, "sigma"),
    ("update with zero noise", lambda f: f.update([[10.0, 1.0]], [0], _SR, 0.0), ValueError, "sigma"),
    ("update with a negative range", lambda f: f.update([[-10.0, 1.0]], [0], _SR, _SB), ValueError, "range > 0"),
    ("update with a NaN bearing", lambda f: f.update([[10.0, math.nan]], [0], _SR, _SB), ValueError, "finite"),
    ("augment with a zero range", lambda f: f.augment([[0.0, 1.0]], _SR, _SB), ValueError, "range > 0"),
    ("augment with sigma inf", lambda f: f.augment([[5.0, 1.0]], math.inf, _SB), ValueError, "sigma"),
    ("augment with triples", lambda f: f.augment(np.ones((2, 3)), _SR, _SB), ValueError, r"\(n, 2\)"),
    ("gating with a negative sigma", lambda f: f.innovation_d2([[5.0, 1.0]], -_SR, _SB), ValueError, "sigma"),
    ("gps fix NaN", lambda f: f.gps_update([math.nan, 0.0], 0.05), ValueError, "finite"),
    ("gps sigma zero", lambda f: f.gps_update([0.0, 0.0], 0.0), ValueError, "sigma"),
]


@pytest.mark.parametrize("what, call, error, match", BAD_CALLS, ids=[b[0] for b in BAD_CALLS])
def test_bad_arguments_raise_and_leave_the_filter_unchanged(what, call, error, match):
    """Each of these is refused, not silently accepted (remove([-1]) would delete the
    pose's y and phi). Both backends refuse it the same way, and the state is untouched."""
    for f in _filter_with_landmarks():
        x, P = (a.copy() for a in f.state())
        with pytest.raises(error, match=match):
            call(f)
        x2, P2 = f.state()
        np.testing.assert_array_equal(x2, x)
        np.testing.assert_array_equal(P2, P)


def test_zero_dt_is_no_step_and_good_calls_still_work():
    for f in _filter_with_landmarks():
        x = f.state()[0].copy()
        f.predict(_controls()[0], 0.0)
        np.testing.assert_array_equal(f.state()[0], x)
        f.remove([0, 19])
        assert f.n_landmarks == 18
        f.remove([])
        assert f.n_landmarks == 18
