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

__all__ = ["as_array", "wrap_angle", "rot", "to_frame", "from_frame", "numerical_jacobian"]


def as_array(name: str, value, tail: tuple[int, ...] = ()) -> np.ndarray:
    """``value`` as a finite float array whose trailing dimensions are ``tail``.

    Leading (batch) dimensions are allowed. Raises ValueError naming ``name``
    on non-numeric input, a wrong trailing shape, NaN or infinity.
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    n = len(tail)
    if arr.ndim < n or (n and arr.shape[-n:] != tail):
        want = "(..., " + ", ".join(map(str, tail)) + ")" if n else "scalar or array"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


def wrap_angle(a) -> np.ndarray:
    """Angles wrapped to (-pi, pi]: +pi stays +pi and -pi maps to +pi.

    Returns an array of the input's shape (a NumPy scalar for scalar input)."""
    a = as_array("angle", a)
    # pi - mod(pi - a, 2 pi): mod is in [0, 2 pi), so the result is in (-pi, pi].
    # Angles already in range pass through untouched, so wrapping is idempotent to the bit.
    inside = (a > -np.pi) & (a <= np.pi)
    return np.where(inside, a, np.pi - np.mod(np.pi - a, 2.0 * np.pi))[()]


def rot(phi) -> np.ndarray:
    """Rotation matrix R(phi) = [[cos, -sin], [sin, cos]], shape (..., 2, 2)."""
    phi = as_array("phi", phi)
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def to_frame(pose, p) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Express world point ``p`` in the frame of ``pose``: p_local = R(phi)^T (p - t).

    pose (..., 3), p (..., 2), broadcast over leading dimensions.
    Returns (p_local (..., 2), J_pose (..., 2, 3), J_p (..., 2, 2)).
    """
    pose = as_array("pose", pose, (3,))
    p = as_array("point", p, (2,))
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

    pose (..., 3), p_local (..., 2). Returns (p (..., 2), J_pose (..., 2, 3),
    J_p_local (..., 2, 2)).
    """
    pose = as_array("pose", pose, (3,))
    q = as_array("p_local", p_local, (2,))
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
    """
    x = as_array("x", x)
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
