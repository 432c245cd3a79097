"""Trajectory accuracy against GPS (notebook 01 "Dead reckoning against GPS"; reused by
the EKF-SLAM chapters for the trajectory RMSE of a filter).

A trajectory is a (K, 4) array of rows (t, x, y, phi): time in seconds on the run's
clock, the LASER position in the world frame and the heading. The ACFR GPS antenna
sits with the laser, so a GPS fix is compared with the trajectory's (x, y) at the
fix's time, found by :func:`interpolate_poses`.

Two errors are reported: absolute (the trajectory as estimated, in the GPS frame) and
SE(2)-aligned, after the best rigid motion (rotation and translation, no scale) of the
estimated positions onto the fixes (``evaluation.map.rigid_align``, Kabsch): the frame
error that a SLAM run cannot observe (chapter 06) is removed, the shape error is left.
This is evo's ``evo_ape --align`` on the translation part (``tests/test_trajectory_evo.py``
checks the two agree).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..data.records import Gps
from ..models.geometry import interpolate_poses
from .map import rigid_align

__all__ = ["TrajectoryErrors", "trajectory_errors", "gps_outliers"]


@dataclass(frozen=True)
class TrajectoryErrors:
    """Position errors of a trajectory at the GPS fixes inside its time span.

    t (N,): times of the fixes used; offset (N, 2): trajectory minus GPS (East,
    North), metres; error (N,): its length; rmse, mean, max, final: sqrt(mean
    error^2), mean, largest and last error (m); t_max: time of the largest error;
    n_outside: fixes left out because they lie outside the trajectory's span;
    rmse_aligned: the RMSE after the best SE(2) alignment onto the fixes (module docstring;
    NaN with fewer than 2 fixes or a trajectory that does not move), rotation (rad) and
    translation (2,) of that alignment (estimate -> GPS).
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
    rmse_aligned: float = math.nan
    rotation: float = math.nan
    translation: np.ndarray = field(default_factory=lambda: np.full(2, math.nan))

    def summary(self) -> str:
        """One line: RMSE, max (with its time) and final error, rounded to cm."""
        return (f"RMSE {self.rmse:.2f} m ({self.rmse_aligned:.2f} m aligned), max "
                f"{self.max:.2f} m (t = {self.t_max:.1f} s), final {self.final:.2f} m over "
                f"{self.t.size} fixes")


def trajectory_errors(traj, gps: Gps) -> TrajectoryErrors:
    """Errors of the trajectory's positions against the GPS fixes (notebook 01).

    Only fixes whose time lies inside the trajectory's span are used (the count of
    the others is returned as ``n_outside``); the trajectory is interpolated at
    each with :func:`interpolate_poses`. The GPS point is the laser point, the
    position the course's state holds, so no lever arm is applied.

    Parameters
    ----------
    traj : array_like, shape (K, 4)
        Rows (t, x, y, phi) (s, m, m, rad), times non-decreasing.
    gps : records.Gps
        The fixes: times ``t`` (s) and positions ``xy`` (m).

    Returns
    -------
    TrajectoryErrors
        Per fix used (N of them): time, offset (N, 2) and error (N,); the RMSE, mean,
        max and final error, absolute and after SE(2) alignment.

    Raises
    ------
    TypeError
        For a ``gps`` that is not a :class:`~annslam_lib.data.records.Gps`.
    ValueError
        For a malformed trajectory, or no fix inside the span.
    """
    traj = _checks.trajectory("trajectory", traj)
    if not isinstance(gps, Gps):
        raise TypeError(f"gps must be an annslam_lib.data.records.Gps, got {type(gps).__name__}")
    inside = (gps.t >= traj[0, 0]) & (gps.t <= traj[-1, 0])
    if not inside.any():
        raise ValueError(f"no GPS fix inside the trajectory's span {traj[0, 0]:.6g}.."
                         f"{traj[-1, 0]:.6g} s (GPS covers {gps.t[0]:.6g}..{gps.t[-1]:.6g} s)"
                         if len(gps) else "gps holds no fixes")
    t = gps.t[inside]
    offset = interpolate_poses(traj, t)[:, :2] - gps.xy[inside]
    error = np.hypot(offset[:, 0], offset[:, 1])
    i = int(np.argmax(error))
    est = offset + gps.xy[inside]
    rmse_al, rot, shift = math.nan, math.nan, np.full(2, math.nan)
    if t.size >= 2 and np.ptp(est, axis=0).max() > 0 and np.ptp(gps.xy[inside], axis=0).max() > 0:
        R, shift = rigid_align(est, gps.xy[inside])
        d = est @ R.T + shift - gps.xy[inside]
        rmse_al, rot = float(np.sqrt(np.mean(np.sum(d * d, axis=1)))), math.atan2(R[1, 0], R[0, 0])
    return TrajectoryErrors(t=t, offset=offset, error=error,
                            rmse=float(np.sqrt(np.mean(error**2))), mean=float(error.mean()),
                            max=float(error[i]), final=float(error[-1]), t_max=float(t[i]),
                            n_outside=int(np.count_nonzero(~inside)), rmse_aligned=rmse_al,
                            rotation=rot, translation=shift)


def gps_outliers(gps: Gps, max_speed: float = 10.0, tolerance: float = 3.0) -> np.ndarray:
    """Boolean (K,) mask of GPS fixes the car cannot have reached: the step from the
    previous fix is longer than ``max_speed`` * dt + ``tolerance``, unless the previous fix
    is itself flagged (then this step is the way back from an outlier, e.g. the far side of
    a one-fix spike). Notebook 06 "the track against GPS".

    max_speed (m/s): Victoria Park's odometry never exceeds 6.7 m/s. tolerance (m): the
    receiver's own fix-to-fix jitter (in Victoria Park 99 % of the steps between fixes
    0.2 s apart are below 1.8 m, 99.9 % below 4.5 m). Uses the GPS alone, so a receiver
    that jumps and STAYS off is flagged only at the jump: after it, GPS alone cannot tell
    its offset from the filter's drift.

    Parameters
    ----------
    gps : records.Gps
        The K fixes.
    max_speed : float, optional
        Fastest speed of the car, m/s.
    tolerance : float, optional
        The receiver's fix-to-fix jitter, m.

    Returns
    -------
    ndarray of bool, shape (K,)
        True at the flagged fixes.

    Raises
    ------
    TypeError
        If ``gps`` is not a records.Gps or a setting is not a number.
    ValueError
        For a negative or non-finite setting.
    """
    _checks.instance("gps", gps, Gps, "records.Gps")
    _checks.real("max_speed", max_speed, lo=0.0)
    _checks.real("tolerance", tolerance, lo=0.0)
    flag = np.zeros(len(gps), dtype=bool)
    if len(gps) < 2:
        return flag
    step = np.hypot(np.diff(gps.east), np.diff(gps.north))
    fast = (step > max_speed * np.diff(gps.t) + tolerance).tolist()
    for i, f in enumerate(fast, start=1):
        flag[i] = f and not flag[i - 1]
    return flag
