"""The EKF against factor-graph smoothing on the same data (chapter 10;
``python -m annslam_lib compare --out DIR``).

Per dataset: the course's EKF-SLAM run (``slam.run`` with the dataset's configuration),
the graph of that run (``smoothing.problem.build_problem``: its associations, its noise,
its start), solved by iSAM2 one pose at a time and then by batch Levenberg-Marquardt from
the iSAM2 solution (``smoothing.solve``). Rows of :func:`compare`:

- ``traj_rmse_m``, ``traj_rmse_aligned_m``: the dense track (at every odometry sample;
  for a graph the smoothed poses carried forward by the odometry) against the valid GPS
  fixes (chapter 06: without ``evaluation.trajectory.gps_outliers``), absolute and after
  the best rigid motion;
- ``map_rmse_aligned_m``: the map against the surveyed beacons after the best rigid motion
  (``evaluation.map.map_errors``), None without a surveyed map (Victoria Park);
- ``cpu_s``: process CPU seconds of the estimator's own work (EKF: the run; iSAM2: building
  the graph and the updates; batch: the LM pass); ``cpu_total_s``: everything its answer
  needed (iSAM2 and batch use the EKF's associations, and batch starts from iSAM2).

The smoothers use the data the EKF used (GPS only where the EKF took it, the first seconds)
and every scan's detections at once: the track is a smoothed one, not a filtered one.
Timings depend on the machine and its load: read them against each other.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from ..data.records import Gps
from ..evaluation.map import map_errors
from ..evaluation.trajectory import gps_outliers, trajectory_errors
from .problem import build_problem
from .solve import solve_batch, solve_isam2
from ..plots.style import BLUE, GREEN, PURPLE, RED

__all__ = ["DATASETS", "ESTIMATORS", "valid_fixes", "compare", "compare_dataset",
           "write_comparison", "plot_comparison"]

DATASETS = ("car_park", "victoria_park")
ESTIMATORS = ("ekf", "isam2", "batch")


def valid_fixes(gps: Gps) -> Gps:
    """The GPS fixes without those no car could have reached (chapter 06's valid fixes)."""
    ok = ~gps_outliers(gps)
    return Gps(t=gps.t[ok], east=gps.east[ok], north=gps.north[ok])


def compare_dataset(name: str, *, every: int = 1) -> tuple[list[dict], dict]:
    """Rows (module docstring) for one dataset, and what the figure needs (tracks, maps,
    GPS, iSAM2's cost per update)."""
    from ..data import loaders
    from ..slam import SlamConfig, run
    if name not in DATASETS:
        raise ValueError(f"dataset must be one of {DATASETS}, got {name!r}")
    ds = loaders.load(name)
    c0 = time.process_time()
    ekf = run(ds, SlamConfig.for_dataset(name), progress=False)
    ekf_cpu = time.process_time() - c0
    c0 = time.process_time()
    problem = build_problem(ds, ekf)
    build_cpu = time.process_time() - c0
    isam = solve_isam2(problem, every=every)
    batch = solve_batch(problem, isam.poses, isam.landmarks)
    gps = valid_fixes(ds.gps)
    tracks = {"ekf": ekf.odometry_trajectory, "isam2": problem.dense_track(isam.poses),
              "batch": problem.dense_track(batch.poses)}
    maps = {"ekf": ekf.landmarks, "isam2": isam.landmarks, "batch": batch.landmarks}
    own = {"ekf": ekf_cpu, "isam2": build_cpu + isam.cpu_s, "batch": batch.cpu_s}
    total = {"ekf": ekf_cpu, "isam2": ekf_cpu + build_cpu + isam.cpu_s,
             "batch": ekf_cpu + build_cpu + isam.cpu_s + batch.cpu_s}
    rows = []
    for est in ESTIMATORS:
        e = trajectory_errors(tracks[est], gps)
        m = (None if ds.beacons is None
             else float(map_errors(maps[est], ds.beacons).rmse_aligned))
        rows.append({"dataset": name, "estimator": est, "traj_rmse_m": float(e.rmse),
                     "traj_rmse_aligned_m": float(e.rmse_aligned), "map_rmse_aligned_m": m,
                     "cpu_s": float(own[est]), "cpu_total_s": float(total[est]),
                     "poses": problem.n_poses, "landmarks": int(maps[est].shape[0])})
    extra = {"tracks": tracks, "maps": maps, "gps": gps, "beacons": ds.beacons,
             "step_cpu": isam.step_cpu, "step_landmarks": isam.step_landmarks,
             "ekf_cpu_per_scan": ekf_cpu / max(ekf.counts["scans"], 1),
             "errors": {"isam2": isam.error_final, "batch": batch.error_final},
             "counts": problem.counts}
    return rows, extra


def compare(datasets=DATASETS, *, every: int = 1) -> tuple[list[dict], dict]:
    """Rows for every dataset (EKF, iSAM2, batch each), and per dataset the figure's data."""
    rows, extras = [], {}
    for name in datasets:
        r, x = compare_dataset(name, every=every)
        rows += r
        extras[name] = x
    return rows, extras


def plot_comparison(rows, extras):
    """One row of panels per dataset: the tracks against GPS (and the map against the
    beacons), and iSAM2's CPU per update as the map grows beside the EKF's per scan."""
    import matplotlib.pyplot as plt
    names = list(extras)
    fig, axes = plt.subplots(len(names), 2, figsize=(11, 4.6 * len(names)), squeeze=False,
                             layout="constrained")
    colour = {"ekf": RED, "isam2": GREEN, "batch": "k"}
    for (ax, ax2), name in zip(axes, names):
        x = extras[name]
        ax.plot(x["gps"].east, x["gps"].north, ".", ms=2, color=BLUE, label="GPS (valid)")
        for est in ESTIMATORS:
            row = next(r for r in rows if r["dataset"] == name and r["estimator"] == est)
            tr = x["tracks"][est]
            ax.plot(tr[:, 1], tr[:, 2], "-", lw=0.8, color=colour[est],
                    label=f"{est}: {row['traj_rmse_m']:.2f} m ({row['traj_rmse_aligned_m']:.2f} aligned)")
        if x["beacons"] is not None:
            ax.plot(*x["beacons"].T, "s", mfc="none", color=PURPLE, label="surveyed beacons")
        ax.plot(*x["maps"]["batch"].T, "+", color="k", ms=5, label="batch map")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{name}: tracks against GPS (RMSE absolute, aligned)")
        ax.set_xlabel("East (m)")
        ax.set_ylabel("North (m)")
        ax.legend(loc="best")
        step = np.asarray(x["step_cpu"]) * 1e3
        ax2.plot(x["step_landmarks"], step, ".", ms=2, color=GREEN, alpha=0.4,
                 label="iSAM2, one update")
        if step.size >= 25:
            k = 25
            med = np.array([np.median(step[max(0, i - k):i + k]) for i in range(step.size)])
            ax2.plot(x["step_landmarks"], med, "-", color=GREEN, label="iSAM2, running median")
        ax2.axhline(x["ekf_cpu_per_scan"] * 1e3, color=RED,
                    label="EKF, mean per scan (whole run / scans)")
        ax2.set_yscale("log")
        ax2.set_xlabel("landmarks in the map")
        ax2.set_ylabel("CPU per step (ms)")
        ax2.set_title(f"{name}: cost per step as the map grows")
        ax2.legend()
    return fig


def write_comparison(out, datasets=DATASETS, *, every: int = 1) -> Path:
    """``python -m annslam_lib compare --out DIR``: DIR/comparison.json (the rows) and
    DIR/comparison.png (:func:`plot_comparison`). Returns the JSON's path."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows, extras = compare(datasets, every=every)
    for r in rows:
        for k, v in r.items():
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"{r['dataset']} / {r['estimator']}: {k} is {v}")
    path = out / "comparison.json"
    path.write_text(json.dumps(rows, indent=1) + "\n")
    fig = plot_comparison(rows, extras)
    fig.savefig(out / "comparison.png", dpi=110)
    plt.close(fig)
    return path
