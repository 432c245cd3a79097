"""Checks for the graded exercises of chapter 01 (vehicle kinematics) and chapter 02 (laser
offset transform).

Each ``check_*`` compares a student's function with the library (:mod:`annslam_lib.models.motion`,
itself checked against SymPy and finite differences) on seeded random cars, poses and controls
plus edge cases, and names the known mistakes: the paper's printed equations of sections 2.2
and 4.1 (:mod:`annslam_lib.paper`, erratum ids in the messages) and the usual slips (no
encoder correction, the rear axle's model for the laser's, the lever arm turned the wrong way,
a missing identity in F, ...). Student functions take plain numbers for the car (``L``, ``a``,
``b``, ``H``) so that nothing but NumPy is needed to write them. Every check prints its
one-line success message (unless ``quiet``, for hidden tests) and returns it.

| exercise | student function | check |
|---|---|---|
| 01, 1.1 encoder to axle speed | ``my_axle_speed(v_e, alpha, H, L)`` | :func:`check_axle_speed` |
| 01, 1.2 Euler step of the laser | ``my_euler_step(pose, control, dt, L, a, b)`` | :func:`check_euler_step` |
| 01, 1.3 its Jacobians F, G | ``my_process_jacobians(pose, control, dt, L, a, b)`` | :func:`check_process_jacobians` |
| 02, 2.1 axle pose from the laser (the inverse transform) | ``my_axle_pose(laser_pose, a, b)`` | :func:`check_axle_pose` |
| 02, 2.2 Jacobian of the transform | ``my_laser_pose_jacobian(axle_pose, a, b)`` | :func:`check_laser_pose_jacobian` |
| 02, 2.3 laser velocity through J (not graded) | ``my_laser_velocity(pose, control, L, a, b)`` | :func:`check_laser_velocity` |
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..models import motion as kinematics
from .. import paper
from ..models.geometry import from_frame, numerical_jacobian, wrap_angle
from ..models.vehicle import ACFR_UTE, Vehicle
from .core import (forbids, GradingError, Mistake, Passed, call, check_function, check_jacobian, describe,
                   copying, fmt, passing_prefetch, prefetch)

__all__ = ["check_axle_speed", "check_euler_step", "check_process_jacobians", "check_axle_pose",
           "check_laser_velocity", "check_laser_pose_jacobian"]

_H = ACFR_UTE.H          # the encoder offset plays no role in the laser model


def _car(L, a, b, H=_H) -> Vehicle:
    return Vehicle(L=float(L), H=float(H), a=float(a), b=float(b))


def _name(fn: Callable, default: str) -> str:
    name = getattr(fn, "__name__", "")
    return name if name.isidentifier() else default


def _copying_prefetched(fn: Callable) -> Callable:
    """:func:`copying` that also passes prefetching on to ``fn``."""
    # unlike verdict's and ann's checks, these let the grader's proxy batch their inputs
    return passing_prefetch(copying(fn), fn)


def _show(x) -> str:
    try:
        return fmt(x)
    except ValueError:          # ragged sequences
        return f"{x!r:.80}"


def _part(fn: Callable, name: str, k: int, parts: tuple[str, ...], shapes: tuple[tuple, ...],
          arg_names) -> Callable:
    """Student function returning a tuple ``parts``: pick part ``k``, with a clear message
    if it does not return such a tuple (or returns the parts in the wrong order)."""
    want = "(" + ", ".join(parts) + ")"

    def pick(*args):
        out = call(fn, args, name=name, arg_names=arg_names)
        where = describe(args, arg_names)
        if not isinstance(out, (tuple, list)) or len(out) != len(parts):
            raise GradingError(f"{name} must return the tuple {want}; at {where} it returned "
                               f"{type(out).__name__} {_show(out)}")
        got = [np.shape(o) for o in out]
        if got == list(shapes[::-1]) and shapes[0] != shapes[1]:
            raise GradingError(f"{name} returns {parts[1]} first: return {want} in that order "
                               f"(shapes {shapes}).")
        if got[k] == shapes[k][::-1] and shapes[k][0] != shapes[k][1]:
            raise GradingError(f"{name} returns {parts[k]} transposed, shape {got[k]}: rows are "
                               f"the outputs, columns the inputs you differentiate by, so its "
                               f"shape is {shapes[k]}.")
        return out[k]
    return passing_prefetch(pick, fn)


# ------------------------------------------------------------------ cases

def _cars(rng, n: int):
    """Half the ACFR ute, half random cars (so a, b, L mix-ups show)."""
    L = np.where(np.arange(n) % 2 == 0, ACFR_UTE.L, rng.uniform(1.5, 4.0, n))
    a = np.where(np.arange(n) % 2 == 0, ACFR_UTE.a, rng.uniform(-2.0, 5.0, n))
    b = np.where(np.arange(n) % 2 == 0, ACFR_UTE.b, rng.uniform(-1.5, 1.5, n))
    return L, a, b


def _motion_cases(seed: int, n: int, *, with_dt: bool):
    """(pose, control, [dt,] L, a, b) cases: random ones, then edge cases."""
    rng = np.random.default_rng(seed)
    pose = np.c_[rng.uniform(-50, 50, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    u = np.c_[rng.uniform(-3.0, 5.0, n), rng.uniform(-0.6, 0.6, n)]
    dt = rng.uniform(0.0, 0.3, n)
    L, a, b = _cars(rng, n)
    rows = [(pose[i], u[i], dt[i], L[i], a[i], b[i]) for i in range(n)]
    U = ACFR_UTE
    rows += [
        (np.array([1.0, -2.0, 3.1]), np.array([3.0, 0.5]), 0.3, U.L, U.a, U.b),     # heading past +pi
        (np.array([-4.0, 2.0, -3.1]), np.array([3.0, -0.5]), 0.3, U.L, U.a, U.b),   # past -pi
        (np.array([2.0, 5.0, 0.7]), np.array([2.0, 0.0]), 0.1, U.L, U.a, U.b),      # straight
        (np.array([2.0, 5.0, -2.0]), np.array([0.0, 0.4]), 0.1, U.L, U.a, U.b),     # standing
        (np.array([-3.0, 1.0, 1.2]), np.array([-1.5, 0.3]), 0.2, U.L, U.a, U.b),    # reversing
        (np.array([0.0, 0.0, np.pi / 2]), np.array([2.0, 0.6]), 0.05, U.L, U.a, U.b),  # full lock
        (np.array([0.0, 0.0, 0.0]), np.array([2.0, -0.6]), 0.05, U.L, U.a, -U.b),   # laser right
        (np.array([5.0, 5.0, 2.5]), np.array([1.0, 0.3]), 0.0, U.L, U.a, U.b),      # dt = 0
        (np.array([7.0, -1.0, 0.4]), np.array([1.8, 0.35]), 0.025, U.L, 0.0, 0.0),  # rear axle
    ]
    if not with_dt:
        rows = [(p, c, L_, a_, b_) for p, c, _, L_, a_, b_ in rows]
    return rows


def _pose_cases(seed: int, n: int):
    """(axle_pose, a, b) cases: random ones, then edge cases."""
    rng = np.random.default_rng(seed)
    pose = np.c_[rng.uniform(-50, 50, (n, 2)), rng.uniform(-np.pi, np.pi, n)]
    _, a, b = _cars(rng, n)
    rows = [(pose[i], a[i], b[i]) for i in range(n)]
    U = ACFR_UTE
    rows += [(np.array([0.0, 0.0, 0.0]), U.a, U.b), (np.array([1.0, 2.0, np.pi / 2]), U.a, U.b),
             (np.array([-1.0, 3.0, 3.1]), U.a, U.b), (np.array([4.0, -3.0, -3.1]), U.a, U.b),
             (np.array([2.0, 2.0, -np.pi / 2]), U.a, -U.b), (np.array([2.0, 2.0, 1.0]), 0.0, 0.0),
             (np.array([-6.0, 1.0, 0.5]), 0.0, 1.0)]
    return rows


# ------------------------------------------------------------------ 01, exercise 1.1

_SPEED_ARGS = ("v_e", "alpha", "H", "L")


def _axle_speed_ref(v_e, alpha, H, L):
    return kinematics.axle_speed(v_e, alpha, _car(L, 0.0, 0.0, H))[0]


_SPEED_MISTAKES = (
    Mistake("my_axle_speed returns the encoder speed unchanged: that is the paper's printed "
            "equation of section 4.1 read literally (V_c on both sides, erratum 4.1-speed), which "
            "holds only when driving straight. In a turn the encoder wheel and C run on two "
            "different circles about the ICR at the same rate: compare their radii.",
            lambda v_e, alpha, H, L: v_e,
            answer="The back-left wheel runs on a circle of radius R - H about the ICR, "
                   "R = L / tan(alpha), so v_e = v_c (R - H)/R and v_c = v_e / (1 - tan(alpha) H/L)."),
    Mistake("my_axle_speed gives the wheel speed from the axle speed (v_e from v_c): the "
            "inverse of what is asked. Write v_e in terms of v_c, then solve for v_c.",
            lambda v_e, alpha, H, L: v_e * (1 - np.tan(alpha) * H / L),
            answer="Solve v_e = v_c (1 - tan(alpha) H/L) for v_c: v_c = v_e / (1 - tan(alpha) H/L)."),
    Mistake("my_axle_speed has the sign of the H term reversed. The encoder is on the LEFT "
            "wheel, the inside wheel of a left turn (alpha > 0), which runs slower than the axle "
            "centre, so v_c > v_e when alpha > 0.",
            lambda v_e, alpha, H, L: v_e / (1 + np.tan(alpha) * H / L),
            answer="v_c = v_e / (1 - tan(alpha) H/L)."),
    Mistake("my_axle_speed uses a first-order approximation of the correction, off by several "
            "percent at full lock: use the exact ratio of the two radii.",
            lambda v_e, alpha, H, L: v_e * (1 + np.tan(alpha) * H / L),
            answer="1 + tan(alpha) H/L approximates 1 / (1 - tan(alpha) H/L): divide by "
                   "(1 - tan(alpha) H/L) instead."),
    Mistake("my_axle_speed uses L/H where H/L belongs (H the encoder's offset, L the "
            "wheelbase): check which length is the turning radius's and which the wheel's.",
            lambda v_e, alpha, H, L: v_e / (1 - np.tan(alpha) * L / H),
            answer="The correction is 1 - tan(alpha) H / L."),
    Mistake("my_axle_speed uses sin(alpha) where another function of alpha belongs: look at "
            "the turning radius R of section 1.",
            lambda v_e, alpha, H, L: v_e / (1 - np.sin(alpha) * H / L),
            answer="R = L / tan(alpha), so the correction is 1 - tan(alpha) H / L."),
)


@forbids(kinematics.axle_speed)
def check_axle_speed(fn: Callable, *, seed: int = 0, n: int = 40,
                     quiet: bool = False) -> str:
    """Grade ``fn(v_e, alpha, H, L) -> v_c``, the rear-axle-centre speed from the back-left
    encoder speed (notebook 01 section 2; paper 4.1 corrected: v_c = v_e / (1 - tan(alpha) H/L)).

    Cases: ``n`` seeded random speeds (reversing included), steering within the ute's
    +-0.6 rad and random cars, plus straight ahead, standing still and both full locks.
    Known mistakes: no correction (the printed V_c = V_c / ..., erratum 4.1-speed), the
    inverse, the sign of H, the first-order factor, L/H, sin for tan.
    """
    rng = np.random.default_rng(seed)
    cases = [(v, al, H, L) for v, al, H, L in zip(rng.uniform(-3, 5, n), rng.uniform(-0.6, 0.6, n),
                                                  rng.uniform(0.3, 1.0, n), rng.uniform(1.5, 4.0, n))]
    U = ACFR_UTE
    cases += [(2.0, 0.0, U.H, U.L), (0.0, 0.4, U.H, U.L), (2.0, 0.6, U.H, U.L),
              (2.0, -0.6, U.H, U.L), (-1.5, 0.3, U.H, U.L)]
    name = _name(fn, "my_axle_speed")
    mistakes = [m.renamed("my_axle_speed", name) for m in _SPEED_MISTAKES]
    return check_function(_copying_prefetched(fn), _axle_speed_ref, cases, name=name,
                          arg_names=_SPEED_ARGS, labels=None, mistakes=mistakes,
                          what="motion.axle_speed", quiet=quiet)


# ------------------------------------------------------------------ 01, exercise 1.2

_STEP_ARGS = ("pose", "control", "dt", "L", "a", "b")
_STEP_LABELS = ("x_k", "y_k", "phi_k")


def _step_ref(pose, control, dt, L, a, b):
    return kinematics.predict(pose, control, dt, _car(L, a, b))[0]


def _printed_discrete(inside: bool):
    return lambda pose, u, dt, L, a, b: paper.discrete_model_printed(
        pose, u, dt, _car(L, a, b), tan_inside=inside)


def _euler_with(rate: Callable):
    def step(pose, u, dt, L, a, b):
        out = pose + dt * rate(pose, u, _car(L, a, b))
        out[..., 2] = wrap_angle(out[..., 2])
        return out
    return step


_DISCRETE_MSG = (
    "{name} is the paper's printed discrete model (section 4.1, {reading}; errata "
    "4.1-discrete-x, 4.1-discrete-y, 4.1-discrete-phi). Three misprints: the lever-arm term sits "
    "INSIDE cos() and sin() (it belongs outside, added to the axle's term, not to the angle); "
    "the sign of the y row's b sin(phi) term; and the heading row is the yaw rate alone, not "
    "the previous heading advanced over the step.")
_STEP_ANSWER = (
    "Correct step: pose + dt * (laser velocity), i.e. "
    "x + dt [v cos(phi) - v/L tan(alpha) (a sin(phi) + b cos(phi))], "
    "y + dt [v sin(phi) + v/L tan(alpha) (a cos(phi) - b sin(phi))], phi + dt v tan(alpha) / L.")

_STEP_MISTAKES = (
    Mistake(_DISCRETE_MSG.replace("{reading}", "tan(alpha) read outside the cosine"),
            _printed_discrete(False), answer=_STEP_ANSWER),
    Mistake(_DISCRETE_MSG.replace("{reading}", "tan(alpha) read inside the cosine"),
            _printed_discrete(True), answer=_STEP_ANSWER),
    Mistake("{name} takes cos and sin of the heading RATE: that is the paper's section 2.2 "
            "continuous model read literally, x' = V cos(phi'), y' = V sin(phi') (erratum "
            "2.2-rate, a stray prime). The car moves along its heading, not its heading rate.",
            _euler_with(paper.rate_2_2_printed),
            answer="v cos(phi), v sin(phi) for the rear axle, plus the lever-arm terms for the laser."),
    Mistake("{name} moves the REAR AXLE (the section 2.2 model, right for the point C), but the "
            "state is the LASER pose, a m ahead and b m left of C. When the car turns, the lever "
            "arm swings: section 3's laser velocity has the terms you are missing.",
            lambda pose, u, dt, L, a, b: kinematics.predict(pose, u, dt, _car(L, 0.0, 0.0))[0],
            answer="Add dt * omega x r, with omega = v tan(alpha) / L and r = R(phi) (a, b)."),
    Mistake("{name} uses the paper's printed 'full state' as the rate (section 4.1, errata "
            "4.1-full-x and 4.1-full-y): its x and y rows are misprinted. Derive the laser's "
            "velocity from the laser's position (section 3 of this notebook).",
            _euler_with(paper.full_state_printed),
            answer="The x row has a cos(phi) where a sin(phi) belongs and the y row subtracts the "
                   "lever-arm term instead of adding it."),
    Mistake("{name} computes the exact circular arc (like motion.predict_exact). That is "
            "the better integrator, but the filter's process model, and the F and G of the "
            "next exercise, are the EULER step.",
            lambda pose, u, dt, L, a, b: kinematics.predict_exact(pose, u, dt, _car(L, a, b)),
            answer="The Euler step is pose + dt * (laser velocity at the start of the step)."),
    Mistake("{name} leaves the heading unchanged: the car turns during the step.",
            lambda pose, u, dt, L, a, b: np.r_[_step_ref(pose, u, dt, L, a, b)[:2], pose[2]],
            answer="It must advance by dt * v tan(alpha) / L."),
)


def _check_wrapped(fn, cases, name, arg_names, column: int | None, label: str) -> None:
    """The heading of every output must lie in (-pi, pi] (check_function compares angles
    modulo 2 pi, so it would accept an unwrapped one)."""
    prefetch(fn, cases)
    for args in cases:
        out = np.asarray(call(fn, args, name=name, arg_names=arg_names), dtype=float)
        h = float(out[column] if column is not None else out)
        if not abs(h) <= np.pi + 1e-12:     # (-pi, pi] or [-pi, pi): both fine
            raise GradingError(
                f"{label} is right modulo 2π but not wrapped into (-π, π]: at "
                f"{describe(args, arg_names)} got {fmt(h)}, expected {fmt(wrap_angle(h))}. "
                f"Wrap it, e.g. (h + np.pi) % (2 * np.pi) - np.pi.")


@forbids(kinematics.predict, kinematics.predict_exact, kinematics.laser_velocity)
def check_euler_step(fn: Callable, *, seed: int = 0, n: int = 40,
                     quiet: bool = False) -> str:
    """Grade ``fn(pose, control, dt, L, a, b) -> pose_next`` (3,), one Euler step of the laser
    model with the heading wrapped to (-pi, pi] (notebook 01 section 4; the reference is
    ``motion.predict``, paper 4.1 corrected).

    ``pose`` = laser (x, y, phi), ``control`` = (v_c, alpha). Cases: ``n`` seeded random
    poses, controls (reversing included), steps up to 0.3 s and cars, plus headings that cross
    +-pi, straight ahead, standing still, full lock, the laser on the right, dt = 0 and a = b = 0.
    Known mistakes: the printed discrete model (both bracket readings, errata 4.1-discrete-*),
    the 2.2 rate read literally (2.2-rate), the rear-axle model, the printed full state
    (4.1-full-x/y), the exact arc, a frozen heading; then the heading must be wrapped.
    """
    cases = _motion_cases(seed, n, with_dt=True)
    name = _name(fn, "my_euler_step")
    mistakes = [m.renamed("{name}", name) for m in _STEP_MISTAKES]
    student = _copying_prefetched(fn)
    msg = check_function(student, _step_ref, cases, name=name, arg_names=_STEP_ARGS,
                         labels=_STEP_LABELS, angles=[2], mistakes=mistakes,
                         what="motion.predict", quiet=True)
    _check_wrapped(student, cases, name, _STEP_ARGS, 2, "'phi_k'")
    if not quiet:
        print(msg)
    return msg


# ------------------------------------------------------------------ 01, exercise 1.3

_FG_ROWS = ("x_k", "y_k", "phi_k")
_F_COLS = ("x", "y", "phi")
_G_COLS = ("v", "alpha")


def _printed_jacobians(inside: bool, which: int):
    """Central-difference F (which = 0) or G (1) of the printed discrete model."""
    def jac(pose, u, dt, L, a, b):
        car = _car(L, a, b)
        if which == 0:
            return numerical_jacobian(lambda p: paper.discrete_model_printed(
                p, u, dt, car, tan_inside=inside), pose, angle_outputs=[2])
        return numerical_jacobian(lambda w: paper.discrete_model_printed(
            pose, w, dt, car, tan_inside=inside), u, angle_outputs=[2])
    return jac


def _ref_fg(k: int):
    return lambda pose, u, dt, L, a, b: kinematics.predict(pose, u, dt, _car(L, a, b))[k]


_PRINTED_JAC_MSG = (
    "{name}: these are the Jacobians of the paper's PRINTED discrete model (section 4.1, "
    "{reading}; errata 4.1-discrete-x/-y/-phi), e.g. its heading row does not depend on phi. "
    "Differentiate the corrected Euler step pose + dt * (laser velocity) instead.")

_F_MISTAKES = (
    Mistake("{name}: F has no identity: the step starts from X_(k-1) itself, and that term "
            "has a derivative too.",
            lambda pose, u, dt, L, a, b: _ref_fg(1)(pose, u, dt, L, a, b) - np.eye(3),
            answer="The step is X_k = X_(k-1) + dt f(X_(k-1), u), so F = I + dt df/dX."),
    Mistake("{name}: F is the rear axle's (a = b = 0): d x_k / d phi and d y_k / d phi miss the "
            "lever arm. Turning the car also swings the laser around C: differentiate the "
            "a and b terms of the laser velocity by phi too.",
            lambda pose, u, dt, L, a, b: _ref_fg(1)(pose, u, dt, L, 0.0, 0.0)),
    Mistake(_PRINTED_JAC_MSG.replace("{reading}", "tan(alpha) outside the cosine"),
            _printed_jacobians(False, 0)),
    Mistake(_PRINTED_JAC_MSG.replace("{reading}", "tan(alpha) inside the cosine"),
            _printed_jacobians(True, 0)),
)

_G_MISTAKES = (
    Mistake("{name}: G lacks the factor dt: you returned the Jacobian of the rate f, not of "
            "the step.",
            lambda pose, u, dt, L, a, b: _ref_fg(2)(pose, u, 1.0, L, a, b),
            answer="The control acts through dt f(X, u), so G = dt df/du."),
    Mistake("{name}: the columns of G are in the order (alpha, v); the control is "
            "u = (v, alpha), so column 0 is d/dv and column 1 is d/dalpha.",
            lambda pose, u, dt, L, a, b: _ref_fg(2)(pose, u, dt, L, a, b)[:, ::-1]),
    Mistake("{name}: G is the rear axle's (a = b = 0): the laser's velocity also depends on v "
            "and alpha through the lever-arm terms.",
            lambda pose, u, dt, L, a, b: _ref_fg(2)(pose, u, dt, L, 0.0, 0.0),
            answer="The lever-arm terms are omega x r, omega = v tan(alpha) / L."),
    Mistake(_PRINTED_JAC_MSG.replace("{reading}", "tan(alpha) outside the cosine"),
            _printed_jacobians(False, 1)),
    Mistake(_PRINTED_JAC_MSG.replace("{reading}", "tan(alpha) inside the cosine"),
            _printed_jacobians(True, 1)),
)


@forbids(kinematics.predict)
def check_process_jacobians(fn: Callable, *, seed: int = 0, n: int = 30,
                            quiet: bool = False) -> str:
    """Grade ``fn(pose, control, dt, L, a, b) -> (F, G)``, the Jacobians of the Euler step of
    the laser model: F = d pose_k / d pose_(k-1) (3 x 3), G = d pose_k / d (v_c, alpha) (3 x 2)
    (notebook 01 section 4; reference ``motion.predict``, finite-difference tested).

    Same cases as :func:`check_euler_step`. A wrong entry is named ('d y_k / d phi (entry
    [1, 2])'), with sign errors, entries left at zero and transposes flagged. Known mistakes:
    F without the identity, G without dt, G's columns swapped, the rear axle's Jacobians and
    those of the printed discrete model (errata 4.1-discrete-*).
    """
    cases = _motion_cases(seed, n, with_dt=True)
    name = _name(fn, "my_process_jacobians")
    shapes = ((3, 3), (3, 2))
    for k, (cols, mist) in enumerate(((_F_COLS, _F_MISTAKES), (_G_COLS, _G_MISTAKES))):
        which = f"{name} ({'FG'[k]})"
        part = _part(_copying_prefetched(fn), name, k, ("F", "G"), shapes, _STEP_ARGS)
        try:
            check_jacobian(part, _ref_fg(k + 1), cases, name=which, rows=_FG_ROWS, cols=cols,
                           arg_names=_STEP_ARGS, quiet=True,
                           mistakes=[m.renamed("{name}", which)
                                     for m in mist])
        except GradingError as e:   # say which matrix, also in the generic messages
            msg = str(e)
            raise GradingError(msg if msg.startswith(name) else f"{which}: {msg}") from None
    msg = f"✓ {name}: F and G agree with motion.predict on {len(cases)} inputs."
    if not quiet:
        print(msg)
    return Passed(msg)


# ------------------------------------------------------------------ 02, exercise 2.1

_POSE_ARGS = ("axle_pose", "a", "b")
_AXLE_ARGS = ("laser_pose", "a", "b")
_AXLE_LABELS = ("x_c", "y_c", "phi")


def _axle_ref(pose, a, b):
    return kinematics.axle_pose(pose, _car(ACFR_UTE.L, a, b))[0]


def _lever(pose, a, b, rot: Callable):
    """pose with a lever arm ``rot(phi, a, b)`` added to its position."""
    dx, dy = rot(pose[2], a, b)
    return np.array([pose[0] + dx, pose[1] + dy, pose[2]])


def _back(rot: Callable) -> Callable:
    """The laser pose with the lever arm ``rot(phi, a, b)`` taken off its position."""
    return lambda p, a, b: _lever(p, a, b, lambda f, a, b: tuple(-d for d in rot(f, a, b)))


def _rotated_position(p, a, b):
    """R(phi)^T applied to the laser's world position, then (a, b) taken off: the world point
    carried into the car's frame, as if the whole pose had to be inverted."""
    c, s = np.cos(p[2]), np.sin(p[2])
    return np.array([c * p[0] + s * p[1] - a, -s * p[0] + c * p[1] - b, p[2]])


_INVERSE = ("P_c = P_l - R(phi) (a, b) = P_l - a T(phi) - b T(phi + pi/2): "
            "x_c = x_l - a cos(phi) + b sin(phi), y_c = y_l - a sin(phi) - b cos(phi).")
_VECTOR_FORM_MSG = (
    "{name} undoes the paper's VECTOR form of P_l read literally (section 4.1, erratum "
    "4.1-Pl-vector): {how}. b is the offset to the car's LEFT: which direction is that, for a "
    "car heading phi?")
_VECTOR_FORM_ANSWER = (
    "The printed P_l = P_c + a T_theta + b T_phi + pi_2 means b T(phi + pi/2) = "
    "b (-sin(phi), cos(phi)): the pi/2 belongs inside T. The scalar form printed right after it "
    "is correct, and solved for P_c: " + _INVERSE)

_AXLE_MISTAKES = (
    Mistake("{name} adds the lever arm: that is the forward transform, from the axle to the "
            "laser (chapter 01, section 3). Going back, which way does C lie from the laser?",
            lambda p, a, b: _lever(p, a, b, lambda f, a, b: (a * np.cos(f) - b * np.sin(f),
                                                            a * np.sin(f) + b * np.cos(f))),
            answer=_INVERSE),
    Mistake("{name} turns the lever arm by -phi (the transposed rotation R(phi)^T). The heading "
            "is shared, so the lever arm in the world is the very vector the forward transform "
            "added: only its sign changes on the way back.",
            _back(lambda f, a, b: (a * np.cos(f) + b * np.sin(f), -a * np.sin(f) + b * np.cos(f))),
            answer="The lever arm in the world is R(phi) (a, b) = (a cos(phi) - b sin(phi), "
                   "a sin(phi) + b cos(phi)) both ways. " + _INVERSE),
    Mistake("{name} rotates the laser's position itself into the car's frame: the laser pose "
            "is already in world coordinates, and only the lever arm turns with the car.",
            _rotated_position, answer=_INVERSE),
    Mistake("{name} swaps a and b: a is the FORWARD offset (along T(phi)), b the offset to the "
            "LEFT (along T(phi + pi/2)).",
            _back(lambda f, a, b: (b * np.cos(f) - a * np.sin(f), b * np.sin(f) + a * np.cos(f))),
            answer=_INVERSE),
    Mistake("{name} puts the laser b m to the RIGHT of the car: positive b is to the left.",
            _back(lambda f, a, b: (a * np.cos(f) + b * np.sin(f), a * np.sin(f) - b * np.cos(f))),
            answer="The left of a car heading phi is T(phi + pi/2) = (-sin(phi), cos(phi)). "
                   + _INVERSE),
    Mistake("{name} takes off only the forward offset a: the laser is also b m to the left "
            "of C.",
            _back(lambda f, a, b: (a * np.cos(f), a * np.sin(f))), answer=_INVERSE),
    Mistake(_VECTOR_FORM_MSG.replace("{how}", "the b offset points along the heading"),
            _back(lambda f, a, b: ((a + b) * np.cos(f), (a + b) * np.sin(f))),
            answer=_VECTOR_FORM_ANSWER),
    Mistake(_VECTOR_FORM_MSG.replace("{how}", "pi/2 added to both coordinates"),
            _back(lambda f, a, b: ((a + b) * np.cos(f) + np.pi / 2, (a + b) * np.sin(f) + np.pi / 2)),
            answer=_VECTOR_FORM_ANSWER),
)


@forbids(kinematics.axle_pose, kinematics.laser_pose, from_frame)
def check_axle_pose(fn: Callable, *, seed: int = 0, n: int = 40,
                    quiet: bool = False) -> str:
    """Grade ``fn(laser_pose, a, b) -> axle_pose`` (3,): the rear-axle centre, a m behind and b m
    to the right of the laser, heading unchanged: the inverse of the laser offset transform
    (notebook 02, exercise 2.1; paper 4.1 P_l solved for P_c; reference ``motion.axle_pose``).

    Cases: ``n`` seeded random poses and offsets plus headings 0, pi/2, near +-pi, the laser on
    the right, a = b = 0 and a pure sideways offset. Known mistakes: the forward transform
    (lever arm added), R(-phi), the laser's position rotated into the car's frame, a and b
    swapped, b to the right, b left out, the printed vector form read literally (erratum
    4.1-Pl-vector, two readings). The library's ``axle_pose`` is refused, and so is the forward
    transform (``laser_pose``, or ``geometry.from_frame`` with the lever arm negated).
    """
    cases = _pose_cases(seed, n)
    name = _name(fn, "my_axle_pose")
    mistakes = [m.renamed("{name}", name) for m in _AXLE_MISTAKES]
    return check_function(_copying_prefetched(fn), _axle_ref, cases, name=name,
                          arg_names=_AXLE_ARGS, labels=_AXLE_LABELS, angles=[2], mistakes=mistakes,
                          what="motion.axle_pose", quiet=quiet)


# ------------------------------------------------------------------ 02, exercise 2.3 (not graded)

_RATE_ARGS = ("pose", "control", "L", "a", "b")
_RATE_LABELS = ("x_dot", "y_dot", "phi_dot")


def _rate_ref(pose, u, L, a, b):
    return kinematics.laser_velocity(pose, u, _car(L, a, b))


def _rate_rows(x_printed: bool, y_printed: bool):
    """The corrected rate with the printed x and/or y row of section 4.1 put in."""
    def rate(pose, u, L, a, b):
        car = _car(L, a, b)
        out = kinematics.laser_velocity(pose, u, car)
        printed = paper.full_state_printed(pose, u, car)
        for row, use in ((0, x_printed), (1, y_printed)):
            if use:
                out[..., row] = printed[..., row]
        return out
    return rate


_X_ROW = "the x row's lever-arm term has the wrong function of phi on a (erratum 4.1-full-x)"
_Y_ROW = "the y row's lever-arm term has the wrong sign (erratum 4.1-full-y)"
_X_ANSWER = "x_dot = v cos(phi) - v/L tan(alpha) (a sin(phi) + b cos(phi))."
_Y_ANSWER = "y_dot = v sin(phi) + v/L tan(alpha) (a cos(phi) - b sin(phi))."

_RATE_MISTAKES = (
    Mistake("{name} is the paper's printed 'full state' (section 4.1). Two rows are misprinted: "
            + _X_ROW + "; and " + _Y_ROW + ". The heading row is right.",
            _rate_rows(True, True), answer=_X_ANSWER + " " + _Y_ANSWER),
    Mistake("{name}: the x row is the paper's misprint: " + _X_ROW + ". The y and heading rows "
            "are right.", _rate_rows(True, False), answer=_X_ANSWER),
    Mistake("{name}: the y row is the paper's misprint: " + _Y_ROW + ". The x and heading rows "
            "are right.", _rate_rows(False, True), answer=_Y_ANSWER),
    Mistake("{name} is the rear axle's velocity, right for the point C but not for the laser: "
            "the lever arm from C to the laser turns with the car.",
            lambda pose, u, L, a, b: _rate_ref(pose, u, L, 0.0, 0.0),
            answer="Add omega x r = omega (-r_y, r_x), r = R(phi) (a, b), omega = v tan(alpha) / L."),
    Mistake("{name} turns the lever arm the wrong way in omega x r (clockwise instead of "
            "counter-clockwise for a left turn).",
            lambda pose, u, L, a, b: 2 * _rate_ref(pose, u, L, 0.0, 0.0) - _rate_ref(pose, u, L, a, b),
            answer="omega x r in the plane is omega (-r_y, r_x), not omega (r_y, -r_x)."),
    Mistake("{name} takes cos and sin of the heading RATE: the section 2.2 model read literally, "
            "x' = V cos(phi') (erratum 2.2-rate, a stray prime); the laser also needs the "
            "lever-arm terms.",
            lambda pose, u, L, a, b: paper.rate_2_2_printed(pose, u, _car(L, a, b)),
            answer="It is cos(phi) and sin(phi) of the heading itself."),
)


@forbids(kinematics.laser_velocity)
def check_laser_velocity(fn: Callable, *, seed: int = 0, n: int = 40,
                         quiet: bool = False) -> str:
    """Grade ``fn(pose, control, L, a, b) -> (x_dot, y_dot, phi_dot)``, the velocity of the laser
    point (notebook 02 "How the laser moves"; paper 4.1 "full state" corrected; reference
    ``motion.laser_velocity``).

    Cases as in :func:`check_euler_step` without dt. Known mistakes: the printed full state
    (both rows, or only its x row, erratum 4.1-full-x, or only its y row, 4.1-full-y), the rear
    axle's velocity, omega x r turned the wrong way, the 2.2 rate read literally (2.2-rate).
    """
    cases = _motion_cases(seed, n, with_dt=False)
    name = _name(fn, "my_laser_velocity")
    mistakes = [m.renamed("{name}", name) for m in _RATE_MISTAKES]
    return check_function(_copying_prefetched(fn), _rate_ref, cases, name=name,
                          arg_names=_RATE_ARGS, labels=_RATE_LABELS, mistakes=mistakes,
                          what="motion.laser_velocity", quiet=quiet)


# ------------------------------------------------------------------ 02, exercise 2.2

_J_ROWS = ("x_l", "y_l", "phi_l")
_J_COLS = ("x_c", "y_c", "phi")


def _jac_ref(pose, a, b):
    return kinematics.laser_pose(pose, _car(ACFR_UTE.L, a, b))[1]


def _with_column(pose, a, b, col):
    J = np.eye(3)
    J[:2, 2] = col(pose[2], a, b)
    return J


_JAC_MISTAKES = (
    Mistake("{name}: the heading column has the wrong sign in both rows; that is the Jacobian "
            "of the inverse transform (motion.axle_pose, which subtracts the lever arm).",
            lambda p, a, b: _with_column(p, a, b, lambda f, a, b: (a * np.sin(f) + b * np.cos(f),
                                                                  -a * np.cos(f) + b * np.sin(f))),
            answer="d x_l / d phi = d/dphi (a cos(phi) - b sin(phi))."),
    Mistake("{name}: the diagonal is missing: the laser's position moves one for one with the "
            "axle's, and its heading is the car's.",
            lambda p, a, b: _jac_ref(p, a, b) - np.eye(3),
            answer="d x_l / d x_c = 1, and likewise for y and phi: J = I plus the heading column."),
    Mistake("{name} differentiates the paper's vector form read literally, with the b offset "
            "along the heading (section 4.1, erratum 4.1-Pl-vector): b points to the car's left.",
            lambda p, a, b: _with_column(p, a, b, lambda f, a, b: (-(a + b) * np.sin(f),
                                                                  (a + b) * np.cos(f))),
            answer="The b entries of the heading column are -b cos(phi) and -b sin(phi)."),
)


@forbids(kinematics.laser_pose)
def check_laser_pose_jacobian(fn: Callable, *, seed: int = 0, n: int = 30,
                              quiet: bool = False) -> str:
    """Grade ``fn(axle_pose, a, b) -> J`` (3 x 3), the Jacobian of the laser pose with respect
    to the axle pose (x_c, y_c, phi) (notebook 02 "The Jacobian of the transform"; reference
    ``motion.laser_pose``, checked against SymPy and finite differences).

    Cases as in :func:`check_axle_pose`. A wrong entry is named ('d y_l / d phi (entry
    [1, 2])') with sign errors and transposes flagged. Known mistakes: the inverse's Jacobian,
    no identity, the literal vector form (erratum 4.1-Pl-vector).
    """
    cases = _pose_cases(seed, n)
    name = _name(fn, "my_laser_pose_jacobian")
    mistakes = [m.renamed("{name}", name) for m in _JAC_MISTAKES]
    return check_jacobian(_copying_prefetched(fn), _jac_ref, cases, name=name, rows=_J_ROWS,
                          cols=_J_COLS, arg_names=_POSE_ARGS, mistakes=mistakes,
                          what="the Jacobian of motion.laser_pose", quiet=quiet)
