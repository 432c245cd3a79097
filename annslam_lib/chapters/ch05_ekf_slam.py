"""Chapter 05 companion: the EKF-SLAM run on the Car Park, scrubbed in time and re-tuned (the
explorer), and the chapter's figures.

The pure function :func:`slam_summary` runs the filter (``slam.runner.run``, about 0.2 s on
the Car Park) on the data up to a time ``t_end`` (:func:`truncate`) and measures it: the
map against the surveyed beacons (``evaluation.map.map_errors``), the path against GPS
(``evaluation.trajectory.trajectory_errors``), and the normalised NIS of the laser updates. The widget
:func:`slam_explorer` moves ``t_end`` and the noise / gate settings and draws the
Figure 5 view of the result (``plots.slam.plot_true_vs_mapped``).

Re-running up to ``t_end`` gives exactly the state the full run had at that time: the
filter is causal, and the initial pose is fixed once from the WHOLE run (the GPS heading
fit looks ahead ``initial_window`` seconds, so fitting it on a cut run would change it).
"""
from __future__ import annotations

import html
import math

import numpy as np
from ipywidgets import HTML, FloatSlider, Image, Layout, SelectionSlider, VBox
from matplotlib.figure import Figure

from .. import _checks
from ..data.records import Dataset, truncate
from ..evaluation import consistency
from ..evaluation.summary import pose_trace, run_metrics
from ..evaluation.trajectory import trajectory_errors
from ..plots.slam import (CAR_PARK_LIMITS, plot_consistency, plot_correlation,
                          plot_landmark_zooms, plot_true_vs_mapped, true_path)
from ..plots.blit import Blit, drawn_by
from ..plots.alt import alt_text, describe
from ..plots.style import BLUE, DPI, FIG_WIDTH, GREEN, ORANGE, PURPLE, RED, figure, show_in_image
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig
from ..slam.runner import initial_pose, run

__all__ = ["setup", "fixed_initial_pose", "slam_summary", "slam_explorer", "GATE_OPTIONS",
           "consistency_figure", "nees_comparison_figure", "figure5", "landmark_zooms_figure",
           "correlation_figure", "CONSISTENCY_SEEDS", "WIDE_GATE", "consistency_study", "judge_study"]

#: Size of the explorer's image (inches at plots.style.DPI): shown at its own pixel size.
EXPLORER_FIGSIZE = (FIG_WIDTH, 5.6)

#: Gate probabilities offered by the explorer's gate slider.
GATE_OPTIONS = (0.5, 0.9, 0.95, 0.99, 0.999)

#: The consistency study's runs (section 4): 300 seeded scenes fixed before looking, not
#: used to choose any setting (chapter 04a's study uses the same scenes for localisation).
CONSISTENCY_SEEDS = tuple(range(20000, 20300))
#: The study's second filter: a 99.99 % gate (and a new-landmark threshold above it).
WIDE_GATE = {"gate_prob": 0.9999, "new_landmark_prob": 0.99999}


def consistency_study(seeds=CONSISTENCY_SEEDS) -> dict:
    """Chapter 05, section 4: the midpoint SLAM filter on ``seeds`` (the simulator's loop,
    two laps), with the course's 99 % gate and with :data:`WIDE_GATE` on the same runs,
    judged by :func:`judge_study`. Computed once per machine, then read back (the notebook
    computes the two Monte Carlos in separate cells)."""
    seeds = tuple(int(s) for s in seeds)
    return judge_study(consistency.monte_carlo(seeds, "midpoint"),
                       consistency.monte_carlo(seeds, "midpoint", **WIDE_GATE))


def judge_study(gate_99: consistency.MonteCarlo, gate_9999: consistency.MonteCarlo) -> dict:
    """The two gates' SLAM Monte Carlos on the same runs judged (chapter 05, section 4).

    Returns {'gate_99', 'gate_9999': the Monte Carlos; for each gate g, 'pose_g' and
    'map_g': consistency.Effect of each run's ANEES per dof and map NEES per dof
    (:data:`consistency.EFFECT_RULE`); 'pose_difference', 'map_difference': the paired
    Effect of 99 % minus 99.99 %}."""
    out = {"gate_99": gate_99, "gate_9999": gate_9999}
    for k in ("gate_99", "gate_9999"):
        if not isinstance(out[k], consistency.MonteCarlo) or out[k].map is None:
            raise TypeError(f"{k} must be a SLAM consistency.monte_carlo result (with a map)")
    if gate_99.nees_runs.shape != gate_9999.nees_runs.shape:
        raise ValueError("the two gates must be run on the same runs")
    vals = {}
    for g, label in (("99", "99 %"), ("9999", "99.99 %")):
        mc = out["gate_" + g]
        vals["pose_" + g] = consistency.run_ratios(mc.nees_runs)
        vals["map_" + g] = mc.map.runs
        out["pose_" + g] = consistency.ratio_effect(vals["pose_" + g], f"{label} gate, pose ANEES / dof")
        out["map_" + g] = consistency.ratio_effect(vals["map_" + g], f"{label} gate, map NEES / dof")
    for q in ("pose", "map"):
        out[q + "_difference"] = consistency.paired_effect(
            vals[q + "_99"], vals[q + "_9999"], f"99 % minus 99.99 %, {q} NEES / dof")
    return out


def fixed_initial_pose(dataset: Dataset, config: SlamConfig) -> SlamConfig:
    """``config`` with the initial pose it would use on the whole ``dataset`` made
    explicit (so that runs on a truncated dataset start from the same pose)."""
    if not isinstance(config.initial_pose, str):
        return config
    pose, _ = initial_pose(dataset, config)
    return config.replace(initial_pose=tuple(float(v) for v in pose))


def slam_summary(dataset: Dataset, config: SlamConfig | None = None, *, t_end: float | None = None,
                 max_distance: float = 1.0) -> dict:
    """Run EKF-SLAM on ``dataset`` up to ``t_end`` (None: the whole run) and measure it.

    config: None -> ``SlamConfig.for_dataset(dataset.name)``; with ``t_end`` its initial
    pose is fixed from the whole run first (:func:`fixed_initial_pose`). Returns a dict:
    ``result`` (the SlamResult), ``dataset`` (the data it ran on), ``t_end`` (its last
    odometry time), ``metrics`` (``evaluation.summary.run_metrics``, maps matched within
    ``max_distance``) and the metrics' own keys (``RunMetrics.as_dict``)."""
    _checks.instance("dataset", dataset, Dataset, "records.Dataset")
    cfg = SlamConfig.for_dataset(dataset.name) if config is None else config
    _checks.instance("config", cfg, SlamConfig)
    ds = dataset
    if t_end is not None:
        cfg = fixed_initial_pose(dataset, cfg)
        ds = truncate(dataset, t_end)
    r = run(ds, cfg, progress=False)
    m = run_metrics(r, ds, max_distance=max_distance)
    return {"result": r, "dataset": ds, "t_end": float(ds.odometry.t[-1]), "metrics": m,
            **m.as_dict()}


def _line(s: dict) -> str:
    return f"t = {s['t_end']:.1f} s: " + s["metrics"].line()


def _explorer_axes(fig):
    """The explorer's three axes (map; distance to GPS; position uncertainty), labelled."""
    gs = fig.add_gridspec(2, 2, width_ratios=[1, 1.25])
    ax = fig.add_subplot(gs[:, 0])
    ax_e, ax_p = fig.add_subplot(gs[0, 1]), fig.add_subplot(gs[1, 1])
    ax_e.set(ylabel="distance to GPS [m]", title="the path against GPS")
    ax_p.set_yscale("log")
    ax_p.set(xlabel="time [s]", ylabel="√(P_xx + P_yy) [m]",
             title="the filter's own position uncertainty")
    for a in (ax_e, ax_p):
        a.grid(True, alpha=0.3)
    return ax, ax_e, ax_p


def _curves(summary: dict):
    """The right panels' data: (t, distance to GPS) or None when no fix lies inside the run,
    and (t, sqrt(P_xx + P_yy))."""
    r, ds = summary["result"], summary["dataset"]
    odo = r.odometry_trajectory
    inside = (ds.gps.t >= odo[0, 0]) & (ds.gps.t <= odo[-1, 0])
    e = trajectory_errors(odo, ds.gps) if inside.any() else None
    t, tr = pose_trace(r)
    return (None if e is None else (e.t, e.error)), (t, np.sqrt(tr))


def _draw_data(axes3, summary: dict, ellipse_scale: float, limits, *, legend: bool) -> list:
    """Draw a summary's data on the explorer's axes; returns the artists drawn (and the
    map's title), so that a blitted step can remove them again."""
    ax, ax_e, ax_p = axes3

    def draw():
        r, ds = summary["result"], summary["dataset"]
        plot_true_vs_mapped(r, ds, ax=ax, ellipse_scale=ellipse_scale, limits=limits,
                            title=f"EKF-SLAM up to t = {summary['t_end']:.1f} s",
                            legend="below" if legend else None)
        x, y = r.trajectory[-1, 1:3]
        ax.plot(x, y, "o", color="k", ms=7, zorder=7)
        e, (t, sd) = _curves(summary)
        if e is not None:
            ax_e.plot(*e, lw=1.0, color=BLUE)
        ax_p.plot(t, sd, lw=1.0, color=PURPLE)

    _, drawn = drawn_by(axes3, draw)
    return [c for c in drawn if c is not ax.get_legend()] + [ax.title]   # the legend stays


def _view(summary: dict, extent: dict, limits, ellipse_scale: float, t_range) -> Blit:
    """The explorer's figure, drawn once (:class:`plots.blit.Blit`) with fixed views: the
    map at ``limits`` (None: around ``extent``'s path, map and truth), the right panels over
    ``t_range`` and the values of ``extent`` (a summary whose curves the view must hold,
    e.g. the run to the end); a step replaces only the data."""
    fig = Figure(figsize=EXPLORER_FIGSIZE, dpi=DPI, layout="constrained")
    axes3 = _explorer_axes(fig)
    ax, ax_e, ax_p = axes3
    own_limits = limits is None
    if own_limits:
        r, ds = extent["result"], extent["dataset"]
        pts = np.vstack([r.trajectory[:, 1:3], r.landmarks.reshape(-1, 2), true_path(ds)[0]])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 0.05 * max(float(np.max(hi - lo)), 1.0)
        limits = ((lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad))
    e, (_, sd) = _curves(extent)
    top = 1.1 * float(np.max(e[1])) if e is not None and len(e[1]) else 1.0
    ax_e.set_ylim(0.0, max(top, 1e-3))
    sd = sd[np.isfinite(sd) & (sd > 0)]
    ax_p.set_ylim(*((sd.min() / 1.3, sd.max() * 1.3) if sd.size else (1e-3, 1.0)))
    for a in (ax_e, ax_p):
        a.set_xlim(*t_range)
    moving = _draw_data(axes3, summary, ellipse_scale, limits, legend=True)
    view = Blit(fig, moving)
    view.limits, view.own_limits = limits, own_limits
    return view


def _fits(view: Blit, summary: dict) -> bool:
    """Whether a summary's curves lie inside the view's fixed ranges (else it is drawn anew)."""
    _, ax_e, ax_p = view.fig.axes
    e, (_, sd) = _curves(summary)
    if e is not None and len(e[1]) and float(np.max(e[1])) > ax_e.get_ylim()[1]:
        return False
    lo, hi = ax_p.get_ylim()
    sd = sd[np.isfinite(sd)]
    if sd.size and (float(sd.min()) < lo or float(sd.max()) > hi):
        return False
    if view.own_limits:                  # a map view of its own (not a surveyed site's)
        (x0, x1), (y0, y1) = view.limits
        p = summary["result"].trajectory[:, 1:3]
        return bool(np.all((p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)))
    return True


def _step(view: Blit, summary: dict, ellipse_scale: float) -> None:
    """Replace the data of a view by a summary's (a blitted step)."""
    ax = view.fig.axes[0]
    view.clear(keep=(ax.title,))
    view.set_moving(_draw_data(view.fig.axes, summary, ellipse_scale, view.limits, legend=False))


def slam_explorer(dataset: Dataset, config: SlamConfig | None = None, *,
                  t_end: float | None = None, ellipse_scale: float = 10.0):
    """Sliders over the run's time and the filter's noise and gate; each change re-runs
    the filter (:func:`slam_summary`) and draws the map with its 2-sigma ellipses
    (magnified ``ellipse_scale`` times) and the summary line below it.

    Returns a VBox whose first six children are the sliders (t, sigma speed, sigma steer
    in degrees, sigma range, sigma bearing in degrees, gate probability), then the image
    and the text. The latest summary dict is in ``widget.holder["summary"]``, its text in
    ``holder["text"]``.

    The figure blits (:class:`plots.blit.Blit`): its views are fixed to hold the run to the
    slider's end at the starting settings (a run cut at t is a prefix of it), so a step of
    t only re-runs the filter and draws the data; a setting whose curves leave the view gets
    a new view (the run to the end at that setting, then drawn in full).

    Built from plain widgets (an Image and an HTML text) rather than ``interactive``: an
    Output widget makes headless executors (nbclient) send every captured output back
    to the kernel on the shell channel while they wait for the cell's reply on the same
    socket, and with this widget's large figure that intermittently left notebook
    execution hanging.
    """
    if not isinstance(dataset, Dataset):
        raise TypeError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    base = fixed_initial_pose(dataset, SlamConfig.for_dataset(dataset.name)
                              if config is None else config)
    t0 = float(dataset.odometry.t[0])
    ends = [dataset.odometry.t[-1], dataset.gps.t[-1] if len(dataset.gps) else -math.inf]
    if dataset.scan_times.size:
        ends.append(dataset.scan_times[-1])
    t1 = math.ceil(2.0 * float(max(ends))) / 2.0          # on the slider's 0.5 s grid
    start = t1 if t_end is None else float(min(max(t_end, t0), t1))
    limits = CAR_PARK_LIMITS if dataset.name == "car_park" else None
    gate0 = min(GATE_OPTIONS, key=lambda g: abs(g - base.gate_prob))
    holder: dict = {}

    sliders = [
        FloatSlider(value=start, min=min(t0 + 1.0, t1), max=t1, step=0.5,
                    description="t [s]", continuous_update=False),
        FloatSlider(value=base.sigma_speed, min=0.05, max=1.5, step=0.05,
                    description="σ speed", continuous_update=False),
        FloatSlider(value=round(math.degrees(base.sigma_steer), 1), min=0.5, max=15.0, step=0.5,
                    description="σ steer °", continuous_update=False),
        FloatSlider(value=base.sigma_range, min=0.01, max=0.5, step=0.01,
                    description="σ range", continuous_update=False),
        FloatSlider(value=round(math.degrees(base.sigma_bearing), 1), min=0.1, max=5.0,
                    step=0.1, description="σ bearing °", continuous_update=False),
        SelectionSlider(options=list(GATE_OPTIONS), value=gate0, description="gate",
                        continuous_update=False),
    ]
    # shown at its own pixel size (a stretched PNG is blurred), never wider than the page
    w, h = (round(v * DPI) for v in EXPLORER_FIGSIZE)
    image = Image(format="png", width=w, height=h,
                  layout=Layout(width=f"{w}px", max_width="100%", height="auto"))
    text = HTML()

    # The view's ranges hold the run to the slider's end at these settings (a run cut at t is
    # a prefix of it: see the module docstring), so moving t only redraws the data.
    extent = slam_summary(dataset, base, t_end=t1)
    t_range = (t0, max(float(extent["t_end"]), t0 + 1.0))
    view: list = []

    def update(_change=None) -> None:
        t, sv, sa, sr, sb, gate = (float(w.value) for w in sliders)
        cfg = base.replace(sigma_speed=sv, sigma_steer=math.radians(sa), sigma_range=sr,
                           sigma_bearing=math.radians(sb), gate_prob=gate,
                           new_landmark_prob=max(base.new_landmark_prob, gate))
        s = slam_summary(dataset, cfg, t_end=t)
        holder["summary"], holder["text"] = s, _line(s)
        if not view or not _fits(view[0], s):
            # the first draw, or a setting took the curves outside the view: drawn anew, its
            # ranges holding the run to the end at these settings
            ext = extent if not view else slam_summary(dataset, cfg, t_end=t1)
            view[:] = [_view(s, ext, limits, ellipse_scale, t_range)]
        else:
            _step(view[0], s, ellipse_scale)
        show_in_image(image, view[0].png(), alt_text(view[0].fig))
        text.value = f"<pre>{html.escape(holder['text'])}</pre>"

    for w in sliders:
        w.observe(update, names="value")
    update()
    widget = VBox([*sliders, image, text])
    widget.holder = holder
    return keyboard_ready(widget)


def _turning_shade(ax, t, turning) -> None:
    ax.fill_between(t, 0, 1, where=turning, transform=ax.get_xaxis_transform(),
                    color=ORANGE, alpha=0.12, step="mid", label="turning")


def consistency_figure(t_scan, turning, nees, nis, *, title: str = "average pose NEES"):
    """Average pose NEES (top, titled ``title``) and normalised NIS (bottom) of a
    Monte-Carlo batch with their bands, the turns shaded."""
    fig, axs = figure(2, 1, height=6.0, sharex=True)
    for ax in axs:
        _turning_shade(ax, t_scan, turning)
    plot_consistency(nees, ax=axs[0], expected=3.0, title=title)
    plot_consistency(nis, ax=axs[1], expected=1.0, title="normalised NIS")
    axs[0].set(ylim=(0, 8), xlabel="")
    axs[1].set_ylim(0.6, 1.4)
    return fig


def nees_comparison_figure(t_scan, turning, nees_a, nees_b, labels=("Euler", "midpoint")):
    """Two average-NEES curves on one band (the first's), the turns shaded."""
    fig, ax = figure(height=3.8)
    _turning_shade(ax, t_scan, turning)
    plot_consistency(nees_a, ax=ax, expected=3.0, color=RED,
                     label=f"{labels[0]}: mean {nees_a.mean:.2f}, {100 * nees_a.inside:.0f} % inside")
    ax.plot(nees_b.t, nees_b.value, "-", lw=0.9, color=GREEN,
            label=f"{labels[1]}: mean {nees_b.mean:.2f}, {100 * nees_b.inside:.0f} % inside")
    ax.set(ylim=(0, 8), title=f"average pose NEES: {labels[0]} against {labels[1]}")
    ax.legend(loc="upper right", ncol=2)
    return fig


def figure5(result, dataset, *, ellipse_scale: float = 10.0, max_distance: float = 1.0):
    """The paper's Figure 5 (true and mapped path and beacons, 2-sigma ellipses magnified
    ``ellipse_scale`` times), and what it never gives: each beacon's distance from its
    mapped landmark, against the landmark's own 2-sigma radius."""
    from ..evaluation.map import map_errors
    fig, (ax0, ax1) = figure(1, 2, height=7.0, width_ratios=[1, 1.1])
    plot_true_vs_mapped(result, dataset, ax=ax0, ellipse_scale=ellipse_scale,
                        limits=CAR_PARK_LIMITS, title="Car Park: true and mapped (the paper's Figure 5)")
    m = map_errors(result.landmarks, dataset.beacons, max_distance=max_distance)
    order = np.argsort(m.j_true)
    i, j = m.i_mapped[order], m.j_true[order]
    err = np.hypot(*(result.landmarks[i] - dataset.beacons[j]).T)
    sig = np.sqrt(np.linalg.eigvalsh(result.landmark_cov[i])[:, 1])
    x = np.arange(j.size)
    ax1.bar(x, 100 * err, color=BLUE, label="mapped − surveyed")
    ax1.plot(x, 200 * sig, "k_", ms=14, mew=2, label="2σ of the landmark (largest axis)")
    ax1.set_xticks(x, [str(v) for v in j])
    ax1.set(xlabel="surveyed beacon", ylabel="distance [cm]",
            title=f"map error per beacon: RMSE {100 * m.rmse:.1f} cm")
    ax1.grid(True, axis="y", alpha=0.3)
    ax1.legend(loc="upper left")
    return fig


def landmark_zooms_figure(result, beacons, map_err):
    """:func:`plots.slam.plot_landmark_zooms` of every matched beacon, at full width."""
    order = np.argsort(map_err.j_true)
    k = order.size
    ncols = 8
    fig, axs = figure(-(-k // ncols), ncols, height=1.45 * -(-k // ncols), squeeze=False)
    half_width, n_sigma = 0.25, 2.0
    plot_landmark_zooms(result.landmarks, result.landmark_cov, beacons,
                        map_err.i_mapped[order], map_err.j_true[order], axes=axs,
                        half_width=half_width, n_sigma=n_sigma)
    return describe(fig, f"One panel for each of the {k} mapped surveyed beacons, "
                         f"{200 * half_width:.0f} cm wide at true scale: the surveyed position "
                         f"(star), the mapped one (cross) and its {n_sigma:g}-sigma ellipse; "
                         "each title gives the beacon, the distance between "
                         "the two and its squared Mahalanobis distance d²")


def correlation_figure(runs: dict):
    """The final state's correlation matrix of each {title: SlamResult}, side by side."""
    fig, axs = figure(1, len(runs), height=5.2)
    for ax, (name, r) in zip(np.atleast_1d(axs), runs.items()):
        plot_correlation(r.covariance, ax=ax, title=f"final state correlation: {name}")
    sizes = ", ".join(f"{(r.covariance.shape[0] - 3) // 2} landmarks ({name})"
                      for name, r in runs.items())
    return describe(fig, "The correlation matrix of the final state, one panel per run "
                         f"({sizes}): pose x, y, φ first, then each landmark's x and y, "
                         "coloured from -1 (blue) through 0 (white) to +1 (red)")

