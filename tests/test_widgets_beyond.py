"""Chapter 10 companion, headless: the loop-closure split checked against a count made here,
the explorer against a batch solve of the split graph, the shared-error scene, the VP
comparison's rows against a recomputation of the EKF's."""
import math

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from annslam_lib.chapters import ch10_beyond_ekf as ch  # noqa: E402
from annslam_lib.smoothing import solve as gs  # noqa: E402
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures  # noqa: F401


@pytest.fixture(scope="module")
def graph(car_park):
    return ch.car_park_graph(car_park)


def _passes(problem, gap=5.0):
    """Per landmark, the times at which a new pass starts (a sighting > gap s after the
    previous one), counted the plain way."""
    out = {}
    t = problem.t[problem.obs_node]
    for j in range(problem.n_landmarks):
        ts = np.sort(t[problem.obs_landmark == j])
        out[j] = [float(b) for a, b in zip(ts[:-1], ts[1:]) if b - a > gap]
    return out


def test_loop_closures_are_the_returns_after_a_gap_and_dropped_ones_make_copies(graph):
    p = graph["problem"]
    passes = _passes(p)
    n = sum(len(v) for v in passes.values())
    full = ch.split_loop_closures(p, 1.0)
    none = ch.split_loop_closures(p, 0.0)
    assert full.counts["closures"] == none.counts["closures"] == n > 10
    assert full.counts["closures_dropped"] == 0 and full.n_landmarks == p.n_landmarks
    np.testing.assert_array_equal(full.obs_landmark, p.obs_landmark)
    assert none.counts["closures_dropped"] == n and none.n_landmarks == p.n_landmarks + n
    # every observation keeps its measurement and pose; each copy starts at a return
    np.testing.assert_array_equal(none.obs_node, p.obs_node)
    t = p.t[p.obs_node]
    for k in range(p.n_landmarks, none.n_landmarks):
        rows = np.flatnonzero(none.obs_landmark == k)
        orig = set(p.obs_landmark[rows].tolist())
        assert len(orig) == 1
        assert float(t[rows].min()) in passes[orig.pop()]
    half = ch.split_loop_closures(p, 0.5)
    assert half.counts["closures_dropped"] == n - math.floor(0.5 * n)


def test_the_explorer_shows_the_batch_solution_of_the_split_graph(car_park, graph):
    p = graph["problem"]
    w = ch.loop_closure_explorer(car_park, p, drop=0.0)
    w.children[0].value = 1.0
    w.update()
    s = w.holder["summary"]
    b = gs.solve_batch(ch.split_loop_closures(p, 0.0))
    assert s["error_final"] == pytest.approx(b.error_final, rel=1e-9)
    full = ch.loop_closure_summary(car_park, p, 1.0)
    # measured: 0.947 m without the closures against 0.094 m with them
    assert s["traj_rmse"] > 5 * full["traj_rmse"]
    assert s["duplicates"] > 0 and full["duplicates"] == 0


def test_kept_layout_stays_clear_at_the_controls_ends(car_park, graph):
    assert_kept_layouts_clear(lambda: ch.loop_closure_explorer(car_park, graph["problem"], drop=0.0))


def test_the_shared_error_scene_fools_nearest_neighbour_not_jcbb():
    sc = ch.shared_error_scene()
    assert sc["jcbb"].tolist() == [0, 1]
    assert sc["nn"].tolist() != [0, 1]
    # every pairing of the scene passes its individual gate: the scan is ambiguous one by one
    assert np.sum(sc["d2"] <= sc["gate"]) >= 3


def test_the_heading_bound_holds_for_fej_only():
    info = ch.heading_information(seed=7, laps=1)
    assert info["fej"].min() >= 1 - 1e-9
    assert info["ekf"].min() < 0.6


def test_bad_keep_is_refused(graph):
    with pytest.raises(ValueError, match="keep"):
        ch.split_loop_closures(graph["problem"], 1.5)


# -- section 1: the FEJ study, judged ---------------------------------------------------------

def test_level_and_difference_words_follow_the_shared_rule():
    """An interval holding 1 is 'no detectable difference', never 'consistent'; only a
    narrow one is 'within the 5 % margin'; a paired difference is better or worse by which
    filter lies nearer 1."""
    from annslam_lib.evaluation import consistency
    rng = np.random.default_rng(3)
    wide = consistency.ratio_effect(rng.chisquare(30, 40) / 30 * 1.0)
    narrow = consistency.ratio_effect(1.0 + 0.01 * rng.standard_normal(400))
    over = consistency.ratio_effect(1.2 + 0.01 * rng.standard_normal(400))
    assert ch.level_words(wide) == "no detectable difference, not within the 5 % margin"
    assert ch.level_words(narrow) == "no detectable difference, within the 5 % margin"
    assert ch.level_words(over).startswith("over-confident")
    up = consistency.paired_effect(np.full(50, 1.3) + 0.01 * rng.standard_normal(50), np.ones(50))
    down = consistency.paired_effect(np.ones(50), np.full(50, 1.3) + 0.01 * rng.standard_normal(50))
    same = consistency.paired_effect(1 + 0.1 * rng.standard_normal(50), 1 + 0.1 * rng.standard_normal(50))
    assert ch.difference_verdict(1.0, 1.3, up) == "worse"
    assert ch.difference_verdict(1.3, 1.0, down) == "better"          # nearer 1
    assert ch.difference_verdict(0.8, 1.3, up) == "worse"             # overshoots further
    if same.word == "no detectable difference":
        assert ch.difference_verdict(1.0, 1.0, same) == "no detectable difference"
    with pytest.raises(TypeError):
        ch.level_words(up)
    with pytest.raises(TypeError):
        ch.difference_verdict(1.0, 1.0, wide)


def test_fej_table_finds_a_planted_difference_and_its_resolution():
    """Synthetic runs: a consistent EKF (chi-square / dof), and a 'FEJ' 20 % over-confident on
    the same scenes (paired): the table must call FEJ worse, find no difference of the EKF from 1, and resolve
    the difference far more finely than either filter's level."""
    rng = np.random.default_rng(5)
    ekf = rng.chisquare(30, 200) / 30
    fej = 1.2 * ekf
    rows = [{"start": "exact", "estimator": "EKF", "pose": ekf, "map": ekf},
            {"start": "exact", "estimator": "FEJ", "pose": fej, "map": ekf + 1e-3 * rng.normal(size=200)}]
    pose, mp = ch.fej_table(rows)
    assert pose["n"] == 200 and pose["ekf"].word == "no detectable difference"
    assert pose["fej"].word == "over-confident" and pose["diff_verdict"] == "worse"
    assert pose["diff"].lo > 0.15 and pose["resolves"] < 0.5 * (pose["ekf"].hi - pose["ekf"].lo)
    assert mp["diff_verdict"] == "no detectable difference" and mp["resolves"] < 1e-3
    with pytest.raises(ValueError, match="EKF and a FEJ"):
        ch.fej_table(rows[:1])


def test_fej_study_reports_each_runs_own_nees():
    """Three runs: each row's per-run values are the pose NEES / 3 and the map NEES / dof of
    that run, recomputed here from a run of the filter."""
    from annslam_lib.data import simulate
    from annslam_lib.evaluation import consistency
    from annslam_lib.slam.config import SlamConfig
    from annslam_lib.slam.runner import run
    seeds = (2000, 2001, 2002)
    rows = ch.fej_study(seeds)
    assert [(r["start"], r["estimator"]) for r in rows] == [
        ("exact", "EKF"), ("exact", "FEJ"), ("prior", "EKF"), ("prior", "FEJ")]
    ds = simulate.simulate(seed=2001, laps=2, raw_laser=False)
    r = run(ds, SlamConfig.for_dataset("simulated", motion_model="midpoint", association="truth",
                                       first_estimates=True), progress=False)
    fej = rows[1]
    assert fej["pose"][1] == pytest.approx(consistency.pose_nees(r, ds).mean() / 3, rel=1e-12)
    v, dof = consistency.map_nees(r, ds)
    assert fej["map"][1] == pytest.approx(v / dof, rel=1e-12)
    assert rows[2]["pose"].shape == (3,) and not np.allclose(rows[2]["pose"], rows[0]["pose"])
    with pytest.raises(ValueError, match="two distinct seeds"):
        ch.fej_study((5, 5))


def test_the_fej_seeds_are_many_and_were_used_for_nothing_else():
    assert len(ch.FEJ_SEEDS) >= 100 and len(set(ch.FEJ_SEEDS)) == len(ch.FEJ_SEEDS)
    used = set(range(100, 150)) | set(range(400, 420)) | set(range(7000, 7200))
    used |= set(ch.SMOOTHER_SEEDS) | set(ch.JCBB_SEEDS)
    assert used.isdisjoint(ch.FEJ_SEEDS)


# -- section 3: like for like -----------------------------------------------------------------

def test_cost_summary_compares_medians_with_medians_and_totals_with_totals():
    a, b = np.array([1.0, 2.0, 3.0, 100.0]), np.array([2.0, 5.0, 6.0, 7.0])
    c = ch.cost_summary(a, b, 10.0, 5.0)
    assert c["median_ratio"] == pytest.approx(5.5 / 2.5) and c["total_ratio"] == pytest.approx(0.5)
    assert c["cheaper_per_scan"] == "EKF" and c["cheaper_in_all"] == "iSAM2" and c["scans"] == 4
    with pytest.raises(ValueError, match="one length"):
        ch.cost_summary(a, b[:3], 1.0, 1.0)
    with pytest.raises(ValueError, match=">= 0"):
        ch.cost_summary(-a, b, 1.0, 1.0)
    with pytest.raises(ValueError, match="zero"):
        ch.cost_summary(np.zeros(4), b, 1.0, 1.0)


def test_the_car_park_graph_carries_both_sides_timed_and_the_filtered_track(car_park, graph):
    tr = graph["timed"]
    assert tr.ekf_scan_cpu.shape == tr.isam2_scan_cpu.shape == (graph["ekf"].counts["scans"],)
    assert graph["isam2"] is tr.isam2 and graph["problem"] is tr.problem
    c = ch.cost_summary(tr.ekf_scan_cpu, tr.isam2_scan_cpu, tr.ekf_cpu, tr.isam2_cpu)
    assert c["scans"] == tr.scan_t.size and c["median_ratio"] > 0
    vp = {k: getattr(tr, k) for k in ("ekf_scan_cpu", "isam2_scan_cpu", "ekf_landmarks",
                                      "isam2_landmarks")}
    fig = ch.cost_figure(vp)
    assert len(fig.axes[0].lines) == 4                     # dots and running median, each side
    with pytest.raises(TypeError, match="car"):
        ch.car_park_graph("car_park")
