"""Chapter 04a companion: EKF localisation on the surveyed Car Park map, its experiments,
figures and the map-error explorer.

Each experiment is a function returning numbers (tested without a notebook); the filter
is :func:`annslam_lib.slam.localisation.localise` (the course's run with the map known).
The student's own filter (exercise 4a.2) runs in chapter 09's harness with the map given
(:func:`steps`); :func:`reference_localise` is the same loop from the course's pieces.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2
from ipywidgets import FloatSlider, IntSlider, interactive

from .. import _checks
from .._cache import memoize
from ..data.records import Dataset, truncate
from ..evaluation import consistency
from ..evaluation.summary import run_metrics
from ..evaluation.trajectory import trajectory_errors
from ..plots.style import BLUE, GREEN, ORANGE, RED, figure, show_widget_figure, widget_figure
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup
from ..slam import localisation
from ..slam.config import SlamConfig
from ..slam.dead_reckoning import dead_reckon
from ..slam.results import STATUS
from ..slam.runner import run
from ..models.observation import observe
from ..perception.association import REJECTED, associate, mahalanobis
from .harness import Predict, Scan, Start, Track, dataset_of, midpoint_step, score_run
from .harness import steps as _steps

__all__ = ["setup", "compare", "COMPARED", "paths_figure", "SHIFTS",
           "moved_beacon_sweep", "moved_beacon_figure", "missing_beacon", "state_at",
           "wrong_association", "map_error_summary", "map_error_explorer", "EXPLORER_FIGSIZE",
           "Start", "Predict", "Scan", "Track", "steps", "dataset_of", "score_run",
           "midpoint_step", "reference_loc_predict", "reference_gate", "reference_update",
           "reference_localise", "CONSISTENCY_SEEDS", "WIDE_GATE", "consistency_study", "judge_study"]

#: The runs :func:`compare` makes: (label, map mode, GPS mode).
COMPARED = (("SLAM, GPS for 10 s", "slam", "init"), ("SLAM, no GPS", "slam", "none"),
            ("localisation, GPS for 10 s", "known", "init"), ("localisation, no GPS", "known", "none"))
EXPLORER_FIGSIZE = (7.5, 3.6)

#: The consistency study's runs (section 4): 400 seeded scenes fixed before looking and used
#: for nothing else (no setting of the course was chosen on them).
CONSISTENCY_SEEDS = tuple(range(20000, 20400))
#: The gate of the study's second filter: 99.99 % instead of 99 % (the new-landmark
#: threshold must stay above it; a known map never adds one).
WIDE_GATE = {"gate_prob": 0.9999, "new_landmark_prob": 0.99999}


_RUNS: dict = {}


def consistency_study(seeds=CONSISTENCY_SEEDS) -> dict:
    """Chapter 04a, section 4: is the localisation filter consistent, and what makes it not?

    The simulator's loop (two laps) on every seed of ``seeds``, localisation on the true map
    with the midpoint motion model (``consistency.monte_carlo(..., map_mode='known')``),
    twice on the same runs: the course's 99 % gate and a 99.99 % gate (:data:`WIDE_GATE`),
    judged by :func:`judge_study`. Each Monte Carlo is computed once per machine and then
    read back (the notebook computes the two in separate cells)."""
    seeds = tuple(int(s) for s in seeds)
    return judge_study(consistency.monte_carlo(seeds, "midpoint", map_mode="known"),
                       consistency.monte_carlo(seeds, "midpoint", map_mode="known", **WIDE_GATE))


def judge_study(gate_99: consistency.MonteCarlo, gate_9999: consistency.MonteCarlo) -> dict:
    """The two gates' Monte Carlos on the same runs judged (chapter 04a, section 4).

    Returns {'gate_99', 'gate_9999': the Monte Carlos; 'ratio_99', 'ratio_9999':
    consistency.Effect of each run's ANEES per dof (:data:`consistency.EFFECT_RULE`);
    'difference': the paired Effect of 99 % minus 99.99 %; 'refusals': {gate: (share of
    scans that refused a sighting, NEES / dof averaged over those scans, over the others)}}."""
    runs = {"gate_99": gate_99, "gate_9999": gate_9999}
    for k, mc in runs.items():
        if not isinstance(mc, consistency.MonteCarlo) or mc.map is not None or mc.rejected_runs is None:
            raise TypeError(f"{k} must be a known-map consistency.monte_carlo result")
    if gate_99.nees_runs.shape != gate_9999.nees_runs.shape:
        raise ValueError("the two gates must be run on the same runs")
    r99, r9999 = (consistency.run_ratios(runs[k].nees_runs) for k in ("gate_99", "gate_9999"))
    refusals = {}
    for k, mc in runs.items():
        hit = mc.rejected_runs > 0
        refusals[k] = (float(hit.mean()), float(mc.nees_runs[hit].mean() / 3) if hit.any() else math.nan,
                       float(mc.nees_runs[~hit].mean() / 3))
    return {**runs, "refusals": refusals,
            "ratio_99": consistency.ratio_effect(r99, "99 % gate, ANEES / dof"),
            "ratio_9999": consistency.ratio_effect(r9999, "99.99 % gate, ANEES / dof"),
            "difference": consistency.paired_effect(r99, r9999, "99 % minus 99.99 %, ANEES / dof")}


def _localise(car: Dataset, cfg: SlamConfig):
    """:func:`localisation.localise`, remembered for the last few (dataset, config) pairs:
    the chapter's experiments start from the same run (the dataset is kept in the key's
    value, so its id is not reused while remembered)."""
    key = (id(car), cfg)
    if key not in _RUNS:
        if len(_RUNS) >= 8:
            _RUNS.pop(next(iter(_RUNS)))
        _RUNS[key] = (car, localisation.localise(car, cfg))
    return _RUNS[key][1]


def _row(label: str, r, car: Dataset) -> dict:
    m = run_metrics(r, car)
    e = trajectory_errors(r.odometry_trajectory, car.gps)
    return {"label": label, "result": r, "traj_rmse": m.traj_rmse,
            "traj_rmse_aligned": m.traj_rmse_aligned, "max_error": e.max,
            "pose_sigma": math.sqrt(m.pose_trace / 2.0) if m.pose_trace >= 0 else math.nan,
            "nis_per_dof": m.nis_per_dof, "landmarks": m.landmarks,
            "rejected": int(r.counts["rejected"]), "associated": int(r.counts["associated"]),
            "errors": e}


def compare(car: Dataset) -> list[dict]:
    """Dead reckoning, SLAM and localisation on the same run, with GPS for the first 10 s
    and without any: per run its trajectory RMSE against GPS (absolute and SE(2)-aligned),
    largest error, mean position sigma, laser NIS per dof and counts."""
    base = SlamConfig.for_dataset(car.name)
    rows = []
    first = run(car, base.replace(gps_mode="none"), progress=False)
    dr = dead_reckon(car.odometry, first.initial_pose, car.vehicle)
    e = trajectory_errors(dr, car.gps)
    rows.append({"label": "dead reckoning", "result": None, "traj_rmse": e.rmse,
                 "traj_rmse_aligned": e.rmse_aligned, "max_error": e.max,
                 "pose_sigma": math.nan, "nis_per_dof": math.nan, "landmarks": 0,
                 "rejected": 0, "associated": 0, "errors": e, "trajectory": dr})
    for label, mode, gps in COMPARED:
        if (mode, gps) == ("slam", "none"):
            r = first
        elif mode == "known":
            r = _localise(car, base.replace(gps_mode=gps))
        else:
            r = run(car, base.replace(gps_mode=gps), progress=False)
        rows.append(_row(label, r, car))
    return rows


def paths_figure(car: Dataset, rows: list[dict]):
    """Left: GPS, SLAM and localisation without GPS, and the surveyed beacons. Right: the
    position error against GPS along the run, every run of :func:`compare` but dead
    reckoning (off the scale: its RMSE is in the table)."""
    fig, (ax, ax1) = figure(1, 2, height=5.2, width_ratios=[1, 1.6])
    ax.plot(*car.gps.xy.T, ".", color="0.6", ms=2, label="GPS")
    by = {r["label"]: r for r in rows}
    for label, color in [("SLAM, no GPS", ORANGE), ("localisation, no GPS", BLUE)]:
        tr = by[label]["result"].odometry_trajectory
        ax.plot(tr[:, 1], tr[:, 2], color=color, lw=1.2, label=label)
    ax.plot(*car.beacons.T, "k^", ms=7, label="surveyed beacons")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title="the map known or built")
    ax.legend(loc="lower right")
    ax.grid(True, alpha=0.3)
    for r in rows[1:]:
        e = r["errors"]
        ax1.plot(e.t, e.error, lw=1, label=r["label"])
    ax1.set(xlabel="time [s]", ylabel="error against GPS [m]", yscale="log",
            title="position error along the run")
    ax1.legend(ncol=2, loc="lower right")
    ax1.grid(True, alpha=0.3, which="both")
    return fig


# ------------------------------------------------------------------ what if the map is wrong

def _sightings(o, beacon: int) -> np.ndarray:
    """The detections of an observation log associated with ``beacon``."""
    return (o.landmark == beacon) & (o.status == STATUS["associated"])


#: The shifts of the moved-beacon study, in metres: the explorer's slider (0 to 1.5 by 0.1).
SHIFTS = tuple(round(0.1 * k, 1) for k in range(16))


def _moved_row(car: Dataset, beacon: int, shift: float, cfg: SlamConfig, ref, own) -> dict:
    b = car.beacons.copy()
    b[beacon, 0] += shift
    r = ref if shift == 0 else localisation.localise(localisation.with_beacons(car, b), cfg)
    m = run_metrics(r, car)
    return {"beacon": beacon, "shift": float(shift), "sightings": int(own.sum()),
            "accepted": int(np.sum(_sightings(r.observations, beacon)[own])),
            "rejected": int(np.sum((r.observations.status == STATUS["rejected"])[own])),
            "traj_rmse": m.traj_rmse, "nis_per_dof": m.nis_per_dof,
            "errors": trajectory_errors(r.odometry_trajectory, car.gps)}


@memoize
def moved_beacon_sweep(car: Dataset, beacon: int, shifts=SHIFTS, *, gps_mode: str = "none") -> dict:
    """Localisation with beacon ``beacon`` of the known map moved by each of ``shifts``
    metres along x (the true beacon stays where it is). Per shift (``rows``): how many of
    the beacon's sightings (those of the run with the right map) were still associated or
    were rejected, the trajectory RMSE against GPS, the laser NIS per dof and the error
    along the run. Computed once per machine, then read from the study cache (the
    explorer's slider moves over the same runs)."""
    beacon = _checks.integer("beacon", beacon, lo=0, hi=len(car.beacons) - 1)
    cfg = SlamConfig.for_dataset(car.name, gps_mode=gps_mode)
    ref = _localise(car, cfg)
    own = _sightings(ref.observations, beacon)
    rows = [_moved_row(car, beacon, _checks.real("shift", s), cfg, ref, own) for s in shifts]
    return {"beacon": beacon, "sightings": int(own.sum()), "rows": rows}


def moved_beacon_figure(sweep: dict):
    """Trajectory RMSE and the moved beacon's accepted sightings against the shift."""
    fig, (ax0, ax1) = figure(1, 2, height=3.3)
    s = [r["shift"] for r in sweep["rows"]]
    ax0.plot(s, [r["traj_rmse"] for r in sweep["rows"]], "o-")
    ax0.set(xlabel="shift of the beacon in the map [m]", ylabel="trajectory RMSE [m]",
            title=f"beacon {sweep['beacon']} moved: the path")
    ax1.plot(s, [r["accepted"] for r in sweep["rows"]], "o-", color=GREEN, label="accepted")
    ax1.plot(s, [r["rejected"] for r in sweep["rows"]], "s-", color=RED, label="rejected")
    ax1.set(xlabel="shift of the beacon in the map [m]", ylabel="sightings",
            title=f"its {sweep['sightings']} sightings: what the gate did")
    ax1.legend()
    for ax in (ax0, ax1):
        ax.grid(True, alpha=0.3)
    return fig


def missing_beacon(car: Dataset, beacon: int, *, gps_mode: str = "none") -> dict:
    """Localisation with beacon ``beacon`` left out of the map: what became of its
    sightings (associated with another beacon = a wrong association, or rejected)."""
    beacon = _checks.integer("beacon", beacon, lo=0, hi=len(car.beacons) - 1)
    cfg = SlamConfig.for_dataset(car.name, gps_mode=gps_mode)
    own = _sightings(_localise(car, cfg).observations, beacon)
    r = localisation.localise(localisation.with_beacons(car, np.delete(car.beacons, beacon, 0)), cfg)
    st = r.observations.status[own]
    d = np.linalg.norm(car.beacons - car.beacons[beacon], axis=1)
    d[beacon] = np.inf
    return {"beacon": beacon, "sightings": int(own.sum()),
            "wrongly_associated": int(np.sum(st == STATUS["associated"])),
            "rejected": int(np.sum(st == STATUS["rejected"])),
            "nearest": int(np.argmin(d)), "nearest_distance": float(d.min()),
            "traj_rmse": run_metrics(r, car).traj_rmse}


def state_at(car: Dataset, t: float, *, gps_mode: str = "none") -> tuple[np.ndarray, np.ndarray]:
    """The localisation filter's pose and its covariance after the last event before ``t``
    (the run cut at ``t``)."""
    r = localisation.localise(truncate(car, t), SlamConfig.for_dataset(car.name, gps_mode=gps_mode))
    return r.state[:3].copy(), r.covariance[:3, :3].copy()


def wrong_association(car: Dataset, beacon: int, wrong: int, *, after: float = 30.0) -> dict:
    """The first sighting of ``beacon`` after ``after`` seconds, used once with the right
    beacon and once with ``wrong``: the pose each update gives, and each one's d2 against
    the gate (``SlamConfig.gate_prob``, 2 dof)."""
    cfg = SlamConfig.for_dataset(car.name, gps_mode="none")
    o = _localise(car, cfg).observations
    k = int(np.flatnonzero(_sightings(o, beacon) & (o.t > after))[0])
    pose, P = state_at(car, float(o.t[k]) - 1e-6)
    # predict to the sighting's time is what the run did; the cut run stops at the last
    # event before it, so the prior here is that state (a few ms older)
    R = np.diag([cfg.sigma_range**2, cfg.sigma_bearing**2])
    z = np.array([o.range[k], o.bearing[k]])
    out = {"t": float(o.t[k]), "z": z, "prior": pose, "P": P,
           "gate": float(chi2.ppf(cfg.gate_prob, 2))}
    for name, j in (("right", beacon), ("wrong", wrong)):
        new, P_new, info = localisation.beacon_update(pose, P, z, car.beacons[j], R)
        out[name] = {"beacon": j, "pose": new, "P": P_new, "d2": info["d2"],
                     "moved": float(np.hypot(*(new[:2] - pose[:2]))),
                     "turned_deg": math.degrees(float(new[2] - pose[2]))}
    return out


# ----------------------------------------------------------------------------- the explorer

def map_error_summary(car: Dataset, beacon: int, shift: float, *, cache: dict | None = None) -> dict:
    """One setting of the explorer: localisation (no GPS) with ``beacon`` moved by
    ``shift`` m along x; its RMSE, the beacon's accepted and rejected sightings (of those
    the right map's run associated), and the error along the run (a row of
    :func:`moved_beacon_sweep`). ``cache`` keeps earlier settings."""
    cache = {} if cache is None else cache
    beacon = _checks.integer("beacon", beacon, lo=0, hi=len(car.beacons) - 1)
    key = (beacon, round(_checks.real("shift", shift), 6))
    if key not in cache:
        cfg = SlamConfig.for_dataset(car.name, gps_mode="none")
        ref = _localise(car, cfg)
        cache[key] = _moved_row(car, beacon, key[1], cfg, ref,
                                _sightings(ref.observations, beacon))
    return cache[key]


def map_error_explorer(car: Dataset, *, beacon: int = 12, shift: float = 0.0):
    """A slider for the beacon (its index in the map) and one for how far its map position
    is wrong; shows the localisation error along the run and what the gate did with its
    sightings.
    ``widget.holder['summary']`` keeps the latest :func:`map_error_summary`."""
    holder = {}
    # the chapter's study of this beacon (every slider position, from the study cache)
    cache = {(r["beacon"], r["shift"]): r for r in moved_beacon_sweep(car, beacon)["rows"]}
    ref = map_error_summary(car, beacon, 0.0, cache=cache)["errors"]     # the right map

    def draw(shift: float, beacon: int) -> None:
        s = map_error_summary(car, beacon, shift, cache=cache)
        fig, ax = widget_figure(figsize=EXPLORER_FIGSIZE)
        ax.plot(ref.t, ref.error, color="0.6", lw=1, label="the right map")
        ax.plot(s["errors"].t, s["errors"].error, color=RED, lw=1,
                label=f"beacon {s['beacon']} moved {s['shift']:.1f} m")
        ax.set(xlabel="time [s]", ylabel="error against GPS [m]",
               title="localisation without GPS on a wrong map")
        ax.legend(loc="upper left")
        ax.grid(True, alpha=0.3)
        holder["summary"] = s
        print(f"beacon {s['beacon']} moved {s['shift']:.1f} m: RMSE {s['traj_rmse']:.3f} m; of its "
              f"{s['sightings']} sightings {s['accepted']} accepted, {s['rejected']} rejected by "
              f"the gate; laser NIS/dof {s['nis_per_dof']:.3f}")
        show_widget_figure(fig)

    widget = interactive(
        draw,
        shift=FloatSlider(value=shift, min=0.0, max=1.5, step=0.1, description="shift [m]",
                          continuous_update=False, readout_format=".1f"),
        # a slider, not a drop-down: JupyterLab 4.6 takes the arrow keys of a focused
        # drop-down to move between cells, so a keyboard could not choose a beacon there
        beacon=IntSlider(value=beacon, min=0, max=len(car.beacons) - 1, step=1,
                         description="beacon", continuous_update=False))
    widget.holder = holder
    return keyboard_ready(widget)


# ------------------------------------------------------------------ exercise 4a.2's loop

def steps(run: str):
    """The run named ``run`` as steps (chapter 09's harness), the map given: the
    :class:`Start` holds ``beacons``, the true positions on the simulator and the surveyed
    ones on the Car Park."""
    return _steps(run, known_map=True)


def reference_loc_predict(pose, P, control, dt, Q, vehicle):
    """The prediction of the pose alone (eq. 4a.1's filter, chapter 01's model with chapter
    05's midpoint step): pose -> f(pose, u), P -> F P F^T + G Q G^T."""
    new, F, G = midpoint_step(pose, control, dt, vehicle)
    P = F @ np.asarray(P, float) @ F.T + G @ np.asarray(Q, float) @ G.T
    return new, 0.5 * (P + P.T)


def reference_gate(pose, P, z, beacons, R, gate):
    """Per detection of ``z`` (k, 2): the index of its beacon, or -2 rejected. Each beacon's
    predicted sighting and S = H P H^T + R (H by the pose, the map known), d^2 against
    ``gate``, then chapter 04's nearest neighbour with mutual exclusion."""
    z = np.asarray(z, float).reshape(-1, 2)
    if z.shape[0] == 0:
        return np.zeros(0, dtype=int)
    zhat, Hp, _ = observe(np.asarray(pose, float), np.asarray(beacons, float))
    S = np.einsum("nij,jk,nlk->nil", Hp, np.asarray(P, float), Hp) + np.asarray(R, float)
    a = associate(mahalanobis(z, zhat, S), gate, gate)
    a[a < 0] = REJECTED
    return a


def reference_update(pose, P, z, beacon, R):
    """One sighting's update (eq. 4a.1-4a.3, exercise 4a.1)."""
    new, P_new, _ = localisation.beacon_update(pose, P, z, beacon, R)
    return new, P_new


def reference_localise(run: str, predict=reference_loc_predict, gate=reference_gate,
                       update=reference_update) -> dict:
    """The localisation loop from its pieces: predict at every :class:`Predict`; at every
    :class:`Scan` gate all detections against the prior, then update with each gated one
    in turn; record. Returns :meth:`Track.result`."""
    track = Track()
    it = steps(run)
    start = next(it)
    pose, P = start.x0.copy(), start.P0.copy()
    for step in it:
        if isinstance(step, Predict):
            pose, P = predict(pose, P, step.control, step.dt, step.Q, start.vehicle)
            continue
        a = np.asarray(gate(pose, P, step.z, start.beacons, start.R, start.gate))
        for i in np.flatnonzero(a >= 0):
            pose, P = update(pose, P, step.z[i], start.beacons[a[i]], start.R)
        track.record(step.t, pose, P)
    return track.result()
