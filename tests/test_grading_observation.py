"""Chapter 03 graders (annslam_lib.grading.observation): right answers pass, the paper's
printed equations and typical mistakes fail with the message that names them."""
import math
import warnings

import numpy as np
import pytest

from annslam_lib import paper
from annslam_lib.grading import GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import observation as gk
from annslam_lib.models import observation
from solutions import solution
from check_support import stub, wrap


def quiet(check, fn, **kw):
    """Run a check without printing; warnings from wrong forms (dx = 0) silenced; the
    messages as the instructor's returned feedback has them (with the answer part)."""
    with warnings.catch_warnings(), full_feedback():
        warnings.simplefilter("ignore", RuntimeWarning)
        return check(fn, quiet=True, **kw)


# ----------------------------------------------------------------------- the notebook's solutions

nb_observe = solution("03", "my_observe")
nb_jacobian = solution("03", "my_observation_jacobian")
nb_inverse = solution("03", "my_inverse_observe")
nb_two_points = solution("03", "my_two_point_frame")


def lib_jacobian(pose, lm):
    return np.concatenate(observation.observe(pose, lm)[1:], axis=1)


@pytest.mark.parametrize("check, fn", [
    (gk.check_observe, lambda p, m: observation.observe(p, m)[0]),
    (gk.check_observe, nb_observe),
    (gk.check_observation_jacobian, lib_jacobian),
    (gk.check_observation_jacobian, nb_jacobian),
    (gk.check_inverse_observe, lambda p, z: observation.inverse_observe(p, z)[0]),
    (gk.check_inverse_observe, nb_inverse),
    (gk.check_two_point_frame, lambda a, b: observation.landmark_from_two_points(a, b)[0]),
    (gk.check_two_point_frame, nb_two_points),
])
@pytest.mark.parametrize("seed", [0, 7])
def test_right_answers_pass(check, fn, seed):
    msg = quiet(check, fn, seed=seed, n=100)
    assert msg.startswith("✓") and "agrees with" in msg


def test_success_message_is_printed_once(capsys):
    gk.check_observe(nb_observe)
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 1 and out[0].startswith("✓ my_observe agrees with observation.observe")


@pytest.mark.parametrize("check, name", [
    (gk.check_observe, "my_observe"), (gk.check_observation_jacobian, "my_observation_jacobian"),
    (gk.check_inverse_observe, "my_inverse_observe"), (gk.check_two_point_frame, "my_two_point_frame"),
])
def test_stub_is_not_written_yet(check, name):
    with pytest.raises(GradingError, match=f"{name} is not written yet"):
        quiet(check, stub)


# ----------------------------------------------------------------------- 3.1 observe

def bearing_variant(f, *, wrapped=True):
    def fn(pose, lm):
        dx, dy = lm[0] - pose[0], lm[1] - pose[1]
        b = f(dx, dy, pose[2])
        return math.hypot(dx, dy), wrap(b) if wrapped else b
    return fn


def test_printed_bearing_fails_naming_the_paper():
    with pytest.raises(GradingError) as e:
        quiet(gk.check_observe, paper.observation_printed)
    msg = str(e.value)
    assert "sections 4.1 and 4.2" in msg and "off by π" in msg and "x_i < x_L" in msg
    assert "arctan2" in msg and "4.1-bearing" in msg
    # the student's version of the same (differences the other way round) gets it too,
    # although it differs from the print where dx = 0 exactly
    student = bearing_variant(lambda dx, dy, phi: np.arctan(dy / dx) - phi + np.pi / 2)
    with pytest.raises(GradingError, match="as the paper prints it"):
        quiet(gk.check_observe, student)


def test_missing_half_pi_gets_the_bearing_convention():
    with pytest.raises(GradingError) as e:
        quiet(gk.check_observe, bearing_variant(lambda dx, dy, phi: np.arctan2(dy, dx) - phi))
    msg = str(e.value)
    assert "-90.0°" in msg and "RIGHT" in msg and "π/2 = straight ahead" in msg
    # without the wrap as well: still the convention (compared modulo 2 pi)
    with pytest.raises(GradingError, match="ACFR convention"):
        quiet(gk.check_observe, bearing_variant(lambda dx, dy, phi: np.arctan2(dy, dx) - phi,
                                                wrapped=False))


def test_unwrapped_bearing_gets_the_wrap_message():
    fn = bearing_variant(lambda dx, dy, phi: np.arctan2(dy, dx) - phi + np.pi / 2, wrapped=False)
    with pytest.raises(GradingError, match=r"right modulo 2π but not wrapped into \(-π, π\]"):
        quiet(gk.check_observe, fn)


@pytest.mark.parametrize("f, phrase", [
    (lambda dx, dy, phi: np.arctan2(dy, dx) - phi - np.pi / 2, "off by 180° at every input"),
    (lambda dx, dy, phi: np.arctan2(-dy, -dx) - phi + np.pi / 2, "from the landmark to the laser"),
    (lambda dx, dy, phi: np.arctan2(dy, dx) + phi + np.pi / 2, "adds the heading"),
    (lambda dx, dy, phi: np.arctan2(dx, dy) - phi + np.pi / 2, "swaps the arguments of np.arctan2"),
    (lambda dx, dy, phi: np.arctan(dy / dx) - phi, "AND leaves out the laser's bearing"),
])
def test_typical_bearing_mistakes(f, phrase):
    with pytest.raises(GradingError, match=phrase):
        quiet(gk.check_observe, bearing_variant(f))


def test_degrees_and_swapped_outputs():
    with pytest.raises(GradingError, match="in degrees"):
        quiet(gk.check_observe, lambda p, m: (nb_observe(p, m)[0], np.degrees(nb_observe(p, m)[1])))
    with pytest.raises(GradingError, match="range and bearing swapped"):
        quiet(gk.check_observe, lambda p, m: nb_observe(p, m)[::-1])


# ----------------------------------------------------------------------- 3.2 Jacobian

def test_printed_jacobian_fails_naming_the_misprinted_entries():
    with pytest.raises(GradingError) as e:
        quiet(gk.check_observation_jacobian,
              lambda p, m: paper.observation_jacobian_printed(p, m, alignment=0))
    msg = str(e.value)
    assert "section 4.2" in msg and "in the x_i column" in msg
    assert "d range / d x_i must be −Δx/Δ (printed −Δy/Δ)" in msg
    assert "d range / d y_i must be −Δy/Δ (printed 0)" in msg
    assert "d bearing / d y_i must be −Δx/Δ² (printed Δy/Δ²)" in msg
    assert "4.2-jac-range" in msg and "4.2-jac-bearing" in msg
    with pytest.raises(GradingError) as e:
        quiet(gk.check_observation_jacobian,
              lambda p, m: paper.observation_jacobian_printed(p, m, alignment=1))
    msg = str(e.value)
    assert "in the y_i column" in msg and "d range / d x_i must be −Δx/Δ (printed 0)" in msg
    assert "d range / d y_i" not in msg          # right in this reading
    assert "d bearing / d y_i must be −Δx/Δ² (printed Δy/Δ²)" in msg


def test_printed_jacobian_entries_are_really_the_wrong_ones():
    """The message's claims, independently: with alignment 1 only [0, 3] and [1, 4] differ
    from the library; with alignment 0 also [0, 4]."""
    rng = np.random.default_rng(1)
    pose = np.r_[rng.uniform(-9, 9, 2), rng.uniform(-3, 3)]
    lm = pose[:2] + rng.uniform(2, 9, 2)
    ref = lib_jacobian(pose, lm)
    for a, wrong in ((0, {(0, 3), (0, 4), (1, 4)}), (1, {(0, 3), (1, 4)})):
        diff = np.abs(paper.observation_jacobian_printed(pose, lm, alignment=a) - ref) > 1e-9
        assert {tuple(int(k) for k in ix) for ix in np.argwhere(diff)} == wrong


def jac_variant(change):
    def fn(p, m):
        H = nb_jacobian(p, m)
        change(H)
        return H
    return fn


def test_typical_jacobian_mistakes():
    def only_bearing_yi(H):
        H[1, 4] = H[1, 3]

    def flip_positions(H):
        H[:, [0, 1, 3, 4]] *= -1

    def copy_block(H):
        H[:, 3:] = H[:, :2]

    def phi_sign(H):
        H[1, 2] = 1.0

    def zero_entry(H):
        H[0, 4] = 0.0

    cases = [(only_bearing_yi, r"entry \[1, 4\]\) of my_observation_jacobian is the paper's misprint"),
             (flip_positions, "every position entry .* has the wrong sign"),
             (copy_block, "NEGATIVES"),
             (phi_sign, r"d bearing / d phi \(entry \[1, 2\]\) has the wrong sign"),
             (zero_entry, r"d range / d y_i \(entry \[0, 4\]\): expected .* <- left at zero")]
    for change, phrase in cases:
        with pytest.raises(GradingError, match=phrase):
            quiet(gk.check_observation_jacobian, jac_variant(change))
    with pytest.raises(GradingError, match="5 x 2 matrix, the transpose"):
        quiet(gk.check_observation_jacobian, lambda p, m: nb_jacobian(p, m).T)
    with pytest.raises(GradingError, match=r"returned shape \(2, 3\)"):
        quiet(gk.check_observation_jacobian, lambda p, m: nb_jacobian(p, m)[:, :3])


# ----------------------------------------------------------------------- 3.3 inverse

def inverse_variant(angle, trig=(np.cos, np.sin), offset=True):
    def fn(p, z):
        a = angle(p[2], z[1])
        x0, y0 = (p[0], p[1]) if offset else (0.0, 0.0)
        return x0 + z[0] * trig[0](a), y0 + z[0] * trig[1](a)
    return fn


@pytest.mark.parametrize("fn, phrase", [
    (inverse_variant(lambda ph, b: ph + b), "90° counter-clockwise"),
    (inverse_variant(lambda ph, b: ph + b + np.pi / 2), "opposite side of the laser"),
    (inverse_variant(lambda ph, b: ph - b + np.pi / 2), "mirrors the bearing"),
    (inverse_variant(lambda ph, b: ph + b - np.pi / 2, (np.sin, np.cos)), "swaps cos and sin"),
    (inverse_variant(lambda ph, b: ph + b - np.pi / 2, offset=False), "relative to the laser"),
    (inverse_variant(lambda ph, b: b - np.pi / 2), "not yet turned into the world's axes"),
])
def test_inverse_mistakes(fn, phrase):
    with pytest.raises(GradingError, match=phrase):
        quiet(gk.check_inverse_observe, fn)


def test_inverse_mistake_messages_name_the_convention():
    with pytest.raises(GradingError) as e:
        quiet(gk.check_inverse_observe, inverse_variant(lambda ph, b: ph + b))
    assert "φ + β − π/2" in str(e.value) and "right" in str(e.value)


# ----------------------------------------------------------------------- 3.4 two points

def frame_from(theta_fn, ij_fn=None):
    def fn(pr, pl):
        th = theta_fn(pr, pl)
        c, s = math.cos(th), math.sin(th)
        i, j = (-(pl[0] * c + pl[1] * s), pl[0] * s - pl[1] * c) if ij_fn is None \
            else ij_fn(pl, th)
        return i, j, th
    return fn


def test_printed_two_point_forms_fail_naming_section_3_3():
    def printed_nan(pr, pl):               # the print evaluated with NumPy: NaN for x_l > x_r
        th = float(paper.two_point_theta_printed(pr, pl))
        return nb_two_points(pr, pl)[:2].tolist() + [th]

    with pytest.raises(GradingError) as e:
        quiet(gk.check_two_point_frame, printed_nan)
    assert "returned theta = nan" in str(e.value) and "no case for x_l > x_r" in str(e.value)
    assert "3.3-theta-case3" in str(e.value)

    def printed_ifs(pr, pl):               # the same cases written with if/elif
        dx, dy = pr[0] - pl[0], pr[1] - pl[1]
        if pl[0] < pr[0]:
            th = math.atan(dy / dx)
        elif pl[0] == pr[0]:
            th = -math.pi / 2
        elif pl[0] < pr[0]:
            th = math.atan(dy / dx) - math.pi
        return th, th, th                  # th is unbound when no case applies

    with pytest.raises(GradingError, match="raised UnboundLocalError.*no case for x_l > x_r"):
        quiet(gk.check_two_point_frame, printed_ifs)

    def theta_fixed(pr, pl):               # third condition fixed, vertical case as printed
        dx, dy = pr[0] - pl[0], pr[1] - pl[1]
        return -math.pi / 2 if dx == 0 else math.atan(dy / dx) - (math.pi if dx < 0 else 0)

    with pytest.raises(GradingError, match="θ = −π/2 whenever x_l = x_r.*3.3-theta-vertical"):
        quiet(gk.check_two_point_frame, frame_from(theta_fixed))

    right_theta = lambda pr, pl: math.atan2(pr[1] - pl[1], pr[0] - pl[0])  # noqa: E731
    printed_ij = lambda pl, th: tuple(paper.two_point_ij_printed(pl, th))  # noqa: E731
    with pytest.raises(GradingError, match="the same formula twice.*3.3-ij"):
        quiet(gk.check_two_point_frame, frame_from(right_theta, printed_ij))


def test_two_point_mistakes():
    right_theta = lambda pr, pl: math.atan2(pr[1] - pl[1], pr[0] - pl[0])  # noqa: E731
    no_minus = lambda pl, th: (pl[0] * math.cos(th) + pl[1] * math.sin(th),  # noqa: E731
                               -pl[0] * math.sin(th) + pl[1] * math.cos(th))
    with pytest.raises(GradingError, match=r"\(i, j\) has the wrong sign"):
        quiet(gk.check_two_point_frame, frame_from(right_theta, no_minus))
    reversed_theta = lambda pr, pl: math.atan2(pl[1] - pr[1], pl[0] - pr[0])  # noqa: E731
    with pytest.raises(GradingError, match="points from P_r to P_l"):
        quiet(gk.check_two_point_frame, frame_from(reversed_theta))

    def unwrapped(pr, pl):                 # the cases right, but arctan - pi left unwrapped
        dx, dy = pr[0] - pl[0], pr[1] - pl[1]
        if dx == 0:
            return math.copysign(math.pi / 2, dy)
        return math.atan(dy / dx) - (math.pi if dx < 0 else 0)

    with pytest.raises(GradingError, match="'theta' is right modulo 2π but not wrapped"):
        quiet(gk.check_two_point_frame, frame_from(unwrapped))

