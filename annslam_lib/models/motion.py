"""Motion model of the car-like vehicle (paper section 4.1, corrected).

The state is the LASER pose (x, y, phi): the laser position in the world and
the car's heading. The laser sits ``a`` m ahead of the rear-axle centre C and
``b`` m to its left, P_l = P_c + a T(phi) + b T(phi + pi/2), T(phi) = (cos, sin).
Controls are (v_c, alpha): speed of the rear-axle centre and steering angle.
The raw encoder sits on the back-left wheel, ``H`` m left of C.

Everything here is vectorised over leading (batch) dimensions and returns
Jacobians next to values (notebook 01 vehicle kinematics; notebook 02 for the
laser offset transform).

Fast copies (change them together with :func:`predict` and :func:`_rate`): the filter's
scalar step ``slam.efficient.EkfSlam.predict`` (Euler and midpoint, with the noise
dt * Delta * B Q_c B^T), ``slam.dense.DenseEkfSlam.predict`` (calls :func:`predict`), the
stretches compounded between events ``slam.stretches.compound``, the vectorised chain
``slam.dead_reckoning.dead_reckon``, and :func:`control_table`, which precomputes what the
scalar step needs per odometry sample. ``tests/test_ekf_slam.py``,
``tests/test_stretches.py`` and ``tests/test_dead_reckoning.py`` compare each with
:func:`predict`.
"""
from __future__ import annotations

import numpy as np

from .. import _checks
from .geometry import wrap_angle
from .vehicle import Vehicle

__all__ = ["axle_speed", "laser_pose", "axle_pose", "laser_velocity", "predict", "predict_exact",
           "control_table"]

#: Smallest |1 - tan(alpha) H / L| accepted by :func:`axle_speed`.
MIN_SPEED_DENOMINATOR = 1e-6


def _steering(name: str, alpha: np.ndarray) -> np.ndarray:
    if np.any(np.abs(alpha) >= np.pi / 2):
        raise ValueError(f"{name} must satisfy |alpha| < pi/2 (tan(alpha) is infinite), "
                         f"got max |alpha| = {np.max(np.abs(alpha)):.6g}")
    return alpha


def axle_speed(encoder_speed, steering, vehicle: Vehicle):
    """Rear-axle-centre speed from the back-left encoder speed (section 4.1, corrected):
    v_c = v_e / (1 - tan(alpha) H / L).

    The encoder wheel runs on a circle of radius R - H around the instantaneous
    centre of rotation, R = L / tan(alpha), so v_e = v_c (R - H) / R.
    Elementwise over broadcast arrays.

    Parameters
    ----------
    encoder_speed : float or array_like, shape (...)
        Speed v_e of the back-left encoder wheel, m/s.
    steering : float or array_like, shape (...)
        Steering angle alpha, rad, broadcast with ``encoder_speed``.
    vehicle : Vehicle
        The car; its wheelbase ``L`` and encoder offset ``H`` are used.

    Returns
    -------
    v_c : float or ndarray, shape (...)
        Speed of the rear-axle centre, m/s.
    J : ndarray, shape (..., 2)
        d v_c / d(v_e, alpha).

    Raises
    ------
    TypeError
        If an input is not numeric or ``vehicle`` is not a :class:`Vehicle`.
    ValueError
        For |alpha| >= pi/2, a denominator |1 - tan(alpha) H / L| < 1e-6 (the encoder
        wheel on the ICR), non-finite values or shapes that do not broadcast.
    """
    veh = _checks.instance("vehicle", vehicle, Vehicle)
    v_e = _checks.array("encoder_speed", encoder_speed)
    alpha = _steering("steering", _checks.array("steering", steering))
    _checks.broadcast(encoder_speed=v_e.shape, steering=alpha.shape)
    v_e, alpha = np.broadcast_arrays(v_e, alpha)
    t = np.tan(alpha)
    d = 1.0 - t * veh.H / veh.L
    if np.any(np.abs(d) < MIN_SPEED_DENOMINATOR):
        raise ValueError("axle_speed: singular steering, 1 - tan(alpha) H / L is ~0 "
                         "(the encoder wheel sits on the instantaneous centre of rotation)")
    v_c = v_e / d
    J = np.stack([1.0 / d, v_e * (veh.H / veh.L) * (1.0 + t * t) / (d * d)], -1)
    return v_c[()], J


def laser_pose(axle_pose, vehicle: Vehicle):
    """Laser pose from the rear-axle pose (x_c, y_c, phi) (section 4.1, P_l equation).

    The heading is passed through unchanged.

    Parameters
    ----------
    axle_pose : array_like, shape (..., 3)
        Rear-axle pose (x_c, y_c, phi) (m, m, rad), any leading (batch) dimensions.
    vehicle : Vehicle
        The car; its ``a`` (laser ahead of C) and ``b`` (to the left) are used.

    Returns
    -------
    pose : ndarray, shape (..., 3)
        Laser pose (x_l, y_l, phi).
    J : ndarray, shape (..., 3, 3)
        d pose / d axle_pose.

    Raises
    ------
    TypeError
        If ``axle_pose`` is not numeric or ``vehicle`` is not a :class:`Vehicle`.
    ValueError
        If the last dimension of ``axle_pose`` is not 3, or it is not finite.
    """
    veh = _checks.instance("vehicle", vehicle, Vehicle)
    p = _checks.array("axle_pose", axle_pose, (3,))
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    dx, dy = veh.a * c - veh.b * s, veh.a * s + veh.b * c
    out = np.stack([p[..., 0] + dx, p[..., 1] + dy, p[..., 2]], -1)
    return out, _offset_jacobian(-dy, dx)


def axle_pose(laser_pose, vehicle: Vehicle):
    """Rear-axle pose from the laser pose: the inverse of :func:`laser_pose` (notebook 02,
    exercise 2.1).

    The heading is shared by the two points, so the laser pose already holds the phi that
    turns the lever arm, and the lever arm is taken off again:

        P_c = P_l - R(phi) (a, b) = P_l - a T(phi) - b T(phi + pi/2),

    the paper's section 4.1 P_l equation solved for P_c.

    Parameters
    ----------
    laser_pose : array_like, shape (..., 3)
        Laser pose (x_l, y_l, phi) (m, m, rad), any leading (batch) dimensions.
    vehicle : Vehicle
        The car; its ``a`` (laser ahead of C) and ``b`` (to the left) are used.

    Returns
    -------
    pose : ndarray, shape (..., 3)
        Rear-axle pose (x_c, y_c, phi), the heading passed through unchanged.
    J : ndarray, shape (..., 3, 3)
        d pose / d laser_pose: the identity with the heading column
        (a sin(phi) + b cos(phi), -a cos(phi) + b sin(phi), 1), the inverse of the
        Jacobian of :func:`laser_pose`.

    Raises
    ------
    TypeError
        If ``laser_pose`` is not numeric or ``vehicle`` is not a :class:`Vehicle`.
    ValueError
        If the last dimension of ``laser_pose`` is not 3, or it is not finite.
    """
    veh = _checks.instance("vehicle", vehicle, Vehicle)
    p = _checks.array("laser_pose", laser_pose, (3,))
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    dx, dy = veh.a * c - veh.b * s, veh.a * s + veh.b * c
    out = np.stack([p[..., 0] - dx, p[..., 1] - dy, p[..., 2]], -1)
    return out, _offset_jacobian(dy, -dx)


def _offset_jacobian(dxdphi: np.ndarray, dydphi: np.ndarray) -> np.ndarray:
    J = np.zeros(dxdphi.shape + (3, 3))
    J[..., 0, 0] = J[..., 1, 1] = J[..., 2, 2] = 1.0
    J[..., 0, 2] = dxdphi
    J[..., 1, 2] = dydphi
    return J


def _pose_control(pose, control):
    pose = _checks.array("pose", pose, (3,))
    control = _checks.array("control", control, (2,))
    _steering("control[..., 1] (steering)", control[..., 1])
    _checks.broadcast(pose=pose.shape[:-1], control=control.shape[:-1])
    return pose, control


def laser_velocity(pose, control, vehicle: Vehicle) -> np.ndarray:
    """Continuous-time motion of the laser point (section 4.1 "full state", corrected):

        xdot   = v_c cos(phi) - v_c/L tan(alpha) (a sin(phi) + b cos(phi))
        ydot   = v_c sin(phi) + v_c/L tan(alpha) (a cos(phi) - b sin(phi))
        phidot = v_c/L tan(alpha)

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Laser pose (x, y, phi) (m, m, rad).
    control : array_like, shape (..., 2)
        (v_c, alpha): rear-axle-centre speed, m/s, and steering angle, rad; broadcast with
        ``pose`` over leading dimensions.
    vehicle : Vehicle
        The car (``L``, ``a``, ``b``).

    Returns
    -------
    ndarray, shape (..., 3)
        (xdot, ydot, phidot) (m/s, m/s, rad/s).

    Raises
    ------
    TypeError
        If an input is not numeric or ``vehicle`` is not a :class:`Vehicle`.
    ValueError
        If a last dimension is wrong, a value is not finite, the shapes do not broadcast,
        or |alpha| >= pi/2.
    """
    veh = _checks.instance("vehicle", vehicle, Vehicle)
    pose, control = _pose_control(pose, control)
    return _rate(pose, control, veh)[0]


def _rate(pose, control, veh: Vehicle):
    """Rate (..., 3) and its Jacobians w.r.t. pose (..., 3, 3) and control (..., 3, 2)."""
    phi, v, alpha = pose[..., 2], control[..., 0], control[..., 1]
    c, s, t = np.cos(phi), np.sin(phi), np.tan(alpha)
    w = v * t / veh.L                                  # yaw rate
    lx = veh.a * s + veh.b * c                         # -(d/dphi) of the lever arm x
    ly = veh.a * c - veh.b * s
    rate = np.stack([v * c - w * lx, v * s + w * ly, w], -1)
    dw_dalpha = v * (1.0 + t * t) / veh.L
    A = np.zeros(rate.shape[:-1] + (3, 3))
    A[..., 0, 2] = -v * s - w * ly
    A[..., 1, 2] = v * c - w * lx
    B = np.stack([np.stack([c - t / veh.L * lx, -dw_dalpha * lx], -1),
                  np.stack([s + t / veh.L * ly, dw_dalpha * ly], -1),
                  np.stack([t / veh.L + 0 * v, dw_dalpha], -1)], -2)
    return rate, A, B


def _dt(dt) -> np.ndarray:
    dt = _checks.array("dt", dt)
    if np.any(dt < 0):
        raise ValueError(f"dt must be >= 0, got min {np.min(dt):.6g}")
    return dt


def predict(pose, control, dt, vehicle: Vehicle):
    """One Euler step of the laser model (the ACFR discrete model, section 4.1 corrected):

        pose_next = pose + dt * laser_velocity(pose, control), heading wrapped to (-pi, pi].

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Laser pose (x, y, phi) (m, m, rad).
    control : array_like, shape (..., 2)
        (v_c, alpha): rear-axle-centre speed, m/s, and steering angle, rad.
    dt : float or array_like, shape (...)
        Time step, s, >= 0. All three are broadcast over leading dimensions.
    vehicle : Vehicle
        The car (``L``, ``a``, ``b``).

    Returns
    -------
    pose_next : ndarray, shape (..., 3)
        Pose after ``dt``, heading wrapped to (-pi, pi].
    F : ndarray, shape (..., 3, 3)
        d pose_next / d pose.
    G : ndarray, shape (..., 3, 2)
        d pose_next / d control.

    Raises
    ------
    TypeError
        If an input is not numeric or ``vehicle`` is not a :class:`Vehicle`.
    ValueError
        If a last dimension is wrong, a value is not finite, the shapes do not broadcast,
        |alpha| >= pi/2 or dt < 0.
    """
    veh = _checks.instance("vehicle", vehicle, Vehicle)
    pose, control = _pose_control(pose, control)
    dt = _dt(dt)
    _checks.broadcast(pose=pose.shape[:-1], control=control.shape[:-1], dt=dt.shape)
    rate, A, B = _rate(pose, control, veh)
    dtx = dt[..., None]
    nxt = pose + dtx * rate
    nxt[..., 2] = wrap_angle(nxt[..., 2])
    F = np.eye(3) + dtx[..., None] * A
    G = dtx[..., None] * B
    return nxt, F, G


def predict_exact(pose, control, dt, vehicle: Vehicle) -> np.ndarray:
    """Exact laser pose after ``dt`` seconds of constant (v_c, alpha).

    The rear-axle centre runs on a circular arc of radius L / tan(alpha) (a
    straight line for alpha = 0) and the laser is rigidly attached to it. With
    s = v_c dt and dphi = s tan(alpha) / L, the axle advances by
    s (sin(dphi)/dphi, (1 - cos(dphi))/dphi) in its own frame, written with
    sinc so alpha -> 0 needs no special case. Heading wrapped to (-pi, pi].

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Laser pose (x, y, phi) (m, m, rad).
    control : array_like, shape (..., 2)
        (v_c, alpha): rear-axle-centre speed, m/s, and steering angle, rad.
    dt : float or array_like, shape (...)
        Time step, s, >= 0. All three are broadcast over leading dimensions.
    vehicle : Vehicle
        The car (``L``, ``a``, ``b``).

    Returns
    -------
    pose_next : ndarray, shape (..., 3)
        Pose after ``dt``, heading wrapped to (-pi, pi].

    Raises
    ------
    TypeError
        If an input is not numeric or ``vehicle`` is not a :class:`Vehicle`.
    ValueError
        If a last dimension is wrong, a value is not finite, the shapes do not broadcast,
        |alpha| >= pi/2 or dt < 0.
    """
    veh = _checks.instance("vehicle", vehicle, Vehicle)
    pose, control = _pose_control(pose, control)
    dt = _dt(dt)
    _checks.broadcast(pose=pose.shape[:-1], control=control.shape[:-1], dt=dt.shape)
    c_pose, _ = axle_pose(pose, veh)
    s = control[..., 0] * dt
    dphi = s * np.tan(control[..., 1]) / veh.L
    fwd = s * np.sinc(dphi / np.pi)                                  # s sin(dphi)/dphi
    left = s * np.sin(dphi / 2) * np.sinc(dphi / (2 * np.pi))        # s (1-cos dphi)/dphi
    phi = c_pose[..., 2]
    c, sn = np.cos(phi), np.sin(phi)
    moved = np.stack([c_pose[..., 0] + c * fwd - sn * left,
                      c_pose[..., 1] + sn * fwd + c * left,
                      phi + dphi], -1)
    out, _ = laser_pose(moved, veh)
    out[..., 2] = wrap_angle(out[..., 2])
    return out


def control_table(odometry, vehicle: Vehicle, sigma_speed: float, sigma_steer: float,
                  steer_gain: float = 0.0, *, array: bool = False):
    """Per odometry sample k, the tuple (v_c, alpha, tan alpha, w, dw/dalpha, q00, q01, q11,
    Delta_k) the predictions use: axle speed (``motion.axle_speed``), yaw rate
    w = v_c tan(alpha) / L and its steering derivative, the control covariance Q_c
    (see the module docstring; the steering standard deviation is
    sigma_steer + steer_gain |alpha_k|, ``SlamConfig.steer_noise_gain``) and the nominal
    length Delta_k = t_{k+1} - t_k of the interval the sample is held over (the last
    sample: the median interval).

    Precomputed once, vectorised: the scalar per-step code then only needs cos/sin(phi).

    Parameters
    ----------
    odometry : records.Odometry
        K samples: times ``t`` (s), encoder ``speed`` (m/s) and ``steering`` (rad).
    vehicle : Vehicle
        The car (``L``, ``H``).
    sigma_speed : float
        Standard deviation of the encoder speed, m/s.
    sigma_steer : float
        Standard deviation of the steering angle, rad.
    steer_gain : float, optional
        Growth of the steering standard deviation with |alpha|, rad per rad.
    array : bool, optional
        Return the rows as one array instead of a list of tuples.

    Returns
    -------
    list of tuple or ndarray, shape (K, 9)
        One row (v_c, alpha, tan alpha, w, dw/dalpha, q00, q01, q11, Delta_k) per
        sample; with ``array=True`` the (K, 9) array of the same rows
        (``slam.stretches.compound`` takes it).

    Raises
    ------
    ValueError
        As :func:`axle_speed`, for a steering angle with |alpha| >= pi/2 or on the
        singular steering.
    """
    v_c, J = axle_speed(odometry.speed, odometry.steering, vehicle)
    v_c, J = np.atleast_1d(v_c), np.atleast_2d(J)
    alpha = odometry.steering
    ta = np.tan(alpha)
    w = v_c * ta / vehicle.L
    dw = v_c * (1.0 + ta * ta) / vehicle.L
    sv2 = sigma_speed**2
    sa2 = np.broadcast_to((sigma_steer + steer_gain * np.abs(alpha)) ** 2, v_c.shape)
    q00 = J[:, 0] ** 2 * sv2 + J[:, 1] ** 2 * sa2
    q01 = J[:, 1] * sa2
    q11 = sa2
    dt = np.diff(odometry.t)
    last = float(np.median(dt)) if dt.size else 0.0
    span = np.append(dt, last)
    cols = np.column_stack([v_c, alpha, ta, w, dw, q00, q01, q11, span])
    return cols if array else [tuple(row) for row in cols.tolist()]
