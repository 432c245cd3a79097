"""Chapter 04 graders (annslam_lib.grading.association): right answers pass; the mistakes
the exercises are about (unwrapped bearing, S vs S^-1, R vs S, dof, mutual exclusion...)
fail with the message that names them."""
import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2


from annslam_lib.perception.association import NEW, REJECTED
from annslam_lib.grading import GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import association as gk
from annslam_lib.perception import association
from solutions import solution
from check_support import stub, wrap


def quiet(check, fn, **kw):
    return check(fn, quiet=True, **kw)


# ----------------------------------------------------------------------- the notebook's solutions

nb_d2 = solution("04", "my_innovation_d2")
nb_in_gate = solution("04", "my_in_gate")
nb_associate = solution("04", "my_associate")


def lib_d2(z, zhat, H, P, R):
    S = H @ P @ H.T + R
    return association.mahalanobis(np.asarray(z)[None], np.asarray(zhat)[None],
                                   (0.5 * (S + S.T))[None])[0, 0]


@pytest.mark.parametrize("check, fn", [
    (gk.check_innovation_d2, lib_d2), (gk.check_innovation_d2, nb_d2),
    (gk.check_in_gate, lambda d2, p: d2 <= association.gate_threshold(p)),
    (gk.check_in_gate, nb_in_gate),
    (gk.check_in_gate, lambda d2, p: d2 <= -2 * math.log(1 - p)),     # the closed form
    (gk.check_in_gate, lambda d2, p: chi2.cdf(d2, 2) <= p),           # the CDF side
    (gk.check_associate, lambda d2, g, n: association.associate(d2, g, n)),
    (gk.check_associate, nb_associate),
])
@pytest.mark.parametrize("seed", [0, 5])
def test_right_answers_pass(check, fn, seed):
    msg = quiet(check, fn, seed=seed, n=60)
    assert msg.startswith("✓") and "agrees with" in msg


def test_success_message_is_printed_once(capsys):
    gk.check_innovation_d2(nb_d2)
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 1 and "raises ValueError for all 4 S" in out[0]


@pytest.mark.parametrize("check, name", [(gk.check_innovation_d2, "my_innovation_d2"),
                                         (gk.check_in_gate, "my_in_gate"),
                                         (gk.check_associate, "my_associate")])
def test_stub_is_not_written_yet(check, name):
    with pytest.raises(GradingError, match=f"{name} is not written yet"):
        quiet(check, stub)


# ----------------------------------------------------------------------- 4.1 d2

def d2_variant(inner, *, wrapped=True):
    """nu' M nu with M = inner(S, H P H^T, R)."""
    def fn(z, zhat, H, P, R):
        nu = np.asarray(z, float) - np.asarray(zhat, float)
        if wrapped:
            nu[1] = wrap(nu[1])
        HPH = H @ P @ H.T
        return float(nu @ inner(HPH + R, HPH, R) @ nu)
    return fn


@pytest.mark.parametrize("fn, phrase", [
    (d2_variant(lambda S, HPH, R: np.linalg.inv(S), wrapped=False),
     "does not wrap the bearing innovation"),
    (d2_variant(lambda S, HPH, R: S), "weighs the innovation with S itself"),
    (d2_variant(lambda S, HPH, R: np.linalg.inv(R)), "uses the laser's noise R alone"),
    (d2_variant(lambda S, HPH, R: np.linalg.inv(HPH)), "leaves the measurement noise out"),
    (d2_variant(lambda S, HPH, R: np.diag(1 / np.diag(S))), "only the diagonal of S"),
    (lambda *a: math.sqrt(nb_d2(*a)), "distance, not its square"),
])
def test_d2_mistakes(fn, phrase):
    with pytest.raises(GradingError, match=phrase):
        quiet(gk.check_innovation_d2, fn)


def test_the_seam_cases_really_cross_the_seam():
    """The unwrapped-innovation mistake is caught because cases cross +-pi: there the raw
    bearing difference is nearly 2 pi while the wrapped one is below 0.02 rad."""
    cases = gk._d2_cases(0, 0)
    raw = [abs(z[1] - zhat[1]) for z, zhat, *_ in cases[:2]]
    assert all(r > 2 * np.pi - 0.02 for r in raw)
    assert all(abs(wrap(z[1] - zhat[1])) < 0.02 for z, zhat, *_ in cases[:2])


def test_d2_without_a_definiteness_test_must_raise():
    def no_test(z, zhat, H, P, R):
        nu = np.array([z[0] - zhat[0], wrap(z[1] - zhat[1])])
        return float(nu @ np.linalg.inv(H @ P @ H.T + R) @ nu)

    # np.linalg.inv raises for the exactly singular S, but not when rounding leaves a
    # determinant of 1e-20: d2 ~ 1e15 must not pass.
    with pytest.raises(GradingError, match=r"returned \S+e\+1\d; it should raise ValueError "
                                           r"because S = H P H\^T \+ R has rank 1"):
        quiet(gk.check_innovation_d2, no_test)

    def det_test(z, zhat, H, P, R):        # catches singular S, not an indefinite one
        S = H @ P @ H.T + R
        if abs(np.linalg.det(S)) < 1e-15:
            raise ValueError("singular")
        return no_test(z, zhat, H, P, R)

    with pytest.raises(GradingError, match=r"returned -3; it should raise ValueError because "
                                           r"S has a negative variance"):
        quiet(gk.check_innovation_d2, det_test)


def test_singular_cases_are_rejected_by_the_library_too():
    for args, _ in gk._singular_cases():
        with pytest.raises(ValueError, match="not positive definite"):
            lib_d2(*args)


# ----------------------------------------------------------------------- 4.2 gate

@pytest.mark.parametrize("fn, phrase", [
    (lambda d, p: d <= chi2.ppf(p, 1), "1 degree of freedom"),
    (lambda d, p: d <= chi2.ppf(1 - p, 2), "only the share 1 − prob"),
    (lambda d, p: d <= -2 * math.log(p), "only the share 1 − prob"),
    (lambda d, p: math.sqrt(d) <= chi2.ppf(p, 2), "compares √d2"),
    (lambda d, p: d <= math.sqrt(chi2.ppf(p, 2)), "square root of the threshold"),
    (lambda d, p: d <= 9.0, "'3σ' rule"),
    (lambda d, p: d <= 9.21034, "ignores prob"),
    (lambda d, p: d > chi2.ppf(p, 2), "inverted"),
])
def test_gate_mistakes(fn, phrase):
    with pytest.raises(GradingError, match=phrase):
        quiet(gk.check_in_gate, fn)


def test_gate_other_errors_say_where_and_why():
    with pytest.raises(GradingError, match=r"my_in_gate\(d2=9.3, prob=0.99\) returned True, but "
                                           r"the measurement is outside \(False\) the 99 % gate\.$"):
        quiet(gk.check_in_gate, lambda d, p: d <= chi2.ppf(p, 3))
    with full_feedback(), pytest.raises(GradingError, match=r"99 % gate\. The gate is "
                                                            r"d2 <= −2 ln\(1 − prob\).* = 9.21"):
        quiet(gk.check_in_gate, lambda d, p: d <= chi2.ppf(p, 3))
    with pytest.raises(GradingError, match="should return True .* or False"):
        quiet(gk.check_in_gate, lambda d, p: chi2.ppf(p, 2))


@pytest.mark.parametrize("check, fn, formula", [
    (gk.check_in_gate, lambda d, p: d <= -2 * math.log(p), "−2 ln(1 − prob)"),
    (gk.check_in_gate, lambda d, p: d <= 9.0, "−2 ln(1 − prob)"),
    (gk.check_innovation_d2, d2_variant(lambda S, HPH, R: S), "νᵀ S⁻¹ ν"),
    (gk.check_innovation_d2, d2_variant(lambda S, HPH, R: np.linalg.inv(R)), "S = H P H^T + R"),
])
def test_the_formula_is_in_the_instructors_feedback_only(check, fn, formula):
    """The student's own check names the kind of mistake; what would hand the exercise over
    is added only to the feedback an instructor returns (exercise 4.2 derives the gate)."""
    with pytest.raises(GradingError) as plain:
        quiet(check, fn)
    assert formula not in str(plain.value)
    with full_feedback(), pytest.raises(GradingError) as full:
        quiet(check, fn)
    assert formula in str(full.value) and str(full.value).startswith(str(plain.value))


def test_the_gate_must_be_derived_not_looked_up():
    """Exercise 4.2 derives the 2-dof quantile: a solution calling scipy's ppf is refused
    (the rule this module's other tests switch off, see conftest.py)."""
    from annslam_lib.grading import core

    token = core._ALLOWED.set(False)
    try:
        with pytest.raises(GradingError, match="calls .*ppf: write it yourself"):
            gk.check_in_gate(lambda d, p: bool(d <= chi2.ppf(p, 2)), quiet=True)
        gk.check_in_gate(lambda d, p: bool(d <= -2 * math.log(1 - p)), quiet=True)
    finally:
        core._ALLOWED.reset(token)


def test_gate_cases_straddle_each_threshold_and_the_one_dof_gap():
    cases = gk._gate_cases(0, 0)
    for p in gk._PROBS:
        t = chi2.ppf(p, 2)
        d = [c[0] for c in cases if c[1] == p]
        assert any(t * 0.9 < x < t for x in d) and any(t < x < t * 1.1 for x in d)
    assert any(chi2.ppf(0.99, 1) < d < chi2.ppf(0.99, 2) for d, p in cases if p == 0.99)
    assert any(9.0 < d < chi2.ppf(0.99, 2) for d, p in cases if p == 0.99)


# ----------------------------------------------------------------------- 4.3 associate

def row_by_row(d2, gate, new):
    """Each measurement in turn takes its nearest free landmark (no global order)."""
    n, m = d2.shape
    out = np.full(n, REJECTED)
    used = set()
    for i in range(n):
        if m == 0 or np.min(d2[i]) > new:
            out[i] = NEW
            continue
        for j in np.argsort(d2[i]):
            if d2[i, j] <= gate and j not in used:
                out[i] = j
                used.add(j)
                break
    return out


def argmin_only(d2, gate, new):
    """Nearest neighbour without mutual exclusion."""
    n, m = d2.shape
    if m == 0:
        return np.full(n, NEW)
    j = np.argmin(d2, axis=1)
    best = d2[np.arange(n), j]
    return np.where(best <= gate, j, np.where(best > new, NEW, REJECTED))


def hungarian(d2, gate, new):
    n, m = d2.shape
    out = np.where(np.min(d2, axis=1) > new, NEW, REJECTED) if m else np.full(n, NEW)
    if m and n:
        rows, cols = linear_sum_assignment(np.where(d2 <= gate, d2, 1e9))
        for a, b in zip(rows, cols):
            if d2[a, b] <= gate:
                out[a] = b
    return out


def lib_then(change):
    def fn(d2, g, n):
        a = association.associate(d2, g, n)
        change(a)
        return a
    return fn


def test_associate_without_mutual_exclusion():
    with pytest.raises(GradingError) as e:
        quiet(gk.check_associate, argmin_only)
    msg = str(e.value)
    assert "'two measurements, one landmark'" in msg and "Expected [-2, 0], got [0, 0]" in msg
    assert "landmark 0 received both z1 and z0: mutual exclusion" in msg
    assert "(z1: 1.2, z0: 3)" in msg


def test_associate_row_by_row_instead_of_increasing_d2():
    with pytest.raises(GradingError) as e:
        quiet(gk.check_associate, row_by_row)
    msg = str(e.value)
    assert "Expected [-2, 0], got [0, -2]" in msg
    assert "z0 was given landmark 0 (d2 3), but landmark 0 belongs to z1, whose d2 1.2" in msg
    assert "increasing d2 over the whole matrix" in msg and "REJECTED (-2)" in msg


def test_associate_optimal_instead_of_greedy():
    # A Hungarian assignment agrees on most scenes; it differs where greedy is not optimal.
    with pytest.raises(GradingError, match="'pairs in increasing d2 over the whole matrix"):
        quiet(gk.check_associate, hungarian)
    scene = [s for s in gk._assign_scenes() if s[0].startswith("greedy")][0]
    assert hungarian(*scene[1:]).tolist() == [1, 0]
    assert association.associate(scene[1], scene[2], scene[3]).tolist() == [0, 1]


@pytest.mark.parametrize("change, phrase", [
    (lambda a: a.__setitem__(a == NEW, REJECTED), r"NEW landmark \(-1\), not REJECTED \(-2\)"),
    (lambda a: a.__setitem__(a == REJECTED, NEW), "not far enough from every landmark to be new"),
])
def test_associate_new_versus_rejected(change, phrase):
    with pytest.raises(GradingError, match=phrase):
        quiet(gk.check_associate, lib_then(change))


def test_associate_must_use_its_arguments():
    with pytest.raises(GradingError, match=r"'a 99.9 % gate .*inside the gate of landmark 0 "
                                           r"\(d2 12 <= 13.82\)"):
        quiet(gk.check_associate, lambda d2, g, n: association.associate(d2))


def test_associate_gate_violation_and_bad_outputs():
    def outside(d2, g, n):                 # gates as wide as the new-landmark threshold
        return association.associate(d2, gate=n, new_landmark=n)

    with pytest.raises(GradingError, match=r"z0 was given landmark 0, but its d2 = 12 is outside "
                                           r"the gate \(d2 <= 9.21\)"):
        quiet(gk.check_associate, outside)
    with pytest.raises(GradingError, match="one per measurement"):
        quiet(gk.check_associate, lambda d2, g, n: association.associate(d2, g, n)[:-1])
    with pytest.raises(GradingError, match="holds integers"):
        quiet(gk.check_associate, lambda d2, g, n: association.associate(d2, g, n) + 0.5)
    with pytest.raises(GradingError, match=r"landmark index 0..1, NEW \(-1\) or REJECTED \(-2\)"):
        quiet(gk.check_associate, lambda d2, g, n: association.associate(d2, g, n) + 2)


def test_crafted_scenes_expect_what_their_titles_say():
    """The scenes are hand-made; their expected assignments, worked out by hand."""
    expected = {"one measurement per gate": [0, 1, NEW],
                "nearest in d2, not the first landmark in the gate": [1],
                "two measurements, one landmark": [REJECTED, 0],
                "the loser takes its second choice": [1, 0],
                "pairs in increasing d2 over the whole matrix, not measurement by measurement":
                    [REJECTED, 0, 1],
                "between the gate and the new-landmark threshold": [REJECTED],
                "beyond the new-landmark threshold of every landmark": [NEW, NEW],
                "near one landmark, far from the other": [REJECTED],
                "an empty map": [NEW, NEW, NEW], "no measurements": [],
                "+inf: landmarks not worth testing": [1, NEW],
                "greedy, not the optimal assignment": [0, 1],
                "a 99.9 % gate (use the gate argument)": [0],
                "a higher new-landmark threshold (use the argument)": [REJECTED]}
    scenes = gk._assign_scenes()
    assert [s[0] for s in scenes] == list(expected)
    for title, d2, gate, new in scenes:
        assert association.associate(d2, gate, new).tolist() == expected[title], title
