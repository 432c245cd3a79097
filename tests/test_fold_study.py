"""The ANN verdict over folds of the data (paper.study.fold_study, ann.time_folds,
notebook 08 section 4): the folds are what they claim, the sign-flip p-value agrees with
SciPy's permutation test, a stored fold value is what a direct run gives, and the verdict's
fold rows are the corrected interval and equivalence test of FOLD_RULE on the study's own
fold sizes (the statistics themselves: test_verdict_stats.py)."""
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
    # the fold sizes are the folds' own: held out and trained on (train + early stopping)
    tf, bf = ann.time_folds(ts, 5, gap=2.0, seed=fs.seeds[0]), ann.beacon_folds(ts, 5)
    assert fs.n_test["time"].tolist() == [f.test.size for f in tf]
    assert fs.n_train["time"].tolist() == [f.train.size + f.val.size for f in tf]
    assert fs.n_test["beacons"].tolist() == [f.test.size for f in bf]
    assert all(fs.n_test["beacons"] + fs.n_train["beacons"] == len(ts))
    # the verdict's fold rows say what the fold differences say: the interval corrected
    # by Nadeau and Bengio with those sizes, wider than the one that treats folds as independent
    d = fs.per_fold("ann", "traj_rmse") - fs.per_fold("beacons", "traj_rmse")
    ratio = np.mean([f.test.size for f in tf]) / np.mean([f.train.size + f.val.size for f in tf])
    assert 0.2 < ratio < 0.3 and fs.test_train_ratio("traj_rmse") == pytest.approx(ratio)
    half = stats.t.ppf(0.975, 4) * d.std(ddof=1) * np.sqrt(1 / 5 + ratio)
    c = fs.compare("ann", "beacons", "traj_rmse")
    assert (c.lo, c.hi) == pytest.approx((d.mean() - half, d.mean() + half), abs=1e-12)
    old = stats.t.ppf(0.975, 4) * d.std(ddof=1) / np.sqrt(5)
    assert (c.lo_naive, c.hi_naive) == pytest.approx((d.mean() - old, d.mean() + old), abs=1e-12)
    assert c.hi - c.lo > c.hi_naive - c.lo_naive
    margin = 0.1 * fs.per_fold("beacons", "traj_rmse").mean()
    assert c.margin == pytest.approx(margin, rel=1e-12)
    se = d.std(ddof=1) * np.sqrt(1 / 5 + ratio)
    assert c.p_equivalence == pytest.approx(max(stats.t.sf((d.mean() + margin) / se, 4),
                                                stats.t.cdf((d.mean() - margin) / se, 4)))
    flip = np.mean([abs(np.dot(s, d)) >= abs(d.sum()) * (1 - 1e-12)
                    for s in itertools.product((1, -1), repeat=5)])
    assert fs.p_value("ann", "beacons", "traj_rmse") == pytest.approx(flip)
    assert c.p_sign_flip == pytest.approx(flip)
    # another comparator's per-fold values (the natural-feature filter's) by the same rule
    nat = np.full(5, 0.08)
    cn = fs.compare("ann", "natural", "traj_rmse", b_values=nat)
    assert cn.margin == pytest.approx(0.008) and cn.mean == pytest.approx(
        fs.per_fold("ann", "traj_rmse").mean() - 0.08)
    with pytest.raises(ValueError, match="b_values"):
        fs.compare("ann", "natural", "traj_rmse", b_values=np.ones(4))


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
        cb, cc = fs.compare("ann", "beacons", mt), fs.compare("ann", "control", mt)
        assert r["verdict"] == study.fold_claim(cb, cc)
        assert r["holds"] is {"holds": True, "does not hold": False, "not demonstrated": None}[
            r["verdict"]]
        assert cb.text() in r["measured"] and cc.text() in r["measured"]
        assert cb.decision in r["why"] and cc.decision in r["why"]
    seed_rows = [r for c, r in without.items() if "held-out" in c]
    assert len(seed_rows) == 3 and all(r["holds"] is None for r in seed_rows)
    assert not any("verdict" in r for r in without.values())
    # the chapter's table words every row by its verdict
    from annslam_lib.chapters import ch08_verdict as chapter
    table = chapter.verdict_table(list(with_folds.values())).splitlines()[2:]
    for line, r in zip(table, with_folds.values()):
        assert line.split(" | ")[2] == chapter.VERDICT_WORDS[chapter.verdict_word(r)]
    assert chapter.verdict_word(dict(claim="x", holds=None)) == "not testable this way"
    with pytest.raises(ValueError, match="unknown verdict"):
        chapter.verdict_word(dict(claim="x", holds=None, verdict="no detectable difference"))


def test_simulator_rows_are_worded_by_what_was_shown(car_park):
    """A transfer row holds if better, does not hold if worse, is not demonstrated
    otherwise (no margin, so no detectable difference is not 'does not hold')."""
    def tr(plain, ann_):
        plain, ann_ = np.asarray(plain), np.asarray(ann_)
        z = np.zeros(plain.size, dtype=int)
        return study.Transfer(error={}, train_route="loop", test_route="loop", seeds=(1, 2, 3),
                              plain=plain, ann=ann_, plain_missed=z, ann_missed=z,
                              plain_spurious=z, ann_spurious=z)
    rows = study.verdict(study.study(car_park, seeds=5),
                         {"a": tr([0.3, 0.3, 0.3], [0.1, 0.11, 0.12]),
                          "b": tr([0.1, 0.1, 0.1], [0.3, 0.31, 0.32]),
                          "c": tr([0.1, 0.2, 0.1], [0.2, 0.1, 0.12])})
    got = {r["claim"][-2]: (r["verdict"], r["holds"]) for r in rows if "simulator" in r["claim"]}
    assert got == {"a": ("holds", True), "b": ("does not hold", False),
                   "c": ("not demonstrated", None)}
