"""Chapter 05 explorer: the EKF-SLAM run on the Car Park, scrubbed in time and re-tuned.

The pure function :func:`slam_summary` runs the filter (``ekf_slam.run``, about 0.2 s on
the Car Park) on the data up to a time ``t_end`` (:func:`truncate`) and measures it: the
map against the surveyed beacons (``map_metrics.map_errors``), the path against GPS
(``metrics.trajectory_errors``), and the normalised NIS of the laser updates. The widget
:func:`slam_explorer` moves ``t_end`` and the noise / gate settings and draws the
Figure 5 view of the result (``slam_plots.plot_true_vs_mapped``).

Re-running up to ``t_end`` gives exactly the state the full run had at that time: the
filter is causal, and the initial pose is fixed once from the WHOLE run (the GPS heading
fit looks ahead ``initial_window`` seconds, so fitting it on a cut run would change it).
"""
from __future__ import annotations

import dataclasses
import html
import io
import math
import numbers

import numpy as np
from ipywidgets import HTML, FloatSlider, Image, SelectionSlider, VBox
from matplotlib.figure import Figure

from .. import ekf_slam, map_metrics, metrics
from ..dead_reckoning import initial_pose_from_gps
from ..ekf_slam import SlamConfig
from ..records import Dataset, Detections, Gps, Odometry, Truth
from ..slam_plots import CAR_PARK_LIMITS, plot_true_vs_mapped

__all__ = ["truncate", "fixed_initial_pose", "slam_summary", "slam_explorer", "GATE_OPTIONS"]

#: Gate probabilities offered by the explorer's gate slider.
GATE_OPTIONS = (0.5, 0.9, 0.95, 0.99, 0.999)


def truncate(dataset: Dataset, t_end: float) -> Dataset:
    """The run up to and including time ``t_end`` (s): odometry, GPS, raw laser scans,
    detections (whole scans), and the simulator's truth and scan poses.
    Raises ValueError for a non-finite ``t_end`` or one before the first odometry sample."""
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    if isinstance(t_end, bool) or not isinstance(t_end, numbers.Real) or not math.isfinite(t_end):
        raise ValueError(f"t_end must be a finite time in seconds, got {t_end!r}")
    odo = dataset.odometry
    if len(odo) == 0 or t_end < odo.t[0]:
        raise ValueError(f"t_end = {t_end} s lies before the first odometry sample")
    k = odo.t <= t_end
    odometry = Odometry(t=odo.t[k], speed=odo.speed[k], steering=odo.steering[k])
    g = dataset.gps.t <= t_end
    gps = Gps(t=dataset.gps.t[g], east=dataset.gps.east[g], north=dataset.gps.north[g])
    laser = None
    if dataset.laser is not None:
        s = dataset.laser.t <= t_end
        laser = dataclasses.replace(dataset.laser, t=dataset.laser.t[s],
                                    ranges=dataset.laser.ranges[s],
                                    intensity=dataset.laser.intensity[s])
    det = dataset.detections
    detections = None
    if det is not None:
        n = int(np.count_nonzero(det.t <= t_end))
        rows = slice(0, int(det.offsets[n]))
        detections = Detections(t=det.t[:n], offsets=det.offsets[:n + 1], range=det.range[rows],
                                bearing=det.bearing[rows], diameter=det.diameter[rows],
                                landmark_id=det.landmark_id[rows], intensity=det.intensity[rows])
    truth = None
    info = dict(dataset.info)
    if dataset.truth is not None:
        p = dataset.truth.poses
        truth = Truth(poses=p[p[:, 0] <= t_end], landmarks=dataset.truth.landmarks)
        if "scan_poses" in info:
            info["scan_poses"] = np.asarray(info["scan_poses"])[:len(dataset.scan_times)][
                dataset.scan_times <= t_end]
    return dataclasses.replace(dataset, odometry=odometry, gps=gps, laser=laser,
                               detections=detections, truth=truth, info=info)


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
    pose is fixed from the whole run first (:func:`fixed_initial_pose`).
    Returns a dict: ``result`` (the SlamResult), ``dataset`` (the data it ran on),
    ``t_end`` (its last odometry time), ``scans``, ``landmarks``,
    ``rejected`` (observations), and where the run has surveyed beacons ``matched``,
    ``missed``, ``spurious``, ``duplicates``, ``map_rmse``, ``map_rmse_aligned`` (m;
    NaN if fewer than 2 landmarks lie within ``max_distance`` of a beacon: no
    alignment), ``map_errors`` (the MapErrors or None); ``traj_rmse`` (m, the filtered
    path at the odometry rate against the GPS fixes, NaN if none falls in the span),
    ``nis_per_dof`` (total laser NIS / total dof, NaN without updates).
    """
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    cfg = SlamConfig.for_dataset(dataset.name) if config is None else config
    if not isinstance(cfg, SlamConfig):
        raise ValueError(f"config must be a SlamConfig, got {type(cfg).__name__}")
    ds = dataset
    if t_end is not None:
        cfg = fixed_initial_pose(dataset, cfg)
        ds = truncate(dataset, t_end)
    r = ekf_slam.run(ds, cfg, progress=False)
    out = {"result": r, "dataset": ds, "t_end": float(ds.odometry.t[-1]), "scans": r.counts["scans"],
           "landmarks": r.counts["landmarks"], "rejected": r.counts["rejected"],
           "map_errors": None}
    if dataset.beacons is not None:
        i, _ = map_metrics.match_landmarks(r.landmarks, dataset.beacons, max_distance)
        nan = float("nan")
        out.update(matched=int(i.size), missed=len(dataset.beacons) - int(i.size),
                   spurious=len(r.landmarks) - int(i.size), duplicates=0,
                   map_rmse=nan, map_rmse_aligned=nan)
        if i.size >= 2:
            m = map_metrics.map_errors(r.landmarks, dataset.beacons, max_distance=max_distance)
            out.update(map_errors=m, duplicates=m.duplicates, map_rmse=m.rmse,
                       map_rmse_aligned=m.rmse_aligned)
    traj = r.odometry_trajectory
    inside = (ds.gps.t >= traj[0, 0]) & (ds.gps.t <= traj[-1, 0]) if len(traj) else np.zeros(0)
    out["traj_rmse"] = (metrics.trajectory_errors(traj, ds.gps).rmse if np.any(inside)
                        else float("nan"))
    k = r.nis["kind"] == 0
    dof = float(np.sum(r.nis["dof"][k]))
    out["nis_per_dof"] = float(np.sum(r.nis["nis"][k]) / dof) if dof > 0 else float("nan")
    return out


def _line(s: dict) -> str:
    text = (f"t = {s['t_end']:.1f} s: {s['scans']} scans, {s['landmarks']} landmarks, "
            f"{s['rejected']} observations rejected, NIS/dof {s['nis_per_dof']:.3f}, "
            f"path RMSE vs GPS {s['traj_rmse']:.3f} m")
    if "matched" in s:
        text += (f"\nmap: {s['matched']} beacons matched, {s['missed']} not (yet) mapped, "
                 f"{s['spurious']} spurious ({s['duplicates']} duplicates); RMSE "
                 f"{s['map_rmse']:.3f} m absolute, {s['map_rmse_aligned']:.3f} m aligned")
    return text


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
        raise ValueError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
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
