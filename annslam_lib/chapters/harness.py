"""The harness of chapters 04a and 09, in which a student's own filter runs: a run as a
sequence of steps, what the loop estimated, and its score against the truth.

:func:`steps` gives a run as a :class:`Start`, then :class:`Predict` and :class:`Scan` in
time order (the control held over each prediction as the course's filter holds it, no
GPS); :class:`Track` records what the loop estimated after every scan. A run is named by a
string, so that a grader can call a student's loop with a run it has not seen:
``"sim:<seed>"`` (the simulator's 2-lap loop), ``"sim:<seed>:<laps>"`` or ``"car_park"``.
:func:`midpoint_step` is the prediction of chapter 05 (no chapter asks students to write it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.motion import control_table
from ..models.motion import predict as euler_step
from ..perception.association import gate_threshold
from ..slam.config import SlamConfig

__all__ = ["Start", "Predict", "Scan", "Track", "steps", "dataset_of", "score_run",
           "midpoint_step"]


@dataclass(frozen=True)
class Start:
    """The first step: initial state x0 (3,) and P0 (3, 3), the car, the laser noise R
    (2, 2), the gate and new-landmark chi-square thresholds (2 dof), and, for a filter
    that is given the map (chapter 04a), the beacons' known positions (N, 2)."""
    x0: np.ndarray
    P0: np.ndarray
    vehicle: object
    R: np.ndarray
    gate: float
    new_landmark: float
    beacons: np.ndarray | None = None


@dataclass(frozen=True)
class Predict:
    """Move the car: control (v_c, alpha) held for dt seconds; Q (2, 2) the covariance of
    the control error over this step (so that the process noise is G Q G^T)."""
    control: np.ndarray
    dt: float
    Q: np.ndarray


@dataclass(frozen=True)
class Scan:
    """A laser scan at time t: the detections z (k, 2) of (range, laser bearing)."""
    t: float
    z: np.ndarray


@dataclass
class Track:
    """What a loop estimated: after every scan, :meth:`record` (t, x, P); :meth:`result`
    gives the arrays a grader scores (t, pose (K, 3), pose_cov (K, 3, 3), landmarks
    (N, 2) and their joint covariance (2N, 2N) at the end; none for a localisation
    filter, whose state is the pose alone)."""
    t: list = field(default_factory=list)
    pose: list = field(default_factory=list)
    pose_cov: list = field(default_factory=list)
    x: np.ndarray | None = None
    P: np.ndarray | None = None

    nis: list = field(default_factory=list)
    nis_dof: list = field(default_factory=list)

    def record(self, t: float, x, P, nis: float | None = None, dof: int = 0) -> None:
        """The estimate after the scan at time t; ``nis``: that scan's NIS and ``dof`` its
        degrees of freedom (2 per detection in the update), if the loop computes them."""
        x, P = np.asarray(x, dtype=float), np.asarray(P, dtype=float)
        self.t.append(float(t))
        self.pose.append(x[:3].copy())
        self.pose_cov.append(P[:3, :3].copy())
        self.nis.append(math.nan if nis is None else float(nis))
        self.nis_dof.append(int(dof) if nis is not None else 0)
        self.x, self.P = x, P

    def result(self) -> dict:
        x = np.zeros(3) if self.x is None else self.x
        P = np.zeros((3, 3)) if self.P is None else self.P
        return {"t": np.asarray(self.t, dtype=float), "pose": np.asarray(self.pose).reshape(-1, 3),
                "pose_cov": np.asarray(self.pose_cov).reshape(-1, 3, 3),
                "landmarks": x[3:].reshape(-1, 2).copy(), "landmark_cov": P[3:, 3:].copy(),
                "nis": np.asarray(self.nis, dtype=float),
                "nis_dof": np.asarray(self.nis_dof, dtype=int)}


def dataset_of(run: str):
    """The dataset a run name stands for: 'sim:<seed>' (the simulator's loop, 2 laps),
    'sim:<seed>:<laps>', or 'car_park'."""
    _checks.instance("run", run, str, "string")
    if run == "car_park":
        from ..data import loaders
        return loaders.load_car_park()
    parts = run.split(":")
    if parts[0] == "sim" and len(parts) in (2, 3) and all(p.isdigit() for p in parts[1:]):
        from ..data import simulate
        laps = int(parts[2]) if len(parts) == 3 else 2
        return simulate.simulate(seed=int(parts[1]), laps=laps, raw_laser=False)
    raise ValueError(f"run must be 'sim:<seed>', 'sim:<seed>:<laps>' or 'car_park', got {run!r}")


def score_run(result: dict, run: str) -> dict:
    """Measure a loop's result on a simulated run against the truth: the pose NEES after
    every scan and its mean, the position's RMS error, the final map's joint NEES per dof
    over the landmarks matched to a true one (within 1 m), how many true landmarks were
    matched, spurious and duplicated landmarks, and the matched landmarks' RMSE (the map
    entries are NaN or 0 for a localisation filter, which maps nothing)."""
    from ..evaluation.map import match_landmarks

    ds = dataset_of(run)
    if ds.truth is None:
        raise ValueError(f"{run!r} has no ground truth to score against")
    tp = ds.truth.poses
    t = np.asarray(result["t"], float)
    xy = np.column_stack([np.interp(t, tp[:, 0], tp[:, i]) for i in (1, 2)])
    phi = np.interp(t, tp[:, 0], np.unwrap(tp[:, 3]))
    e = np.column_stack([result["pose"][:, :2] - xy, wrap_angle(result["pose"][:, 2] - phi)])
    nees = _nees(e, np.asarray(result["pose_cov"], float))
    lms = np.asarray(result["landmarks"], float).reshape(-1, 2)
    i, j = match_landmarks(lms, ds.beacons, 1.0) if len(lms) else (np.zeros(0, int), np.zeros(0, int))
    near = np.linalg.norm(lms[:, None] - ds.beacons[None], axis=-1) if len(lms) else np.zeros((0, 1))
    nearest = near.argmin(axis=1) if len(lms) else np.zeros(0, int)
    close = near.min(axis=1) <= 1.0 if len(lms) else np.zeros(0, bool)
    duplicates = int(close.sum() - np.unique(nearest[close]).size)
    map_nees = np.nan
    if i.size:
        err = (lms[i] - ds.beacons[j]).ravel()
        idx = np.column_stack([2 * i, 2 * i + 1]).ravel()
        C = np.asarray(result["landmark_cov"], float)[np.ix_(idx, idx)]
        map_nees = float(err @ np.linalg.solve(C, err)) / err.size
    return {"nees": nees, "nees_mean": float(np.mean(nees)), "map_nees_per_dof": map_nees,
            "path_rmse": float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
            "matched": int(i.size), "true": int(len(ds.beacons)),
            "spurious": int(len(lms) - close.sum()), "duplicates": duplicates,
            "map_rmse": float(np.sqrt(np.mean(np.sum((lms[i] - ds.beacons[j]) ** 2, 1))))
            if i.size else np.nan,
            "worst_scan": int(np.argmax(nees)), "worst_t": float(t[int(np.argmax(nees))])}


def _nees(e, C) -> np.ndarray:
    """e_k^T C_k^-1 e_k per scan; infinite where C_k is singular (a filter that claims to
    know a direction exactly)."""
    try:
        return np.einsum("ki,kij,kj->k", e, np.linalg.inv(C), e)
    except np.linalg.LinAlgError:
        out = np.full(len(e), np.inf)
        for k, (ek, Ck) in enumerate(zip(e, C)):
            try:
                out[k] = float(ek @ np.linalg.solve(Ck, ek))
            except np.linalg.LinAlgError:
                pass
        return out


def steps(run: str, *, known_map: bool = False):
    """The run as a sequence: :class:`Start`, then :class:`Predict` and :class:`Scan` in
    time order (no GPS: the filter has only its wheels and its laser). The control of each
    odometry sample is held until the next sample or event, as in the course's filter; the
    configuration is the dataset's default. ``known_map``: the Start holds the beacons'
    positions (the truth on the simulator, the survey on the Car Park)."""
    ds = dataset_of(run)
    name = "simulated" if run.startswith("sim:") else ds.name
    cfg = SlamConfig.for_dataset(name, gps_mode="none", motion_model="midpoint")
    from ..slam.runner import prepare    # the course's own start and detections

    prep = prepare(ds, cfg)
    ds, det = prep.dataset, prep.detections
    yield Start(np.asarray(prep.pose0, float), prep.cov0, ds.vehicle,
                np.diag([cfg.sigma_range**2, cfg.sigma_bearing**2]),
                gate_threshold(cfg.gate_prob), gate_threshold(cfg.new_landmark_prob),
                np.asarray(ds.beacons, float).copy() if known_map else None)
    odo = ds.odometry
    rows = control_table(odo, ds.vehicle, cfg.sigma_speed, cfg.sigma_steer, cfg.steer_noise_gain)
    events = sorted([(float(t), 1, k) for k, t in enumerate(odo.t)]
                    + [(float(t), 2, k) for k, t in enumerate(det.t)])
    u, t_cur = None, float(odo.t[0])
    for t, kind, k in events:
        if t > t_cur and u is not None:
            v, alpha, _, _, _, q00, q01, q11, span = u
            dt = t - t_cur
            yield Predict(np.array([v, alpha]), dt,
                          np.array([[q00, q01], [q01, q11]]) * (span / dt))
        t_cur = max(t_cur, t)
        if kind == 1:
            u = rows[k]
        elif u is not None:
            z = np.column_stack([det.range, det.bearing])[det.offsets[k]:det.offsets[k + 1]]
            inside = (z[:, 0] >= cfg.min_range) & (z[:, 0] <= cfg.max_range)
            yield Scan(t, z[inside])


def midpoint_step(pose, control, dt, vehicle):
    """The course's prediction (chapter 05's default): chapter 01's Euler step evaluated at
    the mid-step heading. Returns (pose_next, F, G) like ``motion.predict``."""
    pose = np.asarray(pose, dtype=float)
    v, alpha = float(control[0]), float(control[1])
    w = v * math.tan(alpha) / vehicle.L
    at = pose.copy()
    at[2] += 0.5 * dt * w
    nxt, F, G = euler_step(at, np.array([v, alpha]), dt, vehicle)
    nxt[2] = float(wrap_angle(pose[2] + dt * w))
    return nxt, F, G
