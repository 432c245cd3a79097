"""Chapter 05 explorer (annslam_lib.widgets.slam): truncation is causal, the summary's
numbers are the metrics modules', and moving a slider re-runs the filter as the model
says (headless)."""
import math

import matplotlib

matplotlib.use("Agg")  # headless: set in the test, never exported to notebook kernels

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

  # noqa: E402
from annslam_lib.slam.config import SlamConfig  # noqa: E402
from annslam_lib.chapters import ch05_ekf_slam as ch05
from annslam_lib.data import records
from annslam_lib.data import simulate
from annslam_lib.evaluation import consistency
from annslam_lib.evaluation import map as map_eval
from annslam_lib.evaluation import trajectory
from annslam_lib.slam import runner
from annslam_lib.evaluation.summary import pose_trace  # noqa: E402
from layout_support import assert_kept_layouts_clear  # noqa: E402
  # noqa: E402


@pytest.fixture(scope="module")
def full_run(car_park):
    return runner.run(car_park, progress=False)


def test_truncate_keeps_exactly_the_data_up_to_t_end(car_park):
    cut = records.truncate(car_park, 40.0)
    assert cut.odometry.t[-1] <= 40.0 < car_park.odometry.t[len(cut.odometry)]
    assert cut.laser.t[-1] <= 40.0 < car_park.laser.t[len(cut.laser)]
    assert cut.gps.t[-1] <= 40.0 < car_park.gps.t[len(cut.gps)]
    np.testing.assert_array_equal(cut.laser.ranges, car_park.laser.ranges[:len(cut.laser)])
    np.testing.assert_array_equal(cut.beacons, car_park.beacons)


def test_truncate_simulated_detections_and_truth():
    ds = simulate.simulate(seed=2, raw_laser=False, laps=1)
    cut = records.truncate(ds, 20.0)
    n = len(cut.detections)
    assert ds.detections.t[n - 1] <= 20.0 < ds.detections.t[n]
    assert cut.detections.count == ds.detections.offsets[n]
    np.testing.assert_array_equal(cut.detections.landmark_id, ds.detections.landmark_id[:cut.detections.count])
    assert len(cut.info["scan_poses"]) == n and cut.truth.poses[-1, 0] <= 20.0
    r = runner.run(cut, SlamConfig.for_dataset("simulated"), progress=False)
    assert consistency.pose_nees(r, cut).shape == (n,)


def test_truncate_rejects_bad_input(car_park):
    with pytest.raises(ValueError, match="before the first odometry"):
        records.truncate(car_park, -1.0)
    with pytest.raises(ValueError, match="t_end must be a finite number"):
        records.truncate(car_park, math.nan)
    with pytest.raises(TypeError, match="records.Dataset"):
        records.truncate("car_park", 10.0)
    with pytest.raises(TypeError, match="records.Dataset"):
        ch05.slam_summary("car_park")


def test_a_cut_run_is_the_full_run_up_to_that_time(car_park, full_run):
    """Causality: the filter on the data up to 40 s reproduces the full run's trajectory
    up to 40 s exactly (same initial pose: fitted once on the whole run)."""
    s = ch05.slam_summary(car_park, t_end=40.0)
    r = s["result"]
    k = len(r.trajectory)
    assert k == np.count_nonzero(full_run.trajectory[:, 0] <= 40.0)
    np.testing.assert_allclose(r.trajectory, full_run.trajectory[:k], rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.initial_pose, full_run.initial_pose, rtol=0, atol=1e-12)
    assert r.config.initial_pose == tuple(full_run.initial_pose)


def test_summary_numbers_are_the_metrics_modules(car_park, full_run):
    s = ch05.slam_summary(car_park)
    m = map_eval.map_errors(full_run.landmarks, car_park.beacons, max_distance=1.0)
    e = trajectory.trajectory_errors(full_run.odometry_trajectory, car_park.gps)
    assert (s["landmarks"], s["matched"], s["missed"], s["spurious"], s["duplicates"]) == \
        (15, 15, 0, 0, 0)
    assert s["map_rmse"] == m.rmse and s["map_rmse_aligned"] == m.rmse_aligned
    assert s["traj_rmse"] == e.rmse
    k = full_run.nis["kind"] == 0
    assert s["nis_per_dof"] == pytest.approx(full_run.nis["nis"][k].sum() / full_run.nis["dof"][k].sum())
    assert "15 beacons matched" in ch05._line(s)


def test_explorer_follows_its_sliders(car_park, full_run):
    """Every slider reaches the filter's configuration, and the summary, the text and the
    image follow (the summary equals the pure function's with the same configuration)."""
    w = ch05.slam_explorer(car_park, t_end=40.0)
    t_slider, speed, steer, rng, bearing, gate = w.children[:6]
    # every slider re-runs the filter (0.2 s): it fires on release only
    assert all(not s.continuous_update for s in w.children[:6])
    first = w.holder["summary"]
    image, text = w.children[6:8]
    png = image.value
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and "NIS/dof" in text.value
    assert first["t_end"] <= 40.0 and first["scans"] == np.count_nonzero(car_park.laser.t <= 40.0)
    assert first["landmarks"] == first["matched"] < 15          # not all beacons seen yet
    # sigma_range: the same numbers as the pure function with that configuration
    plt.close("all")
    rng.value = 0.05
    # The picture is rendered on a Figure outside pyplot (an Image widget): nothing is left
    # open for a kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []
    base = ch05.fixed_initial_pose(car_park, SlamConfig.for_dataset("car_park"))
    ref = ch05.slam_summary(car_park, base.replace(sigma_range=0.05), t_end=40.0)
    assert w.holder["summary"]["nis_per_dof"] == ref["nis_per_dof"] != first["nis_per_dof"]
    rng.value = 0.1
    # the time slider to the end: the whole run, drawn anew
    t_slider.value = t_slider.max
    assert image.value != png and f"{full_run.counts['scans']} scans" in text.value
    s = w.holder["summary"]
    assert s["scans"] == full_run.counts["scans"] and s["landmarks"] == 15
    np.testing.assert_allclose(s["result"].state, full_run.state, rtol=0, atol=1e-12)
    # a 50 % gate: correct associations fall outside it, observations are rejected and the
    # drifting pose starts false landmarks
    gate.value = 0.5
    s = w.holder["summary"]
    assert s["rejected"] > 20 and s["spurious"] > 0 and s["result"].config.gate_prob == 0.5
    # the odometry sliders reach the config too
    speed.value, steer.value, bearing.value = 0.3, 3.0, 2.0
    cfg = w.holder["summary"]["result"].config
    assert (cfg.sigma_speed, cfg.sigma_steer, cfg.sigma_bearing) == pytest.approx(
        (0.3, math.radians(3.0), math.radians(2.0)))
    assert "NIS/dof" in w.holder["text"]
    plt.close("all")


def test_kept_layout_stays_clear_at_the_controls_ends(car_park):
    # The explorer blits (plots.blit.Blit): every step at the controls' ends is measured and
    # equals the same state drawn from scratch (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch05.slam_explorer(car_park, t_end=40.0), only=(0, 1, 5))


def test_time_steps_reuse_one_view_and_a_setting_outside_it_draws_anew(car_park, full_run,
                                                                     monkeypatch):
    views = []
    real = ch05._view
    monkeypatch.setattr(ch05, "_view", lambda *a: views.append(real(*a)) or views[-1])
    w = ch05.slam_explorer(car_park, t_end=40.0)
    t_slider, speed = w.children[0], w.children[1]
    assert len(views) == 1
    _, ax_e, ax_p = views[0].fig.axes
    # the view holds the whole run at the starting settings: the time slider only redraws data
    e = trajectory.trajectory_errors(full_run.odometry_trajectory, car_park.gps).error
    sd = np.sqrt(pose_trace(full_run)[1])
    assert e.max() < ax_e.get_ylim()[1] and ax_p.get_ylim()[0] < sd.min() < sd.max() < ax_p.get_ylim()[1]
    for t in (t_slider.min, t_slider.max, 80.0):
        t_slider.value = t
    assert len(views) == 1
    # the largest speed noise lifts the uncertainty out of the view: drawn anew, with ranges
    # for the whole run at those settings
    speed.value = speed.max
    assert len(views) == 2
    s = ch05.slam_summary(car_park, w.holder["summary"]["result"].config, t_end=t_slider.max)
    top = ax_p.get_ylim()[1]
    assert np.sqrt(pose_trace(s["result"])[1]).max() > top
    assert np.sqrt(pose_trace(s["result"])[1]).max() < views[1].fig.axes[2].get_ylim()[1]
