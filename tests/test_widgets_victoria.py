"""Chapter 06 explorer (annslam_lib.widgets.victoria), headless, on a short simulated run
(the same code reads the Victoria Park result in notebook 06)."""
import matplotlib

matplotlib.use("Agg")  # headless: set in the test, never exported to notebook kernels

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

  # noqa: E402
from annslam_lib.slam.results import STATUS  # noqa: E402
from annslam_lib.data.records import Gps  # noqa: E402
from annslam_lib.models.uncertainty import ellipse_points  # noqa: E402
from annslam_lib.chapters import ch06_victoria_park as ch06
from annslam_lib.data import simulate
from annslam_lib.evaluation import trajectory
from annslam_lib.models import geometry
from annslam_lib.models import uncertainty
from annslam_lib.slam import config as slam_config
from annslam_lib.slam import runner
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures  # noqa: F401
  # noqa: E402


@pytest.fixture(scope="module")
def sim_run():
    ds = simulate.simulate(seed=0, laps=1)
    r = runner.run(ds, slam_config.SlamConfig.for_dataset("simulated"), progress=False)
    # A GPS with a 10 s gap (fixes between 20 and 30 s removed): what Victoria Park has.
    keep = (ds.gps.t < 20.0) | (ds.gps.t > 30.0)
    gps = Gps(t=ds.gps.t[keep], east=ds.gps.east[keep], north=ds.gps.north[keep])
    return ds, r, gps


def test_gps_outliers_flag_impossible_steps_only():
    # 2 m/s along x at 5 Hz; fix 20 is a 100 m spike; fix 40 jumps 6 m in 0.2 s and the
    # receiver then stays 6 m off; fixes 61.. follow a 20 s gap and a legitimate 40 m move.
    t = np.concatenate([np.arange(60) * 0.2, 12.0 + 20.0 + np.arange(10) * 0.2])
    x = 2.0 * t
    y = np.zeros_like(t)
    y[20] = 100.0
    y[40:60] = 6.0
    gps = Gps(t=t, east=x, north=y)
    flag = trajectory.gps_outliers(gps)
    assert np.flatnonzero(flag).tolist() == [20, 40]          # not 21 (the way back), not 60
    assert np.flatnonzero(trajectory.gps_outliers(gps, tolerance=7.0)).tolist() == [20]
    # Jitter: a fix 2.5 m off its neighbours 0.2 s apart is within the 3 m tolerance.
    y2 = np.zeros_like(t)
    y2[30] = 2.5
    assert not trajectory.gps_outliers(Gps(t=t, east=x, north=y2)).any()
    assert trajectory.gps_outliers(Gps(t=t, east=x, north=y2), tolerance=0.2)[30]   # 2.53 m > 2 + 0.2 m
    assert not trajectory.gps_outliers(Gps(t=[0.0], east=[0.0], north=[0.0])).any()
    with pytest.raises(ValueError, match="max_speed"):
        trajectory.gps_outliers(gps, max_speed=-1.0)
    with pytest.raises(ValueError, match="tolerance"):
        trajectory.gps_outliers(gps, tolerance=float("nan"))


def test_first_seen_is_the_creating_observation(sim_run):
    _, r, _ = sim_run
    first = ch06.landmark_first_seen(r)
    log = r.observations
    assert first.shape == (r.landmarks.shape[0],) and r.landmarks.shape[0] >= 10
    for j in range(r.landmarks.shape[0]):
        created = log.t[(log.landmark == j) & (log.status == STATUS["new"])]
        assert created.size == 1 and first[j] == created[0]
        assert first[j] == log.t[log.landmark == j].min()


def test_snapshot_reads_the_stored_run(sim_run):
    _, r, gps = sim_run
    errors = trajectory.trajectory_errors(r.odometry_trajectory, gps)
    first = ch06.landmark_first_seen(r)
    k = 150
    t = float(r.trajectory[k, 0]) + 0.05                        # between two scans
    s = ch06.run_snapshot(r, gps, t)
    assert s["row"] == k and s["scan"] == r.scan_index[k]
    np.testing.assert_array_equal(s["pose"], r.trajectory[k, 1:4])
    assert s["sigma_xy"] == pytest.approx(np.sqrt(np.linalg.eigvalsh(r.pose_cov[k][:2, :2]).max()))
    assert s["landmarks"] == np.count_nonzero(first <= t)
    assert s["fixes"] == np.count_nonzero(gps.t <= t)
    i = np.argmin(np.abs(errors.t - t))
    assert s["fix"]["t"] == errors.t[i] and s["fix"]["error"] == pytest.approx(errors.error[i])
    # The error is the distance from the filtered track to that fix, recomputed here.
    p = geometry.interpolate_poses(r.odometry_trajectory, s["fix"]["t"])
    assert s["fix"]["error"] == pytest.approx(np.hypot(*(p[:2] - s["fix"]["xy"])), abs=1e-12)
    end = ch06.run_snapshot(r, gps, float(r.trajectory[-1, 0]))
    assert end["landmarks"] == r.landmarks.shape[0] and end["row"] == r.trajectory.shape[0] - 1


def test_snapshot_in_a_gps_gap_has_no_fix(sim_run):
    _, r, gps = sim_run
    s = ch06.run_snapshot(r, gps, 25.0)
    last = gps.t[gps.t <= 25.0][-1]
    assert s["fix"] is None and last < 20.0
    assert s["since_fix"] == pytest.approx(25.0 - last)
    assert ch06.run_snapshot(r, gps, 25.0, fix_window=6.0)["fix"] is not None


def test_ellipse_curves_equal_ellipse_points():
    rng = np.random.default_rng(4)
    A = rng.normal(size=(5, 2, 2))
    covs = A @ np.swapaxes(A, 1, 2) + np.array([0.0, 1e-12])[:, None] * np.eye(2)
    covs[0] = np.diag([1.0, 0.0])                                  # singular: a segment
    means = rng.normal(size=(5, 2)) * 10
    curves = uncertainty.ellipse_curves(means, covs, 2.0, 50)
    for m, c, e in zip(means, covs, curves):
        np.testing.assert_allclose(e, ellipse_points(m, c, 2.0, 50), atol=1e-12)


def test_draw_run_shows_the_landmarks_seen_so_far(sim_run):
    _, r, gps = sim_run
    first = ch06.landmark_first_seen(r)
    t = float(np.sort(first)[5]) + 1e-9                           # six landmarks seen
    ax = ch06.draw_run(r, gps, t)
    ells = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(ells) == 1 and len(ells[0].get_segments()) == np.count_nonzero(first <= t) == 6
    plus = [ln for ln in ax.lines if ln.get_marker() == "+"][0]
    np.testing.assert_array_equal(plus.get_xdata(), r.landmarks[first <= t, 0])
    track = [ln for ln in ax.lines if ln.get_label() == "EKF-SLAM track"][0]
    assert track.get_xdata()[-1] == r.trajectory[r.trajectory[:, 0] <= t][-1, 1]


def test_draw_gps_errors_marks_outliers_and_keeps_gaps(sim_run):
    _, r, gps = sim_run
    errors = trajectory.trajectory_errors(r.odometry_trajectory, gps)
    outliers = np.zeros(errors.t.size, bool)
    outliers[3] = True
    ax = ch06.draw_gps_errors(errors, t=10.0, outliers=outliers)
    dots, crosses = ax.lines[0], ax.lines[1]
    assert dots.get_linestyle() == "None" and len(dots.get_xdata()) == errors.t.size - 1
    assert crosses.get_xdata()[0] == errors.t[3]


def rows_upto(r, t):
    return int(np.searchsorted(r.trajectory[:, 0], t, side="right"))


def test_scrubber_follows_the_slider(sim_run):
    _, r, gps = sim_run
    outliers = np.zeros(gps.t.size, bool)
    outliers[10] = True
    w = ch06.run_scrubber(r, gps, start=12, step=1, outliers=outliers)
    assert w.holder["summary"]["t"] == 12.0
    assert w.children[0].min == int(np.ceil(r.trajectory[0, 0]))
    assert w.children[0].max == int(np.floor(r.trajectory[-1, 0]))
    assert not w.children[0].continuous_update          # one redraw per release, not per pixel
    first = w.holder["summary"]
    view = w.views[0]
    plt.close("all")
    w.children[0].value = 25
    # one blitted figure (fixed views): the step moved the time line and redrew the map to t
    assert w.views == [view] and list(view.moving[-1].get_xdata()) == [25.0, 25.0]
    track = [a for a in view.moving if a.get_label() == "EKF-SLAM track"]
    assert len(track) == 1 and track[0].get_xdata().size == rows_upto(r, 25.0)
    # The callback draws outside pyplot (plotting.widget_figure): nothing is left open for a
    # kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []
    s = w.holder["summary"]
    assert s["t"] == 25.0 and s["fix"] is None
    row = np.searchsorted(r.trajectory[:, 0], 25.0, side="right") - 1
    np.testing.assert_array_equal(s["pose"], r.trajectory[row, 1:4])
    assert s["landmarks"] >= first["landmarks"] and s["row"] > first["row"]
    assert s["landmarks"] == ch06.run_snapshot(r, gps, 25.0)["landmarks"]


def test_bad_input_is_a_clear_error(sim_run):
    _, r, gps = sim_run
    with pytest.raises(ValueError, match="outside the run"):
        ch06.run_snapshot(r, gps, float(r.trajectory[-1, 0]) + 1.0)
    with pytest.raises(ValueError, match="finite"):
        ch06.run_snapshot(r, gps, float("nan"))
    with pytest.raises(TypeError, match="SlamResult"):
        ch06.run_snapshot("run", gps, 10.0)
    with pytest.raises(TypeError, match="records.Gps"):
        ch06.run_scrubber(r, gps.xy)
    with pytest.raises(ValueError, match="step"):
        ch06.run_scrubber(r, gps, step=0)
    with pytest.raises(ValueError, match="start"):
        ch06.run_scrubber(r, gps, start=-5)
    with pytest.raises(ValueError, match="outliers"):
        ch06.run_scrubber(r, gps, outliers=np.zeros(3, bool))
    with pytest.raises(ValueError, match="3 means but 2"):
        uncertainty.ellipse_curves(np.zeros((3, 2)), np.zeros((2, 2, 2)))


def test_kept_layout_stays_clear_at_the_controls_ends(sim_run):
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch06.run_scrubber(sim_run[1], sim_run[2], start=12, step=1))
