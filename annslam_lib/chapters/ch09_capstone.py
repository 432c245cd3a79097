"""Chapter 09 companion: the capstone's harness, in which a student's own EKF-SLAM runs.

The student writes the filter's pieces and the loop; this module gives them the data as a
sequence of steps (:func:`steps`: a :class:`Start`, then :class:`Predict` and :class:`Scan`
in time order, the control held over each prediction as the course's filter holds it) and
records what the loop estimated (:class:`Track`). A run is named by a string, so that the
grader can call a student's loop with a run it has not seen: ``"sim:<seed>"`` (the
simulator's 2-lap loop, known association not given) or ``"car_park"``.

The reference pieces (:func:`reference_predict`, :func:`reference_associate`,
:func:`reference_update`, :func:`reference_augment`) are the course's own functions
assembled the same way; :func:`reference_slam` is the loop the instructor's notebook shows.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.motion import control_table
from ..models.motion import predict as euler_step
from ..models.observation import observe
from ..perception.association import associate, gate_threshold, mahalanobis
from ..plots.style import figure
from ..plots.style import notebook_setup as setup
from ..slam.config import SlamConfig
from ..slam.dense import augment_landmark, range_bearing_update

__all__ = ["setup", "Start", "Predict", "Scan", "Track", "steps", "dataset_of", "score_run", "midpoint_step",
           "reference_predict", "reference_associate", "reference_update", "reference_augment",
           "reference_slam", "track_figure"]


@dataclass(frozen=True)
class Start:
    """The first step: initial state x0 (3,) and P0 (3, 3), the car, the laser noise R
    (2, 2), and the gate and new-landmark chi-square thresholds (2 dof)."""
    x0: np.ndarray
    P0: np.ndarray
    vehicle: object
    R: np.ndarray
    gate: float
    new_landmark: float


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
    gives the arrays the grader scores (t, pose (K, 3), pose_cov (K, 3, 3), landmarks
    (N, 2) and their joint covariance (2N, 2N) at the end)."""
    t: list = field(default_factory=list)
    pose: list = field(default_factory=list)
    pose_cov: list = field(default_factory=list)
    x: np.ndarray | None = None
    P: np.ndarray | None = None

    def record(self, t: float, x, P) -> None:
        x, P = np.asarray(x, dtype=float), np.asarray(P, dtype=float)
        self.t.append(float(t))
        self.pose.append(x[:3].copy())
        self.pose_cov.append(P[:3, :3].copy())
        self.x, self.P = x, P

    def result(self) -> dict:
        x = np.zeros(3) if self.x is None else self.x
        P = np.zeros((3, 3)) if self.P is None else self.P
        return {"t": np.asarray(self.t, dtype=float), "pose": np.asarray(self.pose).reshape(-1, 3),
                "pose_cov": np.asarray(self.pose_cov).reshape(-1, 3, 3),
                "landmarks": x[3:].reshape(-1, 2).copy(), "landmark_cov": P[3:, 3:].copy()}


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
    every scan and its mean, the final map's joint NEES per dof over the landmarks matched to
    a true one (within 1 m), how many true landmarks were matched, spurious and duplicated
    landmarks, and the matched landmarks' RMSE."""
    from ..evaluation.map import match_landmarks

    ds = dataset_of(run)
    if ds.truth is None:
        raise ValueError(f"{run!r} has no ground truth to score against")
    tp = ds.truth.poses
    t = np.asarray(result["t"], float)
    xy = np.column_stack([np.interp(t, tp[:, 0], tp[:, i]) for i in (1, 2)])
    phi = np.interp(t, tp[:, 0], np.unwrap(tp[:, 3]))
    e = np.column_stack([result["pose"][:, :2] - xy, wrap_angle(result["pose"][:, 2] - phi)])
    nees = np.einsum("ki,kij,kj->k", e, np.linalg.inv(result["pose_cov"]), e)
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
            "matched": int(i.size), "true": int(len(ds.beacons)),
            "spurious": int(len(lms) - close.sum()), "duplicates": duplicates,
            "map_rmse": float(np.sqrt(np.mean(np.sum((lms[i] - ds.beacons[j]) ** 2, 1))))
            if i.size else np.nan,
            "worst_scan": int(np.argmax(nees)), "worst_t": float(t[int(np.argmax(nees))])}


def steps(run: str):
    """The run as a sequence: :class:`Start`, then :class:`Predict` and :class:`Scan` in
    time order (no GPS: the capstone's filter has only its wheels and its laser). The
    control of each odometry sample is held until the next sample or event, as in the
    course's filter; the configuration is the dataset's default."""
    ds = dataset_of(run)
    name = "simulated" if run.startswith("sim:") else ds.name
    cfg = SlamConfig.for_dataset(name, gps_mode="none", motion_model="midpoint")
    from ..slam.runner import _detections, _initial    # the course's own start and detections

    pose0, _ = _initial(ds, cfg)
    P0 = np.diag([cfg.initial_sigma_xy**2, cfg.initial_sigma_xy**2, cfg.initial_sigma_phi**2])
    yield Start(np.asarray(pose0, float), P0, ds.vehicle,
                np.diag([cfg.sigma_range**2, cfg.sigma_bearing**2]),
                gate_threshold(cfg.gate_prob), gate_threshold(cfg.new_landmark_prob))
    det = _detections(ds, cfg.feature_source)
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


# ------------------------------------------------------------------------- the reference

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


def reference_predict(x, P, control, dt, Q, vehicle):
    """Prediction of the whole state: the pose moves (:func:`midpoint_step`), the map does
    not; P_vv -> F P_vv F^T + G Q G^T, the cross covariances P_vm -> F P_vm."""
    x, P = np.asarray(x, float).copy(), np.asarray(P, float).copy()
    pose, F, G = midpoint_step(x[:3], control, dt, vehicle)
    x[:3] = pose
    P[:3, :] = F @ P[:3, :]
    P[:, :3] = P[:, :3] @ F.T
    P[:3, :3] += G @ Q @ G.T
    return x, 0.5 * (P + P.T)


def reference_associate(x, P, z, R, gate, new_landmark):
    """Gated nearest neighbour with mutual exclusion (chapter 04): per detection the index
    of its landmark, -1 for a new landmark, -2 rejected."""
    z = np.asarray(z, float).reshape(-1, 2)
    N = (len(x) - 3) // 2
    if N == 0 or z.shape[0] == 0:
        return np.full(z.shape[0], -1, dtype=int)
    lms = np.asarray(x[3:], float).reshape(-1, 2)
    zhat, Hp, Hm = observe(x[:3], lms)
    S = np.empty((N, 2, 2))
    for j in range(N):
        H = np.zeros((2, len(x)))
        H[:, :3] = Hp[j]
        H[:, 3 + 2 * j:5 + 2 * j] = Hm[j]
        S[j] = H @ P @ H.T + R
    return associate(mahalanobis(z, zhat, S), gate, new_landmark)


def reference_update(x, P, z, idx, R):
    """The EKF update with detections z (m, 2) of landmarks idx (m,) (chapter 05's
    ``range_bearing_update``)."""
    z = np.asarray(z, float).reshape(-1, 2)
    idx = np.asarray(idx, dtype=int).ravel()
    n = len(x)
    lms = np.asarray(x[3:], float).reshape(-1, 2)[idx]
    zhat, Hp, Hm = observe(x[:3], lms)
    H = np.zeros((2 * idx.size, n))
    for i, j in enumerate(idx.tolist()):
        H[2 * i:2 * i + 2, :3] = Hp[i]
        H[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] = Hm[i]
    Rm = np.kron(np.eye(idx.size), R)
    return range_bearing_update(x, P, z.ravel(), zhat.ravel(), H, Rm)


def reference_augment(x, P, z, R):
    """A new landmark for one detection z (2,) (chapter 05, exercise 5.1)."""
    return augment_landmark(x, P, z, R)


def reference_slam(run: str, predict=reference_predict, associate_=reference_associate,
                   update=reference_update, augment=reference_augment) -> dict:
    """The loop, from its pieces: predict at every :class:`Predict`; at every
    :class:`Scan` associate, one update with the associated detections, then a landmark
    for each new one; record. Returns :meth:`Track.result`."""
    track = Track()
    it = steps(run)
    start = next(it)
    x, P = start.x0.copy(), start.P0.copy()
    for step in it:
        if isinstance(step, Predict):
            x, P = predict(x, P, step.control, step.dt, step.Q, start.vehicle)
            continue
        a = np.asarray(associate_(x, P, step.z, start.R, start.gate, start.new_landmark))
        old = np.flatnonzero(a >= 0)
        if old.size:
            x, P = update(x, P, step.z[old], a[old], start.R)
        for i in np.flatnonzero(a == -1):
            x, P = augment(x, P, step.z[i], start.R)
        track.record(step.t, x, P)
    return track.result()


def track_figure(result: dict, truth_xy=None, beacons=None):
    """The loop's path and map, with the truth where there is one (left), and its position
    uncertainty along the run (right)."""
    fig, (ax, ax1) = figure(1, 2, height=4.6, width_ratios=[1, 1.3])
    if truth_xy is not None:
        ax.plot(*np.asarray(truth_xy).T, color="0.6", lw=1, label="truth")
    ax.plot(result["pose"][:, 0], result["pose"][:, 1], color="tab:blue", lw=1, label="your filter")
    if beacons is not None:
        ax.plot(*np.asarray(beacons).T, "k^", ms=6, label="true landmarks")
    if len(result["landmarks"]):
        ax.plot(*result["landmarks"].T, "r+", ms=9, label="your map")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    sigma = np.sqrt(result["pose_cov"][:, 0, 0] + result["pose_cov"][:, 1, 1])
    ax1.plot(result["t"], sigma, color="tab:blue")
    ax1.set(xlabel="time [s]", ylabel="sqrt(P_xx + P_yy) [m]", title="your filter's position uncertainty")
    ax1.grid(True, alpha=0.3)
    return fig
