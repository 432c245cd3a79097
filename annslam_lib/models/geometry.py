"""Small 2-D geometry blocks shared by the motion and observation models.

Solà style: every geometric function returns its value together with its
Jacobians, so models are composed frame by frame and their Jacobians follow
by the chain rule (notebooks 01-03).

Conventions: world x = East, y = North; a pose is (x, y, phi), phi the heading
counted anticlockwise from East; a frame attached to a pose has x forward and
y to the left. Angles are wrapped to (-pi, pi].
"""
from __future__ import annotations

import numpy as np

from .. import _checks

__all__ = ["wrap_angle", "wrap_difference", "rot", "to_frame", "from_frame",
           "numerical_jacobian", "interpolate_poses"]


def wrap_angle(a) -> np.ndarray:
    """Angles wrapped to (-pi, pi]: +pi stays +pi and -pi maps to +pi.

    Parameters
    ----------
    a : float or array_like
        Angles, rad, any shape.

    Returns
    -------
    ndarray
        The wrapped angles, rad, of the input's shape (a NumPy scalar for scalar input).

    Raises
    ------
    TypeError
        If ``a`` is not numeric.
    ValueError
        If ``a`` holds NaN or infinite values.
    """
    a = _checks.array("angle", a)
    # pi - mod(pi - a, 2 pi): mod is in [0, 2 pi), so the result is in (-pi, pi].
    # Angles already in range pass through untouched, so wrapping is idempotent to the bit.
    inside = (a > -np.pi) & (a <= np.pi)
    return np.where(inside, a, np.pi - np.mod(np.pi - a, 2.0 * np.pi))[()]


def rot(phi) -> np.ndarray:
    """Rotation matrix R(phi) = [[cos, -sin], [sin, cos]].

    Parameters
    ----------
    phi : float or array_like, shape (...)
        Rotation angle, rad, anticlockwise.

    Returns
    -------
    ndarray, shape (..., 2, 2)
        One rotation matrix per angle.

    Raises
    ------
    TypeError
        If ``phi`` is not numeric.
    ValueError
        If ``phi`` holds NaN or infinite values.
    """
    phi = _checks.array("phi", phi)
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def to_frame(pose, p) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Express world point ``p`` in the frame of ``pose``: p_local = R(phi)^T (p - t).

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Frame pose (x, y, phi) (m, m, rad), broadcast with ``p`` over leading dimensions.
    p : array_like, shape (..., 2)
        World point (x, y), m.

    Returns
    -------
    p_local : ndarray, shape (..., 2)
        The point in the frame (x forward, y to the left), m.
    J_pose : ndarray, shape (..., 2, 3)
        d p_local / d pose.
    J_p : ndarray, shape (..., 2, 2)
        d p_local / d p, that is R(phi)^T.

    Raises
    ------
    TypeError
        If an input is not numeric.
    ValueError
        If a last dimension is wrong or a value is not finite.
    """
    pose = _checks.array("pose", pose, (3,))
    p = _checks.array("point", p, (2,))
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    dx, dy = p[..., 0] - pose[..., 0], p[..., 1] - pose[..., 1]
    xl = c * dx + s * dy
    yl = -s * dx + c * dy
    zero = np.zeros_like(xl)
    # d p_local / d phi = R'(phi)^T (p - t) = (yl, -xl).
    J_pose = np.stack([np.stack([-c + zero, -s + zero, yl], -1),
                       np.stack([s + zero, -c + zero, -xl], -1)], -2)
    J_p = np.stack([np.stack([c + zero, s + zero], -1), np.stack([-s + zero, c + zero], -1)], -2)
    return np.stack([xl, yl], -1), J_pose, J_p


def from_frame(pose, p_local) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World coordinates of ``p_local`` given in the frame of ``pose``: p = t + R(phi) p_local.

    Parameters
    ----------
    pose : array_like, shape (..., 3)
        Frame pose (x, y, phi) (m, m, rad), broadcast with ``p_local`` over leading
        dimensions.
    p_local : array_like, shape (..., 2)
        Point in the frame (x forward, y to the left), m.

    Returns
    -------
    p : ndarray, shape (..., 2)
        The point in the world, m.
    J_pose : ndarray, shape (..., 2, 3)
        d p / d pose.
    J_p_local : ndarray, shape (..., 2, 2)
        d p / d p_local, that is R(phi).

    Raises
    ------
    TypeError
        If an input is not numeric.
    ValueError
        If a last dimension is wrong or a value is not finite.
    """
    pose = _checks.array("pose", pose, (3,))
    q = _checks.array("p_local", p_local, (2,))
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    rx = c * q[..., 0] - s * q[..., 1]
    ry = s * q[..., 0] + c * q[..., 1]
    one, zero = np.ones_like(rx), np.zeros_like(rx)
    J_pose = np.stack([np.stack([one, zero, -ry], -1), np.stack([zero, one, rx], -1)], -2)
    J_q = np.stack([np.stack([c + zero, -s + zero], -1), np.stack([s + zero, c + zero], -1)], -2)
    p = np.stack([pose[..., 0] + rx, pose[..., 1] + ry], -1)
    return p, J_pose, J_q


def numerical_jacobian(f, x, *, h: float = 1e-6, angle_outputs=()) -> np.ndarray:
    """Central-difference Jacobian (m, n) of ``f``: R^n -> R^m at ``x`` (n,).

    Differences of the outputs listed in ``angle_outputs`` are wrapped to
    (-pi, pi], so a heading or bearing crossing +-pi does not create a 2 pi jump.
    Used to check every analytic Jacobian of the course (notebooks 01-03).

    Parameters
    ----------
    f : callable
        ``f(x)`` returns an array_like of m values (a scalar counts as m = 1).
    x : array_like, shape (n,)
        The point the Jacobian is taken at.
    h : float, optional
        Step of the central differences, in the units of ``x``.
    angle_outputs : sequence of int, optional
        Indices of the outputs that are angles (rad), whose differences are wrapped.

    Returns
    -------
    ndarray, shape (m, n)
        d f / d x, (f(x + h e_k) - f(x - h e_k)) / 2h in column k.

    Raises
    ------
    TypeError
        If ``x`` is not numeric.
    ValueError
        If ``x`` is not one-dimensional or not finite.
    """
    x = _checks.array("x", x)
    if x.ndim != 1:
        raise ValueError(f"x must be one-dimensional, got shape {x.shape}")
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h
        d = np.atleast_1d(np.asarray(f(x + e), dtype=float) - np.asarray(f(x - e), dtype=float))
        for i in angle_outputs:
            d[i] = wrap_angle(d[i])
        cols.append(d / (2.0 * h))
    return np.stack(cols, -1)


def wrap_difference(a):
    """Angle differences to [-pi, pi): a - 2 pi floor((a + pi) / 2 pi), five cheap array
    operations (``np.mod`` costs ten times more). Used for predicted bearings and
    innovations, where only the size of the difference matters; a state's heading is
    wrapped to (-pi, pi] by :func:`wrap_angle`. Unchecked (the filter's hot path)."""
    return a - (2.0 * np.pi) * np.floor((a + np.pi) / (2.0 * np.pi))


def interpolate_poses(traj, t) -> np.ndarray:
    """Poses (x, y, phi) of trajectory ``traj`` at times ``t`` (notebook 01).

    Positions are interpolated linearly between the rows around each time; the
    heading is interpolated on its unwrapped (continuous) version and wrapped back
    to (-pi, pi], so a heading crossing +-pi between two rows is interpolated the
    short way round. This assumes consecutive rows differ by less than pi in
    heading, true of any trajectory sampled at the odometry rate.

    Parameters
    ----------
    traj : array_like, shape (K, 4)
        Rows (t, x, y, phi) (s, m, m, rad), times non-decreasing.
    t : float or array_like, shape (N,)
        Times, s, every one inside [traj[0, 0], traj[-1, 0]].

    Returns
    -------
    ndarray, shape (3,) or (N, 3)
        Poses (x, y, phi): (3,) for a scalar ``t``, else one row per time.

    Raises
    ------
    ValueError
        For a malformed trajectory, non-finite times, or a time outside the
        trajectory's span (no extrapolation).
    """
    traj = _checks.trajectory("trajectory", traj)
    t_arr = _checks.array("t", t)
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
