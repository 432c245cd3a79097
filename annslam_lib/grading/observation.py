"""Checks for the graded exercises of notebook 03 (the observation model).

Each check compares the student's function with the library's reference (already tested
against SymPy and finite differences) on seeded random inputs plus edge cases that catch
real mistakes: landmarks behind the laser (x_i < x_L, where the paper's single-argument
arctan is off by pi), directly left/right in world x (dx = 0), headings near +-pi, bearings
that need wrapping. Known wrong answers, among them the paper's printed equations
(:mod:`annslam_lib.paper`), fail with a message naming the section, what the print gets
wrong and what is right.
"""
from __future__ import annotations

import math

import numpy as np

from .. import paper
from ..models.observation import inverse_observe, landmark_from_two_points, observe
from .core import forbids, Mistake, call, check_function, check_jacobian, describe, fail

__all__ = ["check_observe", "check_observation_jacobian", "check_inverse_observe",
           "check_two_point_frame", "BEARING_HINT"]

#: Explains a +-90 degree bearing offset: the laser's (ACFR) convention.
BEARING_HINT = ("The laser counts bearings from the vehicle's RIGHT (the ACFR convention): "
                "0 = right, π/2 = straight ahead, π = left; atan2(dy, dx) − φ is the angle "
                "from straight ahead.")

_POSE_LM = ("pose", "landmark")


def _quiet(f):
    """A wrong form evaluated without NumPy's divide-by-zero warnings (dx = 0 cases)."""
    def wrapped(*args):
        with np.errstate(divide="ignore", invalid="ignore"):
            return f(*args)
    return wrapped


# ----------------------------------------------------------------------------- cases

def _pose_landmark_cases(seed: int, n: int, *, avoid_seam: bool) -> list[tuple]:
    """Edge cases, then ``n`` seeded random (pose, landmark) pairs 0.5-60 m apart.

    Edge cases: headings 0, +-pi/2, near +-pi and pi; landmarks ahead, right, behind and
    left-behind of the laser (the last two need the bearing wrapped); landmarks straight
    above and below the laser in world x (dx = 0)."""
    cases = []
    for phi in (0.0, math.pi / 2, -math.pi / 2, math.pi - 1e-3, -math.pi + 1e-3, math.pi):
        for rel, dist in ((0.0, 5.0), (-math.pi / 2, 3.0), (2.5, 8.0), (-2.5, 12.0),
                          (math.pi / 2 - 0.3, 4.0), (math.pi / 2 + 0.3, 20.0)):
            a = phi + rel
            cases.append((np.array([2.0, -1.0, phi]),
                          np.array([2.0 + dist * math.cos(a), -1.0 + dist * math.sin(a)])))
    cases += [(np.array([3.0, 1.0, 0.4]), np.array([3.0, 6.0])),      # dx = 0, landmark north
              (np.array([3.0, 1.0, 0.4]), np.array([3.0, -4.0])),     # dx = 0, landmark south
              (np.array([-7.5, 2.0, -2.9]), np.array([-7.5, 30.0]))]
    rng = np.random.default_rng(seed)
    while len(cases) < 39 + n:
        pose = np.r_[rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)]
        a, r = rng.uniform(-np.pi, np.pi), rng.uniform(0.5, 60)
        cases.append((pose, pose[:2] + r * np.array([math.cos(a), math.sin(a)])))
    if avoid_seam:   # a bearing within 1e-3 of +-pi: a correct wrap may land on either side
        cases = [c for c in cases if abs(observe(*c)[0][1]) < math.pi - 1e-3]
    return cases


# ----------------------------------------------------------------------------- 3.1 observe

_PRINTED_BEARING = (
    "{name} computes the bearing as the paper prints it (sections 4.1 and 4.2): "
    "atan((y_L − y_i)/(x_L − x_i)) − θ + π/2. Single-argument arctan of a ratio cannot tell "
    "(dx, dy) from (−dx, −dy), so the bearing is off by π for every landmark with "
    "x_i < x_L (e.g. at {where}: expected {exp:.4g}, got {got:.4g}). Use an arctangent that "
    "keeps the quadrant (erratum 4.1-bearing).")
_PRINTED_BEARING_ANSWER = "The bearing is np.arctan2(y_i − y, x_i − x) − φ + π/2, wrapped."


def _printed_message(name: str, cases) -> str:
    for pose, lm in cases:
        if lm[0] < pose[0]:
            exp = observe(pose, lm)[0][1]
            got = _quiet(paper.observation_printed)(pose, lm)[1]
            return _PRINTED_BEARING.format(name=name, where=describe((pose, lm), _POSE_LM),
                                           exp=exp, got=got)
    return _PRINTED_BEARING.format(name=name, where="?", exp=math.nan, got=math.nan)


def _bearing_variant(f):
    """(range, bearing) with the bearing computed by f(dx, dy, phi) (a wrong variant)."""
    def wrong(pose, lm):
        dx, dy = lm[0] - pose[0], lm[1] - pose[1]
        return np.array([math.hypot(dx, dy), f(dx, dy, pose[2])])
    return _quiet(wrong)


@forbids(observe)
def check_observe(fn, *, seed: int = 0, n: int = 60, name: str = "my_observe",
                  quiet: bool = False) -> str:
    """Grade ``fn(pose, landmark) -> (range, bearing)``, the observation model h of notebook
    03 section 1 (the paper's 4.1/4.2 observation, corrected): range
    sqrt(dx^2 + dy^2) and bearing atan2(dy, dx) − phi + pi/2 wrapped to (−pi, pi], with
    (dx, dy) = landmark − laser position. Reference: ``observation.observe``.

    Catches the paper's printed atan bearing, a missing +pi/2 (the ACFR convention), an
    unwrapped bearing, −pi/2 or a reversed direction, +phi, swapped atan2 arguments,
    degrees, swapped outputs.
    """
    cases = _pose_landmark_cases(seed, n, avoid_seam=True)
    printed = _printed_message(name, cases)
    mistakes = [
        Mistake(printed, _quiet(paper.observation_printed), answer=_PRINTED_BEARING_ANSWER),
        # the same with the differences the other way round: equal to the print except
        # where dx = 0 exactly (the sign of the zero picks +-pi/2)
        Mistake(printed, _bearing_variant(lambda dx, dy, phi: np.arctan(dy / dx) - phi
                                          + np.pi / 2), answer=_PRINTED_BEARING_ANSWER),
        Mistake(f"{name} uses single-argument arctan of dy/dx (the paper's form, which loses "
                "the quadrant: off by π when x_i < x_L) AND leaves out the laser's bearing "
                "convention. " + BEARING_HINT,
                _bearing_variant(lambda dx, dy, phi: np.arctan(dy / dx) - phi),
                answer=_PRINTED_BEARING_ANSWER),
        Mistake(f"{name}'s bearing is off by 180° at every input: either it gets the laser's "
                "convention backwards (0 = right, π/2 = ahead) or it takes the direction from "
                "the landmark to the laser (the paper's Δ = x − x_i). The bearing points from "
                "the laser to the landmark.",
                _bearing_variant(lambda dx, dy, phi: np.arctan2(dy, dx) - phi - np.pi / 2),
                answer="atan2(y_i − y, x_i − x) − φ + π/2."),
        Mistake(f"{name} adds the heading: the bearing is measured in the laser's frame, so "
                "turning the laser left by δφ moves every bearing by −δφ.",
                _bearing_variant(lambda dx, dy, phi: np.arctan2(dy, dx) + phi + np.pi / 2),
                answer="atan2(dy, dx) − φ + π/2, not + φ."),
        Mistake(f"{name} swaps the arguments of np.arctan2: it takes (y, x).",
                _bearing_variant(lambda dx, dy, phi: np.arctan2(dx, dy) - phi + np.pi / 2),
                answer="np.arctan2(dy, dx), not np.arctan2(dx, dy)."),
    ]
    return check_function(fn, lambda p, m: observe(p, m)[0], cases, name=name,
                          arg_names=_POSE_LM, labels=("range", "bearing"), angles=[1],
                          mistakes=mistakes, angle_hint=BEARING_HINT, what="observation.observe",
                          quiet=quiet)


# ----------------------------------------------------------------------------- 3.2 Jacobian

_COLS = ("x", "y", "phi", "x_i", "y_i")


def _reference_jacobian(pose, lm):
    _, Hp, Hm = observe(pose, lm)
    return np.concatenate([Hp, Hm], axis=1)


def _printed_jacobian_message(name: str, alignment: int) -> str:
    where = "x_i" if alignment == 0 else "y_i"
    wrong = ("d range / d x_i, d range / d y_i" if alignment == 0 else "d range / d x_i")
    return (f"{name} is the Jacobian printed in the paper's section 4.2, reading its lone "
            f"−Δy/Δ of the range row in the {where} column (Δx = x − x_i, Δy = y − y_i, "
            f"Δ = range). Its vehicle columns and d bearing / d x_i are right, but these "
            f"landmark entries are misprinted: {wrong} and d bearing / d y_i (a repeat of the "
            f"x_i entry). The measurement depends on the landmark only through m − t: compare "
            f"the landmark columns with the vehicle's x and y columns (errata 4.2-jac-range, "
            f"4.2-jac-bearing).")


def _printed_jacobian_answer(alignment: int) -> str:
    wrong = ("d range / d x_i must be −Δx/Δ (printed −Δy/Δ), d range / d y_i must be −Δy/Δ "
             "(printed 0)" if alignment == 0 else "d range / d x_i must be −Δx/Δ (printed 0)")
    return (f"{wrong}, and d bearing / d y_i must be −Δx/Δ² (printed Δy/Δ²): "
            f"H_m = −H_pose[:, :2].")


def _jacobian_variant(change):
    def wrong(pose, lm):
        H = _reference_jacobian(pose, lm)
        change(H)
        return H
    return wrong


def _flip_positions(H):
    H[:, [0, 1, 3, 4]] *= -1


def _copy_pose_block(H):
    H[:, 3:] = H[:, :2]


def _printed_bearing_yi(H):
    H[1, 4] = H[1, 3]            # the print repeats d bearing / d x_i


@forbids(observe)
def check_observation_jacobian(fn, *, seed: int = 0, n: int = 60,
                               name: str = "my_observation_jacobian", quiet: bool = False) -> str:
    """Grade ``fn(pose, landmark) -> H`` (2 x 5), the Jacobian of (range, bearing) with
    respect to (x, y, phi, x_i, y_i) derived in notebook 03 section 1 (the paper's 4.2
    dh/dX, corrected). Reference: ``observation.observe``'s [H_pose, H_landmark].

    Catches both readings of the paper's printed Jacobian, its misprinted bearing y_i entry
    alone, offsets taken the wrong way round, landmark columns copied from the vehicle's,
    a transposed (5 x 2) matrix; entry-wise sign errors and entries left at zero come from
    the generic diagnosis.
    """
    cases = _pose_landmark_cases(seed, n, avoid_seam=False)
    try:
        shape = np.shape(np.asarray(call(fn, cases[0], name=name, arg_names=_POSE_LM),
                                    dtype=float))
    except (TypeError, ValueError):
        shape = None                   # malformed: check_jacobian says what it got
    if shape == (5, 2):
        fail(f"{name} returns a 5 x 2 matrix, the transpose of H: rows are the outputs "
             f"(range, bearing), columns the variables (x, y, phi, x_i, y_i).")
    mistakes = [
        Mistake(_printed_jacobian_message(name, 0),
                lambda p, m: paper.observation_jacobian_printed(p, m, alignment=0),
                answer=_printed_jacobian_answer(0)),
        Mistake(_printed_jacobian_message(name, 1),
                lambda p, m: paper.observation_jacobian_printed(p, m, alignment=1),
                answer=_printed_jacobian_answer(1)),
        Mistake(f"d bearing / d y_i (entry [1, 4]) of {name} is the paper's misprint "
                "(section 4.2 repeats the x_i entry; erratum 4.2-jac-bearing). Everything else "
                "is right.", _jacobian_variant(_printed_bearing_yi),
                answer="It must be −Δx/Δ² with Δx = x − x_i, i.e. (x_i − x)/r²."),
        Mistake(f"every position entry of {name} (columns x, y, x_i, y_i) has the wrong "
                "sign; only d bearing / d phi is right. The offsets are taken the wrong "
                "way round: which point do you subtract from which? (The paper's "
                "Δx = x − x_i is the opposite of landmark minus laser.)",
                _jacobian_variant(_flip_positions),
                answer="With d = (x_i − x, y_i − y) (landmark minus laser), "
                       "d range / d x = −d_x/r and d range / d x_i = +d_x/r."),
        Mistake(f"the landmark columns of {name} repeat the vehicle's x and y columns. The "
                "measurement depends on the landmark only through m − t: how does moving the "
                "landmark compare with moving the laser?", _jacobian_variant(_copy_pose_block),
                answer="They are their NEGATIVES: H_m = −H_pose[:, :2]."),
    ]
    return check_jacobian(fn, _reference_jacobian, cases, name=name, rows=("range", "bearing"),
                          cols=_COLS, arg_names=_POSE_LM, mistakes=mistakes,
                          what="the reference Jacobian [H_pose, H_landmark]", quiet=quiet)


# ----------------------------------------------------------------------------- 3.3 inverse

def _inverse_cases(seed: int, n: int) -> list[tuple]:
    """Edge cases (bearings 0, pi/2, pi, near -pi, negative; headings near +-pi; a zero
    heading), then ``n`` seeded random (pose, z) with ranges 0.5-60 m."""
    cases = []
    for phi in (0.0, 1.1, -math.pi / 2, math.pi - 1e-3, -math.pi + 1e-3):
        for beta in (0.0, math.pi / 2, math.pi, 0.4, 2.9, -math.pi + 1e-3, -1.2):
            cases.append((np.array([1.5, -2.0, phi]), np.array([7.0, beta])))
    rng = np.random.default_rng(seed)
    for _ in range(n):
        cases.append((np.r_[rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)],
                      np.array([rng.uniform(0.5, 60), rng.uniform(-np.pi, np.pi)])))
    return cases


def _inverse_variant(angle, *, trig=(np.cos, np.sin), offset=True):
    """x + r trig0(angle(phi, beta)), y + r trig1(...) (a wrong inverse model)."""
    def wrong(pose, z):
        a = angle(pose[2], z[1])
        x0, y0 = (pose[0], pose[1]) if offset else (0.0, 0.0)
        return np.array([x0 + z[0] * trig[0](a), y0 + z[0] * trig[1](a)])
    return wrong


@forbids(inverse_observe)
def check_inverse_observe(fn, *, seed: int = 0, n: int = 60,
                          name: str = "my_inverse_observe", quiet: bool = False) -> str:
    """Grade ``fn(pose, z) -> (x_i, y_i)``, the inverse observation model g of notebook 03
    section 2 (landmark initialisation): x + r cos(phi + beta − pi/2),
    y + r sin(phi + beta − pi/2). Reference: ``observation.inverse_observe``.

    Catches phi + beta without −pi/2 (the bearing convention), +pi/2, −beta, cos and sin
    swapped, the landmark left in the laser frame or relative to the laser.
    """
    cases = _inverse_cases(seed, n)
    conv = ("the bearing counts from the laser's right (β = π/2 is straight ahead): where "
            "does a landmark at β = π/2 lie for a laser heading φ?")
    direction = "The world direction of the landmark is φ + β − π/2."
    mistakes = [
        Mistake(f"{name} puts the landmark 90° counter-clockwise of where it is, around the "
                f"laser: {conv}",
                _inverse_variant(lambda phi, b: phi + b), answer=direction),
        Mistake(f"{name} puts the landmark on the opposite side of the laser (180° off): {conv}",
                _inverse_variant(lambda phi, b: phi + b + np.pi / 2), answer=direction),
        Mistake(f"{name} mirrors the bearing: the laser's bearing grows counter-clockwise like "
                f"φ (right 0, ahead π/2, left π).",
                _inverse_variant(lambda phi, b: phi - b + np.pi / 2), answer=direction),
        Mistake(f"{name} swaps cos and sin: x_i goes with the cosine of the world direction.",
                _inverse_variant(lambda phi, b: phi + b - np.pi / 2, trig=(np.sin, np.cos)),
                answer="x_i = x + r cos(φ + β − π/2), y_i = y + r sin(φ + β − π/2)."),
        Mistake(f"{name} returns the landmark relative to the laser: add the laser's world "
                "position (x, y).", _inverse_variant(lambda phi, b: phi + b - np.pi / 2,
                                                     offset=False)),
        Mistake(f"{name} leaves the landmark in the laser's frame (plus the position): it is "
                "not yet turned into the world's axes by the heading.",
                _inverse_variant(lambda phi, b: b - np.pi / 2),
                answer="Rotate the laser-frame point (r sin β, −r cos β) by φ: m = t + R(φ) p."),
    ]
    return check_function(fn, lambda p, z: inverse_observe(p, z)[0], cases, name=name,
                          arg_names=("pose", "z"), labels=("x_i", "y_i"), mistakes=mistakes,
                          what="observation.inverse_observe", quiet=quiet)


# ----------------------------------------------------------------------------- 3.4 two points

def _two_point_cases(seed: int, n: int) -> list[tuple]:
    """(p_right, p_left) pairs: x_l < x_r, x_l > x_r, vertical both ways (x_l = x_r),
    theta near +-pi (never exactly), then ``n`` seeded random pairs (half with x_l > x_r)."""
    P = np.array
    cases = [(P([5.0, 1.0]), P([2.0, 3.0])), (P([1.0, 1.0]), P([4.0, 3.0])),
             (P([3.0, 1.0]), P([3.0, 4.0])), (P([3.0, 4.0]), P([3.0, 1.0])),
             (P([1.0, 2.001]), P([6.0, 2.0])), (P([1.0, 1.999]), P([6.0, 2.0])),
             (P([8.0, -3.0]), P([8.0, 5.0])), (P([2.0, -0.5]), P([-1.0, -6.0]))]
    rng = np.random.default_rng(seed)
    for _ in range(n):
        pr, pl = rng.uniform(-10, 10, 2), rng.uniform(-10, 10, 2)
        if np.hypot(*(pr - pl)) > 0.05:
            cases.append((pr, pl))
    return [c for c in cases
            if abs(landmark_from_two_points(*c)[0][2]) < math.pi - 1e-4]


def _frame_variant(theta_of, ij_of=None):
    """(i, j, theta) with theta = theta_of(pr, pl) and (i, j) from ij_of(pr, pl, theta)
    (default: the corrected -R(theta)^T p_l)."""
    def wrong(pr, pl):
        with np.errstate(divide="ignore", invalid="ignore"):
            th = float(theta_of(pr, pl))
        c, s = math.cos(th), math.sin(th)
        ij = (-(pl[0] * c + pl[1] * s), pl[0] * s - pl[1] * c) if ij_of is None \
            else ij_of(pr, pl, th)
        return np.array([ij[0], ij[1], th])
    return wrong


def _theta_right(pr, pl):
    return math.atan2(pr[1] - pl[1], pr[0] - pl[0])


def _theta_printed_fixed(pr, pl):
    """The printed cases with the third condition read as x_l > x_r; vertical -pi/2."""
    dx, dy = pr[0] - pl[0], pr[1] - pl[1]
    if dx == 0:
        return -math.pi / 2
    return math.atan(dy / dx) - (math.pi if dx < 0 else 0.0)


@forbids(landmark_from_two_points)
def check_two_point_frame(fn, *, seed: int = 0, n: int = 60,
                          name: str = "my_two_point_frame", quiet: bool = False) -> str:
    """Grade ``fn(p_right, p_left) -> (i, j, theta)``, the landmark frame of two laser
    points (paper section 3.3, corrected; notebook 03 section 5): theta =
    atan2(y_r − y_l, x_r − x_l) in (−pi, pi] and (i, j) = −R(theta)^T (x_l, y_l), the robot
    origin seen from the landmark frame. Reference: ``observation.landmark_from_two_points``.

    Catches the paper's printed case list (no case for x_l > x_r: NaN or an exception),
    its vertical case −pi/2 when y_r > y_l, its printed (i, j) (both rows the same),
    a missing minus sign, the origin at p_right; an unwrapped theta comes from the generic
    diagnosis.
    """
    cases = _two_point_cases(seed, n)
    names = ("p_right", "p_left")
    # The printed case list leaves x_l > x_r undefined: NaN, or an exception such as an
    # unassigned theta. Say so before the generic checks (they would blame a division).
    no_case = Mistake("The paper's case list (section 3.3) has no case for x_l > x_r: its "
                      "third condition repeats the first (X_l < X_r). One function of the two "
                      "differences covers every configuration without cases (erratum "
                      "3.3-theta-case3).", None,
                      answer="θ = atan2(y_r − y_l, x_r − x_l).").text
    for pr, pl in cases:
        if pl[0] > pr[0]:
            try:
                out = fn(pr, pl)
            except NotImplementedError:
                call(fn, (pr, pl), name=name)
            except Exception as e:
                fail(f"{name}({describe((pr, pl), names)}) raised {type(e).__name__}: {e}. "
                     + no_case)
            else:
                try:
                    th = np.asarray(out, dtype=float).ravel()[-1]
                except (TypeError, ValueError, IndexError):
                    break              # a malformed output: the generic check reports it
                if not np.isfinite(th):
                    fail(f"{name}({describe((pr, pl), names)}) returned theta = {th}. "
                         + no_case)
            break
    mistakes = [
        Mistake(f"{name} returns the (i, j) printed in section 3.3: the same formula twice "
                f"(erratum 3.3-ij). The translation of ijT_r is the robot origin seen from the "
                f"landmark frame: the transform must send P_l to (0, 0).",
                _frame_variant(_theta_right, lambda pr, pl, th:
                               tuple(paper.two_point_ij_printed(pl, th))),
                answer="(i, j) = −R(θ)ᵀ (x_l, y_l): i = −(x_l cos θ + y_l sin θ), "
                       "j = x_l sin θ − y_l cos θ."),
        Mistake(f"{name} returns θ = −π/2 whenever x_l = x_r, as printed in section 3.3; that "
                f"is wrong by π when y_r > y_l (the frame's x axis points from P_l to P_r, "
                f"i.e. up) (erratum 3.3-theta-vertical).", _frame_variant(_theta_printed_fixed),
                answer="atan2(y_r − y_l, x_r − x_l) gets both vertical cases right."),
        Mistake(f"{name}'s (i, j) has the wrong sign: the landmark frame's origin P_l must map "
                f"to (0, 0).",
                _frame_variant(_theta_right, lambda pr, pl, th:
                               (pl[0] * math.cos(th) + pl[1] * math.sin(th),
                                -pl[0] * math.sin(th) + pl[1] * math.cos(th))),
                answer="(i, j) = −R(θ)ᵀ (x_l, y_l), the robot origin seen from the landmark frame."),
        Mistake(f"{name} puts the landmark frame's origin at P_r; the paper's formula (and "
                f"the course) puts it at the LEFT point P_l.",
                _frame_variant(_theta_right, lambda pr, pl, th:
                               (-(pr[0] * math.cos(th) + pr[1] * math.sin(th)),
                                pr[0] * math.sin(th) - pr[1] * math.cos(th))),
                answer="(i, j) = −R(θ)ᵀ (x_l, y_l)."),
        Mistake(f"{name}'s θ points from P_r to P_l (off by π): the landmark x axis points "
                f"from the left point to the right one.",
                _frame_variant(lambda pr, pl: math.atan2(pl[1] - pr[1], pl[0] - pr[0])),
                answer="θ = atan2(y_r − y_l, x_r − x_l)."),
    ]
    return check_function(fn, lambda pr, pl: landmark_from_two_points(pr, pl)[0], cases,
                          name=name, arg_names=names, labels=("i", "j", "theta"), angles=[2],
                          mistakes=mistakes, what="observation.landmark_from_two_points",
                          quiet=quiet)
