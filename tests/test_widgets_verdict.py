"""Headless tests of the chapter 08 explorer (annslam_lib.widgets.verdict): the summary is
the filter's own numbers, and moving the R-scale slider changes them as the Kalman filter
says (the covariance follows the R it is told, roughly like sqrt(k); the map does not)."""
import dataclasses
import math
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")  # headless: set in the test, never exported to notebook kernels

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from annslam_lib import ann  # noqa: E402
from annslam_lib.slam.config import SlamConfig  # noqa: E402
from annslam_lib.chapters import ch08_verdict as ch08
from annslam_lib.evaluation import map as map_eval
from annslam_lib.paper import study
from annslam_lib.paper import figures as paper_plots
from annslam_lib.slam import runner
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures  # noqa: F401
  # noqa: E402

SCALES = (0.3, 1.0, 3.0)


@pytest.fixture(scope="module")
def sweep(car_park):
    return study.r_scale_sweep(car_park, SCALES, t_heldout=100.0)


def test_summary_is_an_independent_run_with_the_scaled_noise(car_park, sweep):
    s = sweep[0.3]
    cfg = SlamConfig.for_dataset("car_park")
    r = runner.run(car_park, cfg.replace(sigma_range=cfg.sigma_range * math.sqrt(0.3),
                                           sigma_bearing=cfg.sigma_bearing * math.sqrt(0.3)))
    P = np.asarray(r.pose_cov)
    assert s["pose_trace"] == pytest.approx(np.mean(P[:, 0, 0] + P[:, 1, 1]), rel=1e-12)
    np.testing.assert_allclose(s["trace"], P[:, 0, 0] + P[:, 1, 1], rtol=1e-12)
    m = map_eval.map_errors(r.landmarks, car_park.beacons, max_distance=1.0)
    assert s["map_rmse"] == pytest.approx(m.rmse, rel=1e-12)
    assert s["map_rmse_aligned"] == pytest.approx(m.rmse_aligned, rel=1e-12)
    assert s["sigma_range"] == pytest.approx(0.1 * math.sqrt(0.3), rel=1e-12)
    assert math.degrees(s["sigma_bearing"]) == pytest.approx(math.sqrt(0.3), rel=1e-12)
    late = s["t"] >= 100.0
    assert s["pose_trace_heldout"] == pytest.approx(np.mean(s["trace"][late]), rel=1e-12)
    laser = r.nis["kind"] == 0
    assert s["nis_per_dof"] == pytest.approx(r.nis["nis"][laser].sum() / r.nis["dof"][laser].sum())


def test_variance_follows_the_declared_noise_and_the_map_does_not(sweep):
    """A random walk measured with noise r has a steady-state variance ~ sqrt(q r): scaling R
    by k should scale the mean position variance by roughly sqrt(k)."""
    p = {k: sweep[k]["pose_trace"] for k in SCALES}
    for k in (0.3, 3.0):
        assert p[k] / p[1.0] == pytest.approx(math.sqrt(k), rel=0.15)
    # The map is not better for being more certain: no gain beyond 5 mm from a 3x smaller R,
    # and its shape (aligned RMSE) moves by less than 1 cm over a factor 10 in R.
    assert sweep[0.3]["map_rmse"] > sweep[1.0]["map_rmse"] - 0.005
    aligned = [sweep[k]["map_rmse_aligned"] for k in SCALES]
    assert max(aligned) - min(aligned) < 0.01
    # every run maps the 15 beacons
    assert all(sweep[k]["matched"] == 15 for k in SCALES)


def test_slider_moves_the_summary_and_the_picture(sweep):
    ref = {"label": "ANN", "t": sweep[0.3]["t"], "trace": 0.9 * sweep[0.3]["trace"],
           "pose_trace": 0.9 * sweep[0.3]["pose_trace"], "map_rmse": 0.08,
           "map_rmse_aligned": 0.04, "traj_rmse": 0.15}
    w = ch08.r_scale_explorer(sweep=sweep, reference=ref, scale=1.0)
    slider = w.children[0]
    assert slider.continuous_update is False
    assert w.holder["summary"] is sweep[1.0]
    png1 = w.children[1].value
    plt.close("all")
    slider.value = 0.3
    # The picture is rendered on a Figure outside pyplot (an Image widget): nothing is left
    # open for a kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []
    s = w.holder["summary"]
    assert s["scale"] == 0.3 and s["pose_trace"] < 0.7 * sweep[1.0]["pose_trace"]
    assert "R × 0.3" in w.holder["text"] and f"{s['pose_trace']:.4f}" in w.holder["text"]
    assert "ANN: mean P_xx+P_yy" in w.holder["text"] and w.children[1].value != png1
    slider.value = 3.0
    assert w.holder["summary"]["pose_trace"] > 1.5 * sweep[1.0]["pose_trace"]


def test_plot_shows_the_sweep(sweep):
    ref = {"label": "ANN", "t": sweep[1.0]["t"], "trace": sweep[1.0]["trace"],
           "pose_trace": 0.014, "map_rmse": 0.08, "map_rmse_aligned": 0.04}
    fig = paper_plots.plot_r_scale(sweep, 0.3, ref)
    a0, a1, a2 = fig.axes
    lines = {ln.get_gid(): ln for ax in fig.axes for ln in ax.lines}
    np.testing.assert_array_equal(lines["mean_trace"].get_xdata(), SCALES)
    np.testing.assert_allclose(lines["mean_trace"].get_ydata(), [sweep[k]["pose_trace"] for k in SCALES])
    np.testing.assert_allclose(lines["map_rmse_aligned"].get_ydata(),
                               [sweep[k]["map_rmse_aligned"] for k in SCALES])
    np.testing.assert_allclose(lines["trace_k"].get_ydata(), sweep[0.3]["trace"])
    assert lines["current"].get_ydata()[0] == sweep[0.3]["pose_trace"]
    assert lines["ref_trace"].get_ydata()[0] == 0.014


def test_equivalent_scale(sweep):
    for k in SCALES:
        assert study.equivalent_scale(sweep, sweep[k]["pose_trace"]) == pytest.approx(k, rel=1e-9)
    mid = math.sqrt(sweep[0.3]["pose_trace"] * sweep[1.0]["pose_trace"])
    assert study.equivalent_scale(sweep, mid) == pytest.approx(math.sqrt(0.3), rel=1e-9)
    assert math.isnan(study.equivalent_scale(sweep, 0.5 * sweep[0.3]["pose_trace"]))
    bad = {1.0: {"pose_trace": 0.02}, 2.0: {"pose_trace": 0.01}}
    with pytest.raises(ValueError, match="does not increase"):
        study.equivalent_scale(bad, 0.015)


def test_reference_from_study(sweep):
    r = sweep[1.0]["result"]
    st = SimpleNamespace(seeds=(4,), results={"ann": [r]},
                         runs={"ann": [{"pose_trace": 0.02, "map_rmse": 0.07,
                                        "map_rmse_aligned": 0.04, "traj_rmse": 0.15}]},
                         models={"ann": [ann.InverseModel(0.05, 0.01)]})
    ref = study.reference_from_study(st, 0)
    assert ref["label"] == "ANN-enhanced (seed 4)" and ref["sigma_range"] == 0.05
    np.testing.assert_allclose(ref["trace"], sweep[1.0]["trace"], rtol=1e-12)
    assert ref["map_rmse"] == 0.07


def test_bad_input(car_park, sweep):
    for k in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="R scale"):
            study.r_scale_summary(car_park, k)
    for k in (True, "1"):
        with pytest.raises(TypeError, match="R scale"):
            study.r_scale_summary(car_park, k)
    with pytest.raises(TypeError, match="records.Dataset"):
        study.r_scale_summary("car_park", 1.0)
    with pytest.raises(ValueError, match="no surveyed beacons"):
        study.r_scale_summary(dataclasses.replace(car_park, beacons=None), 1.0)
    with pytest.raises(TypeError, match="SlamConfig"):
        study.r_scale_summary(car_park, 1.0, config={"sigma_range": 0.1})
    with pytest.raises(ValueError, match="distinct"):
        study.r_scale_sweep(car_park, (1.0, 1.0))
    with pytest.raises(ValueError, match="not in the sweep"):
        ch08.r_scale_explorer(sweep=sweep, scale=0.5)
    with pytest.raises(ValueError, match="not in the sweep"):
        paper_plots.plot_r_scale(sweep, 0.5)
    with pytest.raises(ValueError, match="dataset or a precomputed sweep"):
        ch08.r_scale_explorer()


def test_kept_layout_stays_clear_at_the_controls_ends(sweep):
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch08.r_scale_explorer(sweep=sweep, reference=None, scale=1.0))


def test_blitted_steps_with_a_reference_match_a_full_draw_and_hold_every_k(sweep):
    # Chapter 08's explorer blits (plots.blit.Blit): every step of the slider, with the
    # reference's dashed lines kept in the picture, equals the same state drawn from scratch
    # (tests/layout_support.py), and the first panel's one view holds every k's trace.
    ref = {"label": "ANN", "t": sweep[0.3]["t"], "trace": 0.5 * sweep[0.3]["trace"],
           "pose_trace": 0.9 * sweep[0.3]["pose_trace"], "map_rmse": 0.08,
           "map_rmse_aligned": 0.04, "traj_rmse": 0.15}
    views = []
    real = ch08._view

    def spy(*args):
        views.append(real(*args))
        return views[-1]

    ch08._view = spy
    try:
        n = assert_kept_layouts_clear(lambda: ch08.r_scale_explorer(sweep=sweep, reference=ref,
                                                                    scale=0.3))
    finally:
        ch08._view = real
    assert n >= 3
    lo, hi = views[0].fig.axes[0].get_ylim()
    for k in SCALES:
        tr = np.asarray(sweep[k]["trace"])
        assert lo < tr.min() and tr.max() < hi
    assert lo < 0.5 * np.min(sweep[0.3]["trace"])
    with pytest.raises(ValueError, match="not in the sweep"):
        paper_plots.set_r_scale(views[0].fig, sweep, 0.25)
