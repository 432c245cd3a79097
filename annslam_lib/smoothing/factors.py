"""A factor's error written out in numpy (chapter 10, section 3): what GTSAM evaluates
inside ``BetweenFactorPose2`` and ``BearingRangeFactor2D``, and how to read its marginal
covariances in the filter's coordinates. The notebook derives these; the tests check them
against GTSAM's own factors.

GTSAM's Pose2 tangent space: a small change xi = (v_x, v_y, omega) moves a pose X to
X exp(xi), the position part in X's own (body) frame. A factor's error is a vector in the
tangent space of its measurement; its noise model whitens that vector.
"""
from __future__ import annotations

import math

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.observation import observe
from .problem import relative_pose

__all__ = ["se2_log", "between_error", "bearing_range_error", "tangent_to_world"]


def _one(name: str, value, shape: tuple) -> np.ndarray:
    a = _checks.array(name, value, shape)
    if a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    return a


def se2_log(pose) -> np.ndarray:
    """Logarithm of SE(2) (GTSAM's ``Pose2.Logmap``), eq. (10.4): for X = (t, theta) with
    theta wrapped to (-pi, pi] (at theta = -pi exactly GTSAM keeps -pi: the other sign of the
    same rotation), xi = (V(theta)^-1 t, theta), V(theta) = [[s, -c'], [c', s]] with
    s = sin(theta)/theta and c' = (1 - cos(theta))/theta (V = I at theta = 0)."""
    pose = _one("pose", pose, (3,))
    th = float(wrap_angle(pose[2]))
    if abs(th) < 1e-10:
        return np.array([pose[0], pose[1], th])
    s, c = math.sin(th) / th, (1.0 - math.cos(th)) / th
    det = s * s + c * c
    x, y = pose[0], pose[1]
    return np.array([(s * x + c * y) / det, (-c * x + s * y) / det, th])


def between_error(xi, xj, delta) -> np.ndarray:
    """Error of an odometry (between) factor, eq. (10.5): Log(Delta^-1 (X_i^-1 X_j)), zero
    when pose j seen from pose i is exactly the measured relative pose Delta (GTSAM's
    ``BetweenFactorPose2``: its Delta is ``problem.relative_pose``'s a^-1 b)."""
    xi, xj, delta = _one("xi", xi, (3,)), _one("xj", xj, (3,)), _one("delta", delta, (3,))
    return se2_log(relative_pose(delta, relative_pose(xi, xj)))


def bearing_range_error(pose, landmark, z) -> np.ndarray:
    """Error of a range-bearing factor, eq. (10.6), in GTSAM's order (bearing, range):
    (wrap(beta_hat - beta), r_hat - r) with (r_hat, beta_hat) = h(pose, landmark), the
    course's observation model (laser bearing: 0 to the right, pi/2 ahead; GTSAM's own
    bearing is beta - pi/2, which the difference does not see)."""
    z = _one("z", z, (2,))
    zhat, _, _ = observe(pose, landmark)
    return np.array([float(wrap_angle(zhat[1] - z[1])), zhat[0] - z[0]])


def tangent_to_world(S, phi) -> np.ndarray:
    """A pose's marginal covariance as GTSAM gives it (tangent space at a pose of heading
    ``phi``) in the filter's world-frame (dx, dy, dphi), eq. (10.7): B S B^T with
    B = blockdiag(R(phi), 1), the inverse of ``problem.world_to_tangent``."""
    S = _one("S", S, (3, 3))
    phi = _checks.real("phi", phi)
    c, s = math.cos(phi), math.sin(phi)
    B = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return B @ S @ B.T
