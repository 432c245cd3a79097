"""Graded exercises of chapters 01 and 02 (annslam_lib.grading.kinematics): the reference and
the notebooks' solutions pass; the paper's printed equations and the usual slips fail with a
message that names the erratum, the entry or the slip; the unwritten stub says so."""
import re

import numpy as np
import pytest

from annslam_lib import paper
from annslam_lib.grading import NOT_WRITTEN, GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import kinematics as gk
from annslam_lib.models.vehicle import Vehicle
from annslam_lib.models import motion
from solutions import solution


def car(L=2.83, a=3.78, b=0.5, H=0.76):
    return Vehicle(L=L, H=H, a=a, b=b)


def fails(check, fn, *phrases, **kwargs):
    """The check must fail, with every phrase (regex) in its message as the instructor's
    returned feedback has it (with the answer part); returns that message."""
    with pytest.raises(GradingError) as err, full_feedback():
        check(fn, **kwargs)
    msg = str(err.value)
    for p in phrases:
        assert re.search(p, msg), f"{p!r} not in: {msg}"
    return msg


# ---------------------------------------------------- the notebooks' own solutions

my_axle_speed = solution("01", "my_axle_speed")
my_euler_step = solution("01", "my_euler_step")
my_process_jacobians = solution("01", "my_process_jacobians")
my_axle_pose = solution("02", "my_axle_pose")
my_laser_velocity = solution("02", "my_laser_velocity")
my_laser_pose_jacobian = solution("02", "my_laser_pose_jacobian")


SOLUTIONS = [(gk.check_axle_speed, my_axle_speed), (gk.check_euler_step, my_euler_step),
             (gk.check_process_jacobians, my_process_jacobians),
             (gk.check_axle_pose, my_axle_pose), (gk.check_laser_velocity, my_laser_velocity),
             (gk.check_laser_pose_jacobian, my_laser_pose_jacobian)]


# ---------------------------------------------------- library wrapped in the student signatures

def lib_axle_speed(v_e, alpha, H, L):
    return motion.axle_speed(v_e, alpha, car(L=L, H=H))[0]


def lib_step(pose, control, dt, L, a, b):
    return motion.predict(pose, control, dt, car(L, a, b))[0]


def lib_fg(pose, control, dt, L, a, b):
    return motion.predict(pose, control, dt, car(L, a, b))[1:]


def lib_laser_pose(p, a, b):
    return motion.laser_pose(p, car(a=a, b=b))[0]


def lib_axle_pose(p, a, b):
    return motion.axle_pose(p, car(a=a, b=b))[0]


def lib_velocity(pose, control, L, a, b):
    return motion.laser_velocity(pose, control, car(L, a, b))


def lib_jac(p, a, b):
    return motion.laser_pose(p, car(a=a, b=b))[1]


LIBRARY = [(gk.check_axle_speed, lib_axle_speed), (gk.check_euler_step, lib_step),
           (gk.check_process_jacobians, lib_fg), (gk.check_axle_pose, lib_axle_pose),
           (gk.check_laser_velocity, lib_velocity), (gk.check_laser_pose_jacobian, lib_jac)]


# ---------------------------------------------------- (a) right answers pass

@pytest.mark.parametrize("check,fn", LIBRARY + SOLUTIONS,
                         ids=[f"lib-{f.__name__}" for _, f in LIBRARY] + [f.__name__ for _, f in SOLUTIONS])
def test_right_answers_pass_visible_and_hidden_cases(check, fn, capsys):
    msg = check(fn)
    assert msg.startswith("✓ ") and fn.__name__ in msg
    assert capsys.readouterr().out.strip() == msg          # the test cell's one output line
    assert check(fn, seed=7, n=200).startswith("✓ ")      # the hidden tests


def test_success_message_is_deterministic_and_counts_the_cases():
    assert gk.check_axle_speed(my_axle_speed) == \
        "✓ my_axle_speed agrees with motion.axle_speed on 45 inputs."
    assert gk.check_process_jacobians(my_process_jacobians, n=10) == \
        "✓ my_process_jacobians: F and G agree with motion.predict on 19 inputs."


def test_a_student_function_that_edits_its_input_in_place_is_graded_on_clean_inputs():
    def my_euler_step(pose, control, dt, L, a, b):
        nxt = lib_step(pose, control, dt, L, a, b)
        pose[:] = 0.0                                       # vandalises the caller's array
        return nxt
    assert gk.check_euler_step(my_euler_step).startswith("✓ ")


# ---------------------------------------------------- (b) the paper's printed forms

@pytest.mark.parametrize("inside,reading", [(False, "outside"), (True, "inside")])
def test_printed_discrete_model_fails_the_euler_step_naming_its_errata(inside, reading):
    def printed(pose, u, dt, L, a, b):
        return paper.discrete_model_printed(pose, u, dt, car(L, a, b), tan_inside=inside)
    fails(gk.check_euler_step, printed, "printed discrete model", "section 4.1",
          f"tan\\(alpha\\) read {reading}", "4.1-discrete-x", "4.1-discrete-phi",
          "INSIDE cos", r"sign of the y row's b sin\(phi\) term", "yaw rate alone",
          r"Correct step: pose \+ dt")


@pytest.mark.parametrize("inside", [False, True])
def test_jacobians_of_the_printed_discrete_model_fail(inside):
    def printed_fg(pose, u, dt, L, a, b):
        veh = car(L, a, b)
        from annslam_lib.models.geometry import numerical_jacobian
        f = lambda p, w: paper.discrete_model_printed(p, w, dt, veh, tan_inside=inside)  # noqa: E731
        return (numerical_jacobian(lambda p: f(p, u), pose, angle_outputs=[2]),
                numerical_jacobian(lambda w: f(pose, w), u, angle_outputs=[2]))
    fails(gk.check_process_jacobians, printed_fg, r"\(F\)", "PRINTED discrete model",
          "4.1-discrete")


def test_section_2_2_rate_read_literally_fails_naming_the_stray_prime():
    def step_2_2(pose, u, dt, L, a, b):
        return pose + dt * paper.rate_2_2_printed(pose, u, car(L, a, b))
    fails(gk.check_euler_step, step_2_2, "heading RATE", "2.2-rate", r"cos\(phi'\)")

    def rate_2_2(pose, u, L, a, b):
        return paper.rate_2_2_printed(pose, u, car(L, a, b))
    fails(gk.check_laser_velocity, rate_2_2, "heading RATE", "2.2-rate")


def test_the_2_2_discrete_model_is_right_for_the_axle_but_not_the_laser():
    def step_2_2(pose, u, dt, L, a, b):
        return paper.predict_2_2_printed(pose, u, dt, car(L, a, b))
    fails(gk.check_euler_step, step_2_2, "REAR AXLE", "section 2.2", "LASER pose", "lever arm")


def test_printed_full_state_fails_naming_both_rows():
    def printed(pose, u, L, a, b):
        return paper.full_state_printed(pose, u, car(L, a, b))
    msg = fails(gk.check_laser_velocity, printed, "printed 'full state'", "section 4.1",
                r"x row's lever-arm term has the wrong function of phi", "4.1-full-x",
                "y row's lever-arm term has the wrong sign", "4.1-full-y", "heading row is right")
    assert "x_dot = v cos(phi) - v/L tan(alpha) (a sin(phi) + b cos(phi))" in msg

    def euler_printed(pose, u, dt, L, a, b):
        out = pose + dt * paper.full_state_printed(pose, u, car(L, a, b))
        out[2] = (out[2] + np.pi) % (2 * np.pi) - np.pi
        return out
    fails(gk.check_euler_step, euler_printed, "printed 'full state'", "4.1-full-x", "4.1-full-y")


@pytest.mark.parametrize("row,other", [(0, 1), (1, 0)])
def test_a_single_printed_row_is_named(row, other):
    def one_row(pose, u, L, a, b):
        out = lib_velocity(pose, u, L, a, b)
        out[row] = paper.full_state_printed(pose, u, car(L, a, b))[row]
        return out
    msg = fails(gk.check_laser_velocity, one_row, f"the {'xy'[row]} row is the paper's misprint",
                f"4.1-full-{'xy'[row]}")
    assert f"4.1-full-{'xy'[other]}" not in msg


def test_printed_scalar_laser_position_solved_for_the_axle_passes():
    """The paper's scalar form is correct: the lever arm it adds, taken off again, is the
    inverse (it depends on the heading only, which the laser pose holds)."""
    def printed_scalar(laser_pose, a, b):
        lever = paper.laser_position_printed(laser_pose, car(a=a, b=b)) - laser_pose[:2]
        return np.r_[laser_pose[:2] - lever, laser_pose[2]]
    assert gk.check_axle_pose(printed_scalar, seed=3, n=100).startswith("✓ printed_scalar")


@pytest.mark.parametrize("form,how", [
    (lambda p, a, b: np.r_[p[:2] - (a + b) * np.r_[np.cos(p[2]), np.sin(p[2])], p[2]],
     "the b offset points along the heading"),
    (lambda p, a, b: np.r_[p[:2] - (a + b) * np.r_[np.cos(p[2]), np.sin(p[2])] - np.pi / 2, p[2]],
     "pi/2 added to both coordinates")])
def test_printed_vector_form_read_literally_fails(form, how):
    fails(gk.check_axle_pose, form, "VECTOR form", "4.1-Pl-vector", how, "belongs inside T",
          "scalar form printed right after it is correct", r"x_c = x_l - a cos\(phi\) \+ b sin")


def test_printed_vector_form_jacobian_fails():
    def jac(p, a, b):
        J = np.eye(3)
        J[:2, 2] = (a + b) * np.r_[-np.sin(p[2]), np.cos(p[2])]
        return J
    fails(gk.check_laser_pose_jacobian, jac, "vector form", "4.1-Pl-vector")


def test_printed_speed_translation():
    # Read as "V_c stays V_c" (its only solution in a turn is no correction at all): fails.
    fails(gk.check_axle_speed, lambda v_e, alpha, H, L: v_e, "encoder speed unchanged",
          "4.1-speed", "V_c on both sides", r"v_c = v_e / \(1 - tan\(alpha\) H/L\)")
    # Its right-hand side with the ENCODER speed as numerator is the corrected formula: passes.
    assert gk.check_axle_speed(
        lambda v_e, alpha, H, L: paper.speed_translation_printed(v_e, alpha, car(L=L, H=H))
    ).startswith("✓ ")


# ---------------------------------------------------- (c) typical mistakes

@pytest.mark.parametrize("wrong,phrase", [
    (lambda v, al, H, L: v * (1 - np.tan(al) * H / L), "v_e from v_c.*the inverse"),
    (lambda v, al, H, L: v / (1 + np.tan(al) * H / L), "sign of the H term reversed"),
    (lambda v, al, H, L: v * (1 + np.tan(al) * H / L), "first-order approximation"),
    (lambda v, al, H, L: v / (1 - np.tan(al) * L / H), "uses L/H where H/L belongs"),
    (lambda v, al, H, L: v / (1 - np.sin(al) * H / L), r"sin\(alpha\) where another function of alpha"),
    (lambda v, al, H, L: v / (1 - np.tan(np.degrees(al)) * H / L), "disagrees with the reference"),
])
def test_axle_speed_mistakes(wrong, phrase):
    fails(gk.check_axle_speed, wrong, phrase)


def test_euler_step_mistakes():
    fails(gk.check_euler_step,
          lambda p, u, dt, L, a, b: motion.predict_exact(p, u, dt, car(L, a, b)),
          "exact circular arc", "EULER step")
    fails(gk.check_euler_step, lambda p, u, dt, L, a, b: np.r_[lib_step(p, u, dt, L, a, b)[:2], p[2]],
          "leaves the heading unchanged")
    # Unwrapped heading: right modulo 2 pi, found on the edge case that crosses +pi.
    fails(gk.check_euler_step,
          lambda p, u, dt, L, a, b: p + dt * lib_velocity(p, u, L, a, b),
          "'phi_k' is right modulo 2π but not wrapped", r"pose=\(1, -2, 3.1\)", "got 3.274")
    # a and b swapped: no known pattern, so the generic report names the components.
    fails(gk.check_euler_step, lambda p, u, dt, L, a, b: lib_step(p, u, dt, L, b, a),
          "disagrees with the reference at .* of 49 inputs", "'x_k': expected")
    # Heading in degrees.
    fails(gk.check_euler_step,
          lambda p, u, dt, L, a, b: np.r_[lib_step(p, u, dt, L, a, b)[:2],
                                          np.degrees(lib_step(p, u, dt, L, a, b)[2])],
          "'phi_k' is in degrees")


@pytest.mark.parametrize("which,i,j,label", [
    (0, 0, 2, r"d x_k / d phi \(entry \[0, 2\]\)"), (0, 1, 2, r"d y_k / d phi \(entry \[1, 2\]\)"),
    (1, 0, 1, r"d x_k / d alpha \(entry \[0, 1\]\)"), (1, 1, 0, r"d y_k / d v \(entry \[1, 0\]\)"),
    (1, 2, 1, r"d phi_k / d alpha \(entry \[2, 1\]\)")])
def test_a_sign_slip_in_one_jacobian_entry_is_reported_as_that_entry(which, i, j, label):
    def slipped(*args):
        out = [m.copy() for m in my_process_jacobians(*args)]
        out[which][i, j] *= -1
        return tuple(out)
    msg = fails(gk.check_process_jacobians, slipped, label, "has the wrong sign at every input",
                "expected .*, got")
    assert f"({'FG'[which]})" in msg


def test_process_jacobian_mistakes():
    F_ref = lambda *a: lib_fg(*a)[0]  # noqa: E731
    G_ref = lambda *a: lib_fg(*a)[1]  # noqa: E731
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a) - np.eye(3), G_ref(*a)),
          r"\(F\): F has no identity", "F = I \\+ dt df/dX")
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a[:4], 0.0, 0.0), G_ref(*a)),
          r"\(F\): F is the rear axle's")
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a), G_ref(*a[:2], 1.0, *a[3:])),
          r"\(G\): G lacks the factor dt")
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a), G_ref(*a)[:, ::-1]),
          r"columns of G are in the order \(alpha, v\)")
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a), G_ref(*a[:4], 0.0, 0.0)),
          r"\(G\): G is the rear axle's")
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a).T, G_ref(*a)), "transpose")
    fails(gk.check_process_jacobians, lambda *a: (G_ref(*a), F_ref(*a)), "returns G first")
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a), G_ref(*a).T),
          r"returns G transposed, shape \(2, 3\)")
    fails(gk.check_process_jacobians, lambda *a: F_ref(*a), r"must return the tuple \(F, G\)")
    fails(gk.check_process_jacobians, lambda *a: None, r"must return the tuple \(F, G\)",
          "returned NoneType None")
    fails(gk.check_process_jacobians, lambda *a: (*lib_fg(*a), 0.0),
          r"must return the tuple \(F, G\); at pose=.* it returned tuple \(\[")
    fails(gk.check_process_jacobians, lambda *a: (F_ref(*a)[:2], G_ref(*a)),
          r"returned shape \(2, 3\) .* expected shape \(3, 3\)")


def _rot(f, a, b):
    """R(f) (a, b), written out independently of the check's own helpers."""
    return np.r_[a * np.cos(f) - b * np.sin(f), a * np.sin(f) + b * np.cos(f)]


@pytest.mark.parametrize("wrong,phrase", [
    (lambda p, a, b: np.r_[p[:2] + _rot(p[2], a, b), p[2]], "adds the lever arm.*forward transform"),
    (lambda p, a, b: lib_laser_pose(p, a, b), "adds the lever arm.*forward transform"),
    (lambda p, a, b: np.r_[p[:2] - _rot(-p[2], a, b), p[2]], r"by -phi \(the transposed rotation"),
    (lambda p, a, b: np.r_[_rot(-p[2], *p[:2]) - np.r_[a, b], p[2]],
     "rotates the laser's position itself"),
    (lambda p, a, b: lib_axle_pose(p, b, a), "swaps a and b"),
    (lambda p, a, b: lib_axle_pose(p, a, -b), "to the RIGHT"),
    (lambda p, a, b: lib_axle_pose(p, a, 0.0), "only the forward offset a"),
    (lambda p, a, b: lib_axle_pose(p, a, b)[:2], r"returned shape \(2,\)"),
    (lambda p, a, b: np.r_[lib_axle_pose(p, a, b)[:2], p[2] + np.pi / 2], r"constant \+90.0°"),
])
def test_axle_pose_mistakes(wrong, phrase):
    msg = fails(gk.check_axle_pose, wrong, phrase)
    if "shape" not in phrase and "90" not in phrase:   # a named mistake: the answer is the inverse
        assert "P_c = P_l - R(phi) (a, b)" in msg


def test_every_axle_pose_mistake_is_recognised_and_keeps_its_answer_out_of_the_message():
    """Each Mistake of the check, handed in as an answer, is named by its own message (and no
    other's): the student sees the kind of slip, the instructor also the formula."""
    for m in gk._AXLE_MISTAKES:
        def wrong(p, a, b, m=m):
            return m.wrong(p, a, b)
        wrong.__name__ = "my_axle_pose"
        with pytest.raises(GradingError) as err:
            gk.check_axle_pose(wrong, quiet=True)
        assert str(err.value) == m.message.replace("{name}", "my_axle_pose")
        assert m.answer and m.answer not in str(err.value)
        with pytest.raises(GradingError) as err, full_feedback():
            gk.check_axle_pose(wrong, quiet=True)
        assert m.answer in str(err.value)


def test_laser_pose_of_the_library_and_the_axle_pose_solution_are_inverses():
    rng = np.random.default_rng(3)
    for _ in range(20):
        p = np.r_[rng.uniform(-30, 30, 2), rng.uniform(-np.pi, np.pi)]
        a, b = rng.uniform(-2, 5), rng.uniform(-1.5, 1.5)
        np.testing.assert_allclose(my_axle_pose(lib_laser_pose(p, a, b), a, b), p, atol=1e-12)


def test_laser_velocity_mistakes():
    fails(gk.check_laser_velocity, lambda p, u, L, a, b: lib_velocity(p, u, L, 0.0, 0.0),
          "rear axle's velocity", "omega x r")
    fails(gk.check_laser_velocity,
          lambda p, u, L, a, b: 2 * lib_velocity(p, u, L, 0.0, 0.0) - lib_velocity(p, u, L, a, b),
          "turns the lever arm the wrong way")
    fails(gk.check_laser_velocity,
          lambda p, u, L, a, b: lib_velocity(p, u, L, a, b) * np.r_[1.0, 1.0, -1.0],
          "'phi_dot' has the wrong sign at every input")
    fails(gk.check_laser_velocity, lambda p, u, L, a, b: 1 / 0, "raised ZeroDivisionError",
          r"my_laser_velocity\(pose=")


@pytest.mark.parametrize("wrong,phrase", [
    (lambda p, a, b: motion.axle_pose(p, car(a=a, b=b))[1], "Jacobian of the inverse"),
    (lambda p, a, b: lib_jac(p, a, b) - np.eye(3), "the diagonal is missing"),
    (lambda p, a, b: lib_jac(p, a, b).T, "transpose"),
    (lambda p, a, b: lib_jac(p, a, b) * np.r_[1.0, 1.0, 0.0][:, None],
     r"d phi_l / d phi \(entry \[2, 2\]\): expected 1, got 0  <- left at zero"),
])
def test_laser_pose_jacobian_mistakes(wrong, phrase):
    fails(gk.check_laser_pose_jacobian, wrong, phrase)


def test_laser_pose_jacobian_sign_slip_names_the_entry():
    def slipped(p, a, b):
        J = my_laser_pose_jacobian(p, a, b)
        J[1, 2] *= -1
        return J
    fails(gk.check_laser_pose_jacobian, slipped,
          r"d y_l / d phi \(entry \[1, 2\]\) has the wrong sign at every input")


# ---------------------------------------------------- (d) the stub

@pytest.mark.parametrize("check", [c for c, _ in SOLUTIONS],
                         ids=[f.__name__ for _, f in SOLUTIONS])
def test_the_stub_is_not_written_yet(check):
    name = {gk.check_axle_speed: "my_axle_speed", gk.check_euler_step: "my_euler_step",
            gk.check_process_jacobians: "my_process_jacobians",
            gk.check_axle_pose: "my_axle_pose", gk.check_laser_velocity: "my_laser_velocity",
            gk.check_laser_pose_jacobian: "my_laser_pose_jacobian"}[check]
    ns = {}
    exec(f"def {name}(*args):\n    # YOUR CODE HERE\n    raise NotImplementedError()", ns)
    msg = fails(check, ns[name], f"^{name} {NOT_WRITTEN}", "raise NotImplementedError")
    assert "\n" not in msg


# ---------------------------------------------------- feedback without the answer

@pytest.mark.parametrize("mistakes", [gk._SPEED_MISTAKES, gk._STEP_MISTAKES, gk._F_MISTAKES,
                                      gk._G_MISTAKES, gk._AXLE_MISTAKES, gk._RATE_MISTAKES,
                                      gk._JAC_MISTAKES], ids=lambda m: f"{len(m)} mistakes")
def test_a_students_message_never_holds_its_answer(mistakes):
    for m in mistakes:
        if m.answer:
            assert m.answer not in m.message


def test_the_unchanged_encoder_speed_names_the_erratum_but_not_the_formula():
    with pytest.raises(GradingError) as err:
        gk.check_axle_speed(lambda v_e, alpha, H, L: v_e, quiet=True)
    assert "4.1-speed" in str(err.value) and "1 - tan(alpha) H/L" not in str(err.value)
    with pytest.raises(GradingError) as err, full_feedback():
        gk.check_axle_speed(lambda v_e, alpha, H, L: v_e, quiet=True)
    assert "v_c = v_e / (1 - tan(alpha) H/L)" in str(err.value)
