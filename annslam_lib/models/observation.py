"""Range-bearing observation of point landmarks by the laser (paper 4.1/4.2, corrected),
and the two-point landmark frame of section 3.3 (corrected).

Laser convention: the bearing is counted from the vehicle's right, pi/2
straight ahead, so for a laser pose (x, y, phi) and a landmark (x_i, y_i)

    range   = sqrt((x_i - x)^2 + (y_i - y)^2)
    bearing = atan2(y_i - y, x_i - x) - phi + pi/2   wrapped to (-pi, pi].

Built Solà style, frame by frame: world -> laser frame (``geometry.to_frame``)
-> laser polar coordinates, with the Jacobians chained (notebook 03 observation model).

Fast copies (change them together with :func:`observe`, :func:`_to_polar` and
:func:`polar_to_laser`): :func:`observe_values` and :func:`inverse_observe_values` (the same
arithmetic without the Jacobians: bitwise the same values, for the landmark network at run
time), :func:`observe_fast` (the filter's update), the innovation
covariances of ``slam.efficient.EkfSlam.observation_model`` (closed form from the same
Jacobians) and their compiled copy ``slam.compiled.gate_loop`` (long runs' gating), and
``records.Laser.points`` (calls :func:`polar_to_laser`).
``tests/test_ekf_slam.py`` compares the filter with the dense reference, which calls
:func:`observe` itself.
"""
from __future__ import annotations

import numpy as np

from .. import _checks
from .geometry import from_frame, to_frame, wrap_angle

__all__ = ["observe", "inverse_observe", "observe_values", "inverse_observe_values",
           "landmark_from_two_points", "two_point_transform", "polar_to_laser", "observe_fast",
           "MIN_RANGE"]

#: Landmarks closer than this to the sensor have no defined bearing.
MIN_RANGE = 1e-9


def _to_polar(p):
    """Laser-frame point (x forward, y left) -> (range, laser bearing) and Jacobian."""
    x, y = p[..., 0], p[..., 1]
    with np.errstate(over="ignore"):
        q = x * x + y * y
    if np.all(np.isfinite(q)):
        r = np.sqrt(q)
        J = np.stack([np.stack([x / r, y / r], -1), np.stack([-y / q, x / q], -1)], -2)
    else:                     # |p| beyond 1e154: x*x overflows, hypot and (x / r) / r do not
        r = np.hypot(x, y)
        ux, uy = x / r, y / r
        J = np.stack([np.stack([ux, uy], -1), np.stack([-uy / r, ux / r], -1)], -2)
    z = np.stack([r, wrap_angle(np.arctan2(y, x) + np.pi / 2)], -1)
    return z, J


def polar_to_laser(r, bearing) -> np.ndarray:
    """Laser-frame points (..., 2), x forward and y left, of returns at range ``r`` and laser
    bearing ``bearing`` (0 to the right, pi/2 ahead): x = r sin(beta), y = -r cos(beta).
    The one place this convention is written (scans, detections, plots use it)."""
    r, b = np.asarray(r, dtype=float), np.asarray(bearing, dtype=float)
    return np.stack([r * np.sin(b), -r * np.cos(b)], -1)


def _from_polar(z):
    """(range, laser bearing) -> laser-frame point (:func:`polar_to_laser`) and Jacobian."""
    r, b = z[..., 0], z[..., 1]
    s, c = np.sin(b), np.cos(b)
    p = polar_to_laser(r, b)
    J = np.stack([np.stack([s, r * c], -1), np.stack([-c, r * s], -1)], -2)
    return p, J


def observe(pose, landmark):
    """Predicted measurement z = (range, bearing) of ``landmark`` from the laser ``pose``.

    Analytically H_pose = [[-dx/r, -dy/r, 0], [dy/r^2, -dx/r^2, -1]], H_landmark =
    [[dx/r, dy/r], [-dy/r^2, dx/r^2]] with (dx, dy) = landmark - position.

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Laser pose (x, y, phi) (m, m, rad).
    landmark : array_like, shape (..., 2)
        Landmark position (x_i, y_i), m; broadcast with ``pose`` (e.g. pose (3,),
        landmark (M, 2)).

    Returns
    -------
    z : ndarray, shape (..., 2)
        (range, bearing) (m, rad), bearing in (-pi, pi], pi/2 straight ahead.
    H_pose : ndarray, shape (..., 2, 3)
        d z / d pose.
    H_landmark : ndarray, shape (..., 2, 2)
        d z / d landmark.

    Raises
    ------
    TypeError
        If an input is not numeric.
    ValueError
        For a landmark within 1e-9 m of the sensor (bearing undefined), a wrong last
        dimension, non-finite values or shapes that do not broadcast.
    """
    pose = _checks.array("pose", pose, (3,))
    landmark = _checks.array("landmark", landmark, (2,))
    _checks.broadcast(pose=pose.shape[:-1], landmark=landmark.shape[:-1])
    p, Jp_pose, Jp_lm = to_frame(pose, landmark)
    if np.any(np.hypot(p[..., 0], p[..., 1]) < MIN_RANGE):
        raise ValueError("landmark coincides with the sensor position (range < 1e-9 m): "
                         "bearing undefined")
    z, Jz = _to_polar(p)
    return z, Jz @ Jp_pose, Jz @ Jp_lm


def inverse_observe(pose, z):
    """Landmark position from a measurement (landmark initialisation):
    landmark = (x + r cos(phi + beta - pi/2), y + r sin(phi + beta - pi/2)).

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Laser pose (x, y, phi) (m, m, rad).
    z : array_like, shape (..., 2)
        Measurement (range, bearing) (m, rad), range > 0; broadcast with ``pose``.

    Returns
    -------
    landmark : ndarray, shape (..., 2)
        Landmark position in the world, m.
    J_pose : ndarray, shape (..., 2, 3)
        d landmark / d pose.
    J_z : ndarray, shape (..., 2, 2)
        d landmark / d z.

    Raises
    ------
    TypeError
        If an input is not numeric.
    ValueError
        For a range <= 0, a wrong last dimension, non-finite values or shapes that do
        not broadcast.
    """
    pose = _checks.array("pose", pose, (3,))
    z = _checks.array("z", z, (2,))
    _checks.broadcast(pose=pose.shape[:-1], z=z.shape[:-1])
    if np.any(z[..., 0] <= 0):
        raise ValueError(f"z range must be > 0, got min {np.min(z[..., 0]):.6g}")
    p, Jp_z = _from_polar(z)
    lm, J_pose, J_p = from_frame(pose, p)
    return lm, J_pose, J_p @ Jp_z


def observe_values(pose, landmark) -> np.ndarray:
    """:func:`observe`'s z only (bitwise the same, tested): pose (3,), landmark (N, 2),
    both already finite float arrays. Used where the Jacobians are not needed, once per
    scan (the ANN pseudo-measurement), where building them was most of the cost."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dx, dy = landmark[:, 0] - pose[0], landmark[:, 1] - pose[1]
    x, y = c * dx + s * dy, -s * dx + c * dy
    with np.errstate(over="ignore"):
        r = np.sqrt(x * x + y * y)
    if not np.all(np.isfinite(r)):                   # as _to_polar: beyond 1e154
        r = np.hypot(x, y)
    if r.size and r.min() < MIN_RANGE:
        raise ValueError("landmark coincides with the sensor position (range < 1e-9 m): "
                         "bearing undefined")
    return np.column_stack([r, wrap_angle(np.arctan2(y, x) + np.pi / 2)])


def inverse_observe_values(pose, z) -> np.ndarray:
    """:func:`inverse_observe`'s landmark only (bitwise the same, tested): pose (3,) or
    (N, 3), z (N, 2), finite float arrays; raises ValueError for a range <= 0."""
    if z.shape[0] and np.min(z[:, 0]) <= 0:
        raise ValueError(f"z range must be > 0, got min {np.min(z[:, 0]):.6g}")
    q = polar_to_laser(z[:, 0], z[:, 1])
    phi = pose[..., 2]
    c, s = np.cos(phi), np.sin(phi)
    rx = c * q[:, 0] - s * q[:, 1]
    ry = s * q[:, 0] + c * q[:, 1]
    return np.column_stack([pose[..., 0] + rx, pose[..., 1] + ry])


def landmark_from_two_points(p_right, p_left):
    """Landmark frame R_ij from two laser points in the robot frame (section 3.3, corrected).

    The frame has its origin at the left point and its x axis pointing from
    the left point to the right point, at angle

        theta = atan2(y_r - y_l, x_r - x_l)    in (-pi, pi]

    (the paper's three cases, with the third condition as X_l > X_r and the
    vertical case +-pi/2 by the sign of y_r - y_l). The paper's transform
    ijT_r = [[R(theta)^T, (i, j)], [0, 1]] maps robot coordinates to landmark
    coordinates, so its translation is the robot origin seen from the landmark:

        i = -(x_l cos(theta) + y_l sin(theta)),   j = x_l sin(theta) - y_l cos(theta).

    See ``annslam_lib.paper`` for what was printed.

    Parameters
    ----------
    p_right : array_like, shape (..., 2)
        The right point in the robot frame, m.
    p_left : array_like, shape (..., 2)
        The left point in the robot frame, m.

    Returns
    -------
    frame : ndarray, shape (..., 3)
        (i, j, theta) (m, m, rad), theta in (-pi, pi].
    J_right : ndarray, shape (..., 3, 2)
        d frame / d p_right.
    J_left : ndarray, shape (..., 3, 2)
        d frame / d p_left.

    Raises
    ------
    TypeError
        If an input is not numeric.
    ValueError
        If the points coincide (theta undefined), a last dimension is not 2 or a value
        is not finite.
    """
    pr = _checks.array("p_right", p_right, (2,))
    pl = _checks.array("p_left", p_left, (2,))
    dx, dy = pr[..., 0] - pl[..., 0], pr[..., 1] - pl[..., 1]
    q = dx * dx + dy * dy
    if np.any(q < MIN_RANGE**2):
        raise ValueError("p_right and p_left coincide: the landmark orientation is undefined")
    theta = wrap_angle(np.arctan2(dy, dx))
    c, s = np.cos(theta), np.sin(theta)
    xl, yl = pl[..., 0], pl[..., 1]
    i = -(xl * c + yl * s)
    j = xl * s - yl * c
    dth_r = np.stack([-dy / q, dx / q], -1)          # d theta / d p_right
    dth_l = -dth_r
    # di/dtheta = j, dj/dtheta = -i; i, j also depend directly on p_left.
    J_right = np.stack([j[..., None] * dth_r, -i[..., None] * dth_r, dth_r], -2)
    direct_i = np.stack([-c, -s], -1)
    direct_j = np.stack([s, -c], -1)
    J_left = np.stack([direct_i + j[..., None] * dth_l, direct_j - i[..., None] * dth_l, dth_l], -2)
    return np.stack([i, j, theta], -1), J_right, J_left


def two_point_transform(p_right, p_left) -> np.ndarray:
    """The homogeneous 2-D transform ijT_r (..., 3, 3) of section 3.3, corrected:
    landmark-frame coordinates = ijT_r @ (robot-frame x, y, 1).

    Parameters
    ----------
    p_right : array_like, shape (..., 2)
        The right point in the robot frame, m.
    p_left : array_like, shape (..., 2)
        The left point in the robot frame, m.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        [[R(theta)^T, (i, j)], [0, 1]] of :func:`landmark_from_two_points`' frame.

    Raises
    ------
    ValueError
        As :func:`landmark_from_two_points` (the points coincide).
    """
    frame, _, _ = landmark_from_two_points(p_right, p_left)
    i, j, theta = frame[..., 0], frame[..., 1], frame[..., 2]
    c, s = np.cos(theta), np.sin(theta)
    zero, one = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, s, i], -1), np.stack([-s, c, j], -1),
                     np.stack([zero, zero, one], -1)], -2)


def observe_fast(pose, lms):
    """Range/bearing of landmarks lms (N, 2) from the laser pose (3,) and the Jacobians
    H_pose (N, 2, 3), H_lm (N, 2, 2): :func:`observe` (same formulas) without its input
    checks, for the filter's update, which runs it every scan."""
    dx = lms[:, 0] - pose[0]
    dy = lms[:, 1] - pose[1]
    q = dx * dx + dy * dy
    if q.size and q.min() < 1e-18:
        raise ValueError("a landmark coincides with the sensor position (range < 1e-9 m)")
    r = np.sqrt(q)
    b = np.arctan2(dy, dx) - pose[2] + np.pi / 2
    b = np.where((b > -np.pi) & (b <= np.pi), b, np.pi - np.mod(np.pi - b, 2.0 * np.pi))
    Hl = np.empty((lms.shape[0], 2, 2))
    Hl[:, 0, 0] = dx / r
    Hl[:, 0, 1] = dy / r
    Hl[:, 1, 0] = -dy / q
    Hl[:, 1, 1] = dx / q
    Hp = np.zeros((lms.shape[0], 2, 3))
    Hp[:, :, :2] = -Hl
    Hp[:, 1, 2] = -1.0
    return np.column_stack([r, b]), Hp, Hl
