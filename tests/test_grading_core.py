"""The generic grading machinery: each recognisable mistake gets its own message."""
import numpy as np
import pytest


from annslam_lib.grading import (NOT_WRITTEN, GradingError, Mistake, check_function,
                                 check_jacobian, check_raises, fmt)
from annslam_lib.models import observation

RNG = np.random.default_rng(0)
CASES = [(RNG.uniform(-10, 10, 3) * [1, 1, 0.3], RNG.uniform(-20, 20, 2)) for _ in range(40)]
HINT = "ACFR bearings run from the laser's right (0) to its left (pi)."


def z_ref(p, m):
    return observation.observe(p, m)[0]


def h_ref(p, m):
    return np.concatenate(observation.observe(p, m)[1:], axis=1)


def obs(fn, **kw):
    return check_function(fn, z_ref, CASES, name="my_observe", arg_names=("pose", "landmark"),
                          labels=("range", "bearing"), angles=[1], angle_hint=HINT, **kw)


def jac(fn, **kw):
    return check_jacobian(fn, h_ref, CASES, name="my_H", arg_names=("pose", "landmark"),
                          rows=("range", "bearing"), cols=("x", "y", "phi", "x_i", "y_i"), **kw)


def _polar(p, m, offset=0.0, arctan=np.arctan2, wrap=True):
    d = np.asarray(m) - p[:2]
    b = arctan(d[1], d[0]) if arctan is np.arctan2 else np.arctan(d[1] / d[0])
    b = b - p[2] + offset
    return np.array([np.hypot(*d), (b + np.pi) % (2 * np.pi) - np.pi if wrap else b])


def test_the_reference_passes_and_the_message_is_printed(capsys):
    assert obs(z_ref) == "✓ my_observe agrees with the reference on 40 inputs."
    assert capsys.readouterr().out == "✓ my_observe agrees with the reference on 40 inputs.\n"
    assert jac(h_ref, quiet=True).startswith("✓ my_H agrees")
    assert obs(lambda p, m: _polar(p, m, np.pi / 2), quiet=True)


@pytest.mark.parametrize("fn, phrase", [
    (lambda p, m: _polar(p, m), r"'bearing' is off by a constant -90.0° at every input.*ACFR"),
    (lambda p, m: _polar(p, m, -np.pi / 2), r"off by a constant 180° at every.*direction is reversed"),
    (lambda p, m: _polar(p, m, np.pi / 2, arctan=np.arctan), r"off by 180° at some inputs.*arctan2"),
    (lambda p, m: _polar(p, m, np.pi / 2, wrap=False) + [0, 2 * np.pi],
     r"right modulo 2π but not wrapped into \(-π, π\]"),
    (lambda p, m: np.degrees(_polar(p, m, np.pi / 2)) * [np.radians(1), 1], "in degrees"),
    (lambda p, m: _polar(p, m, np.pi / 2)[::-1], "returns range and bearing swapped"),
    (lambda p, m: -_polar(p, m, np.pi / 2), "every output of my_observe has the wrong sign"),
    (lambda p, m: _polar(p, m, np.pi / 2) * [0.5, 1], r"'range' is off by a constant factor 0.5"),
    (lambda p, m: _polar(p, m, np.pi / 2) * [-1, 1], "'range' has the wrong sign at every input"),
    (lambda p, m: None, "returned None .*forget `return`"),
    (lambda p, m: np.zeros(3), r"returned shape \(3,\) .*expected shape \(2,\)"),
    (lambda p, m: "range", "returned str"),
    (lambda p, m: 1 / 0, r"my_observe\(pose=\(.*\), landmark=\(.*\)\) raised ZeroDivisionError"),
])
def test_each_recognisable_mistake_gets_its_message(fn, phrase):
    with pytest.raises(GradingError, match=phrase):
        obs(fn)


def test_not_written_yet_names_the_stub():
    def stub(p, m):
        raise NotImplementedError()
    with pytest.raises(GradingError, match=f"my_observe {NOT_WRITTEN}.*raise NotImplementedError"):
        obs(stub)


def test_nan_from_arctan_of_a_vertical_line_points_to_arctan2():
    cases = [(np.array([0.0, 0.0, 0.0]), np.array([0.0, 5.0]))]

    def atan(p, m):
        d = m - p[:2]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.array([np.hypot(*d), np.arctan(d[1] / d[0]) * np.nan])
    with pytest.raises(GradingError, match=r"returned nan for 'bearing'.*np.arctan2"):
        check_function(atan, z_ref, cases, name="my_observe", labels=("range", "bearing"),
                       angles=[1], arg_names=("pose", "landmark"))


def test_a_known_mistake_wins_over_the_generic_diff():
    wrong = Mistake("you computed the distance squared", lambda p, m: z_ref(p, m) * [0, 1]
                    + [np.sum((m - p[:2]) ** 2), 0])
    with pytest.raises(GradingError, match="^you computed the distance squared$"):
        obs(wrong.wrong, mistakes=[wrong])


def test_jacobian_messages_name_the_entry_and_flag_sign_zero_and_transpose():
    def one_sign(p, m):
        J = h_ref(p, m)
        J[1, 2] *= -1
        return J
    with pytest.raises(GradingError, match=r"d bearing / d phi \(entry \[1, 2\]\) has the wrong "
                                           r"sign at every input .*expected -1, got 1"):
        jac(one_sign)

    def two_entries(p, m):
        J = h_ref(p, m)
        J[0, 3], J[1, 4] = 0.0, 2 * J[1, 4]
        return J
    with pytest.raises(GradingError) as e:
        jac(two_entries)
    msg = str(e.value)
    assert "my_H disagrees with the reference at 40 of 40 inputs" in msg
    assert "d range / d x_i (entry [0, 3])" in msg and "<- left at zero" in msg
    assert "wrong at every failing input: d range / d x_i (entry [0, 3]), d bearing / d y_i" in msg
    assert "d bearing / d y_i (entry [1, 4]) is off by a constant factor 2 at every input" in msg

    sq = [(np.eye(2) * k + [[0, 1], [0, 0]],) for k in (1.0, 2.0)]
    with pytest.raises(GradingError, match="returns the transpose"):
        check_jacobian(lambda A: A.T, lambda A: A, sq, name="my_J", rows=("a", "b"), cols=("u", "v"))


def test_check_raises_demands_a_clear_error():
    def silent(S):
        return np.linalg.pinv(S)
    with pytest.raises(GradingError, match=r"returned \[.*\]; it should raise ValueError because "
                                           r"S is singular"):
        check_raises(silent, (np.zeros((2, 2)),), name="my_inv", why="S is singular",
                     arg_names=("S",))
    with pytest.raises(GradingError, match="raised ZeroDivisionError: division by zero; expected "
                                           "ValueError because S is singular"):
        check_raises(lambda S: 1 / 0, (np.zeros((2, 2)),), name="my_inv", why="S is singular")
    check_raises(lambda S: (_ for _ in ()).throw(ValueError("singular S")), (np.zeros((2, 2)),),
                 name="my_inv", why="S is singular")


def test_fmt_is_compact_and_deterministic():
    assert fmt(np.array([1.0, -2.5e-7, 0.0])) == "(1, -2.5e-07, 0)"
    assert fmt(np.eye(2)) == "[(1, 0), (0, 1)]"
    assert fmt(3.14159265) == "3.142" and fmt(None) == "None" and fmt(True) == "True"
    assert fmt(-2 * np.eye(23)) == "<23x23 array, max |entry| 2>"
    assert fmt((np.ones(2), np.eye(2))) == "((1, 1), [(1, 0), (0, 1)])"


def test_a_wrong_return_structure_is_a_grading_error_not_a_crash():
    with pytest.raises(GradingError, match=r"returned NoneType None .*number and order of the values"):
        check_function(lambda p, m: None, observation.observe, CASES, name="my_observe",
                       angles=[1], output=lambda out: out[0])
    with pytest.raises(GradingError, match=r"returned tuple \(\(1, 2\), \[\(1, 0\), \(0, 1\)\]\)"):
        check_jacobian(lambda p, m: (np.array([1.0, 2.0]), np.eye(2)), observation.observe,
                       CASES, name="my_observe", rows=("range", "bearing"),
                       cols=("x_i", "y_i"), output=lambda out: out[2])


def test_a_passed_check_is_not_displayed_twice_in_a_notebook():
    msg = obs(z_ref, quiet=True)
    assert isinstance(msg, str) and msg._ipython_display_() is None
