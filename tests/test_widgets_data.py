"""Chapter 00 helpers: the scan summary, the scan scrubber (headless) and the scan plot."""
import matplotlib

matplotlib.use("Agg")  # headless: set in the test, never exported to notebook kernels

import matplotlib.pyplot as plt  # noqa: E402
import re  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import scipy.io  # noqa: E402

  # noqa: E402
from annslam_lib.chapters.ch00_course_map import scan_readout  # noqa: E402
from annslam_lib.chapters import ch00_course_map as ch00
from annslam_lib.data import fetch
from annslam_lib.data import simulate
from annslam_lib.plots import data as data_plots
from layout_support import assert_kept_layouts_clear  # noqa: E402

READOUT = re.compile(r"scan (\d+)  t = ([\d.]+) s  returns (\d+)  bright beams (\d+)"
                     r"(?: \(([\d.]+)-([\d.]+) m\))?")


def test_scan_summary_counts_match_the_raw_file(car_park):
    raw = scipy.io.loadmat(fetch.dataset_dir("car_park") / "data_set.mat")
    k = 150
    s = ch00.scan_summary(car_park.laser, k, max_range=20)
    assert s["bright_beams"] == np.count_nonzero(raw["Intensity"][k] > 0) == 2
    assert s["returns"] == np.count_nonzero(raw["Laser"][k] < 20)
    assert s["t"] == pytest.approx(raw["TimeLaser"].ravel()[k] - car_park.info["time_offset_s"], abs=1e-9)
    bright = raw["Laser"][k][raw["Intensity"][k] > 0]
    assert s["bright_range"] == pytest.approx((bright.min(), bright.max()))


def test_scan_scrubber_follows_the_slider(car_park):
    w = ch00.scan_scrubber(car_park, start=10)
    assert w.holder["summary"]["scan"] == 10
    w.children[0].value = 300
    assert w.holder["summary"] == ch00.scan_summary(car_park.laser, 300, max_range=20)
    assert w.children[0].max == len(car_park.laser) - 1
    plt.close("all")


def test_scan_readout_formats_the_summary():
    s = {"scan": 7, "t": 1.234, "returns": 99, "bright_beams": 3, "bright_range": (4.005, 12.5)}
    assert scan_readout(s) == "scan 7  t = 1.23 s  returns 99  bright beams 3 (4.00-12.50 m)"
    assert scan_readout({**s, "bright_beams": 0, "bright_range": None}) == (
        "scan 7  t = 1.23 s  returns 99  bright beams 0")


def test_scan_scrubber_prints_the_readout_the_raw_file_implies(car_park, capsys):
    # What the browser test reads: the printed line, for each slider position, must say
    # what the raw file holds for that scan (counted here from the .mat, not via the loader).
    raw = scipy.io.loadmat(fetch.dataset_dir("car_park") / "data_set.mat")
    t_raw = raw["TimeLaser"].ravel() - car_park.info["time_offset_s"]
    plt.close("all")
    w = ch00.scan_scrubber(car_park, start=150)
    capsys.readouterr()  # the first drawing (scan 150)
    seen = {}
    for k in (151, 300):
        w.children[0].value = k
        # Outside a kernel stdout also holds clear_output's escape codes and the figure's repr.
        (printed,) = re.findall(r"scan \d+ .*", capsys.readouterr().out)
        assert printed == w.holder["readout"] == scan_readout(
            ch00.scan_summary(car_park.laser, k, max_range=20))
        m = READOUT.fullmatch(printed)
        assert m, printed
        assert int(m[1]) == k
        assert float(m[2]) == pytest.approx(t_raw[k], abs=0.005)
        assert int(m[3]) == np.count_nonzero(raw["Laser"][k] < 20)
        assert int(m[4]) == np.count_nonzero(raw["Intensity"][k] > 0)
        seen[k] = (float(m[2]), int(m[3]), int(m[4]))
    # The two scans differ in every number, as the raw file says (tape seen at 151, none at 300).
    assert seen[151][2] > 0 and seen[300][2] == 0
    assert seen[151][1] != seen[300][1] and seen[300][0] - seen[151][0] > 30
    # The plot is drawn outside pyplot: in JupyterLab a kernel subshell thread flushes every
    # open pyplot figure while the callback runs, which showed half-drawn plots.
    assert plt.get_fignums() == []


def test_scan_scrubber_and_summary_reject_bad_input(victoria_park, car_park):
    with pytest.raises(ValueError, match="no raw laser"):
        ch00.scan_scrubber(victoria_park)
    with pytest.raises(IndexError, match="outside 0..585"):
        ch00.scan_summary(car_park.laser, 586)


def test_scan_plot_puts_tape_returns_in_the_vehicle_frame():
    # One pole straight ahead of the laser at 6 m: its bright return must be drawn at
    # x = a + 6, y = b in the rear-axle frame.
    ds = simulate.simulate(seed=1, beacons=np.array([[0.0, 0.0]]), sigma_range=0.0,
                           sigma_bearing=0.0, laps=1)
    k = int(np.argmax((ds.laser.intensity > 0).sum(axis=1)))
    ax = data_plots.plot_scan_vehicle_frame(ds.laser, k, ds.vehicle, max_range=30)
    bright = ax.collections[0].get_offsets()
    r, beta = ds.laser.ranges[k], ds.laser.angles
    hit = ds.laser.intensity[k] > 0
    expected = np.column_stack([ds.vehicle.a + r[hit] * np.sin(beta[hit]), ds.vehicle.b - r[hit] * np.cos(beta[hit])])
    np.testing.assert_allclose(bright, expected, atol=1e-12)
    # ...and those points are where the true pole is, seen from the true laser pose.
    x, y, phi = ds.info["scan_poses"][k]  # true laser pose (x, y, phi) at scan k
    c, s = np.cos(phi), np.sin(phi)
    laser_xy = expected - [ds.vehicle.a, ds.vehicle.b]
    world = np.column_stack([x + c * laser_xy[:, 0] - s * laser_xy[:, 1], y + s * laser_xy[:, 0] + c * laser_xy[:, 1]])
    assert np.all(np.hypot(*(world - ds.beacons[0]).T) <= 0.1 + 1e-9)  # on the pole's surface (radius 0.1 m)
    plt.close("all")


def test_kept_layout_stays_clear_at_the_controls_ends(car_park):
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch00.scan_scrubber(car_park, start=10))
