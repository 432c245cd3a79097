"""Chapter 01a graders (annslam_lib.grading.kalman): for each exercise an honest answer (the
notebook's own, and others written differently), a partial one and the typical mistakes,
each with the message a student gets; then real submissions of the chapter graded by the
course's grader, with their scores."""
import math

import numpy as np
import pytest
from scipy.stats import chi2

from annslam_lib.course.sandbox import Limits
from annslam_lib.grading import GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import kalman as gk
from solutions import ROOT, solution

import grading_support as gs

NOTEBOOK = ROOT / "notebooks" / "01a_kalman_filter.ipynb"


def quiet(check, fn, **kw):
    """The check, silent, with the messages of the instructor's returned feedback."""
    with full_feedback():
        return check(fn, quiet=True, **kw)


def fails(check, fn, match):
    with pytest.raises(GradingError, match=match):
        quiet(check, fn)


# ----------------------------------------------------------------------------- honest answers

def _update_info(mu, var, z, r):            # information form: 1/var+ = 1/var + 1/r
    if var < 0 or r < 0 or var + r == 0:
        raise ValueError("impossible variances")
    if var == 0 or r == 0:
        return (mu, 0.0) if var == 0 else (z, 0.0)
    v = 1 / (1 / var + 1 / r)
    return v * (mu / var + z / r), v


def _gain_inv(P, H, R):
    S = H @ P @ H.T + R
    if np.linalg.eigvalsh(S)[0] <= 1e-12 * abs(np.linalg.eigvalsh(S)[-1]):
        raise ValueError("S is not positive definite")
    return P @ H.T @ np.linalg.inv(S)


def _gain_cholesky(P, H, R):                 # LinAlgError is a ValueError
    S = H @ P @ H.T + R
    L = np.linalg.cholesky(S)
    if np.min(np.diag(L)) ** 2 <= 1e-12 * np.max(np.abs(S)):
        raise ValueError("S is numerically singular")
    return np.linalg.solve(L.T, np.linalg.solve(L, H @ P)).T


def _steady_iterated(q, r):                  # the fixed point, found by the filter itself
    p_minus = 0.5 * (q + math.sqrt(q * q + 4 * q * r))
    for _ in range(3):                       # Newton polish of p^2 - q p - q r = 0
        if p_minus > 0:
            p_minus -= (p_minus**2 - q * p_minus - q * r) / (2 * p_minus - q)
    return p_minus * r / (p_minus + r) if p_minus + r > 0 else 0.0


@pytest.mark.parametrize("check, fn", [
    (gk.check_update_1d, solution("01a", "my_update_1d")), (gk.check_update_1d, _update_info),
    (gk.check_steady_state, solution("01a", "my_steady_state")),
    (gk.check_steady_state, _steady_iterated),
    (gk.check_kalman_gain, solution("01a", "my_kalman_gain")), (gk.check_kalman_gain, _gain_inv),
    (gk.check_kalman_gain, _gain_cholesky),
    (gk.check_gate, solution("01a", "my_gate")),
    (gk.check_gate, lambda nu, S, p: chi2.cdf(np.atleast_1d(nu) @ np.linalg.solve(S, nu),
                                              np.size(nu)) <= p),
])
@pytest.mark.parametrize("seed", [0, 7])
def test_honest_answers_pass(check, fn, seed):
    assert quiet(check, fn, seed=seed).startswith("✓")


@pytest.mark.parametrize("check, name", [(gk.check_update_1d, "my_update_1d"),
                                         (gk.check_steady_state, "my_steady_state"),
                                         (gk.check_kalman_gain, "my_kalman_gain"),
                                         (gk.check_gate, "my_gate")])
def test_stub_is_not_written_yet(check, name):
    def stub(*a):
        raise NotImplementedError()
    with pytest.raises(GradingError, match=f"{name} is not written yet"):
        quiet(check, stub, name=name)


# ----------------------------------------------------------------------------- 1a.1

def _update(K_of, var_of=lambda var, r, K: (1 - K) * var, raises=True):
    def fn(mu, var, z, r):
        if raises and (var < 0 or r < 0 or var + r == 0):
            raise ValueError("no")
        K = K_of(var, r)
        return mu + K * (z - mu), var_of(var, r, K)
    return fn


@pytest.mark.parametrize("fn, match", [
    (_update(lambda v, r: r / (v + r)), "weight to the wrong side"),
    (lambda mu, v, z, r: (mu - v / (v + r) * (z - mu), v * r / (v + r)) if v + r > 0 and v >= 0
     and r >= 0 else (_ for _ in ()).throw(ValueError()), "away from the measurement"),
    (_update(lambda v, r: v / (v + r), lambda v, r, K: K * v), "share of the prior's variance that the measurement REMOVES"),
    (_update(lambda v, r: v / (v + r), lambda v, r, K: v + r), "adds the variances"),
    (_update(lambda v, r: v / (v + r), lambda v, r, K: v), "prior's variance unchanged"),
    (_update(lambda v, r: math.sqrt(v) / (math.sqrt(v) + math.sqrt(r))), "standard deviations"),
])
def test_update_typical_mistakes_are_named(fn, match):
    fails(gk.check_update_1d, fn, match)


def test_update_partial_right_numbers_but_no_error_for_impossible_input():
    ok = _update(lambda v, r: v / (v + r), raises=False)
    fails(gk.check_update_1d, lambda *a: ok(*a) if a[1] + a[3] > 0 else (a[0], 0.0),
          r"var=-0.5.*should raise ValueError because var < 0 is no variance")


# ----------------------------------------------------------------------------- 1a.2

def _p_minus(q, r):
    return 0.5 * (q + math.sqrt(q * q + 4 * q * r))


@pytest.mark.parametrize("fn, match", [
    (_p_minus, "PRIOR's stationary variance"),
    (lambda q, r: 0.5 * (q - math.sqrt(q * q + 4 * q * r)) - q, "negative root"),
    (lambda q, r: _p_minus(r, q) - r, "q and r swapped"),
    (lambda q, r: math.sqrt(_p_minus(q, r) - q), "standard deviation"),
])
def test_steady_state_typical_mistakes_are_named(fn, match):
    fails(gk.check_steady_state, fn, match)


def test_steady_state_partial_fifty_iterations_are_not_the_limit():
    def iterate(q, r, steps=50):
        p = 1.0
        for _ in range(steps):
            p = (p + q) * r / (p + q + r) if p + q + r > 0 else 0.0
        return p
    fails(gk.check_steady_state, iterate, r"disagrees with the reference at \d+ of 47 inputs")


# ----------------------------------------------------------------------------- 1a.3

@pytest.mark.parametrize("fn, match", [
    (lambda P, H, R: P @ H.T @ np.linalg.inv(R), "R⁻¹ instead of S⁻¹"),
    (lambda P, H, R: P @ H.T @ (H @ P @ H.T + R), "S instead of its inverse"),
    (lambda P, H, R: P @ H.T @ np.linalg.inv(H @ P @ H.T), "leaves R out"),
    (lambda P, H, R: P @ H.T @ np.diag(1 / np.diag(H @ P @ H.T + R)), "only the diagonal"),
    (lambda P, H, R: H.T @ np.linalg.inv(H @ P @ H.T + R), "forgets P"),
    (lambda P, H, R: _gain_inv(P, H, R).T, r"shape \(1, 2\).*looks transposed"),
    (lambda P, H, R: P @ H.T @ np.linalg.pinv(H @ P @ H.T + R),
     "should raise ValueError because P = 0 and R = 0"),
])
def test_gain_typical_mistakes_are_named(fn, match):
    fails(gk.check_kalman_gain, fn, match)


@pytest.mark.parametrize("fn", [lambda P, H, R: P @ H.T / (H @ P @ H.T + R),
                                lambda P, H, R: P @ H.T / float((H @ P @ H.T + R)[0, 0])
                                if H.shape[0] == 1 else P @ H.T / (H @ P @ H.T + R).item()])
def test_gain_partial_right_for_one_number_measurements_only(fn):
    fails(gk.check_kalman_gain, fn, r"right for every single measurement \(m = 1\) and fails "
                                    r"for m = \d")


# ----------------------------------------------------------------------------- 1a.4

def _d2(nu, S):
    nu = np.atleast_1d(nu)
    return nu @ np.linalg.solve(S, nu)


@pytest.mark.parametrize("fn, match", [
    (lambda nu, S, p: _d2(nu, S) <= chi2.ppf(p, 2), "always uses 2 degrees of freedom"),
    (lambda nu, S, p: _d2(nu, S) <= chi2.ppf(p, 1), "always uses 1 degree of freedom"),
    (lambda nu, S, p: _d2(nu, S) <= chi2.ppf(1 - p, len(nu)), "quantile of 1 − p"),
    (lambda nu, S, p: math.sqrt(_d2(nu, S)) <= chi2.ppf(p, len(nu)), "distance √d2"),
    (lambda nu, S, p: nu @ S @ nu <= chi2.ppf(p, len(nu)), "νᵀ S ν"),
    (lambda nu, S, p: np.sum(nu**2 / np.diag(S)) <= chi2.ppf(p, len(nu)), "only the diagonal"),
    (lambda nu, S, p: _d2(nu, S) > chi2.ppf(p, len(nu)), "inverted"),
    (lambda nu, S, p: "yes", "should return True"),
])
def test_gate_typical_mistakes_are_named(fn, match):
    fails(gk.check_gate, fn, match)


def test_gate_partial_right_for_scalar_innovations_only():
    # only the first component, as for a 1-D measurement
    fails(gk.check_gate, lambda nu, S, p: nu[0] ** 2 / S[0, 0] <= chi2.ppf(p, len(nu)),
          r"my_gate\(nu=.*returned (True|False), expected (True|False): d2 = .* decisions differ")


# ----------------------------------------------------------------------------- the grader

MIXED = {
    # 1a.1 honest; 1a.2 the prior's variance; 1a.3 right for m = 1 only; 1a.4 two dof always
    "ex01a-steady-state": "def my_steady_state(q, r):\n"
                          "    return 0.5 * (q + math.sqrt(q * q + 4 * q * r))\n",
    "ex01a-kalman-gain": "def my_kalman_gain(P, H, R):\n"
                         "    return P @ H.T / (H @ P @ H.T + R)\n",
    "ex01a-gate": "from scipy.stats import chi2\n\ndef my_gate(nu, S, p):\n"
                  "    return bool(nu @ np.linalg.solve(S, nu) <= chi2.ppf(p, 2))\n",
}


def test_the_grader_scores_honest_and_mixed_submissions_of_the_chapter(tmp_path):
    bodies = gs.solution_bodies(NOTEBOOK)
    limits = Limits(cell_timeout=60.0, call_timeout=20.0, deadline=240.0)
    results = {name: gs.grade_chapter(NOTEBOOK, sub, tmp_path / name, limits)
               for name, sub in [("honest", bodies), ("mixed", {**bodies, **MIXED})]}
    honest, mixed = results["honest"], results["mixed"]
    assert (honest.score, honest.max_score) == (9, 9), honest.report()
    assert honest.errors == [], honest.report()
    assert (mixed.score, mixed.max_score) == (2, 9), mixed.report()
    got = {r.grade_id: (r.points, r.status) for r in mixed.exercises}
    assert got == {"ex01a-update-1d-tests": (2, "passed"),
                   "ex01a-steady-state-tests": (0, "failed"),
                   "ex01a-kalman-gain-tests": (0, "failed"),
                   "ex01a-gate-tests": (0, "failed")}, mixed.report()
    msg = {r.grade_id: r.message for r in mixed.exercises}
    assert "PRIOR's stationary variance" in msg["ex01a-steady-state-tests"]
    assert "right for every single measurement (m = 1)" in msg["ex01a-kalman-gain-tests"]
    assert "always uses 2 degrees of freedom" in msg["ex01a-gate-tests"]


# ----------------------------------------------------------------------------- feedback levels

def _weights_swapped(mu, var, z, r):
    if var < 0 or r < 0 or var + r == 0:
        raise ValueError("impossible variances")
    K = r / (var + r)
    return mu + K * (z - mu), (1 - K) * var


def test_the_weights_swapped_message_teaches_without_handing_over_the_gain():
    """A student's own check names the mistake and where to look, never the formula; the
    instructor's returned feedback (full_feedback) adds it."""
    with pytest.raises(GradingError) as student:
        gk.check_update_1d(_weights_swapped, quiet=True)
    msg = str(student.value)
    assert "weight to the wrong side" in msg
    assert "var / (var + r)" not in msg and "r / (var + r)" not in msg
    with pytest.raises(GradingError) as instructor, full_feedback():
        gk.check_update_1d(_weights_swapped, quiet=True)
    full = str(instructor.value)
    assert full.startswith(msg) and "var / (var + r)" in full
