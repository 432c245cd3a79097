"""The EKF against factor-graph smoothing on the same data (chapter 10;
``python -m annslam_lib compare --out DIR``).

Per dataset: the course's EKF-SLAM run (``slam.run`` with the dataset's configuration),
the graph of that run (``smoothing.problem.build_problem``: its associations, its noise,
its start), solved by iSAM2 one pose at a time and then by batch Levenberg-Marquardt from
the iSAM2 solution (``smoothing.solve``). Rows of :func:`compare`:

- ``traj_rmse_m``, ``traj_rmse_aligned_m``: the dense track (at every odometry sample;
  for a graph the node poses carried forward by the odometry) against the valid GPS
  fixes (chapter 06: without ``evaluation.trajectory.gps_outliers``), absolute and after
  the best rigid motion;
- ``map_rmse_aligned_m``: the map against the surveyed beacons after the best rigid motion
  (``evaluation.map.map_errors``), None without a surveyed map (Victoria Park);
- ``cpu_s``: process CPU seconds of the estimator's own work (EKF: the run; iSAM2: building
  the graph and the whole incremental loop; batch: the LM pass); ``cpu_total_s``:
  everything its answer needed (iSAM2 and batch use the EKF's associations, and batch
  starts from iSAM2).

Estimators: ``ekf``; ``isam2_filtered``, iSAM2's estimate of each pose right after the
update that added it (what it knew at that time, as a filter: the same iSAM2 run, so the
same CPU); ``isam2``, iSAM2's final estimate (smoothed: every pose from all the data);
``batch``. The smoothers use the data the EKF used (GPS only where the EKF took it, the
first seconds) and the EKF's associations.

Cost, like for like (:func:`timed_run`): both sides' whole process CPU, cut at each
processed scan, so that the EKF's and iSAM2's arrays hold the same work per entry.
Timings depend on the machine and its load: read them against each other.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from dataclasses import dataclass

from .. import _checks
from ..data.records import Dataset, Gps
from ..evaluation.map import map_errors
from ..evaluation.trajectory import gps_outliers, trajectory_errors
from ..slam.results import SlamResult
from .problem import KIND, GraphProblem, build_problem
from .solve import SmoothingResult, solve_batch, solve_isam2
from ..plots.style import BLUE, GREEN, ORANGE, PURPLE, RED

__all__ = ["DATASETS", "ESTIMATORS", "valid_fixes", "TimedRun", "timed_run", "compare",
           "compare_dataset", "write_comparison", "plot_comparison", "cost_panel",
           "running_median"]

DATASETS = ("car_park", "victoria_park")
ESTIMATORS = ("ekf", "isam2_filtered", "isam2", "batch")


def valid_fixes(gps: Gps) -> Gps:
    """The GPS fixes without those no car could have reached (chapter 06's valid fixes)."""
    ok = ~gps_outliers(gps)
    return Gps(t=gps.t[ok], east=gps.east[ok], north=gps.north[ok])


@dataclass
class TimedRun:
    """The EKF and iSAM2 on one dataset, timed alike (:func:`timed_run`, chapter 10).

    Per processed scan (S of them, the EKF's ``scan_index`` order): scan_t (S,) its time;
    ekf_scan_cpu, isam2_scan_cpu (S,): each side's whole process CPU seconds from the end of
    the previous scan to the end of this one (the EKF: predictions, GPS updates in between,
    gating, association, the update, new landmarks, its bookkeeping; iSAM2: the poses'
    factors and start values, the update, reading the estimate); the first scan also carries
    each side's set-up (the EKF: screening, the odometry compounded; iSAM2: building the
    graph, ``build_problem``); isam2_update_cpu (S,): the part of isam2_scan_cpu spent in
    ``isam.update`` alone; ekf_landmarks, isam2_landmarks (S,): the landmarks in each
    one's map after the scan. ekf_cpu: the EKF run's whole CPU; isam2_cpu: building the
    graph and the whole iSAM2 solve (without the EKF it took its associations from).
    ekf, problem, isam2: the results (``isam2.filtered``: its estimate of each pose right
    after that pose's update; ``isam2.poses``: the final, smoothed one)."""

    dataset: str
    scan_t: np.ndarray
    ekf_scan_cpu: np.ndarray
    isam2_scan_cpu: np.ndarray
    isam2_update_cpu: np.ndarray
    ekf_landmarks: np.ndarray
    isam2_landmarks: np.ndarray
    ekf_cpu: float
    isam2_cpu: float
    ekf: SlamResult
    problem: GraphProblem
    isam2: SmoothingResult

    def tracks(self) -> dict:
        """Dense tracks (t, x, y, phi) at every odometry sample: 'ekf' (the filter's),
        'isam2_filtered' and 'isam2' (the graph's node poses carried forward by the
        odometry, ``GraphProblem.dense_track``)."""
        return {"ekf": self.ekf.odometry_trajectory,
                "isam2_filtered": self.problem.dense_track(self.isam2.filtered),
                "isam2": self.problem.dense_track(self.isam2.poses)}


def _per_scan(values: np.ndarray, scan_nodes: np.ndarray) -> np.ndarray:
    """Node values summed per scan: each node goes to the first scan node at or after it
    (a GPS node to the next scan); nodes after the last scan are left out."""
    K = values.size
    grp = np.searchsorted(scan_nodes, np.arange(K), side="left")
    keep = grp < scan_nodes.size
    return np.bincount(grp[keep], weights=values[keep], minlength=scan_nodes.size)


def timed_run(dataset, config=None, *, every: int = 1) -> TimedRun:
    """Chapter 10, filtering against smoothing like for like: the course's EKF-SLAM run on
    ``dataset`` (a ``records.Dataset`` or a name of :data:`DATASETS`; ``config`` a
    ``SlamConfig``, default the dataset's), its graph, and iSAM2 over it (``every``
    poses per update; ``every = 1`` makes ``isam2.filtered`` a filtered estimate), each
    side's whole process CPU (``time.process_time``) cut at every processed scan
    (:class:`TimedRun`). The EKF's cut is taken where the run loop stores the scan's pose
    covariance (``inspect`` wraps ``pose_cov_entries``), after the scan's update and new
    landmarks.

    Raises ValueError for an unknown name or a bad ``every``, TypeError for a
    ``config`` that is not a ``SlamConfig``.
    """
    from ..data import loaders
    from ..slam import SlamConfig, run
    if isinstance(dataset, str):
        _checks.choice("dataset", dataset, DATASETS)
        dataset = loaders.load(dataset)
    _checks.instance("dataset", dataset, Dataset)
    every = _checks.integer("every", every, lo=1)
    if config is None:
        config = SlamConfig.for_dataset(dataset.name)
    _checks.instance("config", config, SlamConfig)
    stamps, lms = [], []

    def stamp(filt) -> None:
        inner = filt.pose_cov_entries

        def stamped():
            out = inner()
            lms.append(filt.n_landmarks)
            stamps.append(time.process_time())
            return out
        filt.pose_cov_entries = stamped

    c0 = time.process_time()
    ekf = run(dataset, config, progress=False, inspect=stamp)
    ekf_cpu = time.process_time() - c0
    S = int(ekf.counts["scans"])
    if len(stamps) != S:
        raise RuntimeError(f"the EKF's run stored {len(stamps)} scan poses for {S} scans")
    ekf_scan = np.diff(np.array(stamps), prepend=c0)
    c1 = time.process_time()
    problem = build_problem(dataset, ekf)
    build_cpu = time.process_time() - c1
    isam = solve_isam2(problem, every=every)
    scan_nodes = np.flatnonzero(problem.kind == KIND["scan"])
    if not np.array_equal(problem.scan[scan_nodes], ekf.scan_index):
        raise RuntimeError("the graph's scan poses are not the EKF's processed scans")
    node = isam.node_cpu.copy()
    node[0] += build_cpu
    updated = np.array([k for k in range(problem.n_poses)
                        if (k + 1) % every == 0 or k == problem.n_poses - 1])
    upd = np.zeros(problem.n_poses)
    upd[updated] = isam.step_cpu
    first = np.full(problem.n_landmarks, problem.n_poses)
    np.minimum.at(first, problem.obs_landmark, problem.obs_node)
    return TimedRun(dataset=dataset.name, scan_t=problem.t[scan_nodes].copy(),
                    ekf_scan_cpu=ekf_scan, isam2_scan_cpu=_per_scan(node, scan_nodes),
                    isam2_update_cpu=_per_scan(upd, scan_nodes),
                    ekf_landmarks=np.array(lms, dtype=np.int64),
                    isam2_landmarks=np.searchsorted(np.sort(first), scan_nodes, side="right"),
                    ekf_cpu=float(ekf_cpu), isam2_cpu=float(build_cpu + isam.cpu_s),
                    ekf=ekf, problem=problem, isam2=isam)


def compare_dataset(name: str, *, every: int = 1) -> tuple[list[dict], dict]:
    """Rows (module docstring) for one dataset, and what the figure needs (tracks, maps,
    GPS, the :class:`TimedRun` with both sides' CPU per scan)."""
    if name not in DATASETS:
        raise ValueError(f"dataset must be one of {DATASETS}, got {name!r}")
    from ..data import loaders
    ds = loaders.load(name)
    tr = timed_run(ds, every=every)
    batch = solve_batch(tr.problem, tr.isam2.poses, tr.isam2.landmarks)
    gps = valid_fixes(ds.gps)
    tracks = tr.tracks()
    tracks["batch"] = tr.problem.dense_track(batch.poses)
    isam = tr.isam2
    maps = {"ekf": tr.ekf.landmarks, "isam2_filtered": isam.landmarks, "isam2": isam.landmarks,
            "batch": batch.landmarks}
    own = {"ekf": tr.ekf_cpu, "isam2_filtered": tr.isam2_cpu, "isam2": tr.isam2_cpu,
           "batch": batch.cpu_s}
    total = {"ekf": tr.ekf_cpu, "isam2_filtered": tr.ekf_cpu + tr.isam2_cpu,
             "isam2": tr.ekf_cpu + tr.isam2_cpu,
             "batch": tr.ekf_cpu + tr.isam2_cpu + batch.cpu_s}
    rows = []
    for est in ESTIMATORS:
        e = trajectory_errors(tracks[est], gps)
        m = (None if ds.beacons is None or est == "isam2_filtered"
             else float(map_errors(maps[est], ds.beacons).rmse_aligned))
        rows.append({"dataset": name, "estimator": est, "traj_rmse_m": float(e.rmse),
                     "traj_rmse_aligned_m": float(e.rmse_aligned), "map_rmse_aligned_m": m,
                     "cpu_s": float(own[est]), "cpu_total_s": float(total[est]),
                     "poses": tr.problem.n_poses, "landmarks": int(maps[est].shape[0])})
    extra = {"tracks": tracks, "maps": maps, "gps": gps, "beacons": ds.beacons, "timed": tr,
             "errors": {"isam2": isam.error_final, "batch": batch.error_final},
             "counts": tr.problem.counts}
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
    beacons), and both sides' whole CPU per processed scan as the map grows
    (:func:`cost_panel`)."""
    import matplotlib.pyplot as plt
    names = list(extras)
    fig, axes = plt.subplots(len(names), 2, figsize=(11, 4.6 * len(names)), squeeze=False,
                             layout="constrained")
    colour = {"ekf": RED, "isam2_filtered": ORANGE, "isam2": GREEN, "batch": "k"}
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
        tr = x["timed"]
        cost_panel(ax2, tr.ekf_scan_cpu, tr.ekf_landmarks, tr.isam2_scan_cpu, tr.isam2_landmarks)
        ax2.set_title(f"{name}: CPU per scan as the map grows")
    return fig


def running_median(values, half: int = 25) -> np.ndarray:
    """Median of ``values`` over a window of ``2 half`` entries around each (shorter at the
    ends)."""
    v = np.asarray(values, dtype=float)
    half = _checks.integer("half", half, lo=1)
    return np.array([np.median(v[max(0, i - half):i + half]) for i in range(v.size)])


def cost_panel(ax, ekf_cpu, ekf_landmarks, isam2_cpu, isam2_landmarks) -> None:
    """Both sides' whole CPU seconds per processed scan (``TimedRun.ekf_scan_cpu``,
    ``isam2_scan_cpu``) against the landmarks in each one's map then
    (``ekf_landmarks``, ``isam2_landmarks``): single scans as dots, running medians as lines,
    milliseconds on a log scale (chapter 10). The four arrays must have one length."""
    arrays = [_checks.array(n, v) for n, v in (("ekf_cpu", ekf_cpu), ("ekf_landmarks", ekf_landmarks),
                                                ("isam2_cpu", isam2_cpu),
                                                ("isam2_landmarks", isam2_landmarks))]
    if len({a.shape for a in arrays}) != 1 or arrays[0].ndim != 1:
        raise ValueError(f"the four arrays must be 1-D of one length, got "
                         f"{[a.shape for a in arrays]}")
    for label, cpu, lm, colour in (("EKF", arrays[0], arrays[1], RED),
                                   ("iSAM2", arrays[2], arrays[3], GREEN)):
        ms = np.maximum(cpu * 1e3, 1e-3)
        ax.plot(lm, ms, ".", ms=2, color=colour, alpha=0.3)
        if ms.size >= 50:
            ax.plot(lm, running_median(ms), "-", color=colour,
                    label=f"{label}: running median (dots: single scans)")
        else:
            ax.plot([], [], ".", color=colour, label=f"{label}: single scans")
    ax.set_yscale("log")
    ax.set_xlabel("landmarks in the map")
    ax.set_ylabel("CPU per scan (ms, all its work)")
    ax.legend()
    ax.grid(True, alpha=0.3)


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
