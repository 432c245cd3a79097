"""Figures of the verdict chapter (notebook 08): the pose uncertainty of each
configuration over time, the simulator transfer experiment, the R-scale sweep."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from ..evaluation.summary import pose_trace
from .study import CONFIGURATIONS, Study
from ..plots.blit import log_limits
from ..plots.style import BLUE, FIG_WIDTH, GREEN, PURPLE, RED

__all__ = ["plot_pose_trace", "plot_transfer", "plot_r_scale", "set_r_scale", "r_scale_moving",
           "r_scale_trace_limits"]


def plot_pose_trace(st: Study, ax=None, *, configs=("beacons", "natural", "ann", "control")):
    """Pose covariance trace P_xx + P_yy over time of each configuration (ANN and control:
    seed ``st.seeds[0]``), log scale, the held-out window shaded."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(FIG_WIDTH, 3.8))
    runs = {"beacons": st.results["beacons"], "natural": st.results["natural"],
            "ann": st.results["ann"][0], "control": st.results["control"][0]}
    colors = {"beacons": BLUE, "natural": GREEN, "ann": RED, "control": "0.4"}
    t_end = 0.0
    for k in configs:
        t, tr = pose_trace(runs[k])
        t_end = max(t_end, float(t[-1]))
        ax.plot(t, tr, lw=1.0, color=colors[k], ls=":" if k == "control" else "-",
                label=CONFIGURATIONS[k][0])
    ax.axvspan(st.t_heldout, t_end, color="0.9", zorder=0, label="held-out time")
    ax.set(yscale="log", xlabel="t [s]", ylabel="P_xx + P_yy [m²]", xlim=(0.0, t_end),
           title="position uncertainty after each scan")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=3)
    return ax



def plot_transfer(transfers: dict, ax=None):
    """Map RMSE of the plain and the ANN-enhanced filter per simulator condition
    ({name: Transfer}): one dot per test run, the means as bars."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(FIG_WIDTH, 3.8))
    names = list(transfers)
    for i, name in enumerate(names):
        tr = transfers[name]
        for dx, v, color, label in ((-0.18, tr.plain, BLUE, "plain EKF-SLAM"),
                                    (0.18, tr.ann, RED, "ANN-enhanced")):
            ax.bar(i + dx, v.mean(), width=0.34, color=color, alpha=0.35,
                   label=label if i == 0 else None)
            ax.plot(np.full(v.size, i + dx), v, "o", color=color, ms=4)
    ax.set_xticks(range(len(names)), [n.replace(", ", "\n") for n in names], fontsize=8)
    ax.set(ylabel="map RMSE [m]", title="a network trained on the loop, layout 0, used elsewhere")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend()
    return ax



def plot_r_scale(sweep: dict, scale: float, reference: dict | None = None, fig=None):
    """Three panels for the factor ``scale`` of ``sweep``: P_xx + P_yy over time (k = 1,
    the chosen k, the reference run); the mean against k; the map RMSE (absolute and
    aligned) against k. The reference's values are dashed lines. Returns the Figure."""
    if scale not in sweep:
        raise ValueError(f"scale {scale!r} is not in the sweep {tuple(sweep)}")
    if fig is None:
        fig = plt.figure(figsize=(FIG_WIDTH, 4.2))
    a0, a1, a2 = fig.subplots(1, 3)
    ks = np.array(sorted(sweep))
    s = sweep[scale]
    if 1.0 in sweep:            # hidden at k = 1 (the k line is the same): see set_r_scale
        a0.plot(sweep[1.0]["t"], sweep[1.0]["trace"], color=BLUE, lw=1,
                label="beacons-only, R × 1" if scale != 1.0 else "_trace_1", gid="trace_1",
                visible=scale != 1.0)
    a0.plot(s["t"], s["trace"], color="k", lw=1.2, label=f"beacons-only, R × {scale:g}",
            gid="trace_k")
    if reference is not None:
        a0.plot(reference["t"], reference["trace"], color=RED, lw=1, ls="--",
                label=reference["label"], gid="trace_ref")
    a0.set(xlabel="t (s)", ylabel="P_xx + P_yy (m²)", yscale="log",
           title="position variance after each scan")
    a0.legend()
    trace = np.array([sweep[k]["pose_trace"] for k in ks])
    a1.plot(ks, trace, "o-", color=BLUE, gid="mean_trace")
    a1.plot([scale], [s["pose_trace"]], "s", ms=11, mfc="none", mec="k", mew=1.5, gid="current")
    rmse = np.array([sweep[k]["map_rmse"] for k in ks])
    aligned = np.array([sweep[k]["map_rmse_aligned"] for k in ks])
    a2.plot(ks, rmse, "o-", color=PURPLE, label="map RMSE, absolute", gid="map_rmse")
    a2.plot(ks, aligned, "o-", color=GREEN, label="map RMSE, aligned",
            gid="map_rmse_aligned")
    a2.plot([scale, scale], [s["map_rmse"], s["map_rmse_aligned"]], "s", ms=11, mfc="none",
            mec="k", mew=1.5, gid="current_map")
    if reference is not None:
        a1.axhline(reference["pose_trace"], color=RED, ls="--", label=reference["label"],
                   gid="ref_trace")
        a2.axhline(reference["map_rmse"], color=RED, ls="--",
                   label=f"{reference['label']}, absolute", gid="ref_map_rmse")
        a2.axhline(reference["map_rmse_aligned"], color=RED, ls=":",
                   label=f"{reference['label']}, aligned", gid="ref_map_rmse_aligned")
        a1.legend()
    a1.set(xscale="log", yscale="log", xlabel="R scale k", ylabel="mean P_xx + P_yy (m²)",
           title="uncertainty: falls with the R it is told")
    a2.set(xscale="log", xlabel="R scale k", ylabel="m", ylim=(0, 1.3 * max(rmse.max(), 0.01)),
           title="map error: does not improve")
    a2.legend()
    for ax in (a1, a2):
        ax.set_xticks(ks, [f"{k:g}" for k in ks], fontsize=8)
        ax.minorticks_off()
        ax.grid(alpha=0.3)
    if fig.get_layout_engine() is None:      # the course style already lays out (constrained)
        fig.tight_layout()
    return fig


def _by_gid(fig, gid):
    return next(a for ax in fig.axes for a in ax.get_children() if a.get_gid() == gid)


def r_scale_moving(fig) -> list:
    """The artists of a :func:`plot_r_scale` figure that :func:`set_r_scale` changes: the
    R x 1 and R x k traces, the first panel's legend, the two markers of k."""
    return [_by_gid(fig, g) for g in ("trace_1", "trace_k")] + [fig.axes[0].get_legend()] + [
        _by_gid(fig, g) for g in ("current", "current_map")]


def set_r_scale(fig, sweep: dict, scale: float):
    """Move a :func:`plot_r_scale` figure to the factor ``scale`` of ``sweep`` (its k trace,
    label and markers; the R x 1 trace hidden at k = 1, as plot_r_scale draws it) without
    drawing anything. The first panel's legend is made again with the new label: returns
    (old legend, new legend). Axis limits are not touched (a widget fixes them beforehand)."""
    if scale not in sweep:
        raise ValueError(f"scale {scale!r} is not in the sweep {tuple(sweep)}")
    s = sweep[scale]
    a0 = fig.axes[0]
    if 1.0 in sweep:
        t1 = _by_gid(fig, "trace_1")
        t1.set_visible(scale != 1.0)
        t1.set_label("beacons-only, R × 1" if scale != 1.0 else "_trace_1")
    k = _by_gid(fig, "trace_k")
    k.set_data(s["t"], s["trace"])
    k.set_label(f"beacons-only, R × {scale:g}")
    _by_gid(fig, "current").set_data([scale], [s["pose_trace"]])
    _by_gid(fig, "current_map").set_data([scale, scale], [s["map_rmse"], s["map_rmse_aligned"]])
    old = a0.get_legend()
    new = a0.legend()
    return old, new


def r_scale_trace_limits(sweep: dict, reference: dict | None = None) -> tuple[float, float]:
    """Log-axis limits of the first panel that hold the trace of every k of ``sweep`` and the
    reference's (one view for a slider over k), with a margin of 5 % of the decades."""
    vals = [np.asarray(v["trace"], dtype=float) for v in sweep.values()]
    if reference is not None:
        vals.append(np.asarray(reference["trace"], dtype=float))
    return log_limits(vals, "the sweep has no positive, finite trace")
