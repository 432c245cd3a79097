"""Chapter 05 explorer: the EKF-SLAM run on the Car Park, scrubbed in time and re-tuned.

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
import io
import math

from ipywidgets import HTML, FloatSlider, Image, SelectionSlider, VBox
from matplotlib.figure import Figure

from .. import _checks
from ..data.records import Dataset, truncate
from ..evaluation.summary import run_metrics
from ..plots.slam import CAR_PARK_LIMITS, plot_true_vs_mapped
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig
from ..slam.dead_reckoning import initial_pose_from_gps
from ..slam.runner import run

__all__ = ["setup", "fixed_initial_pose", "slam_summary", "slam_explorer", "GATE_OPTIONS"]

#: Gate probabilities offered by the explorer's gate slider.
GATE_OPTIONS = (0.5, 0.9, 0.95, 0.99, 0.999)


def fixed_initial_pose(dataset: Dataset, config: SlamConfig) -> SlamConfig:
    """``config`` with the initial pose it would use on the whole ``dataset`` made
    explicit (so that runs on a truncated dataset start from the same pose)."""
    policy = config.initial_pose
    if policy == "auto":
        policy = "truth" if dataset.truth is not None else "gps"
    if policy == "truth":
        pose = dataset.truth.poses[0, 1:4]
    elif policy == "gps":
        pose = initial_pose_from_gps(dataset.odometry, dataset.gps, dataset.vehicle,
                                     window=config.initial_window).pose
    else:
        return config
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


def _render(summary: dict, limits, ellipse_scale: float) -> bytes:
    """The Figure 5 view of a summary as PNG bytes (a matplotlib Figure, not pyplot: nothing
    is displayed as a side effect)."""
    fig = Figure(figsize=(6.0, 7.5), dpi=80)
    ax = fig.subplots()
    # the truth up to the same time (the surveyed beacons are all drawn: they are the map
    # being built), and the car's position now
    plot_true_vs_mapped(summary["result"], summary["dataset"], ax=ax,
                        ellipse_scale=ellipse_scale, limits=limits,
                        title=f"EKF-SLAM up to t = {summary['t_end']:.1f} s")
    x, y = summary["result"].trajectory[-1, 1:3]
    ax.plot(x, y, "o", color="k", ms=7, zorder=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def slam_explorer(dataset: Dataset, config: SlamConfig | None = None, *,
                  t_end: float | None = None, ellipse_scale: float = 10.0):
    """Sliders over the run's time and the filter's noise and gate; each change re-runs
    the filter (:func:`slam_summary`) and draws the map with its 2-sigma ellipses
    (magnified ``ellipse_scale`` times) and the summary line below it.

    Returns a VBox whose first six children are the sliders (t, sigma speed, sigma steer
    in degrees, sigma range, sigma bearing in degrees, gate probability), then the image
    and the text. The latest summary dict is in ``widget.holder["summary"]``, its text in
    ``holder["text"]``.

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
    image = Image(format="png")
    text = HTML()

    def update(_change=None) -> None:
        t, sv, sa, sr, sb, gate = (float(w.value) for w in sliders)
        cfg = base.replace(sigma_speed=sv, sigma_steer=math.radians(sa), sigma_range=sr,
                           sigma_bearing=math.radians(sb), gate_prob=gate,
                           new_landmark_prob=max(base.new_landmark_prob, gate))
        s = slam_summary(dataset, cfg, t_end=t)
        holder["summary"], holder["text"] = s, _line(s)
        image.value = _render(s, limits, ellipse_scale)
        text.value = f"<pre>{html.escape(holder['text'])}</pre>"

    for w in sliders:
        w.observe(update, names="value")
    update()
    widget = VBox([*sliders, image, text])
    widget.holder = holder
    return widget
