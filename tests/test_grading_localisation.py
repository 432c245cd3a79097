"""Chapter 04a graders (annslam_lib.grading.localisation): for each exercise honest answers
(the notebook's own and others written differently), a partial one and the typical
mistakes with the messages a student gets; then real submissions of the chapter graded by
the course's grader, with their scores."""
import math

import numpy as np
import pytest
from scipy.stats import chi2

from annslam_lib.course.sandbox import Limits
from annslam_lib.grading import localisation as gl
from annslam_lib.models.observation import observe
from solutions import ROOT, solution
from check_support import fails, wrap

import grading_support as gs

NOTEBOOK = ROOT / "notebooks" / "04a_ekf_localisation.ipynb"


# ----------------------------------------------------------------------------- 4a.1

def _update(*, H_of=lambda Hp, Hm: Hp, wrap_nu=True, wrap_heading=True, sign=1.0, with_R=True,
            form="joseph"):
    def fn(pose, P, z, beacon, R):
        pose, P = np.asarray(pose, float), np.asarray(P, float)
        zhat, Hp, Hm = observe(pose, np.asarray(beacon, float))
        H = H_of(Hp, Hm)
        nu = np.asarray(z, float) - zhat
        if wrap_nu:
            nu[1] = wrap(nu[1])
        S = H @ P @ H.T + (R if with_R else 0 * R)
        K = np.linalg.solve(S, H @ P).T
        new = pose + sign * K @ nu
        if wrap_heading:
            new[2] = wrap(new[2])
        if form == "simple":
            return new, (np.eye(3) - K @ H) @ P
        IKH = np.eye(3) - K @ H
        return new, IKH @ P @ IKH.T + K @ R @ K.T
    return fn


@pytest.mark.parametrize("fn", [solution("04a", "my_beacon_update"), _update(),
                                _update(form="simple")])
@pytest.mark.parametrize("seed", [0, 7])
def test_beacon_update_honest_answers_pass(fn, seed):
    assert gl.check_beacon_update(fn, seed=seed, quiet=True).startswith("✓")


@pytest.mark.parametrize("fn, match", [
    (_update(H_of=lambda Hp, Hm: np.column_stack([Hm, np.zeros(2)])), "Jacobian with respect to the LANDMARK"),
    (_update(wrap_nu=False), "does not wrap the bearing innovation"),
    (_update(wrap_heading=False), "heading unwrapped"),
    (_update(sign=-1.0), "innovation's sign reversed"),
    (_update(with_R=False), "leaves the laser's noise out"),
])
def test_beacon_update_typical_mistakes_are_named(fn, match):
    fails(gl.check_beacon_update, fn, match)


def test_beacon_update_partial_pose_right_covariance_not_updated():
    right = _update()
    fails(gl.check_beacon_update, lambda pose, P, z, b, R: (right(pose, P, z, b, R)[0], P),
          r"(?s)disagrees with the reference at \d+ of 44 inputs.*'P\+\[0, 0\]'")


# ----------------------------------------------------------------------------- 4a.2

def _verdict(lo_q, hi_q, *, D_of=lambda nis, dof: float(np.sum(dof)), avg_of=None):
    def fn(nis, dof, p):
        D = D_of(nis, dof)
        avg = avg_of(nis, dof) if avg_of else float(np.sum(nis) / np.sum(dof))
        lo, hi = chi2.ppf(lo_q(p), D) / D, chi2.ppf(hi_q(p), D) / D
        return "too small" if avg < lo else "too large" if avg > hi else "consistent"
    return fn


@pytest.mark.parametrize("fn", [solution("04a", "my_nis_verdict"),
                                _verdict(lambda p: (1 - p) / 2, lambda p: (1 + p) / 2)])
@pytest.mark.parametrize("seed", [0, 7])
def test_nis_verdict_honest_answers_pass(fn, seed):
    assert gl.check_nis_verdict(fn, seed=seed, quiet=True).startswith("✓")


@pytest.mark.parametrize("fn, match", [
    (_verdict(lambda p: 1e-300, lambda p: p), "checks only the upper side"),
    (_verdict(lambda p: 1 - p, lambda p: p), r"band holds 2p − 1 of the averages"),
    (_verdict(lambda p: (1 - p) / 2, lambda p: (1 + p) / 2, D_of=lambda nis, dof: float(np.mean(dof))),
     "band of a SINGLE update"),
    (_verdict(lambda p: (1 - p) / 2, lambda p: (1 + p) / 2, D_of=lambda nis, dof: float(len(nis))),
     "counts updates, not degrees of freedom"),
    (_verdict(lambda p: (1 - p) / 2, lambda p: (1 + p) / 2, avg_of=lambda nis, dof: float(np.mean(nis))),
     "mean NIS per update"),
    (lambda nis, dof, p: "OK", "should return one of"),
])
def test_nis_verdict_typical_mistakes_are_named(fn, match):
    fails(gl.check_nis_verdict, fn, match)


def test_nis_verdict_partial_right_only_when_every_update_has_two_dof():
    # D = 2 x the number of updates: right for runs of single range-bearing sightings only
    def fn(nis, dof, p):
        D = 2.0 * len(nis)
        avg = float(np.sum(nis)) / D
        lo, hi = chi2.ppf((1 - p) / 2, D) / D, chi2.ppf((1 + p) / 2, D) / D
        return "too small" if avg < lo else "too large" if avg > hi else "consistent"
    dof = np.full(30, 2.0)
    nis = np.random.default_rng(1).chisquare(dof)
    assert fn(nis, dof, 0.95) == gl.localisation.nis_verdict(nis, dof, 0.95)[0]
    fails(gl.check_nis_verdict, fn, r"returned '.*', expected '.*': the average NIS per dof is")


def test_the_band_is_in_the_instructors_feedback_only():
    from grading_support import both_feedbacks

    plain, full = both_feedbacks(gl.check_nis_verdict, _verdict(lambda p: 1 - p, lambda p: p))
    assert "chi2.ppf((1 − p)/2, D)" not in plain
    assert "chi2.ppf((1 − p)/2, D)" in full


# ----------------------------------------------------------------------------- the grader

MIXED = {   # 4a.1 without the bearing wrap (which the loop of 4a.2 then uses); 4a.3 honest
    "ex04a-beacon-update": "def my_beacon_update(pose, P, z, beacon, R):\n"
                           "    zhat, H, _ = observe(np.asarray(pose, float), np.asarray(beacon, float))\n"
                           "    K, _ = dense.kalman_gain(P, H, R)\n"
                           "    new = pose + K @ (np.asarray(z) - zhat)\n"
                           "    new[2] = (new[2] + np.pi) % (2 * np.pi) - np.pi\n"
                           "    IKH = np.eye(3) - K @ H\n"
                           "    return new, IKH @ P @ IKH.T + K @ R @ K.T\n",
}


def test_the_grader_scores_honest_and_mixed_submissions_of_the_chapter(tmp_path):
    bodies = gs.solution_bodies(NOTEBOOK)
    limits = Limits(cell_timeout=120.0, call_timeout=30.0, deadline=400.0)
    results = {name: gs.grade_chapter(NOTEBOOK, sub, tmp_path / name, limits)
               for name, sub in [("honest", bodies), ("mixed", {**bodies, **MIXED})]}
    honest, mixed = results["honest"], results["mixed"]
    assert (honest.score, honest.max_score) == (10, 10), honest.report()
    assert honest.errors == [], honest.report()
    assert (mixed.score, mixed.max_score) == (3, 10), mixed.report()
    got = {r.grade_id: (r.points, r.status) for r in mixed.exercises}
    assert got == {"ex04a-beacon-update-tests": (0, "failed"),
                   "ex04a-filter-runs-tests": (1, "passed"),
                   "ex04a-filter-consistency-tests": (0, "failed"),
                   "ex04a-filter-path-tests": (0, "failed"),
                   "ex04a-nis-verdict-tests": (2, "passed")}, mixed.report()
    for gid in ("ex04a-beacon-update-tests", "ex04a-filter-consistency-tests",
                "ex04a-filter-path-tests"):
        msg = next(r.message for r in mixed.exercises if r.grade_id == gid)
        assert "does not wrap the bearing innovation" in msg, (gid, msg)
    assert math.isfinite(honest.seconds)
