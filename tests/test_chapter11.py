"""Chapter 11's companion (annslam_lib.chapters.ch11_graph_slam): the counts it prints are
the graph's, the gauge shows three free directions without a prior and none with it, and
the experiments' verdicts hold with their margins."""
import numpy as np
import pytest

from annslam_lib.chapters import ch11_graph_slam as ch
from annslam_lib.data import loaders
from annslam_lib.smoothing import gauss_newton as gn

pytest.importorskip("gtsam")


@pytest.fixture(scope="module")
def graph():
    return ch.car_park_problem(loaders.load_car_park())


def test_the_counts_are_the_graphs(graph):
    p = graph["problem"]
    n = ch.sizes(p)
    e, J = gn.linearise(p, p.initial_poses, p.initial_landmarks)
    assert (n["rows"], n["unknowns"]) == J.shape == (e.size, 3 * n["poses"] + 2 * n["landmarks"])
    assert n["odometry"] == n["poses"] - 1 and n["prior"] == 1


def test_the_gauge_is_free_only_without_the_prior_and_gps(graph):
    p = graph["problem"]
    s = gn.solve_gauss_newton(p)
    ev = ch.gauge_eigenvalues(p, s.poses, s.landmarks)
    assert np.sum(np.abs(ev["without"]) < 1e-6) == 3 and ev["without"][3] > 1.0
    assert np.sum(np.abs(ev["with"]) < 1e-6) == 0 and ev["with"][0] > 0.1
    said = ch.without_prior(p)
    assert "missing prior" in said["check"] and "singular" in said["factorisation"]


def test_the_robust_loss_holds_the_map_and_matches_gtsam(graph):
    p = graph["problem"]
    c = ch.against_gtsam(p)
    assert max(c["position"], c["landmark"]) < 1e-5 and c["heading"] < 1e-5
    w = ch.wrong_associations(p)
    assert w["wrong"] == int(ch.WRONG_SHARE * w["detections"])
    assert w["plain"]["landmark"] > 2.0 > 0.15 > w["huber"]["landmark"]
    assert w["huber_vs_gtsam"] < 1e-3
