"""Chapter 10 companion: beyond the EKF. Why the filter claims too much and what
first-estimates Jacobians change (a Monte Carlo study judged run by run: :func:`fej_study`,
:func:`fej_table`), joint compatibility (JCBB), and the same runs as factor graphs with GTSAM
(iSAM2's filtered and smoothed estimates beside the EKF, the cost per scan like for like:
:func:`car_park_graph`, :func:`cost_summary`).

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
from ..plots.style import RED, figure, show_widget_figure, widget_figure
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig
from ..slam.runner import run
from ..smoothing import problem as gp
from ..smoothing import solve as gs
from ..smoothing.compare import compare_dataset, cost_panel, timed_run, valid_fixes

__all__ = ["setup", "heading_information", "heading_figure", "FEJ_SEEDS", "FEJ_PRIOR",
           "SMOOTHER_SEEDS", "fej_study", "level_words",
           "difference_verdict", "fej_table", "shared_error_scene", "JCBB_SEEDS",
           "jcbb_study", "car_park_graph", "cost_summary", "smoother_consistency",
           "victoria_park_comparison", "cost_figure", "split_loop_closures",
           "loop_closure_summary", "loop_closure_explorer", "EXPLORER_FIGSIZE"]

EXPLORER_FIGSIZE = (8.0, 3.8)
#: The loop-closure explorer's slider step (share of closures dropped).
DROP_STEP = 0.25
#: The Monte Carlo runs of section 1 (simulator seeds), fixed before the study was run and
#: disjoint from every seed a setting was chosen on (chapter 04a: 100-119, chapter 05:
#: 100-149, this chapter's other studies and the tests: 400-419, 7000-7199). 200 runs (800
#: filter runs, all four filters) take about two minutes of one core, once per machine: the
#: most that stays well inside a notebook cell's time limit on a loaded machine.
FEJ_SEEDS = tuple(range(2000, 2200))
#: The uncertain start of section 1: the prior's sigmas (m, rad).
FEJ_PRIOR = (0.1, math.radians(2.0))
#: The simulated runs of the smoother's consistency check (section 3.2).
SMOOTHER_SEEDS = tuple(range(400, 412))
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
    """Chapter 10, section 1: the standard EKF and FEJ on the same simulated runs (midpoint
    model, known association, no GPS after the start, chapter 05's configuration
    otherwise), from two starts: 'exact' (chapter 05's: the true pose, zero covariance) and
    'prior' (each run's filter started at a draw from the :data:`FEJ_PRIOR` prior, with
    that covariance). ``evaluation.consistency.monte_carlo`` runs them.

    Returns one row per start and estimator ('EKF', 'FEJ'): ``pose`` (N,), each run's
    pose NEES averaged over its scans, / 3; ``map`` (N,), each run's final map NEES / its
    dof (the landmarks' joint covariance); both equal 1 on average for a consistent filter.
    Computed once per machine (``annslam_lib._cache``)."""
    seeds = tuple(int(s) for s in seeds)
    if len(seeds) < 2 or len(set(seeds)) != len(seeds):
        raise ValueError(f"fej_study needs at least two distinct seeds, got {len(seeds)}")
    rows = []
    for start, drawn in (("exact", False), ("prior", True)):
        prior = (dict(initial_sigma_xy=FEJ_PRIOR[0], initial_sigma_phi=FEJ_PRIOR[1]) if drawn
                 else {})                      # exact: chapter 05's start, zero covariance
        for est, fej in (("EKF", False), ("FEJ", True)):
            mc = consistency.monte_carlo(seeds, "midpoint", draw_initial=drawn,
                                         association="truth", first_estimates=fej, **prior)
            rows.append({"start": start, "estimator": est, "n": len(seeds),
                         "pose": mc.nees_runs.mean(axis=1) / 3, "map": np.array(mc.map.runs)})
    return rows


def level_words(effect: consistency.Effect) -> str:
    """A filter's normalised error over runs in words (chapter 10): the shared rule's word
    (``consistency.EFFECT_RULE``: 'over-confident', 'under-confident' or 'no detectable
    difference') and whether its interval lies within the practical margin around 1. An
    interval that merely holds 1 is no evidence of consistency: only 'within the margin'
    says the filter is as good as consistent."""
    if not isinstance(effect, consistency.Effect) or effect.null != 1.0:
        raise TypeError("level_words needs a consistency.ratio_effect result")
    inside = "within" if effect.within_margin else "not within"
    return f"{effect.word}, {inside} the {100 * effect.margin:.0f} % margin"


def difference_verdict(ekf: float, fej: float, diff: consistency.Effect) -> str:
    """The paired FEJ - EKF difference (``consistency.paired_effect``) of a normalised error
    whose means over the runs are ``ekf`` and ``fej`` (chapter 10): 'no detectable
    difference' if its interval holds 0, else 'better' if FEJ's mean lies nearer 1 (a
    consistent filter's) than the EKF's, else 'worse'."""
    ekf, fej = _checks.real("ekf", ekf), _checks.real("fej", fej)
    if not isinstance(diff, consistency.Effect) or diff.null != 0.0:
        raise TypeError("difference_verdict needs a consistency.paired_effect result")
    if diff.word == "no detectable difference":
        return diff.word
    return "better" if abs(fej - 1.0) < abs(ekf - 1.0) else "worse"


def fej_table(rows: list[dict], prob: float = 0.95) -> list[dict]:
    """:func:`fej_study`'s rows judged by the shared rule (``consistency.EFFECT_RULE``,
    chapter 10): per start ('exact', 'prior') and quantity ('pose', 'map'): n runs; each
    filter's ``consistency.Effect`` ('ekf', 'fej') and its words (:func:`level_words`);
    the paired FEJ - EKF Effect over the same runs ('diff') and :func:`difference_verdict`;
    ``resolves``: the difference interval's half-width, the smallest difference the study
    tells from none."""
    by = {(r["start"], r["estimator"]): r for r in rows}
    out = []
    for start in dict.fromkeys(r["start"] for r in rows):
        if (start, "EKF") not in by or (start, "FEJ") not in by:
            raise ValueError(f"start {start!r} needs an EKF and a FEJ row")
        for q in ("pose", "map"):
            a, b = np.asarray(by[(start, "EKF")][q]), np.asarray(by[(start, "FEJ")][q])
            if a.shape != b.shape:
                raise ValueError(f"{start} {q}: the EKF and FEJ runs differ in number")
            e = consistency.ratio_effect(a, f"{start} {q}, EKF", prob=prob)
            f = consistency.ratio_effect(b, f"{start} {q}, FEJ", prob=prob)
            d = consistency.paired_effect(b, a, f"{start} {q}, FEJ - EKF", prob=prob)
            out.append({"start": start, "quantity": q, "n": int(a.size), "ekf": e, "fej": f,
                        "ekf_verdict": level_words(e), "fej_verdict": level_words(f), "diff": d,
                        "diff_verdict": difference_verdict(e.mean, f.mean, d),
                        "resolves": d.half_width})
    return out


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
    """The Car Park's EKF run, its graph, iSAM2 (one update per pose: its filtered and its
    smoothed estimate) and batch LM from iSAM2's solution; ``timed``: the
    ``smoothing.compare.TimedRun`` with both sides' CPU per scan."""
    _checks.instance("car", car, Dataset)
    tr = timed_run(car, SlamConfig.for_dataset("car_park"))
    batch = gs.solve_batch(tr.problem, tr.isam2.poses, tr.isam2.landmarks)
    return {"ekf": tr.ekf, "problem": tr.problem, "isam2": tr.isam2, "batch": batch, "timed": tr}


def cost_summary(ekf_scan_cpu, isam2_scan_cpu, ekf_cpu: float, isam2_cpu: float) -> dict:
    """The same statistic of the same work on both sides (chapter 10): the median of each
    side's whole CPU per processed scan (``TimedRun.ekf_scan_cpu``, ``isam2_scan_cpu``, one
    entry per scan on both sides) and each side's total (``ekf_cpu``, ``isam2_cpu``), the
    ratios iSAM2 / EKF, and which side is cheaper by each ('EKF' or 'iSAM2')."""
    a, b = _checks.array("ekf_scan_cpu", ekf_scan_cpu), _checks.array("isam2_scan_cpu", isam2_scan_cpu)
    if a.ndim != 1 or a.shape != b.shape or a.size == 0:
        raise ValueError(f"the per-scan arrays must be 1-D, non-empty and of one length, got "
                         f"{a.shape} and {b.shape}")
    if np.any(a < 0) or np.any(b < 0):
        raise ValueError("CPU times must be >= 0")
    ekf_cpu = _checks.real("ekf_cpu", ekf_cpu, lo=0.0)
    isam2_cpu = _checks.real("isam2_cpu", isam2_cpu, lo=0.0)
    ma, mb = float(np.median(a)), float(np.median(b))
    if min(ma, mb, ekf_cpu, isam2_cpu) <= 0:
        raise ValueError("a median or total CPU time of zero: the clock did not resolve the work")
    return {"scans": int(a.size), "ekf_median": ma, "isam2_median": mb, "median_ratio": mb / ma,
            "ekf_total": ekf_cpu, "isam2_total": isam2_cpu, "total_ratio": isam2_cpu / ekf_cpu,
            "cheaper_per_scan": "EKF" if ma < mb else "iSAM2",
            "cheaper_in_all": "EKF" if ekf_cpu < isam2_cpu else "iSAM2"}


@memoize
def smoother_consistency(seeds=SMOOTHER_SEEDS) -> dict:
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
def victoria_park_comparison(every: int = 1) -> dict:
    """``smoothing.compare.compare_dataset('victoria_park', every=every)``, computed once per
    machine: the rows (EKF, iSAM2 filtered, iSAM2 smoothed, batch) and both sides' CPU per
    processed scan (``smoothing.compare.TimedRun``: ``ekf_scan_cpu``, ``isam2_scan_cpu``,
    ``isam2_update_cpu``, the landmarks at each scan, the totals ``ekf_cpu``,
    ``isam2_cpu``)."""
    rows, extra = compare_dataset("victoria_park", every=every)
    tr = extra["timed"]
    return {"rows": rows, "every": every, "ekf_cpu": tr.ekf_cpu, "isam2_cpu": tr.isam2_cpu,
            **{k: getattr(tr, k) for k in ("ekf_scan_cpu", "isam2_scan_cpu", "isam2_update_cpu",
                                           "ekf_landmarks", "isam2_landmarks")}}


def cost_figure(vp: dict):
    """Victoria Park: both sides' whole CPU per scan as the map grows
    (``smoothing.compare.cost_panel``)."""
    fig, ax = figure(height=3.4)
    cost_panel(ax, vp["ekf_scan_cpu"], vp["ekf_landmarks"], vp["isam2_scan_cpu"],
               vp["isam2_landmarks"])
    ax.set_title("Victoria Park: CPU per scan, all of each side's work, as the map grows")
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
    return keyboard_ready(widget)
