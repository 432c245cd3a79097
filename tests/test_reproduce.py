"""Tests of annslam_lib.reproduce: the natural-feature extractor, the metrics, the end-to-end
``reproduce`` pipeline (its numbers recomputed here from the base library functions) and the
command line."""
import csv
import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from annslam_lib import ann
from annslam_lib.course.cli import build_parser, main
from annslam_lib.data.records import LASER_ANGLES, Laser
from annslam_lib.data import simulate
from annslam_lib.evaluation import map as map_eval
from annslam_lib.evaluation import summary
from annslam_lib.evaluation import trajectory
from annslam_lib.paper import report
from annslam_lib.paper import study
from annslam_lib.perception import beacons
from annslam_lib.slam import config as slam_config
from annslam_lib.slam import runner

FIGURES = ("fig5_map.png", "fig6_error_histogram.png", "fig7_performance.png", "fig8_regression.png")


# --------------------------------------------------------------------------- point features

def _scan(ranges, intensity=None):
    r = np.asarray(ranges, dtype=float)[None]
    i = np.zeros_like(r, dtype=np.uint8) if intensity is None else np.asarray(intensity)[None]
    return Laser(t=np.array([0.0]), ranges=r, intensity=i)


def test_point_features_keep_narrow_foreground_segments():
    r = np.full(361, 20.0)
    r[100:104] = 5.0 + np.array([0.0, 0.02, -0.02, 0.0])       # a pole: 4 beams, 17 cm at 5 m
    r[200:230] = 6.0                                             # a wall, 1.6 m wide
    r[300:302] = 3.0                                             # a post in front of NO return
    r[299], r[302] = 81.91, 81.91
    r[0:3] = 2.0                                                 # cut by the field of view
    det = beacons.point_features(_scan(r))
    assert det.count == 2 and len(det) == 1
    np.testing.assert_allclose(det.range, [5.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(det.bearing, [LASER_ANGLES[[100, 103]].mean(),
                                             LASER_ANGLES[[300, 301]].mean()], atol=1e-12)
    np.testing.assert_allclose(det.diameter, [4 * np.radians(0.5) * 5.0, 2 * np.radians(0.5) * 3.0])
    assert np.all(det.intensity == 0)
    # Narrower width limit: the 17 cm pole goes, the 5 cm post stays.
    assert beacons.point_features(_scan(r), max_width=0.1).count == 1


def test_point_features_need_both_sides_farther_and_can_skip_tape():
    r = np.full(361, 20.0)
    r[100:104] = 5.0
    r[104] = 5.2                    # the right neighbour continues the segment (jump < 0.3 m)
    r[105:140] = 4.0                # ... and then something NEARER: not standing in front
    assert beacons.point_features(_scan(r)).count == 0
    r = np.full(361, 20.0)
    r[100:104] = 5.0
    level = np.zeros(361, dtype=np.uint8)
    level[101] = 3
    assert beacons.point_features(_scan(r, level)).count == 1        # intensity ignored
    assert beacons.point_features(_scan(r, level), exclude_tape=True).count == 0
    assert beacons.point_features(_scan(r), max_range=4.0).count == 0


@pytest.mark.parametrize("kw, exc, match", [(dict(max_width=0), ValueError, "max_width"),
                                            (dict(max_range_jump=float("nan")), ValueError,
                                             "max_range_jump"),
                                            (dict(min_range=40.0), ValueError, "min_range"),
                                            (dict(exclude_tape=1), TypeError, "exclude_tape")])
def test_point_features_bad_input(kw, exc, match):
    with pytest.raises(exc, match=match):
        beacons.point_features(_scan(np.full(361, 20.0)), **kw)
    with pytest.raises(TypeError, match="Laser"):
        beacons.point_features(np.zeros((1, 361)))


# --------------------------------------------------------------------------- metrics

def test_heldout_map_rmse_uses_only_the_held_out_beacons():
    beacons = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    mapped = beacons + np.array([[0.1, 0.0], [0.0, 0.3], [5.0, 5.0]])     # the third: no match
    res = SimpleNamespace(landmarks=mapped)
    assert summary.heldout_map_rmse(res, beacons, [0, 1]) == pytest.approx(math.sqrt(0.05))
    assert summary.heldout_map_rmse(res, beacons, [1]) == pytest.approx(0.3)
    assert math.isnan(summary.heldout_map_rmse(res, beacons, [2]))


def test_study_needs_beacons_and_raw_laser():
    with pytest.raises(ValueError, match="raw laser"):
        study.study(simulate.simulate(laps=1, raw_laser=False), seeds=1)
    with pytest.raises(ValueError, match="seeds"):
        study.study(simulate.simulate(laps=1), seeds=0)


# --------------------------------------------------------------------------- the pipeline

@pytest.fixture(scope="module")
def fast_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fast")
    res = report.reproduce(out, fast=True, seeds=2, log=None)
    return out, res


def _csv(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {r["configuration"]: r for r in rows}


def _num(text):
    return math.nan if text == "" else float(text)


def test_reproduce_writes_the_figures_and_the_table(fast_run):
    out, res = fast_run
    for name in FIGURES:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    rows = _csv(out / "results.csv")
    assert list(rows) == [label for label, _ in study.CONFIGURATIONS.values()]
    md = (out / "results.md").read_text()
    claims = study.verdict(res["study"])
    assert all(label in md for label in rows) and "## The paper's claims" in md
    assert md.count("\n|") == (2 + len(rows)) + (2 + len(claims))
    assert res["seconds"] < 60


def test_reproduce_numbers_equal_the_library_functions(fast_run):
    """Every checked number is recomputed from ekf_slam / ann / map_metrics / metrics
    directly, following the documented protocol, not from reproduce's helpers."""
    out, _ = fast_run
    rows = _csv(out / "results.csv")
    ds = study.fast_dataset()
    cfg = slam_config.SlamConfig.for_dataset("simulated")
    plain = runner.run(ds, cfg)
    ts = ann.training_set(plain, ds)
    sp = ann.chronological_split(ts)
    t_h = ts.t[sp.test].min()

    def traj(res, late=False):
        odo = res.odometry_trajectory
        return trajectory.trajectory_errors(odo[odo[:, 0] >= t_h] if late else odo, ds.gps).rmse

    def trace(res):
        return np.mean(res.pose_cov[:, 0, 0] + res.pose_cov[:, 1, 1])

    b = rows["beacons-only EKF-SLAM"]
    m = map_eval.map_errors(plain.landmarks, ds.beacons)
    expect = dict(map_rmse=m.rmse, map_rmse_aligned=m.rmse_aligned, traj_rmse=traj(plain),
                  traj_rmse_heldout=traj(plain, True), pose_trace=trace(plain),
                  landmarks=plain.landmarks.shape[0], matched=m.i_mapped.size, unmatched=m.spurious)
    for k, v in expect.items():
        assert _num(b[k]) == pytest.approx(v, rel=1e-12, abs=1e-15), k
        assert _num(b[k + "_sd"]) == 0.0
    assert int(b["n_runs"]) == 2

    per_seed = []
    for seed in (0, 1):
        model = ann.train(ts, sp, ann.TrainConfig(seed=seed))
        r = runner.run(ds, cfg.replace(landmark_model="ann"), landmark_model=model)
        per_seed.append((map_eval.map_errors(r.landmarks, ds.beacons).rmse, traj(r, True),
                         trace(r), model.sigma_range))
    per_seed = np.array(per_seed)
    a = rows["ANN-enhanced EKF-SLAM"]
    for j, k in enumerate(("map_rmse", "traj_rmse_heldout", "pose_trace")):
        assert _num(a[k]) == pytest.approx(per_seed[:, j].mean(), rel=1e-12), k
        assert _num(a[k + "_sd"]) == pytest.approx(per_seed[:, j].std(ddof=1), rel=1e-9), k
    # Held-out beacons, seed 1: fold 1's network, scored on fold 1's test beacons only.
    fold = ann.beacon_folds(ts)[1]
    rb = runner.run(ds, cfg.replace(landmark_model="ann"),
                      landmark_model=ann.train(ts, fold, ann.TrainConfig(seed=1)))
    held = np.unique(ts.beacon[fold.test])
    i, jt = map_eval.match_landmarks(rb.landmarks, ds.beacons, 1.0)
    sel = np.isin(jt, held)
    e1 = np.sqrt(np.mean(np.sum((rb.landmarks[i[sel]] - ds.beacons[jt[sel]]) ** 2, axis=1)))
    st = fast_run[1]["study"]
    assert st.values("ann", "map_rmse_heldout")[1] == pytest.approx(e1, rel=1e-12)
    # The control is the plain filter with seed 0's R'.
    ctrl = runner.run(ds, cfg.replace(sigma_range=per_seed[0, 3],
                                        sigma_bearing=st.models["ann"][0].sigma_bearing))
    assert st.values("control", "pose_trace")[0] == pytest.approx(trace(ctrl), rel=1e-12)
    # Natural features: the point features of the raw laser, the tentative-landmark filter.
    nat = runner.run(dataclasses.replace(ds, detections=beacons.point_features(ds.laser)),
                       cfg.replace(feature_source="detections", landmark_min_observations=3))
    n = rows["natural-feature EKF-SLAM"]
    assert _num(n["traj_rmse"]) == pytest.approx(traj(nat), rel=1e-12)
    assert _num(n["landmarks"]) == nat.landmarks.shape[0]


def test_cli_reproduce_is_deterministic(fast_run, tmp_path, capsys):
    out, _ = fast_run
    assert main(["reproduce", "--out", str(tmp_path), "--fast", "--seeds", "2"]) == 0
    log = capsys.readouterr().out
    for stage in ("EKF-SLAM, beacons only", "training set", "ANN training, seed 1",
                  "ANN-enhanced EKF-SLAM, seed 1", "natural-feature EKF-SLAM", "reproduce: done"):
        assert stage in log, stage
    assert (tmp_path / "results.csv").read_bytes() == (out / "results.csv").read_bytes()
    assert (tmp_path / "results.md").read_text() == (out / "results.md").read_text()


def test_cli_arguments():
    args = build_parser().parse_args(["reproduce", "--out", "x", "--seeds", "3"])
    assert (args.out, args.fast, args.seeds) == ("x", False, 3)
    for bad in (["reproduce", "--out", "x", "--seeds", "0"], ["reproduce", "--fast"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(bad)
    with pytest.raises(ValueError, match="seeds"):
        report.reproduce("unused", seeds=0)


def test_verdict_rows_follow_the_numbers(fast_run):
    st = fast_run[1]["study"]
    rows = study.verdict(st)
    assert all(set(r) == {"claim", "measured", "holds", "why"} for r in rows)
    first = rows[0]
    assert f"ANN {st.mean('ann', 'pose_trace'):.4f}" in first["measured"]
    assert first["holds"] == (st.mean("ann", "pose_trace") < min(st.mean("beacons", "pose_trace"),
                                                                  st.mean("natural", "pose_trace")))
    assert rows[-1]["holds"] is False and "surveyed" in rows[-1]["measured"]


# --------------------------------------------------------------------------- simulator transfer

def test_transfer_matches_direct_runs():
    tr = study.transfer({"range_bias": 0.3}, test_route="loop", seeds=(1,))
    ds = simulate.simulate(seed=1, route="loop", beacon_seed=1, raw_laser=False, range_bias=0.3)
    cfg = slam_config.SlamConfig.for_dataset("simulated")
    plain = map_eval.map_errors(runner.run(ds, cfg).landmarks, ds.beacons)
    assert tr.plain[0] == pytest.approx(plain.rmse, rel=1e-12)
    assert tr.ann[0] < 0.8 * tr.plain[0]          # the bias is learned on the same route
    assert tr.ratio == pytest.approx(tr.ann[0] / tr.plain[0])
    with pytest.raises(ValueError, match="unknown SimConfig"):
        study.transfer({"range_offset": 0.3})
