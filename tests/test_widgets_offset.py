"""Chapter 02 explorer: laser path vs axle path vs GPS for a trial offset (a, b)."""
import dataclasses

import matplotlib

matplotlib.use("Agg")  # headless: set in the test, never exported to notebook kernels

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.optimize import minimize, minimize_scalar  # noqa: E402

  # noqa: E402
from annslam_lib.data.records import Gps  # noqa: E402
from annslam_lib.models.vehicle import ACFR_UTE, Vehicle  # noqa: E402
from annslam_lib.chapters import ch02_laser_offset as ch02
from annslam_lib.data import simulate
from layout_support import assert_kept_layouts_clear  # noqa: E402
  # noqa: E402


@pytest.fixture(scope="module")
def turn(car_park):
    return ch02.car_park_stretch(car_park)


def test_stretch_is_the_requested_piece_of_the_run(car_park, turn):
    t = turn.axle[:, 0]
    assert t[0] == pytest.approx(6.0, abs=0.025) and t[-1] == pytest.approx(21.0, abs=0.025)
    np.testing.assert_allclose(np.diff(t), 0.025, atol=1e-6)
    assert np.all((turn.gps_t >= t[0]) & (turn.gps_t <= t[-1])) and len(turn.gps_t) == 75
    # The dead-reckoned axle starts at the origin, heading along the first second of GPS.
    chord = np.array([np.interp(t[0] + 1, car_park.gps.t, g) - np.interp(t[0], car_park.gps.t, g)
                      for g in (car_park.gps.east, car_park.gps.north)])
    np.testing.assert_allclose(turn.axle[0, 1:], [0, 0, np.arctan2(chord[1], chord[0])], atol=1e-12)
    # A right turn at (nearly) full lock: the heading falls by ~200 degrees.
    assert -210 < np.degrees(np.unwrap(turn.axle[:, 3])[-1] - turn.axle[0, 3]) < -190


def test_zero_offset_puts_the_laser_on_the_axle(turn):
    p = ch02.offset_paths(turn, 0.0, 0.0)
    np.testing.assert_allclose(p["laser"], p["axle"], atol=1e-12)
    # Independent RMS: axle positions at the GPS times, anchored at the first fix and rotated
    # about it by a brute-force best angle (scipy), against GPS.
    d = turn.axle_at_gps[:, :2] - turn.axle[0, 1:3]
    g = turn.gps_xy - turn.anchor

    def rms(theta):
        c, s = np.cos(theta), np.sin(theta)
        return np.sqrt(np.mean(np.sum((d @ np.array([[c, s], [-s, c]]) - g) ** 2, axis=1)))

    ref = minimize_scalar(rms, bounds=(-1.5, 1.5), method="bounded", options={"xatol": 1e-10})
    s = ch02.offset_summary(turn, 0.0, 0.0)
    assert s["rms"] == pytest.approx(ref.fun, abs=1e-8)
    assert np.radians(s["heading_correction_deg"]) == pytest.approx(ref.x, abs=1e-6)
    assert s["rms"] > 2.0          # ignoring the offset costs metres on this turn


def test_laser_path_is_the_lever_arm_from_the_axle(turn):
    a, b = 3.78, 0.5
    p = ch02.offset_paths(turn, a, b)
    heading = turn.axle[:, 3] + p["heading_correction"]
    arm = np.column_stack([a * np.cos(heading) - b * np.sin(heading),
                           a * np.sin(heading) + b * np.cos(heading)])
    np.testing.assert_allclose(p["laser"] - p["axle"], arm, atol=1e-9)
    np.testing.assert_allclose(p["laser"][0], turn.anchor, atol=1e-12)
    np.testing.assert_allclose(p["error"], np.hypot(*(p["laser_at_gps"] - turn.gps_xy).T), atol=0)
    s = ch02.offset_summary(turn, a, b)
    assert s["rms"] == pytest.approx(np.sqrt(np.mean(p["error"] ** 2)), abs=1e-12)
    assert s["max"] == pytest.approx(p["error"].max(), abs=1e-12)
    # Without alignment nothing is rotated.
    assert ch02.offset_paths(turn, a, b, align=False)["heading_correction"] == 0.0


@pytest.mark.parametrize("align", [True, False])
def test_best_offset_matches_a_generic_optimiser(turn, align):
    best = ch02.best_offset(turn, align=align)
    ref = minimize(lambda ab: ch02.offset_summary(turn, *ab, align=align)["rms"], x0=[3.0, 0.0],
                   method="Nelder-Mead", options={"xatol": 1e-7, "fatol": 1e-12, "maxiter": 2000})
    np.testing.assert_allclose(best, ref.x, atol=1e-4)
    rms_best = ch02.offset_summary(turn, *best, align=align)["rms"]
    for da, db in [(0.01, 0), (-0.01, 0), (0, 0.01), (0, -0.01)]:
        assert ch02.offset_summary(turn, best[0] + da, best[1] + db, align=align)["rms"] > rms_best


def test_best_offset_finds_a_known_offset_on_the_simulator():
    # Perfect sensors, made-up offset. b comes back exactly; a comes back long by the
    # Euler step's half-step lag, v dt / 2 (2 m/s x 12.5 ms = 2.5 cm).
    made_up = Vehicle(L=2.83, H=0.76, a=2.5, b=-0.3)
    sim = simulate.simulate(seed=1, laps=1, raw_laser=False, vehicle=made_up,
                            sigma_speed=0.0, sigma_steer=0.0, sigma_gps=0.0)
    a, b = ch02.best_offset(ch02.car_park_stretch(sim, 7.0, 22.0))
    assert b == pytest.approx(-0.3, abs=0.002)
    assert a - 2.5 == pytest.approx(sim.info["config"].speed * 0.025 / 2, abs=0.003)


def test_real_turn_prefers_an_offset_near_the_acfr_values(turn):
    a, b = ch02.best_offset(turn)
    assert abs(a - ACFR_UTE.a) < 0.2 and abs(b - ACFR_UTE.b) < 0.05
    s_acfr = ch02.offset_summary(turn, ACFR_UTE.a, ACFR_UTE.b)["rms"]
    assert s_acfr < 0.15 and ch02.offset_summary(turn, 0.0, 0.0)["rms"] > 20 * s_acfr


def test_gps_delay_trades_against_a(car_park, turn):
    # Re-stamping every fix 50 ms earlier (a GPS latency) lengthens the best a by ~v * 50 ms.
    late = dataclasses.replace(car_park, gps=Gps(car_park.gps.t - 0.05, car_park.gps.east,
                                                 car_park.gps.north))
    shift = ch02.best_offset(ch02.car_park_stretch(late))[0] - ch02.best_offset(turn)[0]
    speed = np.mean(np.hypot(*np.diff(turn.gps_xy, axis=0).T) / np.diff(turn.gps_t))
    assert shift == pytest.approx(speed * 0.05, rel=0.25)


def test_rms_surface_layout(turn):
    a_vals, b_vals = np.array([3.0, 3.78, 4.5]), np.array([0.0, 0.5])
    surf = ch02.rms_surface(turn, a_vals, b_vals)
    assert surf.shape == (2, 3)
    assert surf[1, 1] == pytest.approx(ch02.offset_summary(turn, 3.78, 0.5)["rms"], abs=1e-15)
    assert surf[0, 2] == pytest.approx(ch02.offset_summary(turn, 4.5, 0.0)["rms"], abs=1e-15)


def test_explorer_follows_the_sliders(car_park, turn):
    w = ch02.offset_explorer(car_park)
    a_slider, b_slider, align_box = w.children[:3]
    s0 = w.holder["summary"]
    assert (s0["a"], s0["b"]) == (ACFR_UTE.a, ACFR_UTE.b)
    assert s0 == ch02.offset_summary(turn, ACFR_UTE.a, ACFR_UTE.b)
    plt.close("all")
    a_slider.value = 0.0
    b_slider.value = 0.0
    # The callback draws outside pyplot (plotting.widget_figure): nothing is left open for a
    # kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []
    s = w.holder["summary"]
    assert (s["a"], s["b"]) == (0.0, 0.0) and s["lever_arm"] == 0.0
    np.testing.assert_allclose(w.holder["paths"]["laser"], w.holder["paths"]["axle"], atol=1e-12)
    assert s["rms"] > 20 * s0["rms"]
    align_box.value = False
    assert w.holder["summary"] == ch02.offset_summary(turn, 0.0, 0.0, align=False)
    assert w.holder["summary"]["heading_correction_deg"] == 0.0
    # Each redraw fits a heading and redraws the map: no redraw while a slider is dragged.
    assert not a_slider.continuous_update and not b_slider.continuous_update
    plt.close("all")


def test_plots_draw_what_they_say(turn):
    s = ch02.plot_offset_stretch(turn, 3.78, 0.5)
    ax_map = plt.gcf().axes[0]
    laser_line = ax_map.lines[1]
    np.testing.assert_allclose(laser_line.get_xydata(), ch02.offset_paths(turn, 3.78, 0.5)["laser"])
    assert s == ch02.offset_summary(turn, 3.78, 0.5)
    plt.close("all")
    ax = ch02.plot_offset_geometry(ACFR_UTE, phi=0.3)
    laser_mark = [ln for ln in ax.lines if ln.get_label().startswith("laser")][0]
    c, sn = np.cos(0.3), np.sin(0.3)
    np.testing.assert_allclose(laser_mark.get_xydata()[0],
                               [3.78 * c - 0.5 * sn, 3.78 * sn + 0.5 * c], atol=1e-12)
    plt.close("all")


def test_bad_input_is_rejected(car_park, turn):
    with pytest.raises(ValueError, match="outside the odometry"):
        ch02.car_park_stretch(car_park, 120.0, 200.0)
    with pytest.raises(ValueError, match="longer than"):
        ch02.car_park_stretch(car_park, 10.0, 11.0)
    with pytest.raises(ValueError, match="moves less than 0.2 m"):
        ch02.car_park_stretch(car_park, 40.0, 55.0)       # the car stands still from ~30 s to ~57 s
    with pytest.raises(ValueError, match="offset a must be finite"):
        ch02.offset_paths(turn, np.nan, 0.5)
    with pytest.raises(ValueError, match="offset b must be finite"):
        ch02.offset_summary(turn, 3.78, np.inf)


def test_kept_layout_stays_clear_at_the_controls_ends(car_park):
    # The explorer blits (plots.blit.Blit): every step at the controls' ends is measured and
    # equals the same state drawn from scratch (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch02.offset_explorer(car_park))


def test_a_small_step_reuses_the_view_and_a_far_offset_draws_anew(car_park):
    w = ch02.offset_explorer(car_park)
    a_slider = w.children[0]
    first = w.views[0]
    top = first.fig.axes[1].get_ylim()[1]
    assert top == pytest.approx(1.5 * np.max(w.holder["paths"]["error"]))
    a_slider.value = a_slider.value + 0.01
    assert w.views[0] is first                        # blitted over the kept picture
    a_slider.value = a_slider.min                     # the path 4.8 m off: out of the range
    err = np.max(w.holder["paths"]["error"])
    assert err > top and w.views[0] is not first
    assert w.views[0].fig.axes[1].get_ylim()[1] == pytest.approx(1.5 * err)
