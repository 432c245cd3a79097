"""Checks of notebook 08's graded exercises (annslam_lib.grading.verdict): the references
agree with the library (map_metrics, ann.regression), the notebook's solutions pass, the
usual slips fail with their own messages, and the stubs say 'not written yet'.

The paper prints no equation for the metrics the verdict uses (sections 4.3 and 5 make
claims; paper.ERRATA has no entry there), so there is no misprint to fail here."""
import math

import numpy as np
import pytest

from annslam_lib import paper
from annslam_lib.grading import GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import verdict as gv
from annslam_lib.evaluation import map as map_eval
from solutions import solution
from check_support import stub


notebook_rigid_align = solution("08", "my_rigid_align")
notebook_aligned_rmse = solution("08", "my_aligned_rmse")
notebook_regression = solution("08", "my_regression")


def test_no_erratum_concerns_the_verdicts_metrics():
    assert not [e for e in paper.ERRATA if e.section.split(",")[0].strip() in ("4.3", "5")]


# ----------------------------------------------------------------------------- 8.1

def test_rigid_align_solution_passes():
    assert gv.check_rigid_align(notebook_rigid_align, quiet=True).startswith(
        "✓ my_rigid_align agrees with evaluation.map.rigid_align on 10 inputs")
    for seed in (7, 8):
        gv.check_rigid_align(notebook_rigid_align, seed=seed, n=12, quiet=True)


def test_rigid_align_cases_separate_the_mistakes():
    """The mirrored case really prefers a reflection, the shrunken one a scale < 1."""
    cases = gv._pairs(0, 6)
    a, b = cases[2]
    R = gv._wrong_rt("reflection")(a, b)[0]
    assert np.linalg.det(R) == pytest.approx(-1.0)
    a, b = cases[3]
    R = gv._wrong_rt("scale")(a, b)[0]
    assert math.sqrt(abs(np.linalg.det(R))) == pytest.approx(0.8, abs=0.02)


@pytest.mark.parametrize("kind, phrase", [
    ("reflection", "REFLECTION"), ("scale", "SCALE factor"), ("transposed", "R transposed"),
    ("reversed", "aligns b onto a"), ("uncentred", "centroids"),
    ("no_rotation_in_t", "ROTATED centroid")])
def test_rigid_align_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gv.check_rigid_align(gv._wrong_rt(kind))


def test_rigid_align_generic_and_format_errors():
    def sign_slip(a, b):                 # t = R a_bar - b_bar
        R, t = notebook_rigid_align(a, b)
        return R, -t
    with pytest.raises(GradingError, match=r"'t_x' has the wrong sign at every input"):
        gv.check_rigid_align(sign_slip)

    def swapped_offdiagonal(a, b):       # [[c, s], [-s, c]] is the transpose: named as such
        R, t = notebook_rigid_align(a, b)
        R = R * np.array([[1, -1], [-1, 1]])
        return R, b.mean(axis=0) - R @ a.mean(axis=0)
    with pytest.raises(GradingError, match="R transposed"):
        gv.check_rigid_align(swapped_offdiagonal)
    with pytest.raises(GradingError, match=r"must return a pair \(R, t\)"):
        gv.check_rigid_align(lambda a, b: notebook_rigid_align(a, b)[0])
    with pytest.raises(GradingError, match=r"R of shape \(2, 2\) and t of shape \(2,\); got \(2, 2\) and \(3,\)"):
        gv.check_rigid_align(lambda a, b: (notebook_rigid_align(a, b)[0], np.zeros(3)))
    with pytest.raises(GradingError, match="is not written yet"):
        gv.check_rigid_align(stub)


# ----------------------------------------------------------------------------- 8.2

def test_aligned_rmse_is_map_errors_aligned_rmse():
    rng = np.random.default_rng(3)
    true = rng.uniform(-20, 20, (12, 2))
    th = 0.01
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    mapped = true @ R.T + np.array([0.05, -0.03]) + rng.normal(0, 0.05, true.shape)
    m = map_eval.map_errors(mapped, true, max_distance=1.0)
    assert m.i_mapped.size == 12 and np.array_equal(m.i_mapped, m.j_true)
    assert gv.aligned_rmse(mapped, true) == pytest.approx(m.rmse_aligned, rel=1e-12)
    assert gv.aligned_rmse(mapped, true) < m.rmse


def test_aligned_rmse_solution_passes():
    assert gv.check_aligned_rmse(notebook_aligned_rmse, quiet=True).startswith("✓ my_aligned_rmse")
    gv.check_aligned_rmse(notebook_aligned_rmse, seed=8, n=12, quiet=True)


@pytest.mark.parametrize("kind, phrase", [
    ("absolute", "WITHOUT the alignment"), ("centroid", "only removes the translation"),
    ("mean", "MEAN distance"), ("coords", "2K coordinates"), ("mse", "square root"),
    ("transposed", "rotates with R transposed"), ("reflection", "mirror"), ("scale", "scale the map")])
def test_aligned_rmse_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gv.check_aligned_rmse(gv._wrong_rmse(kind))


@pytest.mark.parametrize("check, wrong, formula", [
    (gv.check_aligned_rmse, gv._wrong_rmse("absolute"), "2 (s_1 + d s_2)"),
    (gv.check_aligned_rmse, gv._wrong_rmse("reflection"), "not 2 (s_1 + s_2)"),
    (gv.check_regression, gv._wrong_reg("swapped"), "slope = S_go / S_gg"),
    (gv.check_rigid_align, gv._wrong_rt("transposed"), "R = V diag(1, d) U^T"),
])
def test_the_formula_is_in_the_instructors_feedback_only(check, wrong, formula):
    """Exercises 8.2 and 8.3 derive their formulas: a student's check names the kind of
    mistake, the instructor's returned feedback adds what would hand the exercise over."""
    with pytest.raises(GradingError) as plain:
        check(wrong, quiet=True)
    assert formula not in str(plain.value)
    with full_feedback(), pytest.raises(GradingError) as full:
        check(wrong, quiet=True)
    assert formula in str(full.value)


def test_the_aligned_rmse_is_derived_not_aligned():
    """Exercise 8.2's solution forms no rotation: the check forbids rigid_align."""
    from annslam_lib.grading import core

    assert "annslam_lib.evaluation.map:rigid_align" in gv.check_aligned_rmse.__annslam_forbids__
    token = core._ALLOWED.set(False)
    try:
        gv.check_aligned_rmse(notebook_aligned_rmse, quiet=True)
    finally:
        core._ALLOWED.reset(token)


def test_aligned_rmse_must_reject_a_single_pair_and_stub():
    def no_check(mapped, true):
        if len(mapped) < 2:
            return 0.0
        return notebook_aligned_rmse(mapped, true)
    with pytest.raises(GradingError, match="should raise ValueError because one landmark pair"):
        gv.check_aligned_rmse(no_check)
    with pytest.raises(GradingError, match="is not written yet"):
        gv.check_aligned_rmse(stub)


# ----------------------------------------------------------------------------- 8.3

def test_regression_line_is_ann_regression():
    """The reference equals what ann.regression reports for a trained network, positions and
    corrections, per part."""
    torch = pytest.importorskip("torch")  # noqa: F841
    from annslam_lib import ann
    rng = np.random.default_rng(2)
    n = 90
    pose = np.c_[rng.uniform(-5, 5, (n, 2)), rng.uniform(-3, 3, n)]
    z = np.c_[rng.uniform(2, 25, n), rng.uniform(0.2, 2.9, n)]
    X, base = ann.encode(pose, z)
    target = base + rng.normal(0, 0.05, (n, 2))
    ts = ann.TrainingSet(X=X, Y=target - base, base=base, target=target, beacon=np.arange(n) % 6,
                         t=np.arange(n) * 0.1, scan=np.arange(n), pose=pose, z=z)
    split = ann.chronological_split(ts)
    model = ann.train(ts, split, ann.TrainConfig(hidden=(3,), max_epochs=3))
    for kind in ("position", "correction"):
        reg = ann.regression(model, ts, split, kind)
        for part, idx in (("train", split.train), ("test", split.test)):
            out = model.predict(X[idx]) - (base[idx] if kind == "correction" else 0)
            tgt = ts.Y[idx] if kind == "correction" else target[idx]
            s, c, r = gv.regression_line(out, tgt)
            assert (s, c, r) == pytest.approx((reg[part]["slope"], reg[part]["intercept"], reg[part]["r"]),
                                              rel=1e-9, abs=1e-12)


def test_regression_line_bad_input():
    with pytest.raises(ValueError, match="same shape"):
        gv.regression_line(np.zeros((3, 2)), np.zeros((3,)))
    with pytest.raises(ValueError, match="undefined"):
        gv.regression_line(np.arange(4.0), np.ones(4))
    with pytest.raises(ValueError, match="at least 2"):
        gv.regression_line([1.0], [2.0])


def test_regression_solution_passes():
    assert gv.check_regression(notebook_regression, quiet=True).startswith("✓ my_regression")
    gv.check_regression(notebook_regression, seed=7, n=12, quiet=True)


@pytest.mark.parametrize("kind, phrase", [("r2", r"R\^2"), ("swapped", "wrong way round"),
                                          ("x_only", "x coordinates only"), ("ddof", "n / \\(n - 1\\)")])
def test_regression_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gv.check_regression(gv._wrong_reg(kind))


def test_regression_generic_and_stub():
    def no_intercept(o, g):
        s, c, r = notebook_regression(o, g)
        return s, 0.0, r
    with pytest.raises(GradingError, match="'intercept'"):
        gv.check_regression(no_intercept)
    with pytest.raises(GradingError, match="is not written yet"):
        gv.check_regression(stub)
