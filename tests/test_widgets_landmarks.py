"""Chapter 04 explorers (annslam_lib.widgets.landmarks), headless."""
import math

import matplotlib

matplotlib.use("Agg")  # headless: set in the test, never exported to notebook kernels

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

  # noqa: E402
from annslam_lib.perception.association import NEW, REJECTED  # noqa: E402
from annslam_lib.chapters import ch04_landmarks as ch04
from annslam_lib.data import simulate
from annslam_lib.perception import beacons
from annslam_lib.slam import dead_reckoning
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures  # noqa: F401
  # noqa: E402


def test_summary_agrees_with_the_whole_run_extraction(car_park):
    det = beacons.extract_beacons(car_park.laser)
    for k in (150, 300, 475):
        s = ch04.beacon_scan_summary(car_park, k)
        np.testing.assert_array_equal(s["z"], det[k])
        assert s["bright_beams"] == np.count_nonzero(car_park.laser.intensity[k] > 0)
    assert ch04.beacon_scan_summary(car_park, 475)["beacons"] == 0      # only a 0.87 m cluster


def test_summary_reference_residuals_agree_with_the_whole_run_check(car_park):
    poses, valid = dead_reckoning.gps_scan_poses(car_park)
    det = beacons.extract_beacons(car_park.laser)
    whole = beacons.extraction_residuals(det, poses, valid, car_park.beacons)
    for k in (9, 92, 130, 320):
        s = ch04.beacon_scan_summary(car_park, k)
        res = s["reference"]["residuals"]
        assert s["beacons"] >= 3 and np.all(np.isfinite(res))
        rows = slice(det.offsets[k], det.offsets[k + 1])
        np.testing.assert_allclose(res, np.column_stack([whole.range[rows], whole.bearing[rows]]),
                                   atol=1e-12)
        assert np.all(np.abs(res[:, 0]) < 0.15) and np.all(np.abs(res[:, 1]) < math.radians(4))
    # While the car stands still there is no GPS heading, hence no reference.
    assert not valid[150] and ch04.beacon_scan_summary(car_park, 150)["reference"] is None


def test_scrubber_follows_its_sliders(car_park):
    w = ch04.beacon_scrubber(car_park, start=150)
    assert w.holder["summary"]["scan"] == 150
    plt.close("all")
    w.children[0].value = 68                  # a close pole with ordinary beams inside its tape
    merged = w.holder["summary"]["beacons"]
    w.children[1].value = 0                   # strictly contiguous clusters split it
    assert w.holder["summary"]["beacons"] > merged
    # The callback draws outside pyplot (plotting.widget_figure): nothing is left open for a
    # kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []
    assert w.children[0].max == len(car_park.laser) - 1


def test_draw_beacon_scan_puts_the_centre_where_the_simulated_pole_is():
    ds = simulate.simulate(seed=1, beacons=np.array([[0.0, 0.0]]), sigma_range=0.0,
                           sigma_bearing=0.0, laps=1)
    k = int(np.argmax((ds.laser.intensity > 0).sum(axis=1)))
    s = ch04.beacon_scan_summary(ds, k)
    ax = ch04.draw_beacon_scan(ds, s)
    centre = ax.lines[1].get_xydata()                         # the '+' markers
    x, y, phi = ds.info["scan_poses"][k]
    d = -np.array([x, y])
    true_local = [d[0] * math.cos(phi) + d[1] * math.sin(phi), -d[0] * math.sin(phi) + d[1] * math.cos(phi)]
    assert np.linalg.norm(centre[0] - true_local) < 0.1 + 1e-9   # within the pole radius
    assert s["reference"] is not None and s["reference"]["z"].shape == (1, 2)


def test_summary_and_scrubber_reject_bad_input(victoria_park, car_park):
    with pytest.raises(ValueError, match="no raw laser"):
        ch04.beacon_scrubber(victoria_park)
    with pytest.raises(ValueError, match="no raw laser"):
        ch04.beacon_scan_summary(victoria_park, 0)
    with pytest.raises(IndexError, match="outside 0..585"):
        ch04.beacon_scan_summary(car_park, 586)


def test_crafted_scene_outcomes_follow_the_gate():
    w = ch04.gate_explorer()
    s = w.holder["summary"]
    assert s["gate"] == pytest.approx(-2 * math.log(0.01))
    # z0 -> landmark 1 (Mahalanobis beats metres), z1 wins landmark 2 over z2,
    # z3 is 3.5 sigma out in range (d2 = 12.25, rejected), z4 is new.
    assert s["assign"].tolist() == [1, 2, REJECTED, REJECTED, NEW]
    assert s["d2"][3, 3] == pytest.approx(3.5**2)
    w.children[0].value = 0.999               # gate 13.8: z3 now accepted
    assert w.holder["summary"]["assign"].tolist() == [1, 2, REJECTED, 3, NEW]
    w.children[0].value = 0.5                 # gate 1.39: z0 (d2 = 2.56) is rejected too
    assert w.holder["summary"]["assign"].tolist() == [REJECTED, 2, REJECTED, REJECTED, NEW]
    with pytest.raises(ValueError, match="prob must be one of"):
        ch04.gate_explorer(prob=0.42)


def test_draw_gates_draws_the_chi_square_ellipse():
    scene = ch04.crafted_scene()
    _, ax = plt.subplots()
    ch04.draw_gates(ax, scene["zhat"][:1], scene["S"][:1], gate=9.21)
    e = ax.lines[0].get_xydata()
    # Points of the drawn curve, back in (range, bearing rad), have d2 = 9.21 exactly.
    nu = np.column_stack([e[:, 1] - scene["zhat"][0, 0], np.radians(e[:, 0]) - scene["zhat"][0, 1]])
    d2 = np.einsum("ni,ij,nj->n", nu, np.linalg.inv(scene["S"][0]), nu)
    np.testing.assert_allclose(d2, 9.21, rtol=1e-9)


def test_slow_sliders_wait_for_release(car_park):
    """Re-extracting a scan and redrawing on every pixel of a drag would lag."""
    scrub = ch04.beacon_scrubber(car_park, start=92)
    gate = ch04.gate_explorer()
    for w in (scrub, gate):
        controls = [c for c in w.children if hasattr(c, "continuous_update")]
        assert controls and all(c.continuous_update is False for c in controls)


def test_scrubber_summary_follows_the_scan_slider(car_park):
    """The slider's scan is the one summarised: its beacons are that scan's extraction."""
    det = beacons.extract_beacons(car_park.laser)
    w = ch04.beacon_scrubber(car_park, start=0)
    for k in (92, 320):
        w.children[0].value = k
        s = w.holder["summary"]
        assert s["scan"] == k and s["t"] == pytest.approx(car_park.laser.t[k])
        np.testing.assert_array_equal(s["z"], det[k])


def test_kept_layout_stays_clear_at_the_controls_ends(car_park):
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch04.beacon_scrubber(car_park, start=150))
    assert_kept_layouts_clear(lambda: ch04.gate_explorer())
