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

import numbers
from dataclasses import dataclass, field, replace

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import SelectionSlider, interactive

from .. import ann
from ..ann_plots import plot_performance
from ..plotting import show_widget_figure, widget_figure

__all__ = ["HiddenSizeGrid", "hidden_size_grid", "grid_summary", "plot_hidden_grid",
           "hidden_size_explorer"]


@dataclass
class HiddenSizeGrid:
    """Results of :func:`hidden_size_grid`.

    hidden (H,), seeds (S,): the grid axes. chrono (H, S): test RMSE (m) of the network on
    the chronological split; lbo (H, S): leave-beacons-out RMSE (m) (NaN if not computed);
    chrono_base, lbo_base: the inverse model's RMSE on the same samples; models: {(h, s):
    the chronological TrainedModel} (for its history); n_params (H,): weights and biases.
    """

    hidden: tuple
    seeds: tuple
    chrono: np.ndarray
    lbo: np.ndarray
    chrono_base: float
    lbo_base: float
    n_params: np.ndarray
    models: dict = field(default_factory=dict)

    def index(self, hidden: int, seed: int) -> tuple[int, int]:
        if hidden not in self.hidden:
            raise ValueError(f"hidden size {hidden!r} is not in the grid {self.hidden}")
        if seed not in self.seeds:
            raise ValueError(f"seed {seed!r} is not in the grid {self.seeds}")
        return self.hidden.index(hidden), self.seeds.index(seed)


def _int_tuple(name: str, values, lo: int) -> tuple:
    vals = tuple(values)
    if not vals or any(isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < lo
                       for v in vals) or len(set(vals)) != len(vals):
        raise ValueError(f"{name} must be distinct integers >= {lo}, got {values!r}")
    return tuple(int(v) for v in vals)


def hidden_size_grid(ts: ann.TrainingSet, hidden=(1, 2, 5, 10, 20, 40), seeds=range(5), *,
                     config: ann.TrainConfig | None = None, leave_beacons_out: bool = True,
                     n_folds: int = 5) -> HiddenSizeGrid:
    """Train one network per (hidden size, seed) on ``ts`` (``config`` with ``hidden``
    and ``seed`` replaced): on the chronological split, and, if ``leave_beacons_out``,
    in leave-beacons-out cross-validation with ``n_folds`` folds."""
    if not isinstance(ts, ann.TrainingSet):
        raise ValueError(f"ts must be an ann.TrainingSet, got {type(ts).__name__}")
    hidden = _int_tuple("hidden", hidden, 1)
    seeds = _int_tuple("seeds", seeds, 0)
    base_cfg = ann.TrainConfig() if config is None else config
    if not isinstance(base_cfg, ann.TrainConfig):
        raise ValueError(f"config must be an ann.TrainConfig, got {type(base_cfg).__name__}")
    sp = ann.chronological_split(ts)
    folds = ann.beacon_folds(ts, n_folds) if leave_beacons_out else None
    chrono = np.full((len(hidden), len(seeds)), np.nan)
    lbo = np.full_like(chrono, np.nan)
    models = {}
    chrono_base = lbo_base = np.nan
    for i, h in enumerate(hidden):
        for j, s in enumerate(seeds):
            cfg = replace(base_cfg, hidden=(h,), seed=s)
            m = ann.train(ts, sp, cfg)
            models[(h, s)] = m
            r = ann.split_rmse(m, ts, sp)["test"]
            chrono[i, j], chrono_base = r["rmse_ann"], r["rmse_base"]
            if folds is not None:
                ev = ann.evaluate(ts, folds, cfg, protocol="leave_beacons_out")
                lbo[i, j], lbo_base = ev.rmse_ann, ev.rmse_base
    n_in = len(base_cfg.columns)
    n_params = np.array([n_in * h + h + 2 * h + 2 for h in hidden])
    return HiddenSizeGrid(hidden=hidden, seeds=seeds, chrono=chrono, lbo=lbo,
                          chrono_base=float(chrono_base), lbo_base=float(lbo_base),
                          n_params=n_params, models=models)


def grid_summary(grid: HiddenSizeGrid, hidden: int, seed: int) -> dict:
    """What the explorer shows for (hidden, seed): the network's best epoch, epochs run,
    parameters, its chronological-test and leave-beacons-out RMSE, the means over seeds
    at this size and the baselines (all RMSE in m)."""
    i, j = grid.index(hidden, seed)
    m = grid.models[(hidden, seed)]
    return {"hidden": int(hidden), "seed": int(seed), "n_params": int(grid.n_params[i]),
            "best_epoch": int(m.best_epoch), "epochs": int(m.epochs),
            "best_val_mse": float(m.history["val"][m.best_epoch]),
            "chrono_rmse": float(grid.chrono[i, j]), "lbo_rmse": float(grid.lbo[i, j]),
            "chrono_mean": float(np.mean(grid.chrono[i])), "lbo_mean": float(np.mean(grid.lbo[i])),
            "chrono_base": grid.chrono_base, "lbo_base": grid.lbo_base}


def plot_hidden_grid(grid: HiddenSizeGrid, ax=None, *, hidden: int | None = None,
                     seed: int | None = None):
    """Held-out RMSE against the hidden size: mean over seeds (line, +-1 std band) for the
    chronological test and leave-beacons-out, the inverse-model baselines (dashed) and,
    if given, the (hidden, seed) network marked. Returns the Figure."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4.2))
    h = np.asarray(grid.hidden, dtype=float)
    for name, vals, base, color in (("chronological test", grid.chrono, grid.chrono_base, "tab:red"),
                                    ("leave-beacons-out", grid.lbo, grid.lbo_base, "tab:purple")):
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
    ax.legend(fontsize=7)
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

    def draw(hidden: int, seed: int) -> None:
        holder["summary"] = s = grid_summary(grid, hidden, seed)
        fig, (a0, a1) = widget_figure(1, 2, figsize=(12, 4.2))  # not pyplot: see widget_figure
        plot_performance(grid.models[(hidden, seed)], ax=a0)
        plot_hidden_grid(grid, ax=a1, hidden=hidden, seed=seed)
        a1.set_title(f"{hidden} neurons, seed {seed}: test {s['chrono_rmse']:.3f} m, "
                     f"unseen beacons {s['lbo_rmse']:.3f} m", fontsize=10)
        fig.tight_layout()
        show_widget_figure(fig)

    widget = interactive(
        draw,
        hidden=SelectionSlider(options=list(grid.hidden), value=hidden, description="hidden",
                               continuous_update=False),
        seed=SelectionSlider(options=list(grid.seeds), value=seed, description="seed",
                             continuous_update=False))
    widget.holder = holder
    widget.grid = grid
    return widget
