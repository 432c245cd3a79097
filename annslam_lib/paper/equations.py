"""The paper's equations AS PRINTED (sections 2.2, 3.3, 4.1, 4.2), typos included.

Paper: "Adapting Enhanced the Simultaneous Localization and Mapping (SLAM) Process Based on
Artificial Neural Network" (2013). Each ``*_printed`` function implements a printed formula
literally, so the notebooks and the graders can show that it fails; the correct forms live
in :mod:`annslam_lib.models.motion` and :mod:`annslam_lib.models.observation`, and
:mod:`annslam_lib.paper.errata` proves each difference.
"""
from __future__ import annotations

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle
from ..models.vehicle import Vehicle

__all__ = ["rate_2_2_printed", "predict_2_2_printed", "two_point_theta_printed", "two_point_ij_printed", "two_point_transform_printed", "laser_position_printed", "full_state_printed", "speed_translation_printed", "discrete_model_printed", "observation_printed", "observation_jacobian_printed", "ann_neuron_printed"]


def rate_2_2_printed(pose, control, vehicle: Vehicle) -> np.ndarray:
    """2.2 continuous model read literally: x' = V cos(phi'), y' = V sin(phi'),
    phi' = V tan(gamma) / L. The prime inside cos/sin makes it the heading RATE."""
    pose, u = _checks.array("pose", pose, (3,)), _checks.array("control", control, (2,))
    w = u[..., 0] * np.tan(u[..., 1]) / vehicle.L
    return np.stack([u[..., 0] * np.cos(w), u[..., 0] * np.sin(w), w + 0 * pose[..., 2]], -1)



def predict_2_2_printed(pose, control, dt, vehicle: Vehicle) -> np.ndarray:
    """2.2 discrete model as printed (correct, for the REAR-AXLE pose):
    x + dt V cos(phi), y + dt V sin(phi), phi + dt V tan(gamma) / L."""
    p, u = _checks.array("pose", pose, (3,)), _checks.array("control", control, (2,))
    v, g, phi = u[..., 0], u[..., 1], p[..., 2]
    return np.stack([p[..., 0] + dt * v * np.cos(phi), p[..., 1] + dt * v * np.sin(phi),
                     phi + dt * v * np.tan(g) / vehicle.L], -1)



def two_point_theta_printed(p_right, p_left) -> np.ndarray:
    """3.3 orientation, the three printed cases evaluated in order:
    arctan(dy/dx) if X_l < X_r; -pi/2 if X_l = X_r; arctan(dy/dx) - pi if X_l < X_r.
    The third condition repeats the first, so for X_l > X_r no case applies: NaN."""
    pr, pl = _checks.array("p_right", p_right, (2,)), _checks.array("p_left", p_left, (2,))
    dx, dy = pr[..., 0] - pl[..., 0], pr[..., 1] - pl[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        first = np.arctan(dy / dx)
    xl, xr = pl[..., 0], pr[..., 0]
    return np.select([xl < xr, xl == xr, xl < xr], [first, -np.pi / 2 + 0 * dx, first - np.pi],
                     default=np.nan)



def two_point_ij_printed(p_left, theta) -> np.ndarray:
    """3.3 position as printed: i = x_l cos(theta) - y_l sin(theta), j = the same expression."""
    pl, th = _checks.array("p_left", p_left, (2,)), _checks.array("theta", theta)
    i = pl[..., 0] * np.cos(th) - pl[..., 1] * np.sin(th)
    return np.stack([i, i], -1)



def two_point_transform_printed(p_left, theta) -> np.ndarray:
    """3.3 transition matrix ijT_r as printed (4 x 4): rotation block R(theta)^T and a
    translation column whose two rows are the same x_l cos(theta) - y_l sin(theta)."""
    th = _checks.array("theta", theta)
    c, s = np.cos(th), np.sin(th)
    ij = two_point_ij_printed(p_left, th)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, s, z, ij[..., 0]], -1), np.stack([-s, c, z, ij[..., 1]], -1),
                     np.stack([z, z, o, z], -1), np.stack([z, z, z, o], -1)], -2)



def laser_position_printed(axle_pose, vehicle: Vehicle) -> np.ndarray:
    """4.1 scalar form (correct): x_l = x_c + a cos(phi) + b cos(phi + pi/2),
    y_l = y_c + a sin(phi) + b sin(phi + pi/2)."""
    p = _checks.array("axle_pose", axle_pose, (3,))
    phi, a, b = p[..., 2], vehicle.a, vehicle.b
    return np.stack([p[..., 0] + a * np.cos(phi) + b * np.cos(phi + np.pi / 2),
                     p[..., 1] + a * np.sin(phi) + b * np.sin(phi + np.pi / 2)], -1)



def full_state_printed(pose, control, vehicle: Vehicle) -> np.ndarray:
    """4.1 "full state" rate as printed:
    [V cos(phi) - V/L (a cos(phi) + b cos(phi)) tan(alpha),
     V sin(phi) - V/L (a cos(phi) - b sin(phi)) tan(alpha),
     V/L tan(alpha)]."""
    p, u = _checks.array("pose", pose, (3,)), _checks.array("control", control, (2,))
    v, t, phi = u[..., 0], np.tan(u[..., 1]), p[..., 2]
    a, b, L = vehicle.a, vehicle.b, vehicle.L
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([v * c - v / L * (a * c + b * c) * t,
                     v * s - v / L * (a * c - b * s) * t,
                     v / L * t], -1)



def speed_translation_printed(v_c, steering, vehicle: Vehicle) -> np.ndarray:
    """4.1 right-hand side of the printed V_c = V_c / (1 - tan(alpha) H / L).

    The printed equation claims this equals ``v_c`` itself, which holds only for
    v_c = 0 or alpha = 0: the numerator must be the ENCODER speed V_e."""
    v, al = _checks.array("v_c", v_c), _checks.array("steering", steering)
    return v / (1.0 - np.tan(al) * vehicle.H / vehicle.L)



def discrete_model_printed(pose, control, dt, vehicle: Vehicle, *,
                           tan_inside: bool = False) -> np.ndarray:
    """4.1 discrete model as printed. Its brackets are unbalanced; the lever-arm term
    sits inside cos()/sin() either way. ``tan_inside=False`` reads
    x + dt V cos(phi - V/L (a sin(phi) + b cos(phi))) tan(alpha) (tan outside the cos),
    ``True`` reads cos(phi - V/L (a sin(phi) + b cos(phi)) tan(alpha)); same for the y
    row with sin(phi + V/L (a cos(phi) + b sin(phi))). The third row is printed as
    V/L tan(alpha): the rate, without phi(k-1) + dt."""
    p, u = _checks.array("pose", pose, (3,)), _checks.array("control", control, (2,))
    v, t, phi = u[..., 0], np.tan(u[..., 1]), p[..., 2]
    a, b, L = vehicle.a, vehicle.b, vehicle.L
    ax = v / L * (a * np.sin(phi) + b * np.cos(phi))
    ay = v / L * (a * np.cos(phi) + b * np.sin(phi))
    if tan_inside:
        x = p[..., 0] + dt * v * np.cos(phi - ax * t)
        y = p[..., 1] + dt * v * np.sin(phi + ay * t)
    else:
        x = p[..., 0] + dt * v * np.cos(phi - ax) * t
        y = p[..., 1] + dt * v * np.sin(phi + ay) * t
    return np.stack([x, y, v / L * t + 0 * phi], -1)



def observation_printed(pose, landmark) -> np.ndarray:
    """4.1/4.2 observation as printed: range sqrt((x_L - x_i)^2 + (y_L - y_i)^2),
    bearing atan((y_L - y_i) / (x_L - x_i)) - theta + pi/2 (theta = the heading phi),
    wrapped to (-pi, pi]."""
    p, m = _checks.array("pose", pose, (3,)), _checks.array("landmark", landmark, (2,))
    dx, dy = p[..., 0] - m[..., 0], p[..., 1] - m[..., 1]
    return np.stack([np.sqrt(dx**2 + dy**2), wrap_angle(np.arctan(dy / dx) - p[..., 2] + np.pi / 2)],
                    -1)



def observation_jacobian_printed(pose, landmark, *, alignment: int = 0) -> np.ndarray:
    """4.2 Jacobian as printed, columns (x, y, phi, x_i, y_i), shape (..., 2, 5), with
    Dx = x - x_i, Dy = y - y_i, D = sqrt(Dx^2 + Dy^2):
    range row (1/D)[Dx, Dy, 0, ..., -Dy, 0, ...]; bearing row
    [-Dy/D^2, Dx/D^2, -1, ..., Dy/D^2, Dy/D^2, ...].
    The ellipses hide where the range row's single landmark entry -Dy sits:
    ``alignment`` 0 puts it in the x_i column, 1 in the y_i column."""
    p, m = _checks.array("pose", pose, (3,)), _checks.array("landmark", landmark, (2,))
    dx, dy = p[..., 0] - m[..., 0], p[..., 1] - m[..., 1]
    d2 = dx**2 + dy**2
    d = np.sqrt(d2)
    z = 0 * dx
    lm = [-dy / d, z] if alignment == 0 else [z, -dy / d]
    rng_row = np.stack([dx / d, dy / d, z, *lm], -1)
    brg_row = np.stack([-dy / d2, dx / d2, z - 1, dy / d2, dy / d2], -1)
    return np.stack([rng_row, brg_row], -2)



def ann_neuron_printed(w, x, b) -> tuple[np.ndarray, np.ndarray]:
    """4.2 "f(x) = sign(w, x) + b = sign(b + sum_i w_i x_i)": both printed sides,
    (sign(<w, x>) + b, sign(b + <w, x>)), which disagree."""
    w, x, b = _checks.array("w", w), _checks.array("x", x), _checks.array("b", b)
    s = np.sum(w * x, -1)
    return np.sign(s) + b, np.sign(b + s)
