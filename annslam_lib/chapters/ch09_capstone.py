"""Chapter 09 companion: the capstone, in which a student's own EKF-SLAM runs.

The student writes the filter's pieces and the loop; the harness (:mod:`.harness`, shared
with chapter 04a and re-exported here) gives them the data as a sequence of steps
(:func:`steps`: a :class:`Start`, then :class:`Predict` and :class:`Scan` in time order,
the control held over each prediction as the course's filter holds it) and records what
the loop estimated (:class:`Track`). A run is named by a string, so that the grader can call
a student's loop with a run it has not seen: ``"sim:<seed>"`` (the simulator's 2-lap loop,
known association not given) or ``"car_park"``.

The reference pieces (:func:`reference_predict`, :func:`reference_associate`,
:func:`reference_update`, :func:`reference_augment`) are the course's own functions
assembled the same way; :func:`reference_slam` is the loop the instructor's notebook shows.
"""
from __future__ import annotations

import numpy as np

from ..models.geometry import wrap_angle
from ..models.observation import observe
from ..perception.association import associate, mahalanobis
from ..plots.style import BLUE, RED, figure
from ..plots.style import notebook_setup as setup
from ..slam.dense import augment_landmark, range_bearing_update
from .harness import Predict, Scan, Start, Track, dataset_of, midpoint_step, score_run, steps

__all__ = ["setup", "Start", "Predict", "Scan", "Track", "steps", "dataset_of", "score_run", "midpoint_step",
           "reference_predict", "reference_associate", "reference_update", "reference_augment",
           "reference_slam", "scan_nis", "track_figure", "SIGMA_SURVEY", "car_park_scores",
           "consistency_lines"]

#: The survey's own uncertainty per axis (chapter 05's map NEES against the survey).
SIGMA_SURVEY = 0.02


# ------------------------------------------------------------------------- the reference

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


def scan_nis(x, P, z, idx, R) -> float:
    """The NIS of one scan's update (chapter 04a): nu^T S^-1 nu of the stacked innovation
    nu = z - z_hat (bearings wrapped) of detections z (m, 2) of landmarks idx (m,), with
    S = H P H^T + R over the whole state; chi-square with 2m dof for a consistent filter."""
    z = np.asarray(z, float).reshape(-1, 2)
    idx = np.asarray(idx, dtype=int).ravel()
    lms = np.asarray(x[3:], float).reshape(-1, 2)[idx]
    zhat, Hp, Hm = observe(x[:3], lms)
    H = np.zeros((2 * idx.size, len(x)))
    for i, j in enumerate(idx.tolist()):
        H[2 * i:2 * i + 2, :3] = Hp[i]
        H[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] = Hm[i]
    nu = z - zhat
    nu[:, 1] = wrap_angle(nu[:, 1])
    nu = nu.ravel()
    return float(nu @ np.linalg.solve(H @ P @ H.T + np.kron(np.eye(idx.size), R), nu))


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
        nis = None
        if old.size:
            nis = scan_nis(x, P, step.z[old], a[old], start.R)
            x, P = update(x, P, step.z[old], a[old], start.R)
        for i in np.flatnonzero(a == -1):
            x, P = augment(x, P, step.z[i], start.R)
        track.record(step.t, x, P, nis, 2 * old.size)
    return track.result()


def car_park_scores(result: dict) -> dict:
    """A loop's Car Park run measured as chapter 05 measures the course's filter there: the
    map against the surveyed beacons (each matched to a mapped landmark within 1 m; the
    joint NEES per dof e^T (P_mm + s^2 I)^-1 e / 2K over the K matched landmarks, with their
    joint covariance and the survey's own s = :data:`SIGMA_SURVEY` per axis, chi-square
    with 2K dof for a consistent filter), and the path against GPS, RMS after the best
    rigid alignment (the filter's frame is its start; GPS has its own errors, so this is a
    distance to GPS, not an error against the truth)."""
    from ..data import loaders
    from ..evaluation.map import match_landmarks
    from ..evaluation.trajectory import trajectory_errors

    car = loaders.load_car_park()
    lms = np.asarray(result["landmarks"], float).reshape(-1, 2)
    i, j = match_landmarks(lms, car.beacons, 1.0) if len(lms) else (np.zeros(0, int),) * 2
    nees = np.nan
    if i.size:
        idx = np.column_stack([2 * i, 2 * i + 1]).ravel()
        C = np.asarray(result["landmark_cov"], float)[np.ix_(idx, idx)]
        e = (lms[i] - car.beacons[j]).ravel()
        nees = float(e @ np.linalg.solve(C + SIGMA_SURVEY**2 * np.eye(e.size), e)) / e.size
    path = trajectory_errors(np.column_stack([result["t"], result["pose"]]), car.gps)
    return {"matched": int(i.size), "beacons": int(len(car.beacons)),
            "landmarks": int(len(lms)), "map_nees_per_dof": nees,
            "gps_rmse_aligned": float(path.rmse_aligned)}


def _band_line(what: str, value: float, dof: int, count: int, p: float = 0.95) -> str:
    from scipy import stats

    lo, hi = stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof) / count
    verdict = "below" if value < lo else "above" if value > hi else "inside"
    return (f"{what} {value:.2f}: {verdict} the {100 * p:.0f}% band [{lo:.2f}, {hi:.2f}] for "
            f"independent samples")


def consistency_lines(result: dict, run: str) -> str:
    """What a loop's NEES and NIS say (chapter 09 section 5), each against its two-sided
    95 % chi-square band as if the scans were independent (they are not: chapter 05): on a
    simulated run the mean pose NEES (3 dof per scan) and the NIS per dof over the scans
    with an update; on the Car Park the NIS per dof and the map's NEES per dof against the
    survey (:func:`car_park_scores`). A result without NIS (``nis_dof`` all 0) says so."""
    lines = []
    dof = np.asarray(result.get("nis_dof", np.zeros(0)), dtype=int)
    nis = np.asarray(result.get("nis", np.zeros(0)), dtype=float)
    if run.startswith("sim:"):
        nees = score_run(result, run)["nees"]
        lines.append(_band_line("mean pose NEES per dof", float(np.mean(nees)) / 3,
                                3 * nees.size, 3 * nees.size))
    if dof.sum() > 0:
        used = dof > 0
        lines.append(_band_line(f"NIS per dof over {int(used.sum())} updates",
                                float(np.sum(nis[used]) / dof.sum()), int(dof.sum()),
                                int(dof.sum())))
    else:
        lines.append("no NIS recorded: pass each scan's NIS and dof to track.record")
    if run == "car_park":
        c = car_park_scores(result)
        if c["matched"]:
            lines.append(_band_line(f"map NEES per dof against the survey ({c['matched']} beacons)",
                                    c["map_nees_per_dof"], 2 * c["matched"], 2 * c["matched"]))
    return "\n".join(lines)


def track_figure(result: dict, truth_xy=None, beacons=None):
    """The loop's path and map, with the truth where there is one (left), and its position
    uncertainty along the run (right)."""
    fig, (ax, ax1) = figure(1, 2, height=4.6, width_ratios=[1, 1.3])
    if truth_xy is not None:
        ax.plot(*np.asarray(truth_xy).T, color="0.6", lw=1, label="truth")
    ax.plot(result["pose"][:, 0], result["pose"][:, 1], color=BLUE, lw=1, label="your filter")
    if beacons is not None:
        ax.plot(*np.asarray(beacons).T, "k^", ms=6, label="true landmarks")
    if len(result["landmarks"]):
        ax.plot(*result["landmarks"].T, "+", color=RED, ms=9, label="your map")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
    ax.legend()
    ax.grid(True, alpha=0.3)
    sigma = np.sqrt(result["pose_cov"][:, 0, 0] + result["pose_cov"][:, 1, 1])
    ax1.plot(result["t"], sigma, color=BLUE)
    ax1.set(xlabel="time [s]", ylabel="sqrt(P_xx + P_yy) [m]", title="your filter's position uncertainty")
    ax1.grid(True, alpha=0.3)
    return fig
