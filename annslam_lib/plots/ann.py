"""Plots of the landmark network (notebook 07 "ANN landmarks"; the paper's Figures 6-8, drawn
like MATLAB nntool's training diagnostics).

Signatures (each returns the matplotlib ``Figure`` it drew on):

- ``plot_performance(model, ax=None) -> Figure``: paper Figure 7. MSE per epoch (m^2 per
  coordinate, ``model.history``) of the training, validation and test parts on a log
  scale; the best validation epoch (``model.best_epoch``) marked by a dotted vertical line
  and a circle; title "Best Validation Performance is X at epoch N".
- ``plot_error_histogram(source, ts=None, split=None, *, bins=20, ax=None) -> Figure``:
  paper Figure 6. ``source`` is either the dict returned by ``ann.error_histogram`` (then
  ``ts``, ``split`` and ``bins`` are not used) or a model (``TrainedModel`` or
  ``InverseModel``; then ``ts`` and ``split`` are required and the histogram is
  ``ann.error_histogram(source, ts, split, bins)``). Bars stacked per part (training,
  validation, test) in ``bins`` equal bins of the error target - output (m, both
  coordinates pooled), and an orange zero-error line.
  The stacked heights of each part sum to its number of errors (2 per sample).
- ``plot_regression(source, ts=None, split=None, *, kind="position", axes=None) -> Figure``:
  paper Figure 8. ``source`` is the dict returned by ``ann.regression`` or a model
  (``TrainedModel`` or ``InverseModel``; then ``ts``, ``split`` required and ``kind`` =
  'position' or 'correction' is passed on). Four panels, Training, Validation, Test,
  All: outputs against targets, the least-squares fit (slope and intercept from
  ``ann.regression``), the dotted line Y = T and R in each title. ``axes``: four axes to draw on (else a new
  2 x 2 figure). A part without samples says so instead of plotting.

Course figures of notebook 07 (also returning the Figure):

- ``plot_activations(axes=None) -> Figure``: the paper's sign unit against the tanh unit
  of the course's network, values and derivatives (why back-propagation cannot train a
  sign unit).
- ``plot_rmse_comparison(rows, ax=None) -> Figure``: held-out RMSE of the inverse model
  (baseline) and the network per experiment; ``rows`` is a list of dicts with 'label',
  'base' (m) and 'ann' (m: one value or one per training seed; mean bar, +-1 std error
  bar over seeds).
- ``plot_landmark_errors(base, predicted, target, ax=None, title="") -> Figure``: errors
  of single landmark estimates relative to their true beacons, inverse model (grey)
  against network (blue).

The library computes the numbers (``annslam_lib.ann``); these functions only draw them.
"""
from __future__ import annotations

import numbers

import matplotlib.pyplot as plt
import numpy as np

from .. import ann
from .blit import log_limits
from .style import BEACON_STYLE, BLUE, FIG_WIDTH, GREEN, ORANGE, RED, axes
from ..evaluation.map import point_rmse

__all__ = ["PART_LABELS", "PART_COLORS", "plot_performance", "set_performance",
           "performance_moving", "performance_limits", "plot_error_histogram",
           "plot_regression", "plot_activations", "plot_rmse_comparison",
           "plot_landmark_errors"]

#: nntool's names of the parts.
PART_LABELS = {"train": "Training", "val": "Validation", "test": "Test", "all": "All"}
#: nntool's colours of the parts.
PART_COLORS = {"train": BLUE, "val": GREEN, "test": RED, "all": "0.3"}
_ZERO_COLOR = ORANGE


def _performance_data(model):
    """(history, train MSE, epochs, best epoch, {part: MSE per epoch}) of a model, checked
    (:func:`plot_performance`, :func:`set_performance`)."""
    hist = getattr(model, "history", None)
    if not isinstance(hist, dict) or any(k not in hist for k in ("train", "val")):
        raise TypeError("model must have a history with 'train' and 'val' MSE per epoch "
                         "(a TrainedModel from ann.train or ann.load)")
    train = np.asarray(hist["train"], dtype=float)
    epoch = np.asarray(hist.get("epoch", np.arange(train.size)))
    best = getattr(model, "best_epoch", None)
    if isinstance(best, bool) or not isinstance(best, numbers.Integral) or not 0 <= best < train.size:
        raise ValueError(f"model.best_epoch must be an epoch of the history (0..{train.size - 1}), "
                         f"got {best!r}")
    parts = {}
    for p in ann.SPLITS:
        v = np.asarray(hist.get(p, np.full(train.size, np.nan)), dtype=float)
        if v.shape != train.shape:
            raise ValueError(f"history[{p!r}] has {v.size} epochs, 'train' has {train.size}")
        parts[p] = v
    return hist, train, epoch, best, parts


def plot_performance(model, ax=None):
    """The performance plot (paper Figure 7): per-epoch MSE of each part, log scale, the
    best validation epoch marked. ``model``: a ``TrainedModel`` (anything with ``history``
    holding 'epoch', 'train', 'val', 'test' arrays and ``best_epoch``)."""
    hist, train, epoch, best, parts = _performance_data(model)
    ax = axes(ax, figsize=(FIG_WIDTH, 4.0))
    for p, v in parts.items():
        if np.all(np.isnan(v)):
            continue                                   # e.g. no test part
        ax.plot(epoch, v, color=PART_COLORS[p], lw=1.8, label=f"{PART_LABELS[p]}", gid=f"mse_{p}")
    best_val = float(hist["val"][best])
    ax.axvline(epoch[best], color=PART_COLORS["val"], ls=":", lw=1.2, gid="best_epoch")
    ax.plot([epoch[best]], [best_val], "o", ms=11, mfc="none", mec=PART_COLORS["val"], mew=1.8,
            label="Best", gid="best_point")
    ax.set_yscale("log")
    ax.set(xlabel=f"{train.size - 1} epochs", ylabel="Mean squared error (m$^2$)",
           title=f"Best Validation Performance is {best_val:.4g} at epoch {int(epoch[best])}")
    ax.legend(loc="best", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    return ax.figure


def set_performance(ax, model):
    """Move a :func:`plot_performance` axes to ``model`` without drawing (a widget's step):
    its MSE lines, the best epoch's line and point and the title; the x label (the epoch
    count) is left alone: the axis label is drawn with the axis, which does not move. The
    legend is made again (its best place depends on the lines): returns (old legend, new
    legend). Axis limits are not touched (a widget fixes them beforehand). A split the axes
    has no line for, but the model has data for, raises ValueError."""
    hist, train, epoch, best, parts = _performance_data(model)
    lines = {ln.get_gid(): ln for ln in ax.lines}
    for p, v in parts.items():
        line = lines.get(f"mse_{p}")
        if line is None:
            if not np.all(np.isnan(v)):
                raise ValueError(f"the axes has no line for the {p!r} part this model has")
            continue
        line.set_data(epoch, v)
    best_val = float(hist["val"][best])
    lines["best_epoch"].set_xdata([epoch[best], epoch[best]])
    lines["best_point"].set_data([epoch[best]], [best_val])
    ax.set_title(f"Best Validation Performance is {best_val:.4g} at epoch {int(epoch[best])}")
    old = ax.get_legend()
    return old, ax.legend(loc="best", fontsize=9)


def performance_moving(ax) -> list:
    """The artists of a :func:`plot_performance` axes that :func:`set_performance` changes."""
    return [ln for ln in ax.lines if ln.get_gid() in
            {f"mse_{p}" for p in ann.SPLITS} | {"best_epoch", "best_point"}] + [
        ax.get_legend(), ax.title]


def performance_limits(models) -> tuple[tuple[float, float], tuple[float, float]]:
    """(x limits, log y limits) of a :func:`plot_performance` axes that hold every model's
    history (one view for a slider over models), with a margin of 5 % (of the decades in y)."""
    n, vals = 0, []
    for m in models:
        for p in ann.SPLITS:
            v = np.asarray(m.history.get(p, []), dtype=float)
            n = max(n, v.size)
            vals.append(v)
    if n == 0:
        raise ValueError("the models have no positive, finite MSE to show")
    x_pad = 0.05 * max(n - 1, 1)
    return (-x_pad, n - 1 + x_pad), log_limits(vals, "the models have no positive, finite MSE")


# --------------------------------------------------------------------------- Figure 6

def _histogram_data(source, ts, split, bins, span=None) -> dict:
    if isinstance(source, dict):
        missing = [k for k in ("edges", "counts") if k not in source]
        if missing:
            raise ValueError(f"histogram dict lacks {missing} (expected ann.error_histogram's result)")
        return source
    if callable(getattr(source, "predict", None)):
        if ts is None or split is None:
            raise ValueError("plot_error_histogram(model, ...) needs the TrainingSet and the Split")
        return ann.error_histogram(source, ts, split, bins, span=span)
    raise ValueError("source must be ann.error_histogram's dict or a model (TrainedModel, "
                     "InverseModel), got "
                     f"{type(source).__name__}")


def plot_error_histogram(source, ts=None, split=None, *, bins: int = 20, span=None, ax=None):
    """The error histogram (paper Figure 6): stacked bars of the errors target - output of
    each part in equal bins, and the zero-error line (module docstring for ``source``;
    ``span``: :func:`annslam_lib.ann.error_histogram`'s, the title says how many errors the
    end bins hold from beyond)."""
    h = _histogram_data(source, ts, split, bins, span)
    edges = np.asarray(h["edges"], dtype=float)
    nb = edges.size - 1
    if nb < 1 or not np.all(np.diff(edges) > 0):
        raise ValueError("histogram edges must be increasing, at least two of them")
    ax = axes(ax, figsize=(FIG_WIDTH, 4.0))
    width = np.diff(edges)
    bottom = np.zeros(nb)
    for p in ann.SPLITS:
        c = np.asarray(h["counts"].get(p, np.zeros(nb)), dtype=float)
        if c.shape != (nb,):
            raise ValueError(f"counts[{p!r}] must have {nb} bins, got shape {c.shape}")
        if c.sum() == 0:
            continue
        ax.bar(edges[:-1], c, width=width, bottom=bottom, align="edge", color=PART_COLORS[p],
               edgecolor="k", lw=0.4, label=PART_LABELS[p], gid=f"bars_{p}")
        bottom = bottom + c
    ax.axvline(0.0, color=_ZERO_COLOR, lw=2, label="Zero Error", gid="zero_error")
    beyond = sum(h.get("beyond", {}).values())
    title = f"Error Histogram with {nb} Bins"
    if beyond:
        title += f" ({beyond} errors beyond them counted in the end bins)"
    ax.set(xlabel="Errors = Targets - Outputs (m)", ylabel="Instances", title=title)
    ax.legend(fontsize=9)
    return ax.figure


# --------------------------------------------------------------------------- Figure 8

def _regression_data(source, ts, split, kind) -> dict:
    if isinstance(source, dict):
        if "all" not in source or any(p not in source for p in ann.SPLITS):
            raise ValueError("regression dict must have 'train', 'val', 'test', 'all' "
                             "(expected ann.regression's result)")
        return source
    if callable(getattr(source, "predict", None)):
        if ts is None or split is None:
            raise ValueError("plot_regression(model, ...) needs the TrainingSet and the Split")
        return ann.regression(source, ts, split, kind)
    raise ValueError("source must be ann.regression's dict or a model (TrainedModel, "
                     "InverseModel), got "
                     f"{type(source).__name__}")


def plot_regression(source, ts=None, split=None, *, kind: str = "position", axes=None):
    """The regression plot (paper Figure 8): outputs against targets for each part and
    all together, with the least-squares fit, Y = T and R (module docstring)."""
    reg = _regression_data(source, ts, split, kind)
    parts = (*ann.SPLITS, "all")
    if axes is None:
        fig, axes = plt.subplots(2, 2, figsize=(FIG_WIDTH, 8.0))
    axes = list(np.ravel(axes))
    if len(axes) != 4:
        raise ValueError(f"axes must be four axes (Training, Validation, Test, All), got {len(axes)}")
    for ax, p in zip(axes, parts):
        d = reg[p]
        o, g = np.asarray(d["outputs"], dtype=float), np.asarray(d["targets"], dtype=float)
        if o.size == 0:
            ax.text(0.5, 0.5, "no samples", ha="center", va="center", transform=ax.transAxes)
            ax.set(title=f"{PART_LABELS[p]}: no samples")
            continue
        lo, hi = float(min(g.min(), o.min())), float(max(g.max(), o.max()))
        pad = 0.05 * (hi - lo) if hi > lo else 0.5
        xs = np.array([lo - pad, hi + pad])
        ax.plot(g, o, ".", ms=3, color="k", label="Data", gid="data")
        ax.plot(xs, xs, ":", color="0.4", lw=1.2, label="Y = T", gid="identity")
        if np.isfinite(d["slope"]):
            ax.plot(xs, d["slope"] * xs + d["intercept"], color=PART_COLORS[p], lw=1.8,
                    label="Fit", gid="fit")
        ax.set(xlim=xs, ylim=xs, aspect="equal", xlabel="Target (m)",
               ylabel=f"Output ~= {d['slope']:.3g}*Target {'-' if d['intercept'] < 0 else '+'} "
                      f"{abs(d['intercept']):.2g}",
               title=f"{PART_LABELS[p]}: R={d['r']:.5g}")
        ax.legend(loc="upper left")
    fig = axes[0].figure
    if kind in ("position", "correction") and not isinstance(source, dict):
        fig.suptitle(f"Regression ({kind})")
    if fig.get_layout_engine() is None:   # the course style lays out already
        fig.tight_layout()
    return fig


# --------------------------------------------------------------------------- course figures

def plot_activations(axes=None, s_max: float = 3.0):
    """Section 4.2's sign unit against the course's tanh unit on s = <w, x> + b in
    [-s_max, s_max]: left the outputs, right their derivatives d/ds (sign: 0 everywhere
    except s = 0, where it jumps; tanh: 1 - tanh^2 > 0). Two axes or a new figure."""
    if not (isinstance(s_max, numbers.Real) and np.isfinite(s_max) and s_max > 0):
        raise ValueError(f"s_max must be a positive number, got {s_max!r}")
    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=(FIG_WIDTH, 3.6))
    axes = list(np.ravel(axes))
    if len(axes) != 2:
        raise ValueError(f"axes must be two axes (values, derivatives), got {len(axes)}")
    s = np.linspace(-s_max, s_max, 601)
    a0, a1 = axes
    a0.plot(s, np.sign(s), color=RED, lw=2, label="sign(s)  (paper)", gid="sign")
    a0.plot(s, np.tanh(s), color=BLUE, lw=2, label="tanh(s)  (hidden layer)", gid="tanh")
    a0.plot(s, s, color="0.5", ls="--", lw=1, label="s  (linear output)", gid="linear")
    a0.set(xlabel="s = <w, x> + b", ylabel="unit output", ylim=(-1.6, 1.6),
           title="What a unit can output")
    a1.plot(s, np.zeros_like(s), color=RED, lw=2, label="d sign / ds = 0 (s != 0)",
            gid="dsign")
    a1.plot(s, 1.0 - np.tanh(s) ** 2, color=BLUE, lw=2, label="d tanh / ds = 1 - tanh^2",
            gid="dtanh")
    a1.plot([0], [0], "o", mfc="white", mec=RED, ms=8, gid="jump")
    a1.set(xlabel="s", ylabel="derivative", ylim=(-0.2, 1.2),
           title="What back-propagation sees")
    for a in axes:
        a.axhline(0, color="k", lw=0.5)
        a.legend(loc="upper left")
        a.grid(alpha=0.3)
    if a0.figure.get_layout_engine() is None:   # the course style lays out already
        a0.figure.tight_layout()
    return a0.figure


def plot_rmse_comparison(rows, ax=None):
    """Held-out RMSE per experiment: the inverse model (grey bar) next to the network
    (blue bar at the mean over training seeds, +-1 standard deviation error bar); the
    value of each bar written above it (m, 3 decimals)."""
    rows = list(rows)
    if not rows:
        raise ValueError("rows must not be empty")
    base, mean, std, labels = [], [], [], []
    for r in rows:
        if not isinstance(r, dict) or any(k not in r for k in ("label", "base", "ann")):
            raise TypeError(f"each row must be a dict with 'label', 'base', 'ann', got {r!r}")
        a = np.atleast_1d(np.asarray(r["ann"], dtype=float))
        b = float(r["base"])
        if a.size == 0 or not np.all(np.isfinite(a)) or not np.isfinite(b):
            raise ValueError(f"row {r['label']!r}: RMSE values must be finite numbers")
        labels.append(str(r["label"]))
        base.append(b)
        mean.append(float(a.mean()))
        std.append(float(a.std()))
    ax = axes(ax, figsize=(FIG_WIDTH, 4.2))
    x = np.arange(len(rows))
    w = 0.38
    bb = ax.bar(x - w / 2, base, w, color="0.7", edgecolor="k", lw=0.5,
                label="inverse model (no network)", gid="base")
    ba = ax.bar(x + w / 2, mean, w, yerr=std, capsize=4, color=BLUE, edgecolor="k", lw=0.5,
                label="network (mean +- std over seeds)", gid="ann")
    for bars, vals, err in ((bb, base, np.zeros(len(rows))), (ba, mean, std)):
        for rect, v, e in zip(bars, vals, err):                # label above the error bar
            ax.annotate(f"{v:.3f}", (rect.get_x() + rect.get_width() / 2, v + e),
                        xytext=(0, 3), textcoords="offset points", ha="center", fontsize=8)
    ax.set_xticks(x, labels, fontsize=8)
    ax.set(ylabel="held-out RMSE (m)", ylim=(0, 1.25 * max(max(base), max(np.add(mean, std)))))
    ax.legend(loc="upper right")
    ax.grid(axis="y", alpha=0.3)
    return ax.figure


def plot_landmark_errors(base, predicted, target, ax=None, title: str = ""):
    """Errors of single landmark estimates, each drawn relative to its own true beacon
    (the beacon at the origin): the inverse model's ``base - target`` (grey) and the
    network's ``predicted - target`` (blue), m; RMSEs in the legend. Memorisation shows
    as the blue cloud collapsing onto the origin."""
    base = np.asarray(base, dtype=float)
    predicted = np.asarray(predicted, dtype=float)
    target = np.asarray(target, dtype=float)
    for name, a in (("base", base), ("predicted", predicted), ("target", target)):
        if a.ndim != 2 or a.shape[1] != 2 or not np.all(np.isfinite(a)):
            raise ValueError(f"{name} must be an (n, 2) array of finite points, got shape {a.shape}")
    if not base.shape == predicted.shape == target.shape:
        raise ValueError(f"base, predicted and target must have the same shape, got {base.shape}, "
                         f"{predicted.shape} and {target.shape}")
    ax = axes(ax, figsize=(5.5, 5.5))
    eb, ep = base - target, predicted - target
    rms = [point_rmse(e) for e in (eb, ep)]
    ax.plot(eb[:, 0], eb[:, 1], ".", color="0.55", ms=3, gid="base",
            label=f"inverse model g(prior, z): RMSE {rms[0]:.3f} m")
    ax.plot(ep[:, 0], ep[:, 1], ".", color=BLUE, ms=3, gid="predicted", zorder=6,
            label=f"network: RMSE {rms[1]:.3f} m")
    ax.scatter([0.0], [0.0], label="true beacon", gid="beacon", **BEACON_STYLE)
    lim = 1.1 * float(np.max(np.abs(np.concatenate([eb, ep])))) if eb.size else 1.0
    ax.set(xlim=(-lim, lim), ylim=(-lim, lim), aspect="equal", title=title,
           xlabel="estimate - true beacon, x [m]", ylabel="estimate - true beacon, y [m]")
    ax.legend(loc="upper left")
    ax.grid(alpha=0.3)
    return ax.figure
