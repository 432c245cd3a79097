"""The ANN verdict over folds of the data (issue 21; paper.study.fold_study, ann.time_folds,
notebook 08 section 4): the folds are what they claim, the sign-flip p-value agrees with
SciPy's permutation test, and a stored fold value is what a direct run gives."""
import dataclasses
import itertools

import numpy as np
import pytest
from scipy import stats

from annslam_lib import ann
from annslam_lib.paper import study
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig


def _toy_set(n_scans=60, per_scan=3, n_beacons=6, seed=0):
    """A TrainingSet whose times and beacons are all that matters for the folds."""
    rng = np.random.default_rng(seed)
    t = np.repeat(np.arange(n_scans) * 0.5, per_scan)
    n = t.size
    beacon = rng.integers(0, n_beacons, n)
    X = rng.normal(size=(n, len(ann.FEATURE_NAMES)))
    Y = rng.normal(size=(n, 2))
    base = rng.normal(size=(n, 2))
    return ann.TrainingSet(X=X, Y=Y, base=base, target=base + Y, beacon=beacon, t=t,
                           scan=np.repeat(np.arange(n_scans), per_scan))


def test_time_folds_partition_the_run_and_keep_the_gap():
    ts = _toy_set()
    edges = ann.time_fold_edges(ts, 5)
    folds = ann.time_folds(ts, 5, gap=2.0, seed=1)
    tests = np.concatenate([f.test for f in folds])
    assert np.array_equal(np.sort(tests), np.arange(len(ts)))       # every sample tested once
    for k, f in enumerate(folds):
        lo, hi = edges[k], edges[k + 1]
        assert np.all((ts.t[f.test] >= lo) & (ts.t[f.test] <= hi))
        used = np.concatenate([f.train, f.val])
        assert np.all((ts.t[used] < lo - 2.0) | (ts.t[used] > hi + 2.0))
        # everything outside the window and the gap is used, 15 % of it for validation
        outside = np.flatnonzero((ts.t < lo - 2.0) | (ts.t > hi + 2.0))
        assert np.array_equal(np.sort(used), outside)
        assert f.val.size == round(0.15 * outside.size)
    other = ann.time_folds(ts, 5, gap=2.0, seed=2)
    assert any(not np.array_equal(a.val, b.val) for a, b in zip(folds, other))
    assert all(np.array_equal(a.test, b.test) for a, b in zip(folds, other))


@pytest.mark.parametrize("kwargs, match", [
    (dict(n_folds=1), "n_folds"), (dict(n_folds=True), "n_folds"), (dict(gap=-1.0), "gap"),
    (dict(gap=float("nan")), "gap"), (dict(val_fraction=0.0), "val_fraction"),
    (dict(val_fraction=1.0), "val_fraction"), (dict(n_folds=40), "cannot make")])
def test_time_folds_refuse_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ann.time_folds(_toy_set(), **kwargs)


def test_beacon_holdout_sizes_by_brute_force():
    ts = _toy_set(n_beacons=12, seed=3)
    edges = ann.time_fold_edges(ts, 4)
    expected = []
    for k in range(4):
        seen = {int(b) for b, t in zip(ts.beacon, ts.t) if edges[k] <= t <= edges[k + 1]}
        expected.append(sum(1 for b, t in zip(ts.beacon, ts.t)
                            if (t < edges[k] - 1.0 or t > edges[k + 1] + 1.0) and int(b) not in seen))
    assert ann.beacon_holdout_sizes(ts, 4, gap=1.0).tolist() == expected


@pytest.mark.parametrize("d", [[0.3, -0.1, 0.2, 0.25, 0.05], [-0.02, 0.01, -0.03, 0.0, -0.01, 0.02],
                               [1.0, 2.0, 3.0, 4.0, 5.0], [0.5, -0.5, 0.5, -0.5]])
def test_sign_flip_p_equals_scipys_exact_permutation_test(d):
    ref = stats.permutation_test((np.asarray(d),), np.mean, permutation_type="samples",
                                 alternative="two-sided", n_resamples=np.inf).pvalue
    assert study.sign_flip_p(d) == pytest.approx(ref, abs=1e-12)


def test_sign_flip_p_cannot_reject_with_five_folds():
    assert study.sign_flip_p([0.1, 0.2, 0.3, 0.4, 0.5]) == pytest.approx(2 / 32)
    assert study.sign_flip_p(np.full(6, -1.0)) == pytest.approx(2 / 64)
    for bad in ([], [np.nan, 1.0], np.ones(21)):
        with pytest.raises(ValueError, match="sign_flip_p"):
            study.sign_flip_p(bad)


def test_fold_study_values_are_what_direct_runs_give(car_park):
    """One time fold and one beacon fold recomputed from the public pieces, without the
    study's helpers: the stored values, the plain filter's per-fold values and the verdict
    rows built on them."""
    fs = study.fold_study(car_park)
    assert fs.seeds == (0, 1, 2) and fs.edges.size == 6
    for c in ("ann", "control", "beacons"):
        for mt in study.FOLD_METRICS:
            assert fs.values[c][mt].shape == (5, 3) and np.all(np.isfinite(fs.values[c][mt]))
    cfg = SlamConfig.for_dataset("car_park")
    plain = runner.run(car_park, cfg)
    ts = ann.training_set(plain, car_park)
    k, j = 2, 1
    split = ann.time_folds(ts, 5, gap=2.0, seed=fs.seeds[j])[k]
    model = ann.train(ts, split, dataclasses.replace(ann.TrainConfig(), seed=fs.seeds[j]))
    res = runner.run(car_park, cfg.replace(landmark_model="ann"), landmark_model=model)
    lo, hi = fs.edges[k], fs.edges[k + 1]
    odo = res.odometry_trajectory
    win = odo[(odo[:, 0] >= lo) & (odo[:, 0] <= hi)]
    from annslam_lib.evaluation.trajectory import trajectory_errors
    assert fs.values["ann"]["traj_rmse"][k, j] == pytest.approx(
        trajectory_errors(win, car_park.gps).rmse, rel=1e-9)
    # the plain filter's window error, and its map error on a beacon fold's held-out poles
    odo = plain.odometry_trajectory
    win = odo[(odo[:, 0] >= lo) & (odo[:, 0] <= hi)]
    assert fs.values["beacons"]["traj_rmse"][k, 0] == pytest.approx(
        trajectory_errors(win, car_park.gps).rmse, rel=1e-9)
    from annslam_lib.evaluation.map import match_landmarks
    held = fs.held_beacons[k]
    i_m, j_t = match_landmarks(plain.landmarks, car_park.beacons, 1.0)
    sel = np.isin(j_t, held)
    e = plain.landmarks[i_m[sel]] - car_park.beacons[j_t[sel]]
    assert fs.values["beacons"]["map_rmse"][k, 0] == pytest.approx(
        np.sqrt(np.mean(np.sum(e ** 2, axis=1))), rel=1e-9)
    # the verdict's fold rows say what the fold differences say
    d = fs.per_fold("ann", "traj_rmse") - fs.per_fold("beacons", "traj_rmse")
    half = stats.t.ppf(0.975, 4) * d.std(ddof=1) / np.sqrt(5)
    p = fs.paired("ann", "beacons", "traj_rmse")
    assert (p.lo, p.hi) == pytest.approx((d.mean() - half, d.mean() + half), abs=1e-12)
    assert fs.p_value("ann", "beacons", "traj_rmse") == pytest.approx(
        np.mean([abs(np.dot(s, d)) >= abs(d.sum()) * (1 - 1e-12)
                 for s in itertools.product((1, -1), repeat=5)]))


def test_verdict_rows_come_from_the_folds_or_are_not_counted(car_park):
    st = study.study(car_park, seeds=5)
    fs = study.fold_study(car_park)
    with_folds = {r["claim"]: r for r in study.verdict(st, folds=fs)}
    without = {r["claim"]: r for r in study.verdict(st)}
    fold_rows = [c for c in with_folds if "folds" in c]
    assert len(fold_rows) == 3 and not any("folds" in c for c in without)
    for c in fold_rows:
        r = with_folds[c]
        mt = {"trajectory": "traj_rmse", "map vs": "map_rmse", "map shape": "map_rmse_aligned"}[
            next(k for k in ("trajectory", "map vs", "map shape") if k in c)]
        both = all(fs.paired("ann", o, mt).decision == "better" for o in ("beacons", "control"))
        assert r["holds"] is both
        assert fs.paired("ann", "beacons", mt).text() in r["measured"]
    seed_rows = [r for c, r in without.items() if "held-out" in c]
    assert len(seed_rows) == 3 and all(r["holds"] is None for r in seed_rows)
