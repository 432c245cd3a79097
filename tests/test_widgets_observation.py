"""Chapter 03 explorer (annslam_lib.widgets.observation), headless: the pure function's
S = H P H^T + R against an independent Monte Carlo, and the sliders."""
import math

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from annslam_lib.chapters import ch03_observation as ch03
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures  # noqa: F401

  # noqa: E402


def reference_measurements(pose, landmark, P, R, n, seed):
    """Independent Monte Carlo: sample (pose, landmark) and the laser noise with NumPy,
    range and laser bearing by complex numbers (no library code)."""
    rng = np.random.default_rng(seed)
    x = np.r_[pose, landmark] + rng.standard_normal((n, 5)) * np.sqrt(np.diag(P))
    d = (x[:, 3] - x[:, 0]) + 1j * (x[:, 4] - x[:, 1])
    z = np.c_[np.abs(d), np.angle(d * np.exp(-1j * x[:, 2]) * 1j)]
    return z + rng.standard_normal((n, 2)) * np.sqrt(np.diag(R))


@pytest.mark.parametrize("landmark", [(10.0, 3.0), (-4.0, 6.0), (25.0, -12.0)])
def test_S_matches_independent_monte_carlo_at_small_sigma(landmark):
    s = ch03.measurement_prediction(*landmark, sigma_xy=0.05, sigma_phi=math.radians(1.0),
                                    sigma_landmark=0.05)
    d = complex(*landmark)
    assert s["range"] == pytest.approx(abs(d), rel=1e-12)
    assert s["bearing"] == pytest.approx(np.angle(d * 1j), abs=1e-12)
    z = reference_measurements(ch03.POSE, landmark, s["P"], s["R"], 200_000, seed=11)
    e = z - s["z"]
    e[:, 1] = np.angle(np.exp(1j * e[:, 1]))
    C = np.cov(e, rowvar=False)
    sd = np.sqrt(np.diag(s["S"]))
    # variances within 2 % (sampling error ~0.3 %), correlation coefficient within 0.01
    np.testing.assert_allclose(np.diag(C), np.diag(s["S"]), rtol=0.02)
    assert C[0, 1] / (sd[0] * sd[1]) == pytest.approx(s["correlation"], abs=0.01)
    assert abs(e.mean(axis=0)[0]) < 0.02 * sd[0] + 1e-3


def test_heading_enters_the_bearing_linearly():
    """With only heading and laser noise, S is exactly diag(sr^2, sphi^2 + sb^2)."""
    s = ch03.measurement_prediction(8.0, -2.0, sigma_xy=0.0, sigma_phi=0.3, sigma_range=0.1,
                                    sigma_bearing=0.02)
    np.testing.assert_allclose(s["S"], np.diag([0.1**2, 0.3**2 + 0.02**2]), atol=1e-15)


def test_position_sigma_shrinks_in_bearing_with_range():
    """Position noise sigma perpendicular to the line of sight moves the bearing by
    sigma / r: the bearing variance from position alone is sigma^2 / r^2."""
    for r in (2.0, 10.0, 40.0):
        s = ch03.measurement_prediction(r, 0.0, sigma_xy=0.4, sigma_phi=0.0, sigma_range=0.0,
                                        sigma_bearing=0.0)
        np.testing.assert_allclose(s["S"], np.diag([0.4**2, 0.4**2 / r**2]), rtol=1e-12,
                                   atol=1e-15)


def test_bad_input_is_rejected():
    with pytest.raises(ValueError, match="sigma_xy"):
        ch03.measurement_prediction(5.0, 0.0, sigma_xy=-0.1, sigma_phi=0.1)
    with pytest.raises(ValueError, match="sigma_phi"):
        ch03.measurement_prediction(5.0, 0.0, sigma_xy=0.1, sigma_phi=float("nan"))
    with pytest.raises(ValueError, match="bearing undefined"):
        ch03.measurement_prediction(0.0, 0.0, sigma_xy=0.1, sigma_phi=0.1)


def sliders(w):
    return {c.description: c for c in w.children if hasattr(c, "continuous_update")}


def test_explorer_summary_follows_the_sliders():
    w = ch03.measurement_explorer(landmark=(10.0, 0.0), sigma_xy=0.3, sigma_phi_deg=2.0,
                                  n_samples=4000)
    s0 = w.holder["summary"]
    assert s0["range"] == pytest.approx(10.0) and s0["bearing"] == pytest.approx(np.pi / 2)
    # small sigmas: the Monte-Carlo cloud fills the 2-sigma ellipse like a Gaussian
    assert s0["mc_coverage"] == pytest.approx(0.8647, abs=0.025)
    np.testing.assert_allclose(s0["mc_sd_ratio"], 1.0, atol=0.05)
    sl = sliders(w)

    plt.close("all")
    sl["landmark x"].value = 30.0          # farther: range grows, bearing spread shrinks
    s1 = w.holder["summary"]
    # The callback draws outside pyplot (plotting.widget_figure): nothing is left open for a
    # kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []
    assert s1["range"] == pytest.approx(30.0)
    assert s1["sigma_bearing"] < s0["sigma_bearing"]
    assert s1["sigma_range"] == pytest.approx(s0["sigma_range"], rel=1e-12)

    sl["σ heading°"].value = 10.0           # the heading adds exactly to the bearing variance
    s2 = w.holder["summary"]
    assert s2["sigma_bearing"]**2 - s1["sigma_bearing"]**2 == pytest.approx(
        math.radians(10.0)**2 - math.radians(2.0)**2, rel=1e-9)

    sl["landmark x"].value = 20.0
    sl["landmark y"].value = 20.0           # 45 degrees to the left: bearing 135 degrees
    assert w.holder["summary"]["bearing"] == pytest.approx(math.radians(135.0))

    sl["landmark x"].value = 0.0
    sl["landmark y"].value = 0.0            # on the sensor: a message, not a crash
    assert "bearing undefined" in w.holder["summary"]["error"]


def test_explorer_shows_the_linearisation_failing_close_to_a_vague_pose():
    """Landmark 0.5 m away, position sigma 0.5 m: the true bearing spread is far wider
    and the range spread narrower than the Jacobian predicts (a Rice-like range)."""
    w = ch03.measurement_explorer(landmark=(0.5, 0.0), sigma_xy=0.5, sigma_phi_deg=0.0,
                                  n_samples=4000)
    ratio = w.holder["summary"]["mc_sd_ratio"]
    assert ratio[0] < 0.85 and ratio[1] > 1.05


def test_sliders_wait_for_release():
    """Each move redraws a Monte-Carlo cloud: no update while a slider is dragged."""
    w = ch03.measurement_explorer(n_samples=500)
    assert len(sliders(w)) == 5
    assert all(s.continuous_update is False for s in sliders(w).values())


def test_landmark_sigma_slider_adds_its_variance_through_H_m():
    """The range row of H_m is the unit line-of-sight vector and the bearing row has norm
    1/r, so an isotropic landmark sigma adds sigma^2 to the range variance and
    sigma^2 / r^2 to the bearing variance, and nothing to their covariance."""
    w = ch03.measurement_explorer(landmark=(6.0, 8.0), sigma_xy=0.2, sigma_phi_deg=3.0,
                                  n_samples=500)
    s0 = w.holder["summary"]
    sliders(w)["σ landmark"].value = 0.5
    s1 = w.holder["summary"]
    assert s1["range"] == pytest.approx(10.0)
    dS = s1["S"] - s0["S"]
    np.testing.assert_allclose(dS, np.diag([0.25, 0.25 / 100.0]), atol=1e-12)


def test_kept_layout_stays_clear_at_the_controls_ends():
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch03.measurement_explorer(landmark=(10.0, 3.0), sigma_xy=0.3, sigma_phi_deg=5.0))


def test_explorer_keeps_its_view_while_the_cloud_stays_in_it():
    """The figure blits (plots.blit): a landmark step of 0.5 m keeps measurement space's view;
    a move the cloud leaves it for gets a new view, and every drawn point lies inside the view
    it is drawn in."""
    w = ch03.measurement_explorer(landmark=(10.0, 3.0), sigma_xy=0.3, sigma_phi_deg=5.0,
                                  n_samples=500)
    sl = sliders(w)
    view = w.views[0]
    seen = [view]
    for x, y in ((10.5, 3.0), (11.0, 3.0), (11.0, 15.0), (2.0, -1.0), (35.0, 0.0)):
        sl["landmark x"].value, sl["landmark y"].value = x, y
        v = w.views[0]
        (bx0, bx1), (ry0, ry1) = v.fig.axes[1].get_xlim(), v.fig.axes[1].get_ylim()
        assert (bx0, bx1) == pytest.approx(v.limits[0]) and (ry0, ry1) == pytest.approx(v.limits[1])
        for line in v.fig.axes[1].lines:
            pts = line.get_xydata()
            assert np.all((pts[:, 0] >= bx0) & (pts[:, 0] <= bx1) & (pts[:, 1] >= ry0)
                          & (pts[:, 1] <= ry1)), (x, y)
        if not any(v is s for s in seen):
            seen.append(v)
        if (x, y) == (11.0, 3.0):
            assert seen == [view]              # two 0.5 m steps: the same blitted figure
    assert len(seen) >= 3                       # 15 m to the left, then close, then far: new views
