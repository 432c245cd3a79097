"""Chapter 01 explorer (annslam_lib.widgets.kinematics), driven headless."""
import math

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pytest

from annslam_lib.models.vehicle import ACFR_UTE, Vehicle
from annslam_lib.chapters import ch01_kinematics as ch01
from layout_support import assert_kept_layouts_clear  # noqa: E402


matplotlib.use("Agg")


@pytest.fixture
def explorer():
    w = ch01.kinematics_explorer(speed=2.0, steering=0.3, dt=0.2)
    yield w
    plt.close("all")


def slider(widget, name):
    return next(c for c in widget.children if getattr(c, "description", "").startswith(name))


def test_moving_the_steering_slider_changes_the_radius(explorer):
    """The radius is MEASURED on the drawn exact arc (circle through three of its points),
    so it checks R = L / tan(alpha) for the rear axle and, for the laser, the distance
    from the instantaneous centre (0, R) to the laser at (a, b): sqrt(a^2 + (R - b)^2)."""
    a, b, L = ACFR_UTE.a, ACFR_UTE.b, ACFR_UTE.L
    plt.close("all")
    for alpha in (0.3, 0.5, -0.2, 0.05, -0.55):
        slider(explorer, "steer").value = alpha
        s = explorer.holder["summary"]
        R = L / math.tan(alpha)
        assert s["radius_axle"] == pytest.approx(abs(R), abs=1e-9)
        assert s["radius_laser"] == pytest.approx(math.hypot(a, R - b), abs=1e-9)
        assert s["radius_formula"] == pytest.approx(abs(R), abs=1e-12)
    # The callback draws outside pyplot (plotting.widget_figure): nothing is left open for a
    # kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []


def test_straight_ahead_has_no_radius_and_no_euler_error(explorer):
    slider(explorer, "steer").value = 0.0
    s = explorer.holder["summary"]
    assert math.isinf(s["radius_axle"]) and math.isinf(s["radius_laser"])
    assert s["error_laser"] < 1e-12 and s["error_axle"] < 1e-12


def test_euler_error_is_first_order_in_dt(explorer):
    """Over a fixed horizon the Euler end-point error halves with dt (global error O(dt))."""
    slider(explorer, "steer").value = 0.4
    errs = []
    for dt in (0.4, 0.2, 0.1, 0.05):
        slider(explorer, "dt").value = dt
        s = explorer.holder["summary"]
        assert s["steps"] == round(4.0 / dt) and s["horizon"] == pytest.approx(4.0)
        errs.append(s["error_laser"])
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all((ratios > 1.8) & (ratios < 2.2))


def test_speed_slider_scales_the_path(explorer):
    """Same steering, double speed: the same circle, twice the arc, so the heading turned
    at the end doubles (v tan(alpha) / L times the horizon)."""
    slider(explorer, "steer").value = 0.25
    slider(explorer, "speed").value = 1.0
    one = explorer.holder["summary"]["exact_axle"][-1, 2]
    slider(explorer, "speed").value = 2.0
    two = explorer.holder["summary"]["exact_axle"][-1, 2]
    assert one == pytest.approx(1.0 * math.tan(0.25) / ACFR_UTE.L * 4.0, abs=1e-12)
    assert two == pytest.approx(2 * one, abs=1e-12)


def test_arc_vs_euler_rear_axle_is_the_2_2_model():
    s = ch01.arc_vs_euler(1.5, -0.3, 0.1, Vehicle(), horizon=1.0)
    eu = s["euler_axle"]
    w = 1.5 * math.tan(-0.3) / ACFR_UTE.L
    expect = [0.0, 0.0, 0.0]
    for _ in range(s["steps"]):
        expect = [expect[0] + 0.1 * 1.5 * math.cos(expect[2]),
                  expect[1] + 0.1 * 1.5 * math.sin(expect[2]), expect[2] + 0.1 * w]
    np.testing.assert_allclose(eu[-1], expect, atol=1e-12)


def test_circumradius_and_bad_input():
    assert ch01.circumradius([1, 0], [0, 1], [-1, 0]) == pytest.approx(1.0, abs=1e-15)
    assert math.isinf(ch01.circumradius([0, 0], [1, 1], [2, 2]))
    for kwargs in (dict(dt=0.0), dict(dt=float("nan")), dict(horizon=-1.0), dict(dt=1e-6)):
        args = dict(speed=1.0, steering=0.1, dt=0.1) | kwargs
        with pytest.raises(ValueError):
            ch01.arc_vs_euler(**args)


def test_sliders_redraw_only_on_release(explorer):
    """Each redraw chains hundreds of predict steps: no redraw while a slider is dragged."""
    sliders = [c for c in explorer.children if hasattr(c, "continuous_update")]
    assert {s.description.split()[0] for s in sliders} == {"speed", "steer", "dt"}
    assert not any(s.continuous_update for s in sliders)


def test_kinematics_explorer_prints_the_readout_of_its_summary(capsys):
    from annslam_lib.chapters import ch01_kinematics as ch01
    from annslam_lib.models.vehicle import ACFR_UTE as V
    w = ch01.kinematics_explorer(V, speed=2.0, steering=0.3, dt=0.2)
    s = w.holder["summary"]
    line = w.holder["text"]
    assert line == ch01.kinematics_readout(s) and line in capsys.readouterr().out
    # the numbers it shows, against the summary's own
    assert f"{s['steps']} Euler steps of 0.200 s" in line
    assert f"rear-axle radius {s['radius_axle']:.2f} m" in line
    assert f"laser {100 * s['error_laser']:.1f} cm" in line
    w.children[1].value = 0.0                          # straight ahead
    assert "straight ahead" in w.holder["text"] and "rear axle 0.0 cm" in w.holder["text"]


def test_kept_layout_stays_clear_at_the_controls_ends():
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch01.kinematics_explorer(speed=2.0, steering=0.3, dt=0.2))


def test_small_steps_reuse_the_view_and_the_paths_always_lie_inside_it():
    # The explorer blits (plots.blit.Blit) in a view around the paths with room to grow: a
    # speed step of 0.1 m/s keeps it; a path outside it, or shrunk to under half of it, gets
    # a new one; every path drawn lies inside the view it is drawn in.
    w = ch01.kinematics_explorer(speed=2.0, steering=0.3, dt=0.2)
    speed = w.children[0]
    first = w.views[0]
    speed.value = 2.1
    assert w.views[0] is first
    for v in (5.0, 0.5, 0.0, 3.0):
        speed.value = v
        (x0, x1), (y0, y1) = w.views[0].limits
        ax = w.views[0].fig.axes[0]
        assert ax.get_xlim() == (x0, x1) and ax.get_ylim() == (y0, y1)
        for line in ax.lines:
            xy = line.get_xydata()
            if len(xy):
                assert (xy[:, 0] >= x0).all() and (xy[:, 0] <= x1).all()
                assert (xy[:, 1] >= y0).all() and (xy[:, 1] <= y1).all()
    speed.value = 5.0
    big = w.views[0]
    speed.value = 1.0                                 # a fifth of the path: a closer view
    assert w.views[0] is not big
