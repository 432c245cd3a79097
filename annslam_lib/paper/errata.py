"""The errata: every printed equation of the paper the course found wrong, ambiguous or
notation only, with its numerical proof (notebooks 01-03; ``python -m annslam_lib errata``).

:data:`ERRATA` lists the equations we found wrong; :data:`CONFIRMED` the printed equations
we checked and found right. Each record's ``check()`` returns the largest discrepancy of the
PRINTED form (:mod:`annslam_lib.paper.equations`) against an independent reference on
seeded random inputs (``None`` for pure notation), and ``check_correct()`` the same
discrepancy for the course's corrected form. References are independent of the code they
judge: the time derivative of the exact circular-arc flow (central differences),
rigid-body velocities, complex-number bearings, and central-difference Jacobians.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..evaluation.residuals import DIFFERENCES, residual
from ..models import motion as kinematics
from ..models import observation
from ..models.geometry import from_frame, to_frame, wrap_angle
from ..models.vehicle import ACFR_UTE, Vehicle
from .equations import (rate_2_2_printed, predict_2_2_printed, two_point_theta_printed, two_point_ij_printed,
                        two_point_transform_printed, laser_position_printed,
                        full_state_printed, speed_translation_printed,
                        discrete_model_printed, observation_printed,
                        observation_jacobian_printed, ann_neuron_printed)

__all__ = ["Erratum", "ERRATA", "CONFIRMED", "errata_table", "errata_markdown", "check_reading_b"]


def _samples(n: int = 400, seed: int = 2013):
    """Seeded random laser poses, ACFR-range controls and landmarks 1..30 m away."""
    rng = np.random.default_rng(seed)
    pose = np.c_[rng.uniform(-20, 20, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    u = np.c_[rng.uniform(0.5, 3.0, n), rng.uniform(-0.6, 0.6, n)]
    ang, r = rng.uniform(-np.pi, np.pi, n), rng.uniform(1, 30, n)
    lm = pose[:, :2] + r[:, None] * np.c_[np.cos(ang), np.sin(ang)]
    return pose, u, lm, rng



def _flow_rate(pose, u, veh: Vehicle = ACFR_UTE, h: float = 1e-5) -> np.ndarray:
    """d/dt of the exact constant-control flow at t = 0, by central differences
    (running the arc backwards = driving at -v for h seconds)."""
    fwd = kinematics.predict_exact(pose, u, h, veh)
    back = kinematics.predict_exact(pose, u * np.array([-1.0, 1.0]), h, veh)
    d = fwd - back
    d[..., 2] = wrap_angle(d[..., 2])
    return d / (2 * h)



def _axle_flow_rate(axle, u, veh: Vehicle = ACFR_UTE) -> np.ndarray:
    h = 1e-5
    run = lambda v: kinematics.axle_pose(  # noqa: E731
        kinematics.predict_exact(kinematics.laser_pose(axle, veh)[0], u * [v, 1.0], h, veh), veh)[0]
    d = run(1.0) - run(-1.0)
    d[..., 2] = wrap_angle(d[..., 2])
    return d / (2 * h)



def _euler_ref(pose, u, dt, rate) -> np.ndarray:
    out = pose + dt * rate
    out[..., 2] = wrap_angle(out[..., 2])
    return out



def _ref_observation(pose, lm) -> np.ndarray:
    """Range and laser bearing with complex numbers: the landmark direction rotated
    into the laser frame, then by +pi/2 (bearing counted from the right)."""
    d = (lm[..., 0] - pose[..., 0]) + 1j * (lm[..., 1] - pose[..., 1])
    return np.stack([np.abs(d), np.angle(d * np.exp(-1j * pose[..., 2]) * 1j)], -1)



def _fd_batch(f, X, h: float = 1e-6, angle_outputs=()) -> np.ndarray:
    """Central-difference Jacobians (n, m, d) of a batched f: (n, d) -> (n, m)."""
    cols = []
    for k in range(X.shape[1]):
        e = np.zeros_like(X)
        e[:, k] = h
        d = f(X + e) - f(X - e)
        for i in angle_outputs:
            d[:, i] = wrap_angle(d[:, i])
        cols.append(d / (2 * h))
    return np.stack(cols, -1)



def _obs_fd():
    """Printed-layout (x, y, phi, x_i, y_i) Jacobian of the reference observation."""
    pose, _, lm, _ = _samples()
    X = np.c_[pose, lm]
    J = _fd_batch(lambda A: _ref_observation(A[:, :3], A[:, 3:]), X, angle_outputs=[1])
    return pose, lm, J



def _pairs(kind: str, n: int = 400):
    """Random point pairs in the robot frame, of a given configuration."""
    rng = np.random.default_rng(33)
    pl = np.c_[rng.uniform(1, 15, n), rng.uniform(-8, 8, n)]
    pr = np.c_[rng.uniform(1, 15, n), rng.uniform(-8, 8, n)]
    if kind == "vertical":
        pr[:, 0] = pl[:, 0]
    elif kind == "l_gt_r":
        pr[:, 0] = pl[:, 0] - rng.uniform(0.1, 5, n)
    return pr, pl



def _angle_to(pr, pl):
    return np.angle((pr[:, 0] - pl[:, 0]) + 1j * (pr[:, 1] - pl[:, 1]))



def _angle_err(a, b) -> float:
    """Largest wrapped angular difference; NaN (no printed case applies) counts as pi."""
    e = np.abs(wrap_angle(np.nan_to_num(a - b, nan=np.pi)))
    return float(np.max(np.where(np.isnan(a), np.pi, e)))



def _mx(a) -> float:
    return float(np.max(np.abs(a)))



def _c_rate22():
    pose, u, _, _ = _samples()
    return _mx(rate_2_2_printed(pose, u, ACFR_UTE)[:, :2] - _axle_flow_rate(pose, u)[:, :2])



def _c_rate22_ok():
    pose, u, _, _ = _samples()
    ok = np.c_[u[:, 0] * np.cos(pose[:, 2]), u[:, 0] * np.sin(pose[:, 2])]
    return _mx(ok - _axle_flow_rate(pose, u)[:, :2])



def _c_pred22():
    pose, u, _, _ = _samples()
    dt = 0.025
    ref = _euler_ref(pose, u, dt, _axle_flow_rate(pose, u))
    got = predict_2_2_printed(pose, u, dt, ACFR_UTE)
    return max(_mx(got[:, :2] - ref[:, :2]), _angle_err(got[:, 2], ref[:, 2]))



def _c_transform():
    pr, pl = _pairs("any")
    th = _angle_to(pr, pl)
    T = two_point_transform_printed(pl, th)[:, [0, 1, 3]][:, :, [0, 1, 3]]
    h = lambda p: np.c_[p, np.ones(len(p))][..., None]  # noqa: E731
    # The landmark frame's origin must map to (0, 0); try both defining points.
    return min(_mx((T @ h(pl))[:, :2]), _mx((T @ h(pr))[:, :2]))



def _c_transform_ok():
    pr, pl = _pairs("any")
    T = observation.two_point_transform(pr, pl)
    h = lambda p: np.c_[p, np.ones(len(p))][..., None]  # noqa: E731
    return max(_mx((T @ h(pl))[:, :2]), _mx((T @ h(pr))[:, 1]))



def _c_theta_case3():
    pr, pl = _pairs("l_gt_r")
    return _angle_err(two_point_theta_printed(pr, pl), _angle_to(pr, pl))



def _c_theta_vertical():
    pr, pl = _pairs("vertical")
    return _angle_err(two_point_theta_printed(pr, pl), _angle_to(pr, pl))



def _c_theta_ok(kind):
    pr, pl = _pairs(kind)
    return lambda: _angle_err(observation.landmark_from_two_points(pr, pl)[0][:, 2],
                              _angle_to(pr, pl))



def _c_theta_confirmed():
    """Cases 1 and 3 with the third condition fixed to X_l > X_r agree with atan2 mod 2 pi."""
    pr, pl = _pairs("any")
    dx, dy = pr[:, 0] - pl[:, 0], pr[:, 1] - pl[:, 1]
    th = np.where(dx > 0, np.arctan(dy / dx), np.arctan(dy / dx) - np.pi)
    return _angle_err(th, _angle_to(pr, pl))



def _ij_reference(pr, pl):
    """Robot origin expressed in the landmark frame (origin p_l, x axis towards p_r)."""
    frame = np.c_[pl, _angle_to(pr, pl)]
    return to_frame(frame, np.zeros_like(pl))[0]



def _c_ij():
    pr, pl = _pairs("any")
    return _mx(two_point_ij_printed(pl, _angle_to(pr, pl)) - _ij_reference(pr, pl))



def _c_ij_ok():
    pr, pl = _pairs("any")
    return _mx(observation.landmark_from_two_points(pr, pl)[0][:, :2] - _ij_reference(pr, pl))



def _c_rotation_block():
    pr, pl = _pairs("any")
    T = two_point_transform_printed(pl, _angle_to(pr, pl))
    along = np.einsum("nij,nj->ni", T[:, :2, :2], pr - pl)
    return _mx(along[:, 1]) + _mx(along[:, 0] - np.linalg.norm(pr - pl, axis=1))



def _c_rotation_b():
    """Reading B of 3.3-rotation: the printed block against R(theta) (the passage matrix)."""
    pr, pl = _pairs("any")
    th = _angle_to(pr, pl)
    T = two_point_transform_printed(pl, th)[:, :2, :2]
    c, s = np.cos(th), np.sin(th)
    R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
    return _mx(T - R)



def check_reading_b() -> float:
    """Reading B of 3.3-transform: the printed translation column against p_l (m)."""
    pr, pl = _pairs("any")
    T = two_point_transform_printed(pl, _angle_to(pr, pl))
    return _mx(T[:, :2, 3] - pl)



def _c_laser_position():
    pose, _, _, _ = _samples()
    rigid = from_frame(pose, np.broadcast_to([ACFR_UTE.a, ACFR_UTE.b], (len(pose), 2)))[0]
    return _mx(laser_position_printed(pose, ACFR_UTE) - rigid)



def _c_axle_rate():
    pose, u, _, _ = _samples()
    printed = np.c_[u[:, 0] * np.cos(pose[:, 2]), u[:, 0] * np.sin(pose[:, 2]),
                    u[:, 0] / ACFR_UTE.L * np.tan(u[:, 1])]
    return _mx(printed - _axle_flow_rate(pose, u))



def _c_full_row(row, printed: bool):
    def check():
        pose, u, _, _ = _samples()
        f = full_state_printed if printed else kinematics.laser_velocity
        return _mx(f(pose, u, ACFR_UTE)[:, row] - _flow_rate(pose, u)[:, row])
    return check



def _speed_case():
    pose, u, _, _ = _samples()
    v_c, al = u[:, 0], u[:, 1]
    omega = v_c * np.tan(al) / ACFR_UTE.L
    v_e = v_c - omega * ACFR_UTE.H      # rigid body: the wheel H m left of C
    return v_c, v_e, al



def _c_speed():
    v_c, _, al = _speed_case()
    return _mx(speed_translation_printed(v_c, al, ACFR_UTE) - v_c)



def _c_speed_ok():
    v_c, v_e, al = _speed_case()
    return _mx(kinematics.axle_speed(v_e, al, ACFR_UTE)[0] - v_c)



def _c_discrete_row(row, printed: bool):
    def check():
        pose, u, _, _ = _samples()
        dt = 0.025
        ref = _euler_ref(pose, u, dt, _flow_rate(pose, u))
        if printed:
            errs = []
            for inside in (False, True):   # wrong whichever way the brackets are read
                got = discrete_model_printed(pose, u, dt, ACFR_UTE, tan_inside=inside)
                errs.append(_angle_err(got[:, 2], ref[:, 2]) if row == 2
                            else _mx(got[:, row] - ref[:, row]))
            return min(errs)
        got = kinematics.predict(pose, u, dt, ACFR_UTE)[0]
        return _angle_err(got[:, 2], ref[:, 2]) if row == 2 else _mx(got[:, row] - ref[:, row])
    return check



def _c_bearing(printed: bool):
    def check():
        pose, _, lm, _ = _samples()
        z = observation_printed(pose, lm) if printed else observation.observe(pose, lm)[0]
        return _angle_err(z[:, 1], _ref_observation(pose, lm)[:, 1])
    return check



def _c_range():
    pose, _, lm, _ = _samples()
    return _mx(observation_printed(pose, lm)[:, 0] - _ref_observation(pose, lm)[:, 0])



def _c_jac(cols, row, printed: bool):
    def check():
        pose, lm, J = _obs_fd()
        if printed:
            return min(_mx(observation_jacobian_printed(pose, lm, alignment=al)[:, row, cols]
                           - J[:, row, cols]) for al in (0, 1))
        _, Hp, Hl = observation.observe(pose, lm)
        return _mx(np.concatenate([Hp, Hl], -1)[:, row, cols] - J[:, row, cols])
    return check



def _c_jac_vehicle():
    pose, lm, J = _obs_fd()
    P = observation_jacobian_printed(pose, lm)
    return max(_mx(P[:, :, :3] - J[:, :, :3]), _mx(P[:, 1, 3] - J[:, 1, 3]))



def _c_ann():
    rng = np.random.default_rng(4)
    w, x, b = rng.normal(size=(400, 5)), rng.normal(size=(400, 5)), rng.normal(size=400)
    lhs, rhs = ann_neuron_printed(w, x, b)
    return _mx(lhs - rhs)



@dataclass(frozen=True)
class Erratum:
    """One printed equation of the paper, what it should be, and how we know.

    ``kind``: "wrong equation" (numerically wrong), "notation" (typo without a
    numerical consequence once read sensibly) or "ambiguous" (right or wrong
    depending on an unstated assumption, see ``note``). ``check()`` returns the
    largest discrepancy of the printed form against an independent reference
    on seeded random inputs (None: nothing numerical to check);
    ``check_correct()`` the same for the course's corrected form.
    """

    key: str
    section: str
    quantity: str
    printed: str
    correct: str
    how_proven: str
    kind: str = "wrong equation"
    check: Callable[[], float] | None = None
    check_correct: Callable[[], float] | None = None
    note: str = ""



_FLOW = ("reference: time derivative of the exact circular-arc flow "
         "(motion.predict_exact, central differences), 400 seeded states")



_EULER = ("reference: one Euler step pose + dt * (time derivative of the exact arc flow), "
          "dt = 25 ms, 400 seeded states")



_FD_OBS = ("reference: central-difference Jacobian of a complex-number range/bearing, "
           "400 seeded pose/landmark pairs")



ERRATA: list[Erratum] = [
    # ---------------------------------------------------------------- 2.2
    Erratum("2.2-rate", "2.2", "continuous motion model",
            r"x' = V\cos\phi',\; y' = V\sin\phi'",
            r"\dot x = V\cos\phi,\; \dot y = V\sin\phi",
            "read literally, cos/sin of the heading RATE; compared with " + _FLOW
            + " of the rear axle.",
            "notation", _c_rate22, _c_rate22_ok,
            "Counted as notation: read as a derivative mark slipped from x to phi, it is the "
            "standard model, and the discrete model printed next to it uses phi (CONFIRMED "
            "2.2-discrete). The check shows what the literal reading would do."),
    Erratum("2.2-symbols", "2.2", "symbols of the motion model",
            r"\dot\phi = v\tan\gamma / I;\; V, v;\; \gamma",
            r"\dot\phi = V\tan\alpha / L\;\text{(one speed } V\text{, wheelbase } L\text{, steering } \alpha \text{ as in 4.1)}",
            "notation: the wheelbase is printed I in the rate and L in the discrete model, "
            "the speed V and v, the steering gamma here and alpha in 4.1 (where gamma "
            "becomes the range).", "notation"),
    # ---------------------------------------------------------------- 3.3
    Erratum("3.3-transform", "3.3", "translation column of ijT_r",
            r"(x_l\cos\theta - y_l\sin\theta,\; x_l\cos\theta - y_l\sin\theta)",
            r"(-(x_l\cos\theta + y_l\sin\theta),\; x_l\sin\theta - y_l\cos\theta)"
            r" = -R(\theta)^T (x_l, y_l)",
            "the rotation block R(theta)^T makes ijT_r the robot->landmark map, so the "
            "frame origin must map to (0, 0); the printed matrix sends neither defining "
            "point there (check: min over both), the corrected one sends p_l to 0 and p_r "
            "onto the +x axis. 400 seeded point pairs.",
            "wrong equation", _c_transform, _c_transform_ok,
            "The paper never says which point is the origin; we take the left point (the "
            "one whose coordinates appear in the printed column). Wrong under both readings "
            "of ijT_r (see 3.3-rotation): (A) the robot->landmark map, translation "
            "-R(theta)^T p_l (checked above); (B) the 'matrice de passage' [R(theta) | p_l], "
            "translation p_l itself, which the printed column misses too (check_reading_b). "
            "Either way its two entries are identical, a misprint."),
    Erratum("3.3-theta-case3", "3.3", "third case of theta",
            r"\theta = \arctan\frac{y_r - y_l}{X_r - X_l} - \pi \;\text{si}\; X_l < X_r",
            r"... \;\text{si}\; X_l > X_r \quad(\theta = \mathrm{atan2}(y_r - y_l, x_r - x_l))",
            "the condition repeats case 1, so for X_l > X_r no case applies (NaN, counted "
            "as an error of pi); with '>' the case agrees with atan2 modulo 2 pi "
            "(see CONFIRMED). 400 seeded pairs with X_l > X_r.",
            "wrong equation", _c_theta_case3, _c_theta_ok("l_gt_r"),
            "arctan(...) - pi lies in (-3pi/2, -pi/2) when y_r > y_l: equal to atan2 "
            "modulo 2 pi only; the library wraps to (-pi, pi]."),
    Erratum("3.3-theta-vertical", "3.3", "vertical case of theta",
            r"\theta = -\pi/2 \;\text{si}\; X_l = X_r",
            r"\theta = -\pi/2 \text{ if } y_r < y_l,\; +\pi/2 \text{ if } y_r > y_l "
            r"\;\text{(undefined if the points coincide)}",
            "400 seeded vertical pairs of both orientations: the printed value is off by pi "
            "whenever y_r > y_l.",
            "ambiguous", _c_theta_vertical, _c_theta_ok("vertical"),
            "Right if the 'right' point always has the smaller y in the robot frame "
            "(a landmark seen ahead, y to the left), which the paper does not state."),
    Erratum("3.3-ij", "3.3", "position (i, j) of the landmark frame",
            r"i = x_l\cos\theta - y_l\sin\theta,\; j = x_l\cos\theta - y_l\sin\theta",
            r"i = -(x_l\cos\theta + y_l\sin\theta),\; j = x_l\sin\theta - y_l\cos\theta",
            "the two printed formulas are identical; the correct (i, j) is the translation "
            "of ijT_r, the robot origin seen from the landmark frame, computed as a frame "
            "change (geometry.to_frame) on 400 seeded pairs. The printed i is the first "
            "row of R(theta)(x_l, y_l), inconsistent with the R(theta)^T rotation block.",
            "wrong equation", _c_ij, _c_ij_ok,
            "Same origin convention as 3.3-transform (left point). Under reading B of "
            "3.3-rotation (i, j) would be p_l; the two identical printed formulas match "
            "neither reading."),
    Erratum("3.3-rotation", "3.3", "rotation block of ijT_r",
            r"[\cos\theta, \sin\theta; -\sin\theta, \cos\theta] = R(\theta)^T",
            r"\text{(A) as printed: } R(\theta)^T \text{ (robot} \to \text{landmark frame);}\; "
            r"\text{(B) } R(\theta) \text{ (matrice de passage)}",
            "reading A, the course's: R(theta)^T maps p_r - p_l onto the +x axis at length "
            "|p_r - p_l| (check_correct, 0); reading B: the usual 'matrice de passage' holds "
            "the new frame's axes as its COLUMNS, R(theta), and the printed block is its "
            "transpose (check: largest entry of R(theta)^T - R(theta)). 400 seeded pairs.",
            "ambiguous", _c_rotation_b, _c_rotation_block,
            "The paper does not say which way ijT_r maps. The course takes (A), the reading "
            "under which the printed rotation is right and the translation column wrong; under "
            "(B) the rotation is the misprint, and the translation column is wrong as well "
            "(3.3-transform)."),
    Erratum("3.3-names", "3.3", "names of the two points",
            r"R(x_r, y_r),\; R(x_l, y_l),\; x_1,\; X_r,\; \text{si},\; \text{cup}",
            r"P_r = (x_r, y_r),\; P_l = (x_l, y_l);\; x_l;\; \text{if};\; \text{cut}",
            "notation: both points are named R (the robot frame's name too), l is printed "
            "as 1 and x as X, 'si' is French for 'if', 'cup' is 'cut'.", "notation"),
    # ---------------------------------------------------------------- 4.1
    Erratum("4.1-axle-lhs", "4.1", "rear-axle model, left-hand side",
            r"[\chi_c, Y_c, \phi_c]^T = [V_c\cos\phi, V_c\sin\phi, V_c\tan\alpha/L]^T",
            r"[\dot x_c, \dot y_c, \dot\phi]^T = ...",
            "notation: the left side lacks the time derivatives; the right side is correct "
            "(see CONFIRMED).", "notation"),
    Erratum("4.1-Pl-vector", "4.1", "laser position, vector form",
            r"P_l = P_c + a\,\vec T_\theta + b\,\vec T_\phi + \pi_2,\; "
            r"\vec T_\theta = (\cos\phi, \sin\phi)",
            r"P_l = P_c + a\,T(\phi) + b\,T(\phi + \pi/2),\; T(\phi) = (\cos\phi, \sin\phi)",
            "notation: theta for phi and the +pi/2 outside the subscript; the scalar form "
            "that follows is correct (see CONFIRMED).", "notation"),
    Erratum("4.1-full-x", "4.1", "full state, x row",
            r"V_c\cos\phi - \frac{V_c}{L}(a\cos\phi + b\cos\phi)\tan\alpha",
            r"\dot x_L = V_c\cos\phi - \frac{V_c}{L}\tan\alpha\,(a\sin\phi + b\cos\phi)",
            _FLOW + "; also SymPy d/dt of P_l in tests/test_kinematics.py. (Left side also "
            "lacks the dots.)", "wrong equation", _c_full_row(0, True), _c_full_row(0, False)),
    Erratum("4.1-full-y", "4.1", "full state, y row",
            r"V_c\sin\phi - \frac{V_c}{L}(a\cos\phi - b\sin\phi)\tan\alpha",
            r"\dot y_L = V_c\sin\phi + \frac{V_c}{L}\tan\alpha\,(a\cos\phi - b\sin\phi)",
            _FLOW + ": the lever-arm term has the wrong sign.",
            "wrong equation", _c_full_row(1, True), _c_full_row(1, False)),
    Erratum("4.1-speed", "4.1", "encoder to axle-centre speed",
            r"V_c = \frac{V_c}{1 - \tan\alpha\,H/L}",
            r"V_c = \frac{V_e}{1 - \tan\alpha\,H/L}",
            "V_c on both sides holds only for V_c = 0 or alpha = 0; the numerator is the "
            "encoder speed. Reference: rigid body, the encoder wheel H m left of C moves "
            "at V_e = V_c - omega H, omega = V_c tan(alpha)/L; check = residual "
            "|RHS - V_c| of the printed equation, 400 seeded controls.",
            "wrong equation", _c_speed, _c_speed_ok),
    Erratum("4.1-discrete-x", "4.1", "discrete model, x row",
            r"x + \Delta t V_c\cos(\phi - \frac{V_c}{L}(a\sin\phi + b\cos\phi))\tan\alpha)",
            r"x + \Delta t\,[V_c\cos\phi - \frac{V_c}{L}\tan\alpha\,(a\sin\phi + b\cos\phi)]",
            _EULER + ". The lever-arm term is inside cos(); the brackets are unbalanced, so "
            "both readings (tan inside/outside the cos) are checked and the smaller error "
            "reported.", "wrong equation", _c_discrete_row(0, True), _c_discrete_row(0, False)),
    Erratum("4.1-discrete-y", "4.1", "discrete model, y row",
            r"y + \Delta t V_c\sin(\phi + \frac{V_c}{L}(a\cos\phi + b\sin\phi))\tan\alpha)",
            r"y + \Delta t\,[V_c\sin\phi + \frac{V_c}{L}\tan\alpha\,(a\cos\phi - b\sin\phi)]",
            _EULER + ". Lever-arm term inside sin() and +b sin(phi) instead of -b sin(phi); "
            "both bracket readings checked.",
            "wrong equation", _c_discrete_row(1, True), _c_discrete_row(1, False)),
    Erratum("4.1-discrete-phi", "4.1", "discrete model, heading row",
            r"\phi_k = \frac{V_c(k-1)}{L}\tan\alpha(k-1)",
            r"\phi_k = \phi(k-1) + \Delta t\,\frac{V_c(k-1)}{L}\tan\alpha(k-1)",
            _EULER + ": the printed row is the yaw RATE, without phi(k-1) and Delta t.",
            "wrong equation", _c_discrete_row(2, True), _c_discrete_row(2, False)),
    Erratum("4.1-process", "4.1", "process equation",
            r"X(k) + f(X(k-1), \mu(k-1)) + \omega_c(k-1) + \omega_f(k-1)",
            r"X(k) = f(X(k-1), u(k-1)) + \omega(k-1)",
            "notation: '+' for '=', mu (the noise) for the input u, and two noise terms "
            "never defined separately.", "notation"),
    Erratum("4.1-noise-map", "4.1", "input-noise mapping",
            r"[\omega_{\mu(k)}] = [\Delta f_{\mu(k-1)}(X,\mu)]\,\mu(k)",
            r"\omega(k-1) = \nabla_u f(X(k-1), u(k-1))\,\mu(k-1),\; \nabla_u f = G",
            "notation: Delta for the gradient nabla and mixed time indices, and the Jacobian "
            "is taken with respect to the noise mu (df/dmu = d(x, y, phi)/d(mu_1, mu_2)) "
            "instead of the input u; for noise added to the input the two are the same "
            "matrix G = df/du at u. G itself is checked by finite differences in "
            "tests/test_kinematics.py.", "notation"),
    Erratum("4.1-vehicle-xy", "4.1", "vehicle coordinates",
            r"(x_1, y_1)",
            r"(x, y)",
            "notation: 4.1 names the vehicle coordinates (x_1, y_1), the rest of the paper "
            "(x, y); in 3.3 the same x_1 is the left point's x_l (3.3-names).", "notation"),
    Erratum("4.1-z-symbols", "4.1", "symbols of the observation",
            r"z(k) = (\gamma, \beta, I)",
            r"z(k) = (r, \beta, \iota)\;\text{(range, bearing, intensity)}",
            "notation: gamma, the steering angle of 2.2, is reused for the range, and I, the "
            "wheelbase of 2.2's rate, for the intensity.", "notation"),
    Erratum("4.1-bearing", "4.1, 4.2", "bearing of the observation",
            r"\mathrm{atan}\left(\frac{y_l - y_i}{x_L - x_i}\right) - \theta + \frac{\pi}{2}",
            r"\mathrm{atan2}(y_i - y_L,\; x_i - x_L) - \phi + \frac{\pi}{2}",
            "the ratio is the same whichever way the differences are taken, so single-"
            "argument atan cannot tell the landmark from its mirror through the vehicle: "
            "the printed bearing is off by pi whenever x_i < x_L (half of 400 seeded "
            "landmarks). Reference: complex-number bearing. theta stands for the heading phi.",
            "wrong equation", _c_bearing(True), _c_bearing(False)),
    Erratum("4.1-noise-mean", "4.1", "zero-mean noise",
            r"E[\mu(k)] + E[\eta(k)] = 0",
            r"E[\mu(k)] = 0,\; E[\eta(k)] = 0,\; E[\mu(i)\eta^T(j)] = 0",
            "notation/statistics: a zero sum does not make both zero (and the two vectors "
            "differ in meaning); 'temporarily' should be 'temporally'.", "notation"),
    Erratum("4.1-noise-cov", "4.1", "input-noise covariance",
            r"E[\mu(i)\mu^T(j)] = \delta_{ij}\,\delta_{\alpha,\nu}(j)",
            r"E[\mu(i)\mu^T(j)] = \delta_{ij}\,Q_{v,\alpha}(j)",
            "notation: the covariance matrix of (v, alpha) is printed as a second delta.",
            "notation"),
    # ---------------------------------------------------------------- 4.2
    Erratum("4.2-dim", "4.2", "dimension of the map state",
            r"X_L = [x_1, y_1, \dots, x_n, y_n] \in R^N",
            r"X_L \in R^{2N}",
            "counting: N landmarks with two coordinates each (n and N are the same number).",
            "notation"),
    Erratum("4.2-ann", "4.2", "ANN neuron",
            r"f(x) = \mathrm{sign}(w, x) + b = \mathrm{sign}(b + \sum_i w_i x_i)",
            r"f(x) = \mathrm{sign}(\langle w, x\rangle + b)",
            "the two printed sides differ (b inside vs outside the sign): check = largest "
            "difference between them on 400 seeded (w, x, b). A sign() unit has zero "
            "gradient, so it cannot be the back-propagation network the text describes.",
            "wrong equation", _c_ann),
    Erratum("4.2-f-names", "4.2", "the letter f",
            r"f(x) = \mathrm{sign}(\dots)\;\text{(neuron)};\; \chi_v(k+1) = f(\chi_v(k))",
            r"g(x)\text{ for the neuron},\; f\text{ for the process model}",
            "notation: two lines apart, f names the ANN neuron and the vehicle's process "
            "model (whose Jacobian df/dchi_v = J_1 follows).", "notation"),
    Erratum("4.2-vehicle-position", "4.2", "what (x, y) is",
            r"(x, y)\text{ is the position of the vehicle}",
            r"(x_L, y_L)\text{, the laser's position (4.1-Pl-scalar)}",
            "notation: the range and bearing printed just above use the laser point "
            "(x_L, y_L), not the vehicle's reference point (chapter 03).", "notation"),
    Erratum("4.2-model", "4.2", "augmented process model",
            r"\chi_v(k+1) = f(\chi_v(k))",
            r"\chi_v(k+1) = f(\chi_v(k), u(k)),\; \chi_L(k+1) = \chi_L(k)",
            "notation: the control input is missing.", "notation"),
    Erratum("4.2-jacobian-blocks", "4.2", "Jacobian of the augmented model",
            r"\frac{\partial F}{\partial X} = [\frac{\partial f}{\partial\chi_v}; \emptyset^T] "
            r"= [J_1, \emptyset; \emptyset^T, I],\; \emptyset\in R^{3\times N},\; I\in R^{N\times N}",
            r"[J_1, 0_{3\times 2N}; 0_{2N\times 3}, I_{2N}]",
            "notation/counting: the middle expression lacks its right column block, and the "
            "map block has 2N rows (see 4.2-dim); J_1 = F of motion.predict.", "notation"),
    Erratum("4.2-range-formula", "4.2", "range, norm form",
            r"r_i = \|(x, Y) - (x_i - y_i)\|_2",
            r"r_i = \|(x_L, y_L) - (x_i, y_i)\|_2",
            "notation: '-' for ',' inside the landmark point; the square-root form after it "
            "is right (see CONFIRMED).", "notation"),
    Erratum("4.2-bearing-name", "4.2", "bearing equation, left-hand side",
            r"r_i = h_{\alpha(k)} = \dots - \theta + \pi/2",
            r"\alpha_i = h_\alpha(k) = \dots - \phi + \pi/2",
            "notation: the bearing is named r_i like the range, theta for phi; its "
            "atan problem is 4.1-bearing.", "notation"),
    Erratum("4.2-jac-range", "4.2", "range row of dh/dX, landmark columns",
            r"\frac{1}{\Delta}[\Delta x, \Delta y, 0, \dots, -\Delta y, 0, \dots]",
            r"\frac{1}{\Delta}[\Delta x, \Delta y, 0, \dots, -\Delta x, -\Delta y, \dots]",
            _FD_OBS + ". Both placements of the single printed entry are tried; the smaller "
            "error is reported.", "wrong equation",
            _c_jac([3, 4], 0, True), _c_jac([3, 4], 0, False),
            "The ellipses hide which landmark column holds -Delta y; the row is wrong "
            "either way (x_i needs -Delta x, y_i needs -Delta y)."),
    Erratum("4.2-jac-bearing", "4.2", "bearing row of dh/dX, y_i column",
            r"\cdot[-\frac{\Delta y}{\Delta^2}, \frac{\Delta x}{\Delta^2}, -1, \dots, "
            r"\frac{\Delta y}{\Delta^2}, \frac{\Delta y}{\Delta^2}, \dots]",
            r"[-\frac{\Delta y}{\Delta^2}, \frac{\Delta x}{\Delta^2}, -1, \dots, "
            r"\frac{\Delta y}{\Delta^2}, -\frac{\Delta x}{\Delta^2}, \dots]",
            _FD_OBS + " (Delta x = x - x_i, Delta y = y - y_i as printed). A stray "
            "multiplication dot opens the row.", "wrong equation",
            _c_jac([4], 1, True), _c_jac([4], 1, False)),
]



CONFIRMED: list[Erratum] = [
    Erratum("2.2-discrete", "2.2", "discrete rear-axle model",
            r"x + \Delta t V\cos\phi,\; y + \Delta t V\sin\phi,\; \phi + \Delta t V\tan\gamma/L",
            "as printed", "one Euler step of the exact rear-axle arc: " + _EULER,
            "correct", _c_pred22),
    Erratum("3.3-theta-cases", "3.3", "theta, cases 1 and 3 (condition fixed)",
            r"\arctan\frac{y_r - y_l}{x_r - x_l}\;(X_l < X_r),\; \dots - \pi\;(X_l > X_r)",
            r"= \mathrm{atan2}(y_r - y_l, x_r - x_l) \bmod 2\pi",
            "wrapped difference to the complex-number angle, 400 seeded pairs.",
            "correct", _c_theta_confirmed),
    Erratum("4.1-Pl-scalar", "4.1", "laser position, scalar form",
            r"x_l = x_c + a\cos\phi + b\cos(\phi + \pi/2),\; "
            r"y_l = y_c + a\sin\phi + b\sin(\phi + \pi/2)",
            "as printed", "rigid body P_c + R(phi)(a, b), 400 seeded poses.",
            "correct", _c_laser_position),
    Erratum("4.1-axle-rate", "4.1", "rear-axle model, right-hand side",
            r"[V_c\cos\phi, V_c\sin\phi, V_c\tan\alpha/L]",
            "as printed", _FLOW + " of the rear axle.", "correct", _c_axle_rate),
    Erratum("4.1-full-phi", "4.1", "full state, heading row",
            r"\frac{V_c}{L}\tan\alpha", "as printed", _FLOW + ".",
            "correct", _c_full_row(2, True)),
    Erratum("4.1-range", "4.1, 4.2", "range",
            r"\sqrt{(x_L - x_i)^2 + (y_L - y_i)^2}", "as printed",
            "complex-number modulus, 400 seeded pairs.", "correct", _c_range),
    Erratum("4.2-jac-vehicle", "4.2", "dh/dX, vehicle columns and bearing x_i column",
            r"\frac{1}{\Delta}[\Delta x, \Delta y, 0];\; [-\frac{\Delta y}{\Delta^2}, "
            r"\frac{\Delta x}{\Delta^2}, -1, \dots, \frac{\Delta y}{\Delta^2}]",
            "as printed", _FD_OBS + ".", "correct", _c_jac_vehicle),
]



def _entries(entries) -> list[Erratum]:
    """``entries`` as records: None (all of :data:`ERRATA`), records, or their keys (from
    :data:`ERRATA` and :data:`CONFIRMED`, in the order given; an unknown key is an error)."""
    if entries is None:
        return list(ERRATA)
    by_key = {e.key: e for e in (*ERRATA, *CONFIRMED)}
    out = []
    for e in entries:
        if isinstance(e, str):
            if e not in by_key:
                raise KeyError(f"no erratum {e!r}; known: {', '.join(sorted(by_key))}")
            e = by_key[e]
        out.append(e)
    return out


def errata_table(entries=None) -> list[dict]:
    """Rows for display: the record's fields plus the computed discrepancies
    ``printed_error`` and ``corrected_error`` (None where there is no check). ``entries``:
    records or keys (see :func:`_entries`), all errata by default."""
    rows = []
    for e in _entries(entries):
        rows.append({
            "key": e.key, "section": e.section, "quantity": e.quantity, "kind": e.kind,
            "printed": e.printed, "correct": e.correct,
            "printed_error": None if e.check is None else e.check(),
            "corrected_error": None if e.check_correct is None else e.check_correct(),
            "how_proven": e.how_proven, "note": e.note,
        })
    return rows



def _fmt_error(x: float | None) -> str:
    # A discrepancy below the checks' resolution is rounding or finite-difference noise,
    # whose digits depend on the CPU: shown as the bound (evaluation.residuals).
    if x is None:
        return "—"
    return residual(x, DIFFERENCES) if abs(x) < DIFFERENCES else f"{x:.2g}"


def _cell(text: str) -> str:
    # LaTeX's norm bars would end the table cell: write them as \Vert.
    return text.replace(r"\|", r"\Vert ").replace("|", r"\|").replace("\n", " ")


def errata_markdown(entries=None, *, formulas: str = "inline", collapsed: bool = False) -> str:
    """The errata as a Markdown table (docs/errata.md's table is this output, tested):
    section, quantity, printed form, correct form, kind, and the measured
    discrepancy of the printed and the corrected form (see :class:`Erratum`); one below
    the checks' resolution (1e-7, central differences) is written "below 1e-7", since its
    digits are rounding noise that changes with the CPU.

    ``formulas="below"`` (the chapters' form) keeps the table narrow, section, quantity,
    kind and the two discrepancies, and lists the printed and correct formulas under it,
    one line per erratum, where long formulas wrap instead of pushing the error columns
    off the page. ``entries``: records or keys, all errata by default. ``collapsed``: the
    table inside a closed ``<details>`` box whose summary counts the misprints and the
    confirmed equations (the core chapters' form: the paper thread is there to open, not in
    the way)."""
    if formulas not in ("inline", "below"):
        raise ValueError(f"formulas must be 'inline' or 'below', got {formulas!r}")
    rows = errata_table(entries)
    if collapsed:
        table = errata_markdown([r["key"] for r in rows], formulas=formulas)
        wrong = sum(r["kind"] != "correct" for r in rows)
        summary = (f"The paper's printed forms: {wrong} misprint{'s' * (wrong != 1)}, "
                   f"{len(rows) - wrong} confirmed (the paper thread; open to read)")
        return f"<details>\n<summary>{summary}</summary>\n\n{table}\n\n</details>"
    if formulas == "inline":
        lines = ["| § | quantity | printed | correct | kind | error printed | error corrected |",
                 "|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['section']} | {_cell(r['quantity'])} | ${_cell(r['printed'])}$ | "
                         f"${_cell(r['correct'])}$ | {r['kind']} | "
                         f"{_fmt_error(r['printed_error'])} | {_fmt_error(r['corrected_error'])} |")
        return "\n".join(lines)
    lines = ["| | § | quantity | kind | error printed | error corrected |",
             "|---|---|---|---|---|---|"]
    for i, r in enumerate(rows, 1):
        lines.append(f"| {i} | {r['section']} | {_cell(r['quantity'])} | {r['kind']} | "
                     f"{_fmt_error(r['printed_error'])} | {_fmt_error(r['corrected_error'])} |")
    lines.append("")
    for i, r in enumerate(rows, 1):
        lines.append(f"{i}. `{r['key']}`: printed ${r['printed']}$; correct ${r['correct']}$")
    return "\n".join(lines)
