"""Chapter 11 graders (annslam_lib.grading.graph_slam): honest answers (the notebook's own
and others written independently: finite differences of the error, a dense least-squares
solve, a clipped ratio) pass; the typical mistakes fail with their messages; an unwritten
stub says so (calling the course's own function: tests/test_grading_forbidden.py)."""
import numpy as np
import pytest
import scipy.sparse as sp

from annslam_lib.grading import graph_slam as ggs
from annslam_lib.models.observation import observe
from annslam_lib.smoothing import gauss_newton as gn
from check_support import fails, stub, wrap
from solutions import solution


# ----------------------------------------------------------------------------- 11.1

def by_finite_differences(pose, landmark, z, sr, sb):
    """The whitened error written directly, its Jacobians by central differences."""
    def err(p, m):
        zh = observe(p, m)[0]
        return np.array([wrap(zh[1] - z[1]) / sb, (zh[0] - z[0]) / sr])

    p, m = np.asarray(pose, float), np.asarray(landmark, float)
    h = 1e-6
    Jp = np.column_stack([(err(p + h * np.eye(3)[i], m) - err(p - h * np.eye(3)[i], m)) / (2 * h)
                          for i in range(3)])
    Jm = np.column_stack([(err(p, m + h * np.eye(2)[i]) - err(p, m - h * np.eye(2)[i])) / (2 * h)
                          for i in range(2)])
    return err(p, m), Jp, Jm


@pytest.mark.parametrize("fn", [by_finite_differences,
                                solution("11", "my_whitened_range_bearing")])
@pytest.mark.parametrize("seed", [0, 7])
def test_whitened_range_bearing_honest_answers_pass(fn, seed):
    assert ggs.check_whitened_range_bearing(fn, seed=seed, quiet=True).startswith("✓")


def test_whitened_range_bearing_mistakes_are_named():
    ref = ggs.whitened_range_bearing

    def not_whitened(pose, lm, z, sr, sb):
        return ref(pose, lm, z, 1.0, 1.0)

    def by_variance(pose, lm, z, sr, sb):
        return ref(pose, lm, z, sr**2, sb**2)

    def range_first(pose, lm, z, sr, sb):
        e, a, b = by_finite_differences(pose, lm, z, sr, sb)
        return e[::-1], a[::-1], b[::-1]

    def unwrapped(pose, lm, z, sr, sb):
        e, a, b = by_finite_differences(pose, lm, z, sr, sb)
        zh = observe(np.asarray(pose, float), np.asarray(lm, float))[0]
        return np.array([(zh[1] - z[1]) / sb, e[1]]), a, b

    fails(ggs.check_whitened_range_bearing, not_whitened, "does not whiten")
    fails(ggs.check_whitened_range_bearing, by_variance, "divides by the variances")
    fails(ggs.check_whitened_range_bearing, range_first, "puts the range first")
    fails(ggs.check_whitened_range_bearing, unwrapped, "does not wrap")
    fails(ggs.check_whitened_range_bearing, stub, "not written yet")


# ----------------------------------------------------------------------------- 11.2

def dense_least_squares(J, e):
    return np.linalg.lstsq(np.asarray(J.todense()), -np.asarray(e, float), rcond=None)[0]


def by_qr(J, e):
    Q, R = np.linalg.qr(np.asarray(J.todense()))
    return np.linalg.solve(R, -Q.T @ e)


@pytest.mark.parametrize("fn", [dense_least_squares, by_qr,
                                solution("11", "my_gauss_newton_step")])
def test_gauss_newton_step_honest_answers_pass(fn):
    assert ggs.check_gauss_newton_step(fn, quiet=True).startswith("✓")


def test_gauss_newton_step_mistakes_are_named():
    def uphill(J, e):
        return -dense_least_squares(J, e)

    def gradient(J, e):
        return -(J.T @ e)

    def damped(J, e):
        A = np.asarray(J.todense())
        return np.linalg.solve(A.T @ A + np.eye(A.shape[1]), -A.T @ e)

    fails(ggs.check_gauss_newton_step, uphill, "steps uphill")
    fails(ggs.check_gauss_newton_step, gradient, "gradient")
    fails(ggs.check_gauss_newton_step, damped, "Levenberg-Marquardt")
    fails(ggs.check_gauss_newton_step, stub, "not written yet")


def test_the_reference_step_is_the_solvers():
    rng = np.random.default_rng(2)
    J = sp.random(40, 12, density=0.3, random_state=3, format="csr") + sp.vstack(
        [sp.csr_matrix((28, 12)), sp.identity(12, format="csr")])
    e = rng.normal(size=40)
    np.testing.assert_allclose(ggs.gauss_newton_step(J, e), gn.step(J, e), atol=1e-10)


# ----------------------------------------------------------------------------- 11.3

def clipped_ratio(r, k):
    r = np.asarray(r, float)
    return np.minimum(1.0, k / np.maximum(r, 1e-300))


@pytest.mark.parametrize("fn", [clipped_ratio, solution("11", "my_huber_weights")])
def test_huber_weights_honest_answers_pass(fn):
    assert ggs.check_huber_weights(fn, quiet=True).startswith("✓")


def test_huber_weights_mistakes_are_named():
    def everywhere(r, k):
        return k / np.asarray(r, float)

    def inverted(r, k):
        r = np.asarray(r, float)
        return np.where(r > k, r / k, 1.0)

    def squared(r, k):
        r = np.asarray(r, float)
        return np.where(r * r > k, k / r, 1.0)

    def root(r, k):
        return np.sqrt(clipped_ratio(r, k))

    fails(ggs.check_huber_weights, everywhere, "within the threshold")
    fails(ggs.check_huber_weights, inverted, "MORE weight")
    fails(ggs.check_huber_weights, squared, "compares r²")
    fails(ggs.check_huber_weights, root, "returns √w")
    fails(ggs.check_huber_weights, stub, "not written yet")


# ------------------------------------------------------------- the chapter, through the grader

MIXED = {   # one honest exercise, one typical mistake, one left as the stub
    "ex11-whitened-range-bearing": '''def my_whitened_range_bearing(pose, landmark, z, sigma_range, sigma_bearing):
    zhat, Hp, Hl = observe(np.asarray(pose, float), np.asarray(landmark, float))
    w = np.array([1.0 / sigma_bearing, 1.0 / sigma_range])
    d = (zhat[1] - z[1] + np.pi) % (2 * np.pi) - np.pi
    return np.array([d, zhat[0] - z[0]]) * w, Hp[[1, 0]] * w[:, None], Hl[[1, 0]] * w[:, None]''',
    "ex11-gauss-newton-step": '''def my_gauss_newton_step(J, e):
    J = sp.csc_matrix(J)
    return spsolve((J.T @ J).tocsc(), J.T @ np.asarray(e, float))''',
}


def test_the_grader_scores_honest_and_mixed_submissions_of_the_chapter(tmp_path):
    """The released chapter with the notebook's own solutions, and with one right answer,
    one uphill step and one stub, graded by the course's grader (sandboxed where it can be)."""
    import grading_support as gsup
    from annslam_lib.course.sandbox import Limits
    from solutions import ROOT

    notebook = ROOT / "notebooks" / "11_graph_slam.ipynb"
    bodies = gsup.solution_bodies(notebook)
    limits = Limits(cell_timeout=120.0, call_timeout=30.0, deadline=300.0)
    honest = gsup.grade_chapter(notebook, bodies, tmp_path / "honest", limits)
    mixed = gsup.grade_chapter(notebook, MIXED, tmp_path / "mixed", limits)
    assert (honest.score, honest.max_score) == (6, 6), honest.report()
    assert honest.errors == [], honest.report()
    got = {r.grade_id: (r.points, r.status) for r in mixed.exercises}
    assert got == {"ex11-whitened-range-bearing-tests": (2, "passed"),
                   "ex11-gauss-newton-step-tests": (0, "failed"),
                   "ex11-huber-weights-tests": (0, "not written")}, mixed.report()
    msg = {r.grade_id: r.message for r in mixed.exercises}
    assert "steps uphill" in msg["ex11-gauss-newton-step-tests"]
    assert "not written yet" in msg["ex11-huber-weights-tests"]
