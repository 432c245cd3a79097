"""What an EKF-SLAM run returns (:class:`SlamResult`) and its per-detection log
(:class:`ObservationLog`, the ANN chapters' training data)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import SlamConfig

__all__ = ["STATUS", "ObservationLog", "SlamResult"]

#: Codes of ``ObservationLog.status``.
STATUS = {"associated": 0, "new": 1, "rejected": 2, "out_of_range": 3}


@dataclass
class ObservationLog:
    """One row per detection of every processed scan (for the ANN chapters).

    scan: scan index (into the detections); t: scan time (s); range (m), bearing (rad),
    intensity (0..4), diameter (m, cluster width / trunk diameter, NaN if none);
    true_id: the simulator's landmark id (else -1); status: see :data:`STATUS`;
    landmark: index into ``SlamResult.landmarks`` of the landmark it was associated with
    or created (-1: none, or a tentative landmark later deleted); pose_prior (n, 3): the
    predicted pose the association used; pose (n, 3): the pose after the scan's update.
    """

    scan: np.ndarray
    t: np.ndarray
    range: np.ndarray
    bearing: np.ndarray
    intensity: np.ndarray
    diameter: np.ndarray
    true_id: np.ndarray
    status: np.ndarray
    landmark: np.ndarray
    pose_prior: np.ndarray
    pose: np.ndarray

    def __len__(self) -> int:
        return self.scan.size



@dataclass
class SlamResult:
    """What :func:`run` returns.

    trajectory (K, 4): (t, x, y, phi) of the laser pose AFTER the update of every
    processed scan; scan_index (K,): the scan of each row; pose_cov (K, 3, 3).
    odometry_trajectory (J, 4): the filtered pose at every odometry sample (predicted to
    that time, i.e. using all data before it): the dense track for errors against GPS.
    landmarks (M, 2), landmark_cov (M, 2, 2): the final map (tentative landmarks that
    failed their probation removed); landmark_observations: list of M arrays, the scans
    that observed each landmark; landmark_true_id (M,): majority vote of the
    simulator's ids of those observations (-1 where unknown).
    nis: dict of arrays, one entry per update: t, scan (-1 for GPS), kind (0 laser batch,
    1 GPS), nis, dof (2 x observations), accepted (False: a GPS fix beyond its gate).
    counts: predicts (prediction steps), scans, scans_skipped (before the first odometry
    sample), updates (laser batch updates), gps_updates, gps_rejected, gps_skipped
    (outside the GPS mode's window), screen_* (what ``data.screening.screen`` repaired in
    the streams on entry), observations, associated, new, rejected,
    out_of_range (per detection, summing to observations), landmarks_created,
    landmarks_removed (tentative ones deleted), landmarks (final).
    health: dict of arrays scan, t, n (state size), min_eig (smallest eigenvalue of P),
    asymmetry (max |P - P^T|), at every ``checkpoint_every`` scans and at the end.
    state, covariance: final x and P. observations: :class:`ObservationLog`.
    runtime: seconds of the whole call (features included); config, initial_pose (3,)
    at the first odometry time, initial_info (policy, and the GPS fit's numbers).
    gating: 'numpy' or 'compiled', how the efficient filter gated (``run``'s gating).
    """

    trajectory: np.ndarray
    scan_index: np.ndarray
    pose_cov: np.ndarray
    odometry_trajectory: np.ndarray
    landmarks: np.ndarray
    landmark_cov: np.ndarray
    landmark_observations: list
    landmark_true_id: np.ndarray
    nis: dict
    counts: dict
    health: dict
    state: np.ndarray
    covariance: np.ndarray
    observations: ObservationLog
    runtime: float
    config: SlamConfig
    initial_pose: np.ndarray
    initial_info: dict = field(default_factory=dict)
    gating: str = "numpy"

    def summary(self) -> str:
        c = self.counts
        return (f"{c['scans']} scans, {c['landmarks']} landmarks, {c['associated']} associated / "
                f"{c['new']} new / {c['rejected']} rejected observations, min eigenvalue "
                f"{np.min(self.health['min_eig']):.2e}, {self.runtime:.2f} s")



def nis_arrays(rows) -> dict:
    names = ("t", "scan", "kind", "nis", "dof", "accepted")
    types = (float, np.int64, np.int8, float, np.int64, bool)
    return {n: np.array([r[i] for r in rows], dtype=ty) for i, (n, ty) in enumerate(zip(names, types))}



def landmark_history(log: ObservationLog, M: int):
    ok = log.landmark >= 0
    lm, scan, tid = log.landmark[ok], log.scan[ok], log.true_id[ok]
    order = np.argsort(lm, kind="stable")
    lm, scan, tid = lm[order], scan[order], tid[order]
    bounds = np.searchsorted(lm, np.arange(M + 1))
    history = [scan[bounds[j]:bounds[j + 1]] for j in range(M)]
    true = np.full(M, -1, dtype=np.int64)
    for j in range(M):
        ids = tid[bounds[j]:bounds[j + 1]]
        ids = ids[ids >= 0]
        if ids.size:
            vals, cnt = np.unique(ids, return_counts=True)
            true[j] = vals[np.argmax(cnt)]
    return history, true
