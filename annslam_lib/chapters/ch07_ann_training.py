"""Chapter 07 explorer: how big should the landmark network be?

Training is cheap (tens of milliseconds), but not cheap enough to retrain at every slider
move in a lecture, and a slider that retrains would make the plots depend on the
machine's timing. So :func:`hidden_size_grid` trains the whole grid ONCE (hidden sizes x
training seeds, each on the chronological 70/15/15 split and in leave-beacons-out
cross-validation), and :func:`hidden_size_explorer` only looks results up: the slider
picks the hidden-layer size and the seed, the left panel is that network's performance
plot (paper Figure 7), the right one the held-out RMSE against the hidden size with the
inverse-model baseline (notebook 07, "How many neurons?").
"""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import SelectionSlider, interactive

from ..ann.evaluation import HiddenSizeGrid, grid_summary
from ..plots.ann import (performance_limits, performance_moving, plot_landmark_errors,
                         plot_performance, set_performance)
from ..plots.blit import Blit
from ..plots.alt import alt_text
from ..plots.style import PURPLE, RED, figure, show_png, widget_figure
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup

__all__ = ["setup", "plot_hidden_grid", "loop_mistakes_figure", "landmark_errors_figure",
           "hidden_size_explorer"]


def plot_hidden_grid(grid: HiddenSizeGrid, ax=None, *, hidden: int | None = None,
                     seed: int | None = None):
    """Held-out RMSE against the hidden size: mean over seeds (line, +-1 std band) for the
    chronological test and leave-beacons-out, the inverse-model baselines (dashed) and,
    if given, the (hidden, seed) network marked. Returns the Figure."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4.2))
    h = np.asarray(grid.hidden, dtype=float)
    for name, vals, base, color in (("chronological test", grid.chrono, grid.chrono_base, RED),
                                    ("leave-beacons-out", grid.lbo, grid.lbo_base, PURPLE)):
        if np.all(np.isnan(vals)):
            continue
        mu, sd = vals.mean(axis=1), vals.std(axis=1)
        ax.plot(h, mu, "o-", color=color, label=f"network, {name}", gid=f"mean_{name}")
        ax.fill_between(h, mu - sd, mu + sd, color=color, alpha=0.2)
        ax.axhline(base, color=color, ls="--", lw=1.2, label=f"inverse model, {name}",
                   gid=f"base_{name}")
        if hidden is not None and seed is not None:
            i, j = grid.index(hidden, seed)
            ax.plot([hidden], [vals[i, j]], "s", ms=10, mfc="none", mec="k", mew=1.5,
                    gid=f"current_{name}")
    ax.set_xscale("log")
    ax.set_xticks(h, [str(v) for v in grid.hidden])
    ax.minorticks_off()
    ax.set(xlabel="hidden neurons", ylabel="held-out RMSE (m)",
           title=f"{len(grid.seeds)} seeds per size")
    ax.legend()
    ax.grid(alpha=0.3)
    return ax.figure


def hidden_size_explorer(grid: HiddenSizeGrid, *, hidden: int | None = None, seed: int | None = None):
    """Sliders over the precomputed ``grid``: hidden size and seed; the latest
    :func:`grid_summary` is in ``widget.holder["summary"]``."""
    if not isinstance(grid, HiddenSizeGrid) or not grid.models:
        raise ValueError("hidden_size_explorer needs a HiddenSizeGrid from hidden_size_grid")
    hidden = grid.hidden[len(grid.hidden) // 2] if hidden is None else hidden
    seed = grid.seeds[0] if seed is None else seed
    grid.index(hidden, seed)                                   # validates both
    holder = {}

    view = None

    def draw(hidden: int, seed: int) -> None:
        nonlocal view
        holder["summary"] = s = grid_summary(grid, hidden, seed)
        holder["text"] = (f"{hidden} hidden neurons ({s['n_params']} weights), seed {seed}: best "
                          f"epoch {s['best_epoch']} of {s['epochs']}; chronological test RMSE "
                          f"{s['chrono_rmse']:.4f} m, unseen beacons {s['lbo_rmse']:.4f} m "
                          f"(inverse model {s['chrono_base']:.4f} / {s['lbo_base']:.4f} m)")
        print(holder["text"])
        title = (f"{hidden} neurons, seed {seed}: test {s['chrono_rmse']:.3f} m, "
                 f"unseen beacons {s['lbo_rmse']:.3f} m")
        if view is None:
            view = _view(grid, hidden, seed, title)
        else:
            a0, a1 = view.fig.axes
            view.replace(*set_performance(a0, grid.models[(hidden, seed)]))
            _mark(grid, a1, hidden, seed)
            a1.set_title(title, fontsize=10)
        show_png(view.png(), alt_text(view.fig))

    widget = interactive(
        draw,
        hidden=SelectionSlider(options=list(grid.hidden), value=hidden, description="hidden",
                               continuous_update=False),
        seed=SelectionSlider(options=list(grid.seeds), value=seed, description="seed",
                             continuous_update=False))
    widget.holder = holder
    widget.grid = grid
    widget.view = view                  # the figure the first draw made (plots.blit.Blit)
    return keyboard_ready(widget)


def _view(grid: HiddenSizeGrid, hidden: int, seed: int, title: str) -> Blit:
    """The explorer's figure for (hidden, seed), drawn once; a step moves the left panel's
    curves, title and legend and the right panel's markers and title
    (:class:`plots.blit.Blit`). The left panel keeps one view that holds every network's
    history."""
    fig, (a0, a1) = widget_figure(1, 2, figsize=(12, 4.2))
    plot_performance(grid.models[(hidden, seed)], ax=a0)
    xlim, ylim = performance_limits(grid.models.values())
    a0.set(xlim=xlim, ylim=ylim, xlabel="epoch")    # one axis for all (the count is printed)
    plot_hidden_grid(grid, ax=a1, hidden=hidden, seed=seed)
    a1.set_title(title, fontsize=10)
    moving = performance_moving(a0) + [ln for ln in a1.lines
                                       if (ln.get_gid() or "").startswith("current_")] + [a1.title]
    return Blit(fig, moving)


def _mark(grid: HiddenSizeGrid, ax, hidden: int, seed: int) -> None:
    """Move :func:`plot_hidden_grid`'s markers to the (hidden, seed) network."""
    i, j = grid.index(hidden, seed)
    for name, vals in (("chronological test", grid.chrono), ("leave-beacons-out", grid.lbo)):
        for ln in ax.lines:
            if ln.get_gid() == f"current_{name}":
                ln.set_data([hidden], [vals[i, j]])


def loop_mistakes_figure(curves: dict):
    """The loss per epoch of the reference training loop and of each common mistake
    ({label: losses}), on the grader's toy problem (log scale)."""
    fig, ax = figure(height=4.0)
    for label, losses in curves.items():
        ax.semilogy(losses, "o-", ms=3, label=label)
    ax.set(xlabel="epoch", ylabel="loss (as each loop computes it)", ylim=(0.03, 1e4),
           title="the toy problem, SGD with lr 0.1")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper left")
    return fig


def landmark_errors_figure(ts, evaluations: dict):
    """Single landmark estimates against the truth for each {title: evaluation}: the
    inverse model's, the network's and the true positions (plots.ann.plot_landmark_errors)."""
    fig, axs = figure(1, len(evaluations), height=5.2)
    for ax, (title, ev) in zip(np.atleast_1d(axs), evaluations.items()):
        predicted = np.concatenate([m.predict(ts.X[sp.test]) for m, sp in zip(ev.models, ev.splits)])
        plot_landmark_errors(ts.base[ev.index], predicted, ts.target[ev.index], ax=ax, title=title)
    return fig
