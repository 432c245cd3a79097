"""Notebook 05's graded exercises (annslam_lib.grading.ekf): the references and the
notebook's solutions pass, the paper's printed bearing and the typical mistakes fail with
their specific messages, a stub is 'not written yet'."""
import math

import numpy as np
import pytest

from annslam_lib import paper
from annslam_lib.grading import NOT_WRITTEN, GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import ekf as gk
from annslam_lib.models.observation import inverse_observe
from annslam_lib.slam import dense
from solutions import solution
from check_support import stub


# ---------------------------------------------------------------- the notebook's solutions
# (the same code as the solution cells of notebooks/05_ekf_slam.ipynb)

my_augment = solution("05", "my_augment")
my_joseph_covariance = solution("05", "my_joseph_covariance")
my_ekf_update = solution("05", "my_ekf_update")


# ---------------------------------------------------------------- (a) right answers pass

@pytest.mark.parametrize("check, fn", [
    (gk.check_augment, dense.augment_landmark),
    (gk.check_augment, my_augment),
    (gk.check_joseph_covariance, dense.joseph_covariance),
    (gk.check_joseph_covariance, my_joseph_covariance),
    (gk.check_ekf_update, dense.range_bearing_update),
    (gk.check_ekf_update, my_ekf_update),
])
def test_references_and_solutions_pass(check, fn, capsys):
    msg = check(fn)
    assert msg.startswith("✓") and capsys.readouterr().out.strip() == msg
    check(fn, seed=7, n=8)                       # the hidden tests' arguments


def test_cases_are_realistic_and_cover_the_edges():
    aug = gk._augment_cases(0, 6)
    sizes = {args[0].size for args in aug.values()}
    assert {3, 9} <= sizes and max(sizes) >= 15
    assert any(abs(abs(args[0][2]) - math.pi) < 0.05 for args in aug.values())
    upd = gk._update_cases(0, 5)
    wrapped = 0
    for x, P, z, z_hat, H, R in upd.values():
        assert np.all(np.linalg.eigvalsh(P) > 0) and H.shape == (z.size, x.size)
        wrapped += np.any(np.abs(z[1::2] - z_hat[1::2]) > math.pi)
        x_new, _ = dense.range_bearing_update(x, P, z, z_hat, H, R)
        assert -math.pi < x_new[2] <= math.pi
    assert wrapped >= 2                           # cases where z - z_hat needs the wrap
    assert any(args[0].size >= 23 for args in upd.values())
    jos = gk._joseph_cases(0, 4)
    optimal = [lab for lab in jos if "optimal gain" in lab]
    assert 1 <= len(optimal) < len(jos)


# ---------------------------------------------------------------- (b) the paper's bearing

def test_the_papers_printed_bearing_fails_augmentation():
    """Placing the landmark along the printed bearing's vector (landmark -> sensor, erratum
    4.1-bearing) is consistent with the PRINTED observation model but mirrored."""
    def printed_augment(x, P, z, R):
        x_new, P_new = dense.augment_landmark(x, P, z, R)
        x_new[-2:] = 2 * x[:2] - x_new[-2:]        # the mirror through the laser
        return x_new, P_new

    x = np.array([1.0, 2.0, 0.4, 5.0, 5.0])
    z = np.array([7.0, 0.9])
    mirrored = printed_augment(x, np.eye(5), z, np.eye(2))[0][-2:]
    np.testing.assert_allclose(paper.observation_printed(x[:3], mirrored), z, atol=1e-12)
    with pytest.raises(GradingError, match=r"mirrored through the laser.*4\.1-bearing"):
        gk.check_augment(printed_augment)


# ---------------------------------------------------------------- (c) typical mistakes

def _augment_variant(kind):
    def f(x, P, z, R):
        x_new, P_new = my_augment(x, P, z, R)
        n = x.size
        lm, Gv, Gz = inverse_observe(x[:3], z)
        if kind == "ahead":
            x_new[-2:] = x[:2] + z[0] * np.array([math.cos(x[2] + z[1]), math.sin(x[2] + z[1])])
        elif kind == "no-heading":
            x_new[-2:] = x[:2] + z[0] * np.array([math.sin(z[1]), -math.cos(z[1])])
        elif kind == "pose-only":
            P_new[n:, 3:n] = P_new[3:n, n:] = 0.0
        elif kind == "raw-R":
            P_new[n:, n:] = Gv @ P[:3, :3] @ Gv.T + R
        elif kind == "no-noise":
            P_new[n:, n:] = Gv @ P[:3, :3] @ Gv.T
        elif kind == "no-pose":
            P_new[n:, n:] = Gz @ R @ Gz.T
        elif kind == "asymmetric":
            P_new[:n, n:] = 0.0
        elif kind == "cross-sign":
            P_new[n:, :3] *= -1
            P_new[:3, n:] *= -1
        elif kind == "tuple":
            return x_new
        return x_new, P_new
    return f


@pytest.mark.parametrize("kind, phrase", [
    ("ahead", r"90° off: the bearing was counted from straight ahead.*RIGHT"),
    ("no-heading", r"ignores the car's heading"),
    ("pose-only", r"cross covariance with the landmarks already in the map is zero"),
    ("raw-R", r"as R itself.*carried into \(x, y\)"),
    ("no-noise", r"lacks the measurement noise"),
    ("no-pose", r"lacks the pose's uncertainty"),
    ("asymmetric", r"not symmetric at case '#0.*entry \[0, 9\] = 0"),
    ("cross-sign", r"(?s)wrong sign.*wrong part of P_new: the new landmark's cross covariance with "
                   r"the pose"),
    ("tuple", r"must return the pair \(x_new, P_new\)"),
])
def test_augment_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gk.check_augment(_augment_variant(kind))


def _joseph_variant(kind):
    def f(P, H, R, K):
        I_KH = np.eye(P.shape[0]) - K @ H
        S = H @ P @ H.T + R
        return {"short": I_KH @ P, "short-KHP": P - K @ H @ P,
                "symmetrised": 0.5 * (I_KH @ P + (I_KH @ P).T), "kskt": P - K @ S @ K.T,
                "no-krk": I_KH @ P @ I_KH.T, "transposed": I_KH.T @ P @ I_KH + K @ R @ K.T,
                "ksk": I_KH @ P @ I_KH.T + K @ S @ K.T}[kind]
    return f


@pytest.mark.parametrize("kind, phrase", [
    ("short", r"a short form, right only for the optimal gain.*for ANY K"),
    ("short-KHP", r"a short form, right only for the optimal gain"),
    ("symmetrised", r"a short form, symmetrised"),
    ("kskt", r"P - K S K\^T, which is the covariance only for the optimal gain"),
    ("no-krk", r"the measurement noise is missing"),
    ("transposed", r"transposes are on the wrong side"),
    ("ksk", r"passes the innovation covariance S through the gain"),
])
def test_joseph_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gk.check_joseph_covariance(_joseph_variant(kind))


@pytest.mark.parametrize("check, wrong, formula", [
    (gk.check_joseph_covariance, lambda: _joseph_variant("short"), "(I - K H) P (I - K H)^T + K R K^T"),
    (gk.check_joseph_covariance, lambda: _joseph_variant("ksk"), "K R K^T, not K S K^T"),
])
def test_the_formula_is_in_the_instructors_feedback_only(check, wrong, formula):
    """A student's own check names the kind of mistake; the formula that would hand the
    exercise over is added only in the feedback an instructor returns."""
    with pytest.raises(GradingError) as plain:
        check(wrong())
    assert formula not in str(plain.value)
    with full_feedback(), pytest.raises(GradingError) as full:
        check(wrong())
    assert formula in str(full.value) and str(full.value).startswith(str(plain.value))


def test_short_form_is_right_for_the_optimal_gain_only():
    """Why the exercise needs arbitrary gains: with the optimal K the short form agrees."""
    optimal = {lab: a for lab, a in gk._joseph_cases(0, 0).items() if "optimal gain" in lab}
    for P, H, R, K in optimal.values():
        np.testing.assert_allclose(_joseph_variant("short")(P, H, R, K),
                                   dense.joseph_covariance(P, H, R, K), atol=1e-15)


def _update_variant(kind):
    def f(x, P, z, z_hat, H, R):
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(R if kind == "R-gain" else S)
        nu = z - z_hat
        if kind != "unwrapped":
            nu[1::2] = (nu[1::2] + np.pi) % (2 * np.pi) - np.pi
        if kind == "reversed":
            nu = -nu
        x_new = x + K @ nu
        if kind != "heading":
            x_new[2] = (x_new[2] + np.pi) % (2 * np.pi) - np.pi
        I_KH = np.eye(x.size) - K @ H
        P_new = I_KH @ P @ I_KH.T + (0 if kind == "no-krk" else K @ R @ K.T)
        if kind == "plus":
            P_new = P + K @ S @ K.T
        if kind == "asymmetric":
            P_new = I_KH @ P + np.triu(np.full_like(P, 1e-3), 1)
        if kind == "pinv":           # never raises: a silent answer for a singular S
            K = P @ H.T @ np.linalg.pinv(S)
            x_new = x + K @ nu
            x_new[2] = (x_new[2] + np.pi) % (2 * np.pi) - np.pi
            return x_new, P - K @ S @ K.T
        return x_new, P_new
    return f


@pytest.mark.parametrize("kind, phrase", [
    ("unwrapped", r"bearing innovation is not wrapped.*straight to the left"),
    ("reversed", r"innovation has the wrong sign.*which of the measured"),
    ("R-gain", r"gain weighs with the measurement noise alone"),
    ("heading", r"'phi' is right modulo 2π but not wrapped.*turns the heading past \+pi"),
    ("no-krk", r"P_new lacks the measurement noise's term"),
    ("plus", r"P_new grows with the update"),
    ("asymmetric", r"not symmetric at case"),
])
def test_update_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gk.check_ekf_update(_update_variant(kind))


def test_a_singular_innovation_covariance_must_raise():
    """np.linalg.inv raises LinAlgError (a ValueError) for an exactly singular S but not for
    a numerically singular one; pinv never does. The check catches both."""
    def inv_based(x, P, z, z_hat, H, R):
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        nu = dense.innovation(z, z_hat)
        x_new = x + K @ nu
        x_new[2] = (x_new[2] + np.pi) % (2 * np.pi) - np.pi
        return x_new, my_joseph_covariance(P, H, R, K)

    with pytest.raises(GradingError, match=r"rank 1.*returned 'a pair \(x_new, P_new\).*"
                                           r"should raise ValueError because the innovation "
                                           r"covariance S is singular"):
        gk.check_ekf_update(inv_based)
    with pytest.raises(GradingError, match=r"should raise ValueError"):
        gk.check_ekf_update(_update_variant("pinv"))

    def wrong_exception(x, P, z, z_hat, H, R):
        if np.linalg.eigvalsh(H @ P @ H.T + R)[0] <= 1e-12:
            raise RuntimeError("singular")
        return my_ekf_update(x, P, z, z_hat, H, R)

    with pytest.raises(GradingError, match=r"raised RuntimeError: singular; expected ValueError"):
        gk.check_ekf_update(wrong_exception)


def test_student_exceptions_name_the_case():
    def broken(x, P, z, z_hat, H, R):
        return x + P @ z                          # shapes do not fit
    with pytest.raises(GradingError, match=r"my_ekf_update\(case='#0: N = 6 landmarks.*"
                                           r"raised ValueError"):
        gk.check_ekf_update(broken)


# ---------------------------------------------------------------- (d) the stub

@pytest.mark.parametrize("check", [gk.check_augment, gk.check_joseph_covariance,
                                   gk.check_ekf_update])
def test_stub_is_not_written_yet(check):
    with pytest.raises(GradingError, match=NOT_WRITTEN):
        check(stub)
