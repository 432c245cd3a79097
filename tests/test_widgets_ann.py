"""Headless tests of the chapter 07 explorer (annslam_lib.widgets.ann)."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from annslam_lib.plots.alt import alt_text
from annslam_lib import ann
from annslam_lib.ann import evaluation
from annslam_lib.chapters import ch07_ann_training as ch07
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures  # noqa: F401



def _synthetic_set(n_scans: int = 90, bias: float = 0.3, seed: int = 3) -> ann.TrainingSet:
    """Two detections per scan of 10 beacons, measured ``bias`` m too far (no filter)."""
    rng = np.random.default_rng(seed)
    beacons = rng.uniform(-15, 15, (10, 2))
    scan = np.repeat(np.arange(n_scans), 2)
    beacon = np.concatenate([rng.choice(10, 2, replace=False) for _ in range(n_scans)])
    pose = np.repeat(np.c_[rng.uniform(-4, 4, (n_scans, 2)), rng.uniform(-3, 3, n_scans)], 2, 0)
    d = beacons[beacon] - pose[:, :2]
    z = np.c_[np.hypot(d[:, 0], d[:, 1]) + bias + rng.normal(0, 0.05, scan.size),
              np.arctan2(d[:, 1], d[:, 0]) - pose[:, 2] + np.pi / 2]
    X, base = ann.encode(pose, z)
    target = beacons[beacon]
    return ann.TrainingSet(X=X, Y=target - base, base=base, target=target, beacon=beacon,
                           t=0.25 * scan, scan=scan, pose=pose, z=z)


@pytest.fixture(scope="module")
def ts():
    return _synthetic_set()


@pytest.fixture(scope="module")
def grid(ts):
    cfg = ann.TrainConfig(max_epochs=25)
    return evaluation.hidden_size_grid(ts, hidden=(1, 4), seeds=(0, 2), config=cfg), cfg


def test_grid_holds_the_numbers_of_independent_training(ts, grid):
    g, cfg = grid
    assert g.chrono.shape == g.lbo.shape == (2, 2) and set(g.models) == {(1, 0), (1, 2), (4, 0), (4, 2)}
    # One cell recomputed from scratch: same seed, same split -> bitwise the same model.
    c = ann.TrainConfig(max_epochs=25, hidden=(4,), seed=2)
    sp = ann.chronological_split(ts)
    m = ann.train(ts, sp, c)
    err = np.hypot(*(m.predict(ts.X[sp.test]) - ts.target[sp.test]).T)
    assert g.chrono[1, 1] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-12)
    base = np.hypot(*(ts.base[sp.test] - ts.target[sp.test]).T)
    assert g.chrono_base == pytest.approx(np.sqrt(np.mean(base ** 2)), rel=1e-12)
    ev = ann.evaluate_leave_beacons_out(ts, c)
    assert g.lbo[1, 1] == pytest.approx(ev.rmse_ann, rel=1e-12)
    assert g.lbo_base == pytest.approx(ev.rmse_base, rel=1e-12)
    # Parameter count = the length of the trained weight vector.
    for i, h in enumerate(g.hidden):
        assert g.n_params[i] == g.models[(h, 0)].theta.numel()
    # The 0.3 m bias is learnable: the bigger network beats the baseline on unseen beacons.
    assert g.lbo[1].mean() < 0.8 * g.lbo_base


def test_grid_without_leave_beacons_out(ts):
    g = evaluation.hidden_size_grid(ts, hidden=(2,), seeds=(1,), config=ann.TrainConfig(max_epochs=5),
                              leave_beacons_out=False)
    assert np.isnan(g.lbo).all() and np.isnan(g.lbo_base) and np.isfinite(g.chrono).all()
    fig = ch07.plot_hidden_grid(g)
    gids = [ln.get_gid() for ln in fig.axes[0].lines]
    assert "mean_chronological test" in gids and "mean_leave-beacons-out" not in gids


def test_plot_hidden_grid_shows_means_and_baselines(grid):
    g, _ = grid
    fig = ch07.plot_hidden_grid(g, hidden=4, seed=2)
    lines = {ln.get_gid(): ln for ln in fig.axes[0].lines}
    np.testing.assert_allclose(lines["mean_chronological test"].get_ydata(), g.chrono.mean(axis=1))
    np.testing.assert_allclose(lines["mean_leave-beacons-out"].get_ydata(), g.lbo.mean(axis=1))
    np.testing.assert_array_equal(lines["mean_leave-beacons-out"].get_xdata(), g.hidden)
    assert lines["base_leave-beacons-out"].get_ydata()[0] == g.lbo_base
    assert lines["current_chronological test"].get_ydata()[0] == g.chrono[1, 1]


def test_explorer_follows_the_sliders(grid, monkeypatch):
    g, _ = grid
    shown, alts = [], []
    monkeypatch.setattr(ch07, "show_png", lambda png, alt: (shown.append(png), alts.append(alt)))
    w = ch07.hidden_size_explorer(g, hidden=1, seed=0)
    # the plots are redrawn on release only, not at every intermediate slider position
    assert w.children[0].continuous_update is False and w.children[1].continuous_update is False
    s = w.holder["summary"]
    m = g.models[(1, 0)]
    assert (s["hidden"], s["seed"], s["best_epoch"], s["epochs"]) == (1, 0, m.best_epoch, m.epochs)
    assert s["chrono_rmse"] == g.chrono[0, 0] and s["lbo_mean"] == pytest.approx(g.lbo[0].mean())
    plt.close("all")
    w.children[0].value = 4
    w.children[1].value = 2
    s = w.holder["summary"]
    assert (s["hidden"], s["seed"]) == (4, 2)
    # The callback draws outside pyplot (plotting.widget_figure): nothing is left open for a
    # kernel thread's flush_figures to show half drawn.
    assert plt.get_fignums() == []
    assert s["lbo_rmse"] == g.lbo[1, 1] and s["n_params"] == g.n_params[1]
    # Every draw showed a picture, the figure's (blitted: plots.blit.Blit) ...
    assert len(shown) == 3 and all(p[:8] == b"\x89PNG\r\n\x1a\n" for p in shown)
    # each with the alt text read from the figure drawn
    assert alts[-1] == alt_text(w.view.fig) and len(alts[-1]) >= 40
    assert shown[-1] != shown[0]
    # ... whose left panel is that network's performance plot: its lines are its history.
    perf = w.view.fig.axes[0]
    val = [ln for ln in perf.lines if ln.get_gid() == "mse_val"][0]
    np.testing.assert_array_equal(val.get_ydata(), g.models[(4, 2)].history["val"])
    assert s["best_val_mse"] == min(val.get_ydata())
    # the printed readout says the same numbers
    text = w.holder["text"]
    assert text.startswith(f"4 hidden neurons ({g.n_params[1]} weights), seed 2: best epoch "
                           f"{g.models[(4, 2)].best_epoch} of {g.models[(4, 2)].epochs}")
    assert f"unseen beacons {g.lbo[1, 1]:.4f} m" in text


def test_bad_input(ts, grid):
    g, _ = grid
    with pytest.raises(ValueError, match="not in the grid"):
        evaluation.grid_summary(g, 3, 0)
    with pytest.raises(ValueError, match="seed"):
        ch07.hidden_size_explorer(g, hidden=1, seed=7)
    with pytest.raises(ValueError, match="HiddenSizeGrid"):
        ch07.hidden_size_explorer(object())
    with pytest.raises(ValueError, match="hidden"):
        evaluation.hidden_size_grid(ts, hidden=(0, 2))
    with pytest.raises(ValueError, match="seeds"):
        evaluation.hidden_size_grid(ts, seeds=(1, 1))
    with pytest.raises(TypeError, match="TrainingSet"):
        evaluation.hidden_size_grid(np.zeros((3, 12)))
    with pytest.raises(TypeError, match="TrainConfig"):
        evaluation.hidden_size_grid(ts, config={"hidden": (3,)})


def test_kept_layout_stays_clear_at_the_controls_ends(grid):
    # The explorer blits (plots.blit.Blit): every step is measured and compared with the same
    # state drawn from scratch, and the left panel's one view holds every network's history
    # (tests/layout_support.py).
    g, _ = grid
    w = []
    assert_kept_layouts_clear(lambda: w.append(ch07.hidden_size_explorer(g, hidden=1, seed=0))
                              or w[-1])
    (x0, x1), (y0, y1) = w[0].view.fig.axes[0].get_xlim(), w[0].view.fig.axes[0].get_ylim()
    for m in g.models.values():
        for part in ("train", "val"):
            v = np.asarray(m.history[part])
            assert x0 < 0 and v.size - 1 < x1 and y0 < v.min() and v.max() < y1
