"""Chapter 08 explorer: the verdict's control experiment on a slider.

The paper credits the ANN for a smaller position uncertainty. In a Kalman filter the
covariance depends on the measurement noise R the filter is TOLD, not on the
measurements: the plain beacons-only filter told a smaller R becomes just as certain.
:func:`r_scale_summary` runs the beacons-only EKF-SLAM (``slam.runner.run``, about 0.2 s on the
Car Park) with R scaled by a factor k (both standard deviations times sqrt(k)) and measures
what the verdict measures (``evaluation.summary.run_metrics``): the mean P_xx + P_yy, the map RMSE
against the surveyed beacons (absolute and after the best rigid alignment), the path RMSE
against GPS, and the normalised NIS. :func:`r_scale_sweep` does it for a range of k once;
the explorer :func:`r_scale_explorer` only looks the sweep up (notebook 08, section 3):
the covariance falls steadily with k and reaches the ANN run's, while the map error does not
improve.
"""
from __future__ import annotations

import html
import math

from ipywidgets import HTML, Image, Layout, SelectionSlider, VBox
from matplotlib.figure import Figure

from ..data.records import Dataset
from ..paper.study import SCALES, FoldStudy, Study, r_scale_sweep
from ..plots.blit import Blit
from ..paper.figures import (plot_pose_trace, plot_r_scale, plot_transfer, r_scale_moving,
                            r_scale_trace_limits, set_r_scale)
from ..plots.slam import CAR_PARK_LIMITS, plot_true_vs_mapped
from ..plots.alt import alt_text
from ..plots.style import BLUE, DPI, FIG_WIDTH, RED, figure, show_in_image
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig

__all__ = ["setup", "pose_trace_figure", "r_scale_figure", "transfer_figure", "figure5_figure",
           "training_curves_figure", "r_scale_explorer", "VERDICT_WORDS", "verdict_word",
           "verdict_table"]

#: The verdict column's words (section 7), bold where a rule decided.
VERDICT_WORDS = {"holds": "**holds**", "does not hold": "**does not hold**",
                 "not demonstrated": "**not demonstrated**",
                 "not testable this way": "not testable this way"}

#: Size of the explorer's image (inches at plots.style.DPI): the text column's width.
EXPLORER_FIGSIZE = (FIG_WIDTH, 4.2)


def pose_trace_figure(st: Study):
    """P_xx + P_yy after every scan for each configuration of the study (section 3)."""
    fig, ax = figure(height=3.8)
    plot_pose_trace(st, ax=ax)
    return fig


def r_scale_figure(sweep: dict, reference: dict | None = None, scale: float = 0.3):
    """The R-scale sweep's three panels (section 3) with ``scale`` highlighted."""
    return plot_r_scale(sweep, scale, reference)


def transfer_figure(transfers: dict):
    """Map RMSE, plain against ANN filter, for every simulated transfer (section 6)."""
    fig, ax = figure(height=3.8)
    plot_transfer(transfers, ax=ax)
    return fig


def training_curves_figure(fs: FoldStudy, seed_index: int = 0):
    """The networks of the verdict over folds (section 4), training seed ``seeds[seed_index]``:
    training (dashed) and validation MSE per epoch for every time fold (left) and beacon
    fold (right), a dot at the epoch whose weights were kept (early stopping)."""
    fig, axes = figure(1, 2, height=3.4, sharey=True, layout="constrained")
    for ax, (kind, title) in zip(axes, (("time", "time folds"), ("beacons", "beacon folds"))):
        for k, per_seed in enumerate(fs.histories[kind]):
            h = per_seed[seed_index]
            line, = ax.semilogy(h["val"], label=f"fold {k}")
            ax.semilogy(h["train"], "--", color=line.get_color(), lw=0.8)
            ax.plot(h["best_epoch"], h["val"][h["best_epoch"]], "o", color=line.get_color(), ms=4)
        ax.set(title=f"{title} (seed {fs.seeds[seed_index]})", xlabel="epoch")
    axes[0].set_ylabel("MSE per coordinate (m²)")
    axes[1].legend(fontsize="small", title="validation (—), training (--)",
                   title_fontsize="small")
    return fig


def figure5_figure(st: Study, dataset: Dataset, seed_index: int = 0,
                   zoom=((-6.5, 4.5), (-16.0, -8.0))):
    """The paper's Figure 5 with the ANN run of ``st.seeds[seed_index]`` (ellipses x10) and a
    zoom with the beacons-only map on top, ellipses at true size (section 5)."""
    fig, axes = figure(1, 2, height=7.0, width_ratios=(1, 1.1))
    ann_run = st.results["ann"][seed_index]
    plot_true_vs_mapped(ann_run, dataset, ax=axes[0], ellipse_scale=10.0, limits=CAR_PARK_LIMITS,
                        color=RED, label="ANN", title="Figure 5 with the ANN (ellipses x10)")
    plot_true_vs_mapped(ann_run, dataset, ax=axes[1], color=RED, label="ANN",
                        title="zoom: ANN and beacons-only, ellipses at true size")
    plot_true_vs_mapped(st.results["beacons"], ax=axes[1], color=BLUE, label="beacons-only",
                        show_truth=False)
    axes[1].set(xlim=zoom[0], ylim=zoom[1])
    return fig


def verdict_word(row: dict) -> str:
    """The verdict of one ``paper.study.verdict`` row: its 'verdict' word where a rule
    worded it (:func:`paper.study.fold_claim`: 'holds', 'does not hold', 'not
    demonstrated'), else from 'holds': True 'holds', False 'does not hold', None 'not
    testable this way'."""
    word = row.get("verdict")
    if word is None:
        word = {True: "holds", False: "does not hold", None: "not testable this way"}[row["holds"]]
    if word not in VERDICT_WORDS:
        raise ValueError(f"unknown verdict {word!r} in the row {row.get('claim')!r}")
    return word


def verdict_table(rows: list[dict]) -> str:
    """``paper.study.verdict``'s rows as a Markdown table (section 7): claim | what we
    measured | verdict (:func:`verdict_word`) | why."""
    lines = ["| the paper's claim | what we measured | verdict | why |", "|---|---|---|---|"]
    lines += [f"| {r['claim']} | {r['measured']} | {VERDICT_WORDS[verdict_word(r)]} | {r['why']} |"
              for r in rows]
    return "\n".join(lines)


def _line(s: dict, reference: dict | None) -> str:
    text = (f"R × {s['scale']:g}: sigma_range {s['sigma_range']:.3f} m, sigma_bearing "
            f"{math.degrees(s['sigma_bearing']):.2f}°; mean P_xx+P_yy {s['pose_trace']:.4f} m², "
            f"map RMSE {s['map_rmse']:.3f} m ({s['map_rmse_aligned']:.3f} m aligned), path RMSE "
            f"vs GPS {s['traj_rmse']:.3f} m, NIS/dof {s['nis_per_dof']:.2f}")
    if reference is not None:
        text += (f"\n{reference['label']}: mean P_xx+P_yy {reference['pose_trace']:.4f} m², map "
                 f"RMSE {reference['map_rmse']:.3f} m ({reference['map_rmse_aligned']:.3f} m "
                 f"aligned), path RMSE {reference['traj_rmse']:.3f} m")
    return text


def _view(sweep: dict, scale: float, reference: dict | None) -> Blit:
    """The explorer's figure at ``scale``, drawn once; a step moves the k trace, the legend
    and the markers (:func:`set_r_scale`) over the kept picture (:class:`plots.blit.Blit`).
    The first panel keeps one view that holds every k's trace."""
    fig = Figure(figsize=EXPLORER_FIGSIZE, dpi=DPI, layout="constrained")
    plot_r_scale(sweep, scale, reference, fig=fig)
    fig.axes[0].set_ylim(*r_scale_trace_limits(sweep, reference))
    return Blit(fig, r_scale_moving(fig))


def r_scale_explorer(dataset: Dataset | None = None, *, sweep: dict | None = None,
                     reference: dict | None = None, scale: float = 1.0,
                     config: SlamConfig | None = None, t_heldout: float | None = None):
    """A slider over the factor k of R: the beacons-only filter's position variance and map
    error for that k (:func:`plot_r_scale`) next to the ``reference`` run (e.g.
    :func:`reference_from_study`). ``sweep``: a precomputed :func:`r_scale_sweep`; without it
    one is computed from ``dataset`` over :data:`SCALES` (2 s on the Car Park).

    Returns a VBox (slider, image, text); the latest summary is in
    ``widget.holder["summary"]``, the sweep in ``holder["sweep"]``, the text in
    ``holder["text"]``. Plain Image and HTML widgets (no Output widget), like
    ``widgets.slam.slam_explorer``, for headless executors."""
    if sweep is None:
        if dataset is None:
            raise ValueError("r_scale_explorer needs a dataset or a precomputed sweep")
        sweep = r_scale_sweep(dataset, SCALES, config, t_heldout=t_heldout)
    if not isinstance(sweep, dict) or not sweep:
        raise ValueError("sweep must be the dict returned by r_scale_sweep")
    ks = sorted(sweep)
    if scale not in sweep:
        raise ValueError(f"scale {scale!r} is not in the sweep {tuple(ks)}")
    holder: dict = {"sweep": sweep}
    slider = SelectionSlider(options=[(f"{k:g}", k) for k in ks], value=scale,
                             description="R × k", continuous_update=False)
    w, h = (round(v * DPI) for v in EXPLORER_FIGSIZE)
    image = Image(format="png", width=w, height=h,
                  layout=Layout(width=f"{w}px", max_width="100%", height="auto"))
    text = HTML()

    view = _view(sweep, scale, reference)

    def update(_change=None) -> None:
        k = slider.value
        holder["summary"] = sweep[k]
        holder["text"] = _line(sweep[k], reference)
        view.replace(*set_r_scale(view.fig, sweep, k))
        show_in_image(image, view.png(), alt_text(view.fig))
        text.value = f"<pre>{html.escape(holder['text'])}</pre>"

    slider.observe(update, names="value")
    update()
    widget = VBox([slider, image, text])
    widget.holder = holder
    return keyboard_ready(widget)
