"""Chapter 10 companion: beyond the EKF. Why the filter claims too much (first-estimates
Jacobians), joint compatibility (JCBB), and the same runs as factor graphs with GTSAM.

Each experiment is a function returning numbers (tested without a notebook); the heavy
ones are computed once per machine (``annslam_lib._cache``). The smoother is
:mod:`annslam_lib.smoothing`.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from ipywidgets import FloatSlider, interactive

from .. import _checks
from .._cache import memoize
from ..data.records import Dataset
from ..evaluation import consistency
from ..evaluation.map import map_errors
from ..evaluation.trajectory import trajectory_errors
from ..models.observation import inverse_observe
from ..perception import association, jcbb
from ..plots.style import GREEN, RED, figure, show_widget_figure, widget_figure
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig
from ..slam.runner import run
from ..smoothing import problem as gp
from ..smoothing import solve as gs
from ..smoothing.compare import compare_dataset, valid_fixes

__all__ = ["setup", "heading_information", "heading_figure", "FEJ_SEEDS", "FEJ_PRIOR",
           "fej_study", "shared_error_scene", "JCBB_SEEDS", "jcbb_study", "car_park_graph",
           "smoother_consistency", "victoria_park_comparison", "cost_figure", "split_loop_closures",
           "loop_closure_summary", "loop_closure_explorer", "EXPLORER_FIGSIZE"]

EXPLORER_FIGSIZE = (8.0, 3.8)
#: The loop-closure explorer's slider step (share of closures dropped).
DROP_STEP = 0.25
#: The Monte Carlo runs of section 1 (simulator seeds) and the start's prior (m, rad).
FEJ_SEEDS = tuple(range(400, 412))
FEJ_PRIOR = (0.1, math.radians(2.0))
#: The cluttered runs of section 2.
JCBB_SEEDS = tuple(range(400, 405))


# ------------------------------------------------------------------ 1. spurious information

def heading_information(seed: int = 7, laps: int = 2) -> dict:
    """One simulated run without GPS, known association, a 2 deg heading prior: the heading
    variance along the run over its prior, for the standard EKF and for FEJ. Nothing but
    the prior observes the global heading, so a consistent filter keeps the ratio >= 1."""
    from ..data import simulate
    ds = simulate.simulate(seed=seed, laps=laps, raw_laser=False)
    out = {"seed": seed}
    for name, fej in (("ekf", False), ("fej", True)):
        cfg = SlamConfig.for_dataset("simulated", association="truth", gps_mode="none",
                                     first_estimates=fej, initial_sigma_xy=FEJ_PRIOR[0],
                                     initial_sigma_phi=FEJ_PRIOR[1])
        r = run(ds, cfg, progress=False)
        out["t"] = r.trajectory[:, 0]
        out[name] = r.pose_cov[:, 2, 2] / FEJ_PRIOR[1] ** 2
    return out


def heading_figure(info: dict):
    fig, ax = figure(height=3.4)
    ax.plot(info["t"], info["ekf"], color=RED, label="standard EKF")
    ax.plot(info["t"], info["fej"], color="k", label="first-estimates Jacobians (FEJ)")
    ax.axhline(1.0, color="0.5", ls="--", lw=1, label="the prior: the bound")
    ax.set(xlabel="time [s]", ylabel="heading variance / prior", yscale="log",
           title="what the filter claims to know about the global heading (no GPS)")
    ax.legend()
    ax.grid(True, alpha=0.3)
    return fig


@memoize
def fej_study(seeds=FEJ_SEEDS) -> list[dict]:
    """Pose and map NEES of the standard EKF and FEJ over the same simulated runs (midpoint
    model, known association), started exactly (chapter 05's runs: the true pose, zero
    covariance) and from a draw of a 0.1 m / 2 deg prior. Rows: start, estimator, anees (pose NEES / 3 over runs and scans),
    inside (share of scans whose run-average lies in its 95 % band), map (map NEES / dof,
    with its band lo, hi), runs (each run's average pose NEES)."""
    rows = []
    for start, drawn in (("exact", False), ("drawn", True)):
        prior = (dict(initial_sigma_xy=FEJ_PRIOR[0], initial_sigma_phi=FEJ_PRIOR[1]) if drawn
                 else {})                      # exact: chapter 05's start, zero covariance
        for est, fej in (("EKF", False), ("FEJ", True)):
            mc = consistency.monte_carlo(tuple(seeds), "midpoint", draw_initial=drawn,
                                         association="truth", first_estimates=fej, **prior)
            rows.append({"start": start, "estimator": est, "anees": float(mc.nees.mean) / 3,
                         "inside": float(mc.nees.inside), "map": mc.map.per_dof,
                         "map_lo": mc.map.lo, "map_hi": mc.map.hi,
                         "runs": mc.nees_runs.mean(axis=1)})
    return rows


def paired(rows: list[dict], start: str) -> tuple[float, float, float]:
    """FEJ minus EKF run-average pose NEES over the same runs: mean and 95 % t interval."""
    from scipy.stats import t as student_t
    a = next(r["runs"] for r in rows if r["start"] == start and r["estimator"] == "EKF")
    b = next(r["runs"] for r in rows if r["start"] == start and r["estimator"] == "FEJ")
    d = b - a
    h = student_t.ppf(0.975, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size)
    return float(d.mean()), float(d.mean() - h), float(d.mean() + h)


# ---------------------------------------------------------------------- 2. joint compatibility

def shared_error_scene() -> dict:
    """Three landmarks 1.2 m apart, 10 m ahead; only the heading uncertain (4 deg); landmarks
    0 and 1 seen with a shared heading error of 6.3 deg (1.6 sigma): each measurement falls
    near the next landmark's prediction. Returns the scene, the individual distances, the
    nearest-neighbour pairing and JCBB's."""
    lm = np.array([[10.0, 0.0], [10.0, 1.2], [10.0, 2.4]])
    r = np.hypot(lm[:, 0], lm[:, 1])
    zhat = np.column_stack([r, np.arctan2(lm[:, 1], lm[:, 0]) + math.pi / 2])
    P = np.zeros((9, 9))
    P[2, 2] = math.radians(4.0) ** 2
    H = np.zeros((6, 9))
    for j in range(3):
        H[2 * j + 1, 2] = -1.0
        H[2 * j, 3 + 2 * j:5 + 2 * j] = lm[j] / r[j]
    C = H @ P @ H.T
    R = np.diag([0.1 ** 2, math.radians(1.0) ** 2])
    z = zhat[[0, 1]] - np.array([0.0, math.radians(6.3)])
    S = C.reshape(3, 2, 3, 2)[np.arange(3), :, np.arange(3), :] + R
    d2 = association.mahalanobis(z, zhat, S)
    nn = association.associate(d2, association.gate_threshold(0.99),
                               association.gate_threshold(0.99999))
    res = jcbb.jcbb(z, zhat, C, R)
    return {"z": z, "zhat": zhat, "d2": d2, "nn": nn, "jcbb": res.pairs, "joint_nis": res.nis,
            "gate": association.gate_threshold(0.99)}


@memoize
def jcbb_study(seeds=JCBB_SEEDS, clutter: float = 3.0) -> list[dict]:
    """Nearest neighbour against JCBB on the simulator with ``clutter`` spurious detections
    per scan (Poisson) and 40 beacons 1.5 m apart: wrong pairings against the truth, the
    landmarks mapped per run, the CPU seconds of the runs."""
    import time
    from ..data import simulate
    rows = []
    sims = [simulate.simulate(seed=int(s), laps=2, raw_laser=False, clutter_rate=clutter,
                              n_beacons=40, beacon_min_sep=1.5) for s in seeds]
    for assoc in ("nn", "jcbb"):
        wrong = paired_n = 0
        mapped, cpu = [], 0.0
        for ds in sims:
            c0 = time.process_time()
            r = run(ds, SlamConfig.for_dataset("simulated", association=assoc), progress=False)
            cpu += time.process_time() - c0
            log = r.observations
            ok = log.landmark >= 0
            lm_true = r.landmark_true_id[log.landmark[ok]]
            wrong += int(np.sum((log.status[ok] == 0) & (lm_true != log.true_id[ok])))
            paired_n += int(np.sum(log.status[ok] == 0))
            mapped.append(int(r.counts["landmarks"]))
        rows.append({"association": assoc, "wrong": wrong, "associated": paired_n,
                     "landmarks": float(np.mean(mapped)), "cpu_s": cpu})
    return rows


# ------------------------------------------------------------------------ 3. factor graphs

def car_park_graph(car: Dataset) -> dict:
    """The Car Park's EKF run, its graph and both solutions (seconds of CPU)."""
    ekf = run(car, SlamConfig.for_dataset("car_park"), progress=False)
    problem = gp.build_problem(car, ekf)
    isam = gs.solve_isam2(problem)
    batch = gs.solve_batch(problem, isam.poses, isam.landmarks)
    return {"ekf": ekf, "problem": problem, "isam2": isam, "batch": batch}


@memoize
def smoother_consistency(seeds=FEJ_SEEDS) -> dict:
    """The EKF (filtered) against batch smoothing of its graph (``smoothing``) on simulated
    runs (chapter 05's configuration): per run, the pose NEES / 3 averaged over the scans
    (the smoother's covariance: GTSAM's marginals, ``solve.marginals``) and the position
    RMSE against the true laser poses at the scans."""
    from ..data import simulate
    from ..models.geometry import wrap_angle
    out = {k: [] for k in ("ekf_nees", "batch_nees", "ekf_rmse", "batch_rmse")}
    for seed in seeds:
        ds = simulate.simulate(seed=int(seed), laps=2, raw_laser=False)
        r = run(ds, SlamConfig.for_dataset("simulated", motion_model="midpoint"), progress=False)
        p = gp.build_problem(ds, r)
        b = gs.solve_batch(p)
        cov, _ = gs.marginals(p, b)
        truth = np.asarray(ds.info["scan_poses"])
        k = np.flatnonzero(p.scan >= 0)
        e = b.poses[k] - truth[p.scan[k]]
        e[:, 2] = wrap_angle(e[:, 2])
        nees = np.einsum("ki,ki->k", e, np.linalg.solve(cov[k], e[..., None])[..., 0])
        out["ekf_nees"].append(float(consistency.pose_nees(r, ds).mean()) / 3)
        out["batch_nees"].append(float(nees.mean()) / 3)
        d = r.trajectory[:, 1:3] - truth[r.scan_index, :2]
        out["ekf_rmse"].append(math.sqrt(float(np.mean(np.sum(d * d, axis=1)))))
        out["batch_rmse"].append(math.sqrt(float(np.mean(np.sum(e[:, :2] ** 2, axis=1)))))
    return {k: np.array(v) for k, v in out.items()}


@memoize
def victoria_park_comparison(every: int = 25) -> dict:
    """``smoothing.compare.compare_dataset('victoria_park', every=every)``: the rows and
    iSAM2's cost per update, computed once per machine."""
    rows, extra = compare_dataset("victoria_park", every=every)
    return {"rows": rows, "step_cpu": extra["step_cpu"], "step_landmarks": extra["step_landmarks"],
            "ekf_cpu_per_scan": extra["ekf_cpu_per_scan"], "every": every}


def cost_figure(vp: dict):
    fig, ax = figure(height=3.4)
    step = np.asarray(vp["step_cpu"]) * 1e3
    ax.plot(vp["step_landmarks"], step, ".", ms=2, color=GREEN, alpha=0.5,
            label=f"iSAM2, one update (every {vp['every']} poses: scans, GPS fixes)")
    ax.axhline(vp["ekf_cpu_per_scan"] * 1e3 * vp["every"], color=RED,
               label=f"EKF, {vp['every']} scans (mean over the run)")
    ax.set(xlabel="landmarks in the map", ylabel="CPU per update [ms]", yscale="log",
           title="Victoria Park: cost per update as the map grows")
    ax.legend()
    ax.grid(True, alpha=0.3)
    return fig


def split_loop_closures(problem: gp.GraphProblem, keep: float, gap: float = 5.0) -> gp.GraphProblem:
    """The problem with only the first ``keep`` share (0..1) of its loop closures: a
    sighting of a landmark after ``gap`` seconds without one is a closure; a closure that is
    dropped, and every later sighting of that pass, go to a NEW landmark (what a filter that
    does not recognise the place builds: a second copy, not connected to the first).
    ``counts['closures']`` (all) and ``counts['closures_dropped']``: exactly
    ``closures - floor(keep * closures)``."""
    keep = _checks.real("keep", keep, lo=0.0, hi=1.0)
    t = problem.t[problem.obs_node]
    order = np.lexsort((t, problem.obs_landmark))       # by landmark, then time
    lm, tt = problem.obs_landmark[order], t[order]
    first = np.ones(lm.size, dtype=bool)
    first[1:] = lm[1:] != lm[:-1]
    start = first.copy()                                # a pass: sightings < gap apart
    start[1:] |= tt[1:] - tt[:-1] > gap
    closure = start & ~first
    idx = np.flatnonzero(closure)
    idx = idx[np.argsort(tt[idx], kind="stable")]       # the closures in time order
    n_keep = int(math.floor(keep * idx.size + 1e-9))
    dropped = np.zeros(lm.size, dtype=bool)
    dropped[idx[n_keep:]] = True                        # the latest ones, ties by order
    pass_of = np.cumsum(start) - 1                      # each sighting's pass
    dropped_pass = dropped[start]                       # per pass
    new_id = np.full(dropped_pass.size, -1, dtype=np.int64)
    L, n_new = problem.n_landmarks, int(dropped_pass.sum())
    new_id[dropped_pass] = L + np.arange(n_new)
    moved = new_id[pass_of]
    obs_lm = np.empty_like(problem.obs_landmark)
    obs_lm[order] = np.where(moved >= 0, moved, lm)
    src = order[start][dropped_pass]                    # each copy's first sighting
    extra = inverse_observe(problem.initial_poses[problem.obs_node[src]],
                            problem.obs_z[src])[0].reshape(n_new, 2)
    counts = dict(problem.counts, closures=int(closure.sum()), closures_dropped=n_new)
    return dataclasses.replace(problem, obs_landmark=obs_lm,
                               initial_landmarks=np.vstack([problem.initial_landmarks, extra]),
                               landmark_ekf=np.concatenate([problem.landmark_ekf,
                                                            np.full(n_new, -1)]),
                               counts=counts)


def loop_closure_summary(car: Dataset, problem: gp.GraphProblem, keep: float) -> dict:
    """Batch smoothing with a share ``keep`` of the loop closures: the track's errors
    against the valid GPS fixes, the map's landmarks and its aligned RMSE against the survey
    (only the first copy of each beacon is matched), the closures kept."""
    p = split_loop_closures(problem, keep)
    b = gs.solve_batch(p)
    gps = valid_fixes(car.gps)
    e = trajectory_errors(p.dense_track(b.poses), gps)
    m = map_errors(b.landmarks, car.beacons)
    return {"keep": keep, "closures": p.counts["closures"],
            "dropped": p.counts["closures_dropped"], "landmarks": p.n_landmarks,
            "traj_rmse": e.rmse, "traj_rmse_aligned": e.rmse_aligned, "errors": e,
            "map_rmse_aligned": m.rmse_aligned, "duplicates": m.duplicates,
            "error_final": b.error_final}


def loop_closure_explorer(car: Dataset, problem: gp.GraphProblem, *, drop: float = 0.0):
    """A slider for the share of loop closures the graph drops (the latest first; each
    dropped one starts a second copy of its landmark); shows the smoothed track's error
    against GPS along the run. ``widget.holder['summary']`` keeps the latest
    :func:`loop_closure_summary`."""
    holder = {}
    # every slider position solved once here (a batch solve each), so a step only draws
    steps = np.round(np.arange(0.0, 1.0 + 1e-9, DROP_STEP), 2)
    cache = {float(k): loop_closure_summary(car, problem, float(k)) for k in np.round(1.0 - steps, 2)}
    ref = cache[1.0]["errors"]

    def draw(drop: float) -> None:
        keep = float(round(1.0 - float(drop), 2))
        if keep not in cache:
            cache[keep] = loop_closure_summary(car, problem, keep)
        s = cache[keep]
        fig, ax = widget_figure(figsize=EXPLORER_FIGSIZE)
        ax.plot(ref.t, ref.error, color="0.6", lw=1, label="every loop closure")
        ax.plot(s["errors"].t, s["errors"].error, color=RED, lw=1,
                label=f"{s['dropped']} of {s['closures']} closures dropped")
        ax.set(xlabel="time [s]", ylabel="error against GPS [m]",
               title="batch smoothing of the Car Park without GPS after 10 s")
        ax.legend(loc="upper left")
        ax.grid(True, alpha=0.3)
        holder["summary"] = s
        print(f"{s['dropped']} of {s['closures']} loop closures dropped, "
              f"{s['landmarks']} landmarks ({s['duplicates']} second copies near a beacon): "
              f"path RMSE {s['traj_rmse']:.3f} m ({s['traj_rmse_aligned']:.3f} m aligned), "
              f"map {s['map_rmse_aligned']:.3f} m aligned")
        show_widget_figure(fig)

    widget = interactive(draw, drop=FloatSlider(value=drop, min=0.0, max=1.0, step=DROP_STEP,
                                                description="closures dropped",
                                                continuous_update=False, readout_format=".2f"))
    widget.holder = holder
    return widget
