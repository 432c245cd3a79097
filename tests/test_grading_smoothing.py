"""Chapter 10 graders (annslam_lib.grading.smoothing): honest answers (the notebook's own and
others written with GTSAM's own Pose2 and factors, code this course did not write) pass; the
typical mistakes fail with their messages; an unwritten stub says so."""
import math

import gtsam
import numpy as np
import pytest

from annslam_lib.grading import GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import smoothing as gsm
from annslam_lib.models.observation import observe
from solutions import solution
from check_support import fails, wrap

X, L = gtsam.symbol_shorthand.X, gtsam.symbol_shorthand.L


# ----------------------------------------------------------------------------- 10.1

def between_by_gtsam(xi, xj, delta):
    f = gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(*delta),
                                 gtsam.noiseModel.Unit.Create(3))
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2(*xi))
    v.insert(X(1), gtsam.Pose2(*xj))
    return f.unwhitenedError(v)


def between_by_matrices(xi, xj, delta):
    def T(p):
        c, s = math.cos(p[2]), math.sin(p[2])
        return np.array([[c, -s, p[0]], [s, c, p[1]], [0, 0, 1.0]])
    E = np.linalg.inv(T(delta)) @ np.linalg.inv(T(xi)) @ T(xj)
    th = math.atan2(E[1, 0], E[0, 0])
    if abs(th) < 1e-12:
        return np.array([E[0, 2], E[1, 2], th])
    V = np.array([[math.sin(th), -(1 - math.cos(th))], [1 - math.cos(th), math.sin(th)]]) / th
    return np.r_[np.linalg.solve(V, E[:2, 2]), th]


@pytest.mark.parametrize("fn", [between_by_gtsam, between_by_matrices,
                                solution("10", "my_between_error")])
@pytest.mark.parametrize("seed", [0, 7])
def test_between_error_honest_answers_pass(fn, seed):
    assert gsm.check_between_error(fn, seed=seed, quiet=True).startswith("✓")


def test_between_error_mistakes_are_named():
    def world(xi, xj, d):
        e = np.asarray(xj) - np.asarray(xi) - np.asarray(d)
        e[2] = wrap(e[2])
        return e

    def no_log(xi, xj, d):
        g = gtsam.Pose2(*d).between(gtsam.Pose2(*xi).between(gtsam.Pose2(*xj)))
        return np.array([g.x(), g.y(), g.theta()])

    def reversed_pair(xi, xj, d):
        return between_by_gtsam(xj, xi, d)

    def flipped(xi, xj, d):
        return -between_by_gtsam(xi, xj, d)

    fails(gsm.check_between_error, world, "world frame")
    fails(gsm.check_between_error, no_log, "without the logarithm")
    fails(gsm.check_between_error, reversed_pair, "wrong way round")
    # -Log(A) = Log(A^-1): the sign flip is named as such
    fails(gsm.check_between_error, flipped, "sign flipped")

    def stub(xi, xj, d):
        raise NotImplementedError
    fails(gsm.check_between_error, stub, "not written yet")


# ----------------------------------------------------------------------------- 10.2

def br_by_gtsam(pose, landmark, z):
    f = gtsam.BearingRangeFactor2D(X(0), L(0), gtsam.Rot2(z[1] - math.pi / 2), z[0],
                                   gtsam.noiseModel.Unit.Create(2))
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose2(*pose))
    v.insert(L(0), gtsam.Point2(*landmark))
    return f.unwhitenedError(v)


def br_by_hand(pose, landmark, z):
    dx, dy = landmark[0] - pose[0], landmark[1] - pose[1]
    b = math.atan2(dy, dx) - pose[2] + math.pi / 2
    return np.array([wrap(b - z[1]), math.hypot(dx, dy) - z[0]])


@pytest.mark.parametrize("fn", [br_by_gtsam, br_by_hand, solution("10", "my_bearing_range_error")])
def test_bearing_range_error_honest_answers_pass(fn):
    assert gsm.check_bearing_range_error(fn, quiet=True).startswith("✓")


def test_bearing_range_error_mistakes_are_named():
    fails(gsm.check_bearing_range_error, lambda p, m, z: br_by_hand(p, m, z)[::-1], "bearing")
    fails(gsm.check_bearing_range_error, lambda p, m, z: -br_by_hand(p, m, z), "measured − predicted")

    def unwrapped(p, m, z):
        zh = observe(np.asarray(p), np.asarray(m))[0]
        return np.array([zh[1] - z[1], zh[0] - z[0]])
    fails(gsm.check_bearing_range_error, unwrapped, "wrap")

    def conventions(p, m, z):
        dx, dy = m[0] - p[0], m[1] - p[1]
        return np.array([wrap(math.atan2(dy, dx) - p[2] - z[1]), math.hypot(dx, dy) - z[0]])
    fails(gsm.check_bearing_range_error, conventions, "one convention")


# ----------------------------------------------------------------------------- 10.3

def t2w_by_gtsam(S, phi):
    # the adjoint of the pose at (0, 0, phi) maps body-frame twists to the world frame
    Ad = gtsam.Pose2(0.0, 0.0, phi).AdjointMap()
    return Ad @ S @ Ad.T


@pytest.mark.parametrize("fn", [t2w_by_gtsam, solution("10", "my_tangent_to_world")])
def test_tangent_to_world_honest_answers_pass(fn):
    assert gsm.check_tangent_to_world(fn, quiet=True).startswith("✓")


def test_tangent_to_world_mistakes_are_named():
    fails(gsm.check_tangent_to_world, lambda S, phi: np.asarray(S), "as it is")

    def backwards(S, phi):
        Ad = gtsam.Pose2(0.0, 0.0, -phi).AdjointMap()
        return Ad @ S @ Ad.T
    fails(gsm.check_tangent_to_world, backwards, "wrong way")

    def block(S, phi):
        c, s = math.cos(phi), math.sin(phi)
        R = np.array([[c, -s], [s, c]])
        out = np.array(S, float)
        out[:2, :2] = R @ out[:2, :2] @ R.T
        return out
    fails(gsm.check_tangent_to_world, block, "position block")


def test_the_formula_is_in_the_instructors_feedback_only():
    """Exercise 10.3 derives B: a student's check does not print it, an instructor's does."""
    with pytest.raises(GradingError) as plain:
        gsm.check_tangent_to_world(lambda S, phi: np.asarray(S), quiet=True)
    assert "blockdiag" not in str(plain.value)
    with full_feedback(), pytest.raises(GradingError) as full:
        gsm.check_tangent_to_world(lambda S, phi: np.asarray(S), quiet=True)
    assert "B = blockdiag(R(φ), 1)" in str(full.value)
