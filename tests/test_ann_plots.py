"""Tests of annslam_lib.ann_plots: the paper's Figures 6-8 show exactly ann's numbers."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from annslam_lib import ann
from annslam_lib.models.observation import inverse_observe
from annslam_lib.plots import ann as ann_plots
from widget_support import close_figures  # noqa: F401


def _synthetic_set(n_scans: int = 120, bias: float = 0.3, seed: int = 7) -> ann.TrainingSet:
    """Two detections per scan of 10 beacons, each measured 'bias' m too far: a learnable
    correction, built without running a filter (fast)."""
    rng = np.random.default_rng(seed)
    beacons = rng.uniform(-20, 20, (10, 2))
    rows = []
    for k in range(n_scans):
        pose = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)])
        for b in rng.choice(10, 2, replace=False):
            d = beacons[b] - pose[:2]
            r = np.hypot(*d) + bias + rng.normal(0, 0.05)
            brg = np.arctan2(d[1], d[0]) - pose[2] + np.pi / 2 + rng.normal(0, 0.005)
            rows.append((k, b, pose, r, brg))
    scan = np.array([r[0] for r in rows])
    beacon = np.array([r[1] for r in rows])
    pose = np.array([r[2] for r in rows])
    z = np.array([[r[3], r[4]] for r in rows])
    X, base = ann.encode(pose, z)
    np.testing.assert_allclose(base, inverse_observe(pose, z)[0])
    target = beacons[beacon]
    return ann.TrainingSet(X=X, Y=target - base, base=base, target=target, beacon=beacon,
                           t=0.2 * scan, scan=scan, pose=pose, z=z)


@pytest.fixture(scope="module")
def fitted():
    ts = _synthetic_set()
    sp = ann.chronological_split(ts)
    model = ann.train(ts, sp, ann.TrainConfig(hidden=(5,), seed=1, max_epochs=60))
    return ts, sp, model


def _by_gid(ax, gid, kind="lines"):
    return [a for a in getattr(ax, kind) if a.get_gid() == gid]


# --------------------------------------------------------------------------- Figure 7

def test_performance_lines_are_the_history(fitted):
    _, _, model = fitted
    fig = ann_plots.plot_performance(model)
    ax = fig.axes[0]
    h = model.history
    for p in ann.SPLITS:
        (line,) = _by_gid(ax, f"mse_{p}")
        np.testing.assert_array_equal(line.get_xdata(), h["epoch"])
        np.testing.assert_array_equal(line.get_ydata(), h[p])
    (vline,) = _by_gid(ax, "best_epoch")
    np.testing.assert_array_equal(vline.get_xdata(), [model.best_epoch] * 2)
    (pt,) = _by_gid(ax, "best_point")
    assert pt.get_xdata()[0] == model.best_epoch
    assert pt.get_ydata()[0] == h["val"].min() == h["val"][model.best_epoch]
    assert ax.get_yscale() == "log"
    assert ax.get_title() == (f"Best Validation Performance is {h['val'].min():.4g} "
                              f"at epoch {model.best_epoch}")


def test_performance_without_test_part_and_on_given_axes(fitted):
    ts, sp, _ = fitted
    sp2 = ann.Split(sp.train, sp.val, [], name="no test")
    model = ann.train(ts, sp2, ann.TrainConfig(hidden=(3,), seed=0, max_epochs=10))
    fig0, ax = plt.subplots()
    fig = ann_plots.plot_performance(model, ax=ax)
    assert fig is fig0
    assert _by_gid(ax, "mse_test") == [] and len(_by_gid(ax, "mse_train")) == 1


def test_performance_bad_input(fitted):
    _, _, model = fitted
    with pytest.raises(TypeError, match="history"):
        ann_plots.plot_performance(object())

    class Fake:
        history = model.history
        best_epoch = model.history["train"].size        # one past the last epoch
    with pytest.raises(ValueError, match="best_epoch"):
        ann_plots.plot_performance(Fake())


# --------------------------------------------------------------------------- Figure 6

@pytest.mark.parametrize("bins", [20, 7])
def test_histogram_bars_count_every_error(fitted, bins):
    ts, sp, model = fitted
    h = ann.error_histogram(model, ts, sp, bins=bins)
    for fig in (ann_plots.plot_error_histogram(h),
                ann_plots.plot_error_histogram(model, ts, sp, bins=bins)):
        ax = fig.axes[0]
        bottom = np.zeros(bins)
        for p in ann.SPLITS:
            bars = _by_gid(ax, f"bars_{p}", "patches")
            assert len(bars) == bins
            heights = np.array([b.get_height() for b in bars])
            # 2 errors (x, y) per sample, none lost; the bars are exactly ann's counts
            assert heights.sum() == 2 * sp.part(p).size
            np.testing.assert_array_equal(heights, h["counts"][p])
            # stacked: each part starts where the previous ended; bins at ann's edges
            np.testing.assert_array_equal([b.get_y() for b in bars], bottom)
            np.testing.assert_allclose([b.get_x() for b in bars], h["edges"][:-1])
            np.testing.assert_allclose([b.get_width() for b in bars], np.diff(h["edges"]))
            bottom = bottom + heights
        (zero,) = _by_gid(ax, "zero_error")
        np.testing.assert_array_equal(zero.get_xdata(), [0, 0])
        assert ax.get_title() == f"Error Histogram with {bins} Bins"


def test_a_span_bins_the_central_errors_and_counts_the_rest_in_the_end_bins(fitted):
    ts, sp, model = fitted
    full = ann.error_histogram(model, ts, sp, bins=20)
    h = ann.error_histogram(model, ts, sp, bins=20, span=0.9)
    err = np.concatenate([h["errors"][p] for p in ann.SPLITS])
    lo, hi = np.quantile(err, [0.05, 0.95])
    np.testing.assert_allclose(h["edges"][[0, -1]], [lo, hi])
    assert np.ptp(h["edges"]) < np.ptp(full["edges"])            # narrower bins
    for p in ann.SPLITS:
        e = h["errors"][p]
        assert h["counts"][p].sum() == e.size                      # every error counted once
        assert h["beyond"][p] == np.count_nonzero((e < lo) | (e > hi))
        assert h["counts"][p][0] == np.count_nonzero(e < h["edges"][1])
        assert full["beyond"][p] == 0
    beyond = sum(h["beyond"].values())
    assert 0.05 * err.size < beyond < 0.15 * err.size              # about 10 % outside
    ax = ann_plots.plot_error_histogram(model, ts, sp, bins=20, span=0.9).axes[0]
    assert ax.get_title() == f"Error Histogram with 20 Bins ({beyond} errors beyond them " \
        "counted in the end bins)"
    for bad in (0.0, 1.0, 1.5, "0.9", True):
        with pytest.raises(ValueError, match="span must be"):
            ann.error_histogram(model, ts, sp, span=bad)


def test_histogram_of_the_inverse_model_is_centred_on_the_bias(fitted):
    # The plain inverse model measures every beacon 0.3 m too far: its errors are NOT
    # centred on zero, while the trained network's are (the correction was learned).
    ts, sp, model = fitted
    inv = ann.InverseModel(0.05, 0.005)
    mean_abs = {}
    for name, m in (("inverse", inv), ("ann", model)):
        ax = ann_plots.plot_error_histogram(m, ts, sp).axes[0]
        h = ann.error_histogram(m, ts, sp)
        bars = [b for p in ann.SPLITS for b in _by_gid(ax, f"bars_{p}", "patches")]
        x = np.array([b.get_x() + b.get_width() / 2 for b in bars])
        w = np.array([b.get_height() for b in bars])
        assert w.sum() == 2 * len(ts)
        err = np.concatenate(list(h["errors"].values()))
        mean_abs[name] = np.mean(np.abs(err))
        assert abs(np.average(np.abs(x), weights=w) - mean_abs[name]) < np.diff(h["edges"])[0]
    assert mean_abs["ann"] < 0.6 * mean_abs["inverse"]


def test_histogram_bad_input(fitted):
    ts, sp, model = fitted
    with pytest.raises(ValueError, match="TrainingSet and the Split"):
        ann_plots.plot_error_histogram(model)
    with pytest.raises(ValueError, match="source"):
        ann_plots.plot_error_histogram([1, 2, 3])
    with pytest.raises(ValueError, match="lacks"):
        ann_plots.plot_error_histogram({"edges": np.arange(3)})
    h = ann.error_histogram(model, ts, sp)
    with pytest.raises(ValueError, match="bins"):
        ann_plots.plot_error_histogram(dict(h, counts={p: c[:-1] for p, c in h["counts"].items()}))
    with pytest.raises(ValueError, match="bins"):
        ann_plots.plot_error_histogram(model, ts, sp, bins=0)


# --------------------------------------------------------------------------- Figure 8

@pytest.mark.parametrize("kind", ["position", "correction"])
def test_regression_panels_show_anns_fit(fitted, kind):
    ts, sp, model = fitted
    reg = ann.regression(model, ts, sp, kind=kind)
    fig = ann_plots.plot_regression(model, ts, sp, kind=kind)
    assert len(fig.axes) == 4
    for ax, p in zip(fig.axes, ("train", "val", "test", "all")):
        (data,) = _by_gid(ax, "data")
        np.testing.assert_array_equal(data.get_xdata(), reg[p]["targets"])
        np.testing.assert_array_equal(data.get_ydata(), reg[p]["outputs"])
        (fit,) = _by_gid(ax, "fit")
        x, y = fit.get_xdata(), fit.get_ydata()
        slope = (y[1] - y[0]) / (x[1] - x[0])
        np.testing.assert_allclose(slope, reg[p]["slope"], rtol=1e-9)
        np.testing.assert_allclose(y[0] - slope * x[0], reg[p]["intercept"], atol=1e-9)
        (ident,) = _by_gid(ax, "identity")
        np.testing.assert_array_equal(ident.get_xdata(), ident.get_ydata())
        assert ax.get_title() == f"{ann_plots.PART_LABELS[p]}: R={reg[p]['r']:.5g}"
    # On positions spanning tens of metres R ~ 1; the correction is the informative one.
    if kind == "position":
        assert reg["all"]["r"] > 0.999
    else:
        assert 0.5 < reg["test"]["r"] < 0.999


def test_regression_from_dict_on_given_axes_and_empty_part(fitted):
    ts, sp, model = fitted
    sp2 = ann.Split(sp.train, sp.val, [], name="no test")
    reg = ann.regression(model, ts, sp2, kind="correction")
    fig0, axes = plt.subplots(1, 4)
    fig = ann_plots.plot_regression(reg, axes=axes)
    assert fig is fig0
    assert axes[2].get_title() == "Test: no samples" and _by_gid(axes[2], "fit") == []
    assert len(_by_gid(axes[3], "data")[0].get_xdata()) == 2 * (sp.train.size + sp.val.size)


def test_regression_bad_input(fitted):
    ts, sp, model = fitted
    with pytest.raises(ValueError, match="kind"):
        ann_plots.plot_regression(model, ts, sp, kind="positions")
    with pytest.raises(ValueError, match="TrainingSet and the Split"):
        ann_plots.plot_regression(model, ts)
    with pytest.raises(ValueError, match="'all'"):
        ann_plots.plot_regression({"train": {}})
    _, axes = plt.subplots(1, 3)
    with pytest.raises(ValueError, match="four axes"):
        ann_plots.plot_regression(model, ts, sp, axes=axes)


# --------------------------------------------------------------------------- course figures

def test_activations_sign_is_flat_tanh_is_not():
    fig = ann_plots.plot_activations()
    a0, a1 = fig.axes
    (sign,) = _by_gid(a0, "sign")
    s = sign.get_xdata()
    assert set(np.unique(sign.get_ydata())) <= {-1.0, 0.0, 1.0}       # a sign unit outputs +-1
    (tanh,) = _by_gid(a0, "tanh")
    np.testing.assert_allclose(tanh.get_ydata(), np.tanh(s))
    # The plotted derivatives agree with finite differences of the plotted values
    # (away from the jump of sign at 0).
    (dsign,), (dtanh,) = _by_gid(a1, "dsign"), _by_gid(a1, "dtanh")
    away = np.abs(s[1:-1]) > 0.05
    fd_sign = (sign.get_ydata()[2:] - sign.get_ydata()[:-2]) / (s[2:] - s[:-2])
    fd_tanh = (tanh.get_ydata()[2:] - tanh.get_ydata()[:-2]) / (s[2:] - s[:-2])
    np.testing.assert_array_equal(fd_sign[away], dsign.get_ydata()[1:-1][away])
    np.testing.assert_allclose(fd_tanh, dtanh.get_ydata()[1:-1], atol=1e-4)
    assert dtanh.get_ydata().min() > 0
    with pytest.raises(ValueError, match="two axes"):
        ann_plots.plot_activations(axes=[plt.gca()])
    with pytest.raises(ValueError, match="s_max"):
        ann_plots.plot_activations(s_max=-1)


def test_rmse_comparison_bars_are_the_means():
    rows = [dict(label="a", base=0.2, ann=[0.21, 0.23, 0.22]), dict(label="b", base=0.12, ann=0.1)]
    ax = ann_plots.plot_rmse_comparison(rows).axes[0]
    base = [p.get_height() for p in _by_gid(ax, "base", "patches")]
    net = [p.get_height() for p in _by_gid(ax, "ann", "patches")]
    np.testing.assert_allclose(base, [0.2, 0.12])
    np.testing.assert_allclose(net, [0.22, 0.1])
    assert [t.get_text() for t in ax.get_xticklabels()] == ["a", "b"]
    (label,) = [t for t in ax.texts if t.get_text() == "0.220"]
    assert label.xy[1] == pytest.approx(0.22 + np.std([0.21, 0.23, 0.22]))   # above the error bar
    with pytest.raises(ValueError, match="empty"):
        ann_plots.plot_rmse_comparison([])
    with pytest.raises(TypeError, match="'label'"):
        ann_plots.plot_rmse_comparison([dict(label="x", base=0.1)])
    with pytest.raises(ValueError, match="finite"):
        ann_plots.plot_rmse_comparison([dict(label="x", base=0.1, ann=[np.nan])])


def test_landmark_errors_plot(fitted):
    ts, sp, model = fitted
    i = sp.test
    pred = model.predict(ts.X[i])
    ax = ann_plots.plot_landmark_errors(ts.base[i], pred, ts.target[i]).axes[0]
    (base,), (net,) = _by_gid(ax, "base"), _by_gid(ax, "predicted")
    np.testing.assert_allclose(base.get_xydata(), ts.base[i] - ts.target[i])
    np.testing.assert_allclose(net.get_xydata(), pred - ts.target[i])
    # The legend's RMSEs are split_rmse's (an independent computation of the same numbers).
    r = ann.split_rmse(model, ts, sp)["test"]
    assert base.get_label().endswith(f"RMSE {r['rmse_base']:.3f} m")
    assert net.get_label().endswith(f"RMSE {r['rmse_ann']:.3f} m")
    (beacon,) = [c for c in ax.collections if c.get_gid() == "beacon"]
    np.testing.assert_array_equal(beacon.get_offsets(), [[0.0, 0.0]])
    # Every point is inside the (square, symmetric) axes.
    lim = ax.get_xlim()[1]
    assert ax.get_xlim() == (-lim, lim) == ax.get_ylim()
    assert np.abs(base.get_xydata()).max() < lim and np.abs(net.get_xydata()).max() < lim
    with pytest.raises(ValueError, match="same shape"):
        ann_plots.plot_landmark_errors(ts.base[i], ts.base[i][:-1], ts.target[i])
    with pytest.raises(ValueError, match="target"):
        ann_plots.plot_landmark_errors(ts.base[i], ts.base[i], ts.target[i, 0])
