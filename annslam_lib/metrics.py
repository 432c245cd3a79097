"""Trajectory accuracy against GPS (notebook 01 "Dead reckoning against GPS"; reused by
the EKF-SLAM chapters for the trajectory RMSE of a filter).

A trajectory is a (K, 4) array of rows (t, x, y, phi): time in seconds on the run's
clock, the LASER position in the world frame and the heading. The ACFR GPS antenna
sits with the laser, so a GPS fix is compared with the trajectory's (x, y) at the
fix's time, found by :func:`interpolate_poses`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import as_array, wrap_angle
from .records import Gps

__all__ = ["check_trajectory", "interpolate_poses", "TrajectoryErrors", "trajectory_errors"]


def check_trajectory(traj, name: str = "trajectory") -> np.ndarray:
    """``traj`` as a finite float (K, 4) array (t, x, y, phi), K >= 1, times non-decreasing.

    Raises ValueError naming ``name`` otherwise."""
    arr = as_array(name, traj, (4,))
    if arr.ndim != 2 or arr.shape[0] < 1:
        raise ValueError(f"{name} must have shape (K, 4) with K >= 1 rows (t, x, y, phi), "
                         f"got {arr.shape}")
    if np.any(np.diff(arr[:, 0]) < 0):
        raise ValueError(f"{name} times (column 0) must be non-decreasing")
    return arr


def interpolate_poses(traj, t) -> np.ndarray:
    """Poses (x, y, phi) of trajectory ``traj`` at times ``t`` (notebook 01).

    Positions are interpolated linearly between the rows around each time; the
    heading is interpolated on its unwrapped (continuous) version and wrapped back
    to (-pi, pi], so a heading crossing +-pi between two rows is interpolated the
    short way round. This assumes consecutive rows differ by less than pi in
    heading, true of any trajectory sampled at the odometry rate.

    traj (K, 4) rows (t, x, y, phi); t scalar or 1-D, every time inside
    [traj[0, 0], traj[-1, 0]]. Returns (3,) for a scalar t, else (N, 3).
    Raises ValueError for a malformed trajectory, non-finite times, or a time
    outside the trajectory's span (no extrapolation).
    """
    traj = check_trajectory(traj)
    t_arr = as_array("t", t)
    if t_arr.ndim > 1:
        raise ValueError(f"t must be a scalar or one-dimensional, got shape {t_arr.shape}")
    t0, t1 = traj[0, 0], traj[-1, 0]
    if t_arr.size and (t_arr.min() < t0 or t_arr.max() > t1):
        raise ValueError(f"times {t_arr.min():.6g}..{t_arr.max():.6g} s fall outside the "
                         f"trajectory's span {t0:.6g}..{t1:.6g} s (no extrapolation)")
    ts = np.atleast_1d(t_arr)
    phi = np.unwrap(traj[:, 3])
    out = np.column_stack([np.interp(ts, traj[:, 0], traj[:, 1]),
                           np.interp(ts, traj[:, 0], traj[:, 2]),
                           wrap_angle(np.interp(ts, traj[:, 0], phi))])
    return out[0] if t_arr.ndim == 0 else out


@dataclass(frozen=True)
class TrajectoryErrors:
    """Position errors of a trajectory at the GPS fixes inside its time span.

    t (N,): times of the fixes used; offset (N, 2): trajectory minus GPS (East,
    North), metres; error (N,): its length; rmse, mean, max, final: sqrt(mean
    error^2), mean, largest and last error (m); t_max: time of the largest error;
    n_outside: fixes left out because they lie outside the trajectory's span.
    """

    t: np.ndarray
    offset: np.ndarray
    error: np.ndarray
    rmse: float
    mean: float
    max: float
    final: float
    t_max: float
    n_outside: int

    def summary(self) -> str:
        """One line: RMSE, max (with its time) and final error, rounded to cm."""
        return (f"RMSE {self.rmse:.2f} m, max {self.max:.2f} m (t = {self.t_max:.1f} s), "
                f"final {self.final:.2f} m over {self.t.size} fixes")


def trajectory_errors(traj, gps: Gps) -> TrajectoryErrors:
    """Errors of the trajectory's positions against the GPS fixes (notebook 01).

    Only fixes whose time lies inside the trajectory's span are used (the count of
    the others is returned as ``n_outside``); the trajectory is interpolated at
    each with :func:`interpolate_poses`. The GPS point is the laser point, the
    position the course's state holds, so no lever arm is applied.

    Raises ValueError for a malformed trajectory, a ``gps`` that is not a
    :class:`~annslam_lib.records.Gps`, or no fix inside the span.
    """
    traj = check_trajectory(traj)
    if not isinstance(gps, Gps):
        raise ValueError(f"gps must be an annslam_lib.records.Gps, got {type(gps).__name__}")
    inside = (gps.t >= traj[0, 0]) & (gps.t <= traj[-1, 0])
    if not inside.any():
        raise ValueError(f"no GPS fix inside the trajectory's span {traj[0, 0]:.6g}.."
                         f"{traj[-1, 0]:.6g} s (GPS covers {gps.t[0]:.6g}..{gps.t[-1]:.6g} s)"
                         if len(gps) else "gps holds no fixes")
    t = gps.t[inside]
    offset = interpolate_poses(traj, t)[:, :2] - gps.xy[inside]
    error = np.hypot(offset[:, 0], offset[:, 1])
    i = int(np.argmax(error))
    return TrajectoryErrors(t=t, offset=offset, error=error,
                            rmse=float(np.sqrt(np.mean(error**2))), mean=float(error.mean()),
                            max=float(error[i]), final=float(error[-1]), t_max=float(t[i]),
                            n_outside=int(np.count_nonzero(~inside)))
