"""Dead reckoning: the laser pose from odometry alone (notebook 01, "Dead reckoning").

Timing convention (the same as the simulator's truth). Odometry sample k, taken at
t_k, gives the control u_k = (v_c, alpha) that is HELD over [t_k, t_{k+1}). Row 0 of
a dead-reckoned trajectory is the initial pose at t_0; row k + 1 is one Euler step
of the corrected section 4.1 model from row k with control u_k over
dt = t_{k+1} - t_k (``motion.predict``). The last sample's control is unused.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..models import motion as kinematics
from ..models.geometry import wrap_angle
from ..models.geometry import interpolate_poses
from ..data.records import Dataset, Gps, Odometry
from ..models.vehicle import Vehicle

__all__ = ["controls", "dead_reckon", "HeadingFit", "initial_pose_from_gps", "gps_track_heading",
           "gps_heading", "gps_scan_poses"]


def _check(odometry, vehicle) -> None:
    if not isinstance(odometry, Odometry):
        raise TypeError(f"odometry must be an annslam_lib.data.records.Odometry, got {type(odometry).__name__}")
    if not isinstance(vehicle, Vehicle):
        raise TypeError(f"vehicle must be an annslam_lib.models.vehicle.Vehicle, got {type(vehicle).__name__}")
    if len(odometry) < 1:
        raise ValueError("odometry holds no samples")


def controls(odometry: Odometry, vehicle: Vehicle, *, encoder_correction: bool = True) -> np.ndarray:
    """Controls (K, 2) = (v_c, alpha) of every odometry sample (notebook 01, "encoder").

    With ``encoder_correction`` the back-left encoder speed is moved to the rear-axle
    centre, v_c = v_e / (1 - tan(alpha) H / L) (``motion.axle_speed``, section 4.1
    corrected); without it the raw encoder speed is used as v_c (the "what happens
    if" of notebook 01).

    Parameters
    ----------
    odometry : records.Odometry
        K samples: times ``t`` (s), encoder ``speed`` (m/s), ``steering`` (rad).
    vehicle : Vehicle
        The car (``L``, ``H``, ``a``, ``b``).
    encoder_correction : bool, optional
        Move the encoder speed to the rear-axle centre (``motion.axle_speed``); False
        uses the raw encoder speed as v_c.

    Returns
    -------
    ndarray, shape (K, 2)
        (v_c, alpha) per sample (m/s, rad).

    Raises
    ------
    TypeError
        If ``odometry`` or ``vehicle`` has the wrong type, or ``encoder_correction`` is
        not a bool.
    ValueError
        For no samples, |alpha| >= pi/2 or a singular correction.
    """
    _check(odometry, vehicle)
    if not isinstance(encoder_correction, bool):
        raise TypeError(f"encoder_correction must be a bool, got {encoder_correction!r}")
    alpha = odometry.steering
    if np.any(np.abs(alpha) >= np.pi / 2):
        raise ValueError("odometry steering must satisfy |alpha| < pi/2 (tan(alpha) is infinite)")
    v = kinematics.axle_speed(odometry.speed, alpha, vehicle)[0] if encoder_correction \
        else odometry.speed
    return np.column_stack([v, alpha])


def dead_reckon(odometry: Odometry, pose0, vehicle: Vehicle, *,
                encoder_correction: bool = True) -> np.ndarray:
    """Laser poses from odometry alone: chained Euler steps of ``motion.predict``
    (section 4.1 corrected; notebook 01 "Dead reckoning").

    Equal to K - 1 chained calls of ``motion.predict`` (to rounding), computed faster: the
    heading recursion phi_{k+1} = wrap(phi_k + dt_k v_k tan(alpha_k) / L) runs as a scalar
    loop, then every position increment dt_k * laser_velocity(phi_k, u_k) is evaluated at
    once and summed with ``np.cumsum`` (the same sequence of additions as the chain).

    Parameters
    ----------
    odometry : records.Odometry
        K samples: times ``t`` (s), encoder ``speed`` (m/s), ``steering`` (rad).
    pose0 : array_like, shape (3,)
        Laser pose (x, y, phi) (m, m, rad) at ``odometry.t[0]``.
    vehicle : Vehicle
        The car (``L``, ``H``, ``a``, ``b``).
    encoder_correction : bool, optional
        Move the encoder speed to the rear-axle centre (``motion.axle_speed``); False
        uses the raw encoder speed as v_c.

    Returns
    -------
    ndarray, shape (K, 4)
        Rows (t_k, x, y, phi), the pose at each odometry time (see the module's timing
        convention), heading wrapped to (-pi, pi].

    Raises
    ------
    TypeError
        If ``odometry`` or ``vehicle`` has the wrong type, or ``pose0`` is not numeric.
    ValueError
        For no samples, ``pose0`` not a finite (3,) array, |alpha| >= pi/2 or a
        singular encoder correction.
    """
    _check(odometry, vehicle)
    p0 = _checks.array("pose0", pose0, (3,))
    if p0.shape != (3,):
        raise ValueError(f"pose0 must have shape (3,), got {p0.shape}")
    u = controls(odometry, vehicle, encoder_correction=encoder_correction)
    t = odometry.t
    dt = np.diff(t)
    v, alpha = u[:-1, 0], u[:-1, 1]
    # The expressions mirror kinematics._rate/predict term by term, so that the
    # result matches the chained calls to the last few bits.
    w = v * np.tan(alpha) / vehicle.L
    dphi = (dt * w).tolist()
    phi = [float(wrap_angle(p0[2]))]
    two_pi = 2.0 * math.pi
    for d in dphi:
        a = phi[-1] + d
        phi.append(a if -math.pi < a <= math.pi else math.pi - (math.pi - a) % two_pi)
    phi = np.array(phi)
    c, s = np.cos(phi[:-1]), np.sin(phi[:-1])
    lx = vehicle.a * s + vehicle.b * c
    ly = vehicle.a * c - vehicle.b * s
    x = np.cumsum(np.concatenate([[p0[0]], dt * (v * c - w * lx)]))
    y = np.cumsum(np.concatenate([[p0[1]], dt * (v * s + w * ly)]))
    return np.column_stack([t, x, y, phi])


def gps_track_heading(gps: Gps, *, distance: float = 2.0) -> float:
    """Direction (rad) of the GPS track from its first fix to the first fix at least
    ``distance`` metres away: the naive initial heading of notebook 01.

    Biased for this car whenever it starts in a turn: the GPS (laser) point does not
    move along the heading (it sits 3.8 m ahead of the rear axle, so it side-slips
    by atan(a tan(alpha) / (L - b tan(alpha)))), and a chord lags the tangent of a
    curved track by half the angle turned. Use :func:`initial_pose_from_gps`.

    Parameters
    ----------
    gps : records.Gps
        GPS fixes: times ``t`` (s) and positions ``xy`` (m) of the laser point.
    distance : float, optional
        How far from the first fix the chord reaches, m, > 0.

    Returns
    -------
    float
        The chord's direction, rad, anticlockwise from East.

    Raises
    ------
    TypeError
        If ``gps`` is not a records.Gps.
    ValueError
        If ``distance`` is not a positive number, there are fewer than two fixes, or
        the track never gets ``distance`` m from its start.
    """
    if not isinstance(gps, Gps):
        raise TypeError(f"gps must be an annslam_lib.data.records.Gps, got {type(gps).__name__}")
    if not (isinstance(distance, (int, float)) and math.isfinite(distance) and distance > 0):
        raise ValueError(f"distance must be a positive number of metres, got {distance!r}")
    if len(gps) < 2:
        raise ValueError("gps needs at least two fixes for a track direction")
    d = gps.xy - gps.xy[0]
    far = np.flatnonzero(np.hypot(d[:, 0], d[:, 1]) >= distance)
    if far.size == 0:
        raise ValueError(f"the GPS track never gets {distance} m from its first fix")
    return float(np.arctan2(d[far[0], 1], d[far[0], 0]))


@dataclass(frozen=True)
class HeadingFit:
    """Result of :func:`initial_pose_from_gps`.

    pose (3,): laser pose at ``t``, the first odometry time; fixes: GPS fixes used;
    window (s): the fitted span after the first fix; travel (m): farthest fix from the
    first one; rms (m): RMS distance between the fitted dead-reckoned path and the
    fixes used, a measure of how well the model explains the start of the run;
    rejected: fixes of the window left out as outliers (the robust fit, below); t_end:
    time of the window's last fix (s): the fixes up to it went into the fit.
    """

    pose: np.ndarray
    t: float
    fixes: int
    window: float
    travel: float
    rms: float
    rejected: int = 0
    t_end: float = math.nan


def _rotation_fit(D, G, pivot_d, pivot_g):
    """The one-angle Procrustes fit of paths D onto fixes G about the pivots: (R, start,
    residuals (K, 2))."""
    d, g = D - pivot_d, G - pivot_g
    theta = math.atan2(float(np.sum(d[:, 0] * g[:, 1] - d[:, 1] * g[:, 0])),
                       float(np.sum(d[:, 0] * g[:, 0] + d[:, 1] * g[:, 1])))
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, -s], [s, c]])
    return theta, R, pivot_g - R @ pivot_d, d @ R.T - g


def initial_pose_from_gps(odometry: Odometry, gps: Gps, vehicle: Vehicle, *,
                          window: float = 10.0, min_travel: float = 2.0,
                          fit_position: bool = False,
                          encoder_correction: bool = True,
                          outlier_floor: float = 2.0, max_rms: float = 2.0) -> HeadingFit:
    """Initial laser pose estimated from the data (notebook 01, "Where does the car start?").

    Position: the first GPS fix at or after ``odometry.t[0]`` (the GPS antenna is the
    laser point). Heading: the least-squares fit of the dead-reckoned path of the first
    ``window`` seconds after that fix to the GPS fixes of the same span, rotating the
    path about the first fix.

    Dead reckoning is equivariant under rigid motions (the Euler step rotates with
    the pose), so the path started at heading theta is the path started at heading 0,
    rotated by theta: one run from (0, 0, 0) gives positions D(t), and the heading
    minimising sum_i |R(theta) d_i - g_i|^2, with d_i = D(t_i) - D(t_g) and
    g_i = gps_i - gps_g relative to the first fix g, is the closed form
    theta = atan2(sum d_i x g_i, sum d_i . g_i) (a one-angle Procrustes problem).
    The pose at ``odometry.t[0]`` is then (gps_g - R(theta) D(t_g), theta).

    Robust: the fixes of the window are first fitted about their centroids
    (position and heading free) and a fix whose residual exceeds 3 robust standard
    deviations of the residuals (1.4826 MAD) and at least ``outlier_floor`` m (a gross error:
    a receiver's ordinary scatter stays in), is left out;
    the fit is repeated until no fix changes side. The pivot is then the first fix KEPT, so
    a wrong first fix is not trusted as the start. With clean fixes nothing is left out and
    the result is the plain fit above.

    Parameters
    ----------
    odometry : records.Odometry
        K samples: times ``t`` (s), encoder ``speed`` (m/s), ``steering`` (rad).
    gps : records.Gps
        GPS fixes: times ``t`` (s) and positions ``xy`` (m) of the laser point.
    vehicle : Vehicle
        The car (``L``, ``H``, ``a``, ``b``).
    window : float, optional
        Span of the fit after the first fix, s.
    min_travel : float, optional
        Distance the window's fixes must reach from the first one, m.
    fit_position : bool, optional
        Fit about the centroids (position and heading free) instead of pivoting about
        the first fix kept.
    encoder_correction : bool, optional
        Move the encoder speed to the rear-axle centre (``motion.axle_speed``); False
        uses the raw encoder speed as v_c.
    outlier_floor : float, optional
        Smallest residual that can make a fix an outlier, m.
    max_rms : float, optional
        Largest RMS residual of the fit accepted, m.

    Returns
    -------
    HeadingFit
        The pose (3,) at ``odometry.t[0]`` with the fit's fixes, window, travel, RMS
        residual and rejected fixes.

    Raises
    ------
    TypeError
        If ``odometry``, ``gps`` or ``vehicle`` has the wrong type.
    ValueError
        If no fix lies in the odometry's span; if the fixes of the window never get
        ``min_travel`` m from the first one (a standing car shows no heading); if the
        fit's RMS residual over the fixes kept exceeds ``max_rms`` m (the dead-reckoned
        start does not match GPS: a wrong vehicle model, a clock offset or a receiver
        that is off); if fewer than half of the window's fixes (or fewer than 3) are
        kept; or for a setting that is not a positive finite number.
    """
    _check(odometry, vehicle)
    if not isinstance(gps, Gps):
        raise TypeError(f"gps must be an annslam_lib.data.records.Gps, got {type(gps).__name__}")
    for name, val in (("window", window), ("min_travel", min_travel)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be a positive finite number, got {val!r}")
    inside = np.flatnonzero((gps.t >= odometry.t[0]) & (gps.t <= odometry.t[-1]))
    if inside.size == 0:
        raise ValueError("no GPS fix inside the odometry's time span")
    g0 = inside[0]
    use = inside[gps.t[inside] <= gps.t[g0] + window]
    g = gps.xy[use] - gps.xy[g0]
    travel = float(np.max(np.hypot(g[:, 0], g[:, 1])))
    if travel < min_travel:
        raise ValueError(f"the GPS fixes of the first {window} s stay within {travel:.3g} m of "
                         f"the first fix (< min_travel = {min_travel} m): the heading is not "
                         "observable; use a longer window")
    for name, val in (("outlier_floor", outlier_floor), ("max_rms", max_rms)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be a positive finite number, got {val!r}")
    path = dead_reckon(odometry, np.zeros(3), vehicle, encoder_correction=encoder_correction)
    D = interpolate_poses(path, gps.t[use])[:, :2]
    G = gps.xy[use]
    keep = np.ones(use.size, dtype=bool)
    for _ in range(10):                       # robust: centroid fit, outliers out, repeat
        if keep.sum() < 2:
            break
        _, R_all, start_all, _ = _rotation_fit(D[keep], G[keep], D[keep].mean(axis=0),
                                               G[keep].mean(axis=0))
        r_all = np.hypot(*(D @ R_all.T + start_all - G).T)
        mad = 1.4826 * float(np.median(np.abs(r_all[keep] - np.median(r_all[keep]))))
        limit = max(float(np.median(r_all[keep])) + 3.0 * mad, outlier_floor)
        new = r_all <= limit
        if np.array_equal(new, keep):
            break
        keep = new
    n_keep = int(keep.sum())
    if n_keep < max(3, (use.size + 1) // 2):
        raise ValueError(f"only {n_keep} of the {use.size} GPS fixes of the first {window} s fit "
                         "one dead-reckoned path: the fixes or the odometry are not consistent "
                         "enough to give a start")
    D, G = D[keep], G[keep]
    # About the first fix kept (its position is trusted), or about the centroids.
    cd, cg = (D.mean(axis=0), G.mean(axis=0)) if fit_position else (D[0], G[0])
    theta, R, start, resid = _rotation_fit(D, G, cd, cg)
    rms = float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))
    if rms > max_rms:
        raise ValueError(f"the initial-pose fit leaves an RMS residual of {rms:.3g} m over "
                         f"{n_keep} GPS fixes (> max_rms = {max_rms} m): the dead-reckoned start "
                         "does not match GPS (a wrong vehicle model, a clock offset or a "
                         "receiver that is off); the start is not trusted")
    return HeadingFit(pose=np.array([start[0], start[1], theta]), t=float(odometry.t[0]),
                      fixes=n_keep, window=float(window), travel=travel, rms=rms,
                      rejected=int(use.size - n_keep), t_end=float(gps.t[use[-1]]))


def gps_heading(gps: Gps, odometry: Odometry, vehicle: Vehicle, *, min_speed: float = 0.5,
                max_gap: float = 0.5, encoder_correction: bool = True) -> np.ndarray:
    """The car's heading at GPS fixes, from the GPS track and the steering angle
    (notebook 01, "an independent heading from GPS").

    The GPS (laser) point moves in direction phi + beta, where beta is the angle of
    the laser velocity in the car's frame, beta = atan2(a w, v_c - b w) with
    w = v_c tan(alpha) / L (``motion.laser_velocity`` at phi = 0): 22 degrees at
    alpha = 0.28 rad. So phi = (track direction) - beta, with the track direction
    from central differences of the fixes i - 1 and i + 1 (parallel to the tangent
    at fix i on a circle driven at constant speed) and (v_c, alpha) the odometry
    sample held at fix i. Independent of the dead-reckoned heading, it uses the
    speed only for its sign.

    Parameters
    ----------
    gps : records.Gps
        GPS fixes: times ``t`` (s) and positions ``xy`` (m) of the laser point.
    odometry : records.Odometry
        K samples: times ``t`` (s), encoder ``speed`` (m/s), ``steering`` (rad).
    vehicle : Vehicle
        The car (``L``, ``H``, ``a``, ``b``).
    min_speed : float, optional
        Smallest GPS speed and |v_c| used, m/s (a standing car has no track direction).
    max_gap : float, optional
        Largest time between a fix and each of its neighbours, s.
    encoder_correction : bool, optional
        Move the encoder speed to the rear-axle centre (``motion.axle_speed``); False
        uses the raw encoder speed as v_c.

    Returns
    -------
    ndarray, shape (M, 2)
        Rows (t, phi) (s, rad) for the interior fixes inside the odometry's span whose
        neighbours are at most ``max_gap`` s apart and where both the GPS speed and
        |v_c| are at least ``min_speed`` m/s.

    Raises
    ------
    TypeError
        If ``gps``, ``odometry`` or ``vehicle`` has the wrong type.
    ValueError
        If ``min_speed`` or ``max_gap`` is not a positive finite number.
    """
    _check(odometry, vehicle)
    if not isinstance(gps, Gps):
        raise TypeError(f"gps must be an annslam_lib.data.records.Gps, got {type(gps).__name__}")
    for name, val in (("min_speed", min_speed), ("max_gap", max_gap)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be a positive finite number, got {val!r}")
    if len(gps) < 3:
        return np.empty((0, 2))
    t, xy = gps.t[1:-1], gps.xy
    gap = np.diff(gps.t)
    span = gps.t[2:] - gps.t[:-2]
    ok = ((span > 0) & (gap[:-1] <= max_gap) & (gap[1:] <= max_gap)
          & (t >= odometry.t[0]) & (t <= odometry.t[-1]))
    vel = (xy[2:] - xy[:-2]) / np.where(span > 0, span, 1.0)[:, None]
    k = np.clip(np.searchsorted(odometry.t, t, side="right") - 1, 0, len(odometry) - 1)
    u = controls(odometry, vehicle, encoder_correction=encoder_correction)[k]
    ok &= (np.hypot(vel[:, 0], vel[:, 1]) >= min_speed) & (np.abs(u[:, 0]) >= min_speed)
    lv = kinematics.laser_velocity(np.zeros((int(ok.sum()), 3)), u[ok], vehicle)
    beta = np.arctan2(lv[:, 1], lv[:, 0])
    phi = wrap_angle(np.arctan2(vel[ok, 1], vel[ok, 0]) - beta)
    return np.column_stack([t[ok], np.atleast_1d(phi)])


def gps_scan_poses(dataset: Dataset, *, max_heading_gap: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Reference laser poses at the scan times from GPS alone (notebook 04 "how good
    are the beacons?"): position = GPS interpolated at the scan time (the antenna is at
    the laser), heading = :func:`gps_heading` (GPS track direction corrected
    for the laser point's side-slip) interpolated at the scan time.

    Parameters
    ----------
    dataset : records.Dataset
        A run with its scan times, GPS, odometry and vehicle.
    max_heading_gap : float, optional
        Largest time from a scan to a GPS heading, s.

    Returns
    -------
    poses : ndarray, shape (S, 3)
        (x, y, phi) (m, m, rad) at the S scan times.
    valid : ndarray of bool, shape (S,)
        True where the scan lies inside the GPS span and a GPS heading exists within
        ``max_heading_gap`` seconds (the car moving).

    Raises
    ------
    TypeError
        If ``dataset`` is not a records.Dataset.
    ValueError
        If the dataset has fewer than 3 GPS fixes.
    """
    if not isinstance(dataset, Dataset):
        raise TypeError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    t, gps = dataset.scan_times, dataset.gps
    if len(gps) < 3:
        raise ValueError(f"dataset {dataset.name!r} has {len(gps)} GPS fixes: need at least 3")
    heading = gps_heading(gps, dataset.odometry, dataset.vehicle)
    x = np.interp(t, gps.t, gps.east)
    y = np.interp(t, gps.t, gps.north)
    if heading.shape[0] == 0:
        return np.column_stack([x, y, np.zeros_like(t)]), np.zeros(t.size, dtype=bool)
    ht = heading[:, 0]
    phi = wrap_angle(np.interp(t, ht, np.unwrap(heading[:, 1])))
    k = np.searchsorted(ht, t)
    near = np.minimum(np.abs(t - ht[np.clip(k - 1, 0, ht.size - 1)]),
                      np.abs(t - ht[np.clip(k, 0, ht.size - 1)]))
    valid = (near <= max_heading_gap) & (t >= gps.t[0]) & (t <= gps.t[-1])
    return np.column_stack([x, y, np.atleast_1d(phi)]), valid
