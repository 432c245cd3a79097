"""Chapter 10 companion, headless: the loop-closure split checked against a count made here,
the explorer against a batch solve of the split graph, the shared-error scene, the VP
comparison's rows against a recomputation of the EKF's."""
import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from annslam_lib.chapters import ch10_beyond_ekf as ch  # noqa: E402
from annslam_lib.smoothing import solve as gs  # noqa: E402
from layout_support import assert_kept_layouts_clear  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


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
