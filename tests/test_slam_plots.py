"""SLAM plot helpers (annslam_lib.slam_plots): the chi-square bands against sampled
chi-square averages, the consistency statistics against hand computations, the
correlation matrix, and what the Figure 5 plot and the zooms actually draw."""
import math

import matplotlib

matplotlib.use("Agg")  # headless: set in the test, never exported to notebook kernels

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.stats import chi2  # noqa: E402

  # noqa: E402
from annslam_lib.slam.config import SlamConfig  # noqa: E402
from annslam_lib.data import simulate
from annslam_lib.evaluation import consistency
from annslam_lib.plots import slam as slam_plots
from annslam_lib.plots import style
from annslam_lib.slam import runner


@pytest.fixture(scope="module")
def sim_run():
    ds = simulate.simulate(seed=5, raw_laser=False, laps=1)
    return ds, runner.run(ds, SlamConfig.for_dataset("simulated"), progress=False)


# --------------------------------------------------------------------------- bands

@pytest.mark.parametrize("dof, n", [(3, 50), (2, 1), (1, 200)])
def test_chi2_band_covers_95_percent_of_sampled_averages(dof, n):
    """The band of the average of n chi2(dof) values, checked by sampling such averages:
    2.5 % below, 2.5 % above (20 000 samples: the binomial sd is 0.11 %, the tolerance 0.5 %)."""
    lo, hi = consistency.chi2_band(dof, n)
    rng = np.random.default_rng(dof * 1000 + n)
    avg = rng.chisquare(dof, size=(20_000, n)).mean(axis=1)
    assert np.mean(avg < lo) == pytest.approx(0.025, abs=0.005)
    assert np.mean(avg > hi) == pytest.approx(0.025, abs=0.005)


def test_chi2_band_values_and_broadcasting():
    lo, hi = consistency.chi2_band(3, 50)
    assert (round(lo, 2), round(hi, 2)) == (2.36, 3.72)          # the notebook's band
    lo_a, hi_a = consistency.chi2_band(1, np.array([2.0, 20.0, 2000.0]))
    assert lo_a.shape == (3,) and np.all(np.diff(hi_a - lo_a) < 0)  # narrower with more dof
    np.testing.assert_allclose(lo_a, chi2.ppf(0.025, [2, 20, 2000]) / [2, 20, 2000])
    lo99, hi99 = consistency.chi2_band(3, 50, prob=0.99)
    assert lo99 < lo < hi < hi99


@pytest.mark.parametrize("kwargs, match", [
    (dict(dof=0, n=3), "positive"), (dict(dof=3, n=-1), "positive"),
    (dict(dof=np.nan, n=3), "positive"), (dict(dof=3, n=3, prob=1.0), "probability"),
    (dict(dof=3, n=3, prob=True), "prob"),
])
def test_chi2_band_rejects_bad_input(kwargs, match):
    with pytest.raises(TypeError if kwargs.get("prob") is True else ValueError, match=match):
        consistency.chi2_band(**kwargs)


# --------------------------------------------------------------------------- consistency

def test_nees_consistency_by_hand():
    runs = [np.array([1.0, 3.0, 10.0]), np.array([2.0, 3.0, 4.0])]
    c = consistency.nees_consistency(runs, t=[0.0, 1.0, 2.0], dof=3)
    lo, hi = chi2.ppf([0.025, 0.975], 6) / 2
    np.testing.assert_allclose(c.value, [1.5, 3.0, 7.0])
    assert c.mean == pytest.approx(11.5 / 3)
    assert c.inside == pytest.approx(np.mean((c.value >= lo) & (c.value <= hi)))
    np.testing.assert_allclose([c.lo[0], c.hi[0]], [lo, hi])
    assert c.n_runs == 2 and "3 dof" in c.name and "2 runs" in c.summary()


def test_nis_consistency_by_hand():
    nis = [np.array([4.0, 0.0, 1.0]), np.array([2.0, 0.0, 5.0])]
    dof = [np.array([2.0, 0.0, 2.0]), np.array([4.0, 0.0, 2.0])]
    c = consistency.nis_consistency(nis, dof, t=[10.0, 11.0, 12.0])
    np.testing.assert_allclose(c.t, [10.0, 12.0])                   # scan without updates dropped
    np.testing.assert_allclose(c.value, [6.0 / 6.0, 6.0 / 4.0])
    np.testing.assert_allclose(c.dof, [6.0, 4.0])
    assert c.mean == pytest.approx(12.0 / 10.0)
    np.testing.assert_allclose(c.hi, chi2.ppf(0.975, [6, 4]) / [6, 4])


def test_consistency_rejects_mismatched_runs():
    with pytest.raises(ValueError, match="different lengths"):
        consistency.nees_consistency([np.ones(3), np.ones(4)])
    with pytest.raises(ValueError, match="no runs"):
        consistency.nees_consistency([])
    with pytest.raises(ValueError, match="non-finite"):
        consistency.nees_consistency([np.array([1.0, np.nan])])
    with pytest.raises(ValueError, match="differ in shape"):
        consistency.nis_consistency([np.ones(3)], [np.ones(3), np.ones(3)])
    with pytest.raises(ValueError, match="no scan has an update"):
        consistency.nis_consistency([np.zeros(3)], [np.zeros(3)])
    with pytest.raises(ValueError, match="t must have shape"):
        consistency.nees_consistency([np.ones(3)], t=[0.0, 1.0])


def test_scan_nis_follows_the_result_log(sim_run):
    ds, r = sim_run
    s, d = consistency.scan_nis(r, len(ds.detections))
    laser = r.nis["kind"] == 0
    assert s.sum() == pytest.approx(r.nis["nis"][laser].sum())
    assert d.sum() == r.nis["dof"][laser].sum() == 2 * r.counts["associated"]
    k = int(r.nis["scan"][laser][7])
    assert s[k] == r.nis["nis"][laser][7] and d[k] == r.nis["dof"][laser][7]
    with pytest.raises(ValueError, match="outside"):
        consistency.scan_nis(r, 10)


def test_plot_consistency_draws_the_statistic_and_its_band():
    c = consistency.nees_consistency([np.array([1.0, 3.0, 5.0])] * 4, t=[0.0, 1.0, 2.0])
    ax = slam_plots.plot_consistency(c, expected=3.0)
    (line, expected) = ax.get_lines()
    np.testing.assert_allclose(line.get_ydata(), [1.0, 3.0, 5.0])
    assert expected.get_ydata()[0] == 3.0
    band = ax.collections[0].get_paths()[0].vertices
    assert band[:, 1].min() == pytest.approx(c.lo[0]) and band[:, 1].max() == pytest.approx(c.hi[0])
    plt.close("all")


# --------------------------------------------------------------------------- correlation

def test_correlation_matrix_values_and_errors():
    P = np.array([[4.0, 2.0, 0.0], [2.0, 9.0, -3.0], [0.0, -3.0, 1.0]])
    C = consistency.correlation_matrix(P)
    np.testing.assert_allclose(C, [[1, 2 / 6, 0], [2 / 6, 1, -1], [0, -1, 1]])
    with pytest.raises(ValueError, match="non-positive variance at index 1"):
        consistency.correlation_matrix(np.diag([1.0, 0.0]))
    with pytest.raises(ValueError, match="not symmetric"):
        consistency.correlation_matrix(np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(ValueError, match="square"):
        consistency.correlation_matrix(np.ones((2, 3)))
    with pytest.raises(ValueError, match="NaN"):
        consistency.correlation_matrix(np.array([[1.0, np.nan], [np.nan, 1.0]]))


def test_plot_correlation_image_is_the_correlation_matrix(sim_run):
    _, r = sim_run
    ax = slam_plots.plot_correlation(r.covariance)
    img = ax.get_images()[0]
    np.testing.assert_allclose(img.get_array(), consistency.correlation_matrix(r.covariance))
    assert img.get_clim() == (-1.0, 1.0)
    plt.close("all")


# --------------------------------------------------------------------------- Figure 5

def test_true_vs_mapped_draws_paths_landmarks_and_2_sigma_ellipses(sim_run):
    ds, r = sim_run
    ax = slam_plots.plot_true_vs_mapped(r, ds, n_sigma=2.0, limits=((-30, 30), (-20, 20)))
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    np.testing.assert_array_equal(lines["true path"].get_xydata(), ds.truth.poses[:, 1:3])
    np.testing.assert_array_equal(lines["mapped path"].get_xydata(), r.trajectory[:, 1:3])
    np.testing.assert_array_equal(lines["mapped landmarks"].get_xydata(), r.landmarks)
    np.testing.assert_array_equal(ax.collections[0].get_offsets(), ds.beacons)
    # one closed curve per landmark, every point at Mahalanobis distance 2 from it
    ellipses = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-" and ln.get_color() == style.BLUE]
    assert len(ellipses) == len(r.landmarks)
    for ln, m, P in zip(ellipses, r.landmarks, r.landmark_cov):
        d = ln.get_xydata() - m
        d2 = np.einsum("ki,ij,kj->k", d, np.linalg.inv(P), d)
        np.testing.assert_allclose(d2, 4.0, rtol=1e-9)
    assert ax.get_xlim() == (-30, 30) and ax.get_ylim() == (-20, 20)
    plt.close("all")


def test_true_vs_mapped_ellipse_scale_and_overlay(sim_run):
    ds, r = sim_run
    ax = slam_plots.plot_true_vs_mapped(r, ds, ellipse_scale=10.0, legend=None)
    ax = slam_plots.plot_true_vs_mapped(r, ds, ax=ax, show_truth=False, color=style.GREEN,
                                        label="other", legend="lower left")
    blue = [ln for ln in ax.get_lines() if ln.get_color() == style.BLUE and ln.get_linestyle() == "-"]
    green = [ln for ln in ax.get_lines() if ln.get_color() == style.GREEN and ln.get_linestyle() == "-"]
    # x10 magnified: ten times as far from the centre as the unmagnified overlay
    ratio = (np.linalg.norm(blue[0].get_xydata() - r.landmarks[0], axis=1)
             / np.linalg.norm(green[0].get_xydata() - r.landmarks[0], axis=1))
    np.testing.assert_allclose(ratio, 10.0, rtol=1e-9)
    assert sum(ln.get_label() == "true path" for ln in ax.get_lines()) == 1
    assert "other 2σ ellipses" in [t.get_text() for t in ax.get_legend().get_texts()]
    with pytest.raises(ValueError, match="ellipse_scale"):
        slam_plots.plot_true_vs_mapped(r, ds, ellipse_scale=0)
    plt.close("all")


def test_landmark_zooms_titles_give_error_and_mahalanobis(sim_run):
    ds, r = sim_run
    i = np.arange(len(r.landmarks))
    j = r.landmark_true_id
    axes = slam_plots.plot_landmark_zooms(r.landmarks, r.landmark_cov, ds.beacons, i, j, ncols=4)
    assert axes.size == 16 and not axes[-1].axison          # 15 panels, one switched off
    e = r.landmarks[3] - ds.beacons[j[3]]
    d2 = e @ np.linalg.solve(r.landmark_cov[3], e)
    assert axes[3].get_title() == f"#{j[3]}: {100 * math.hypot(*e):.1f} cm, d² {d2:.1f}"
    x0, x1 = axes[3].get_xlim()
    assert (x0 + x1) / 2 == pytest.approx(ds.beacons[j[3], 0]) and x1 - x0 == pytest.approx(0.5)
    with pytest.raises(ValueError, match="equal-length"):
        slam_plots.plot_landmark_zooms(r.landmarks, r.landmark_cov, ds.beacons, i, j[:3])
    plt.close("all")
