"""The verdict's statistics (notebook 08): paired differences over the seeds with a
t-interval, checked against scipy's paired t-test; the decision rule; and the held-out map
error with the frame removed."""
import math

import numpy as np
import pytest
from scipy import linalg, stats

from annslam_lib.evaluation import summary
from annslam_lib.paper import study


def _study(**per_config):
    """A Study holding only per-seed values of 'map_rmse_heldout' per configuration."""
    n = len(next(iter(per_config.values())))
    runs = {k: [{"map_rmse_heldout": v} for v in vals] for k, vals in per_config.items()}
    return study.Study(dataset=None, seeds=tuple(range(n)), runs=runs, t_heldout=0.0,
                       results={}, models={}, training_set=None, split=None, folds=[],
                       natural_dataset=None)


def test_paired_interval_is_scipys_paired_t_interval():
    rng = np.random.default_rng(4)
    a, b = rng.normal(0.08, 0.01, 5), rng.normal(0.09, 0.01, 5)
    p = study.paired(_study(ann=a, beacons=b), "ann", "beacons", "map_rmse_heldout")
    ci = stats.ttest_rel(a, b).confidence_interval(0.95)
    assert p.mean == pytest.approx(np.mean(a - b), abs=1e-15)
    assert (p.lo, p.hi) == (pytest.approx(ci.low, rel=1e-12), pytest.approx(ci.high, rel=1e-12))
    # pairing matters: the unpaired interval of the same numbers is another one
    welch = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    assert abs(welch.low - p.lo) > 1e-4


@pytest.mark.parametrize("diff,decision", [
    ([-0.03, -0.02, -0.025, -0.028, -0.022], "better"),
    ([0.03, 0.02, 0.025, 0.028, 0.022], "worse"),
    ([-0.03, 0.02, -0.01, 0.015, 0.0], "no detectable difference"),
])
def test_decision_rule(diff, decision):
    base = np.full(5, 0.1)
    p = study.paired(_study(ann=base + diff, beacons=base), "ann", "beacons", "map_rmse_heldout")
    assert p.decision == decision
    assert p.decision in study.DECISION_RULE or decision == "no detectable difference"


def test_one_seed_decides_nothing_and_nan_is_refused():
    p = study.paired(_study(ann=[0.05], beacons=[0.09]), "ann", "beacons", "map_rmse_heldout")
    assert (p.lo, p.hi) == (-math.inf, math.inf) and p.decision == "no detectable difference"
    with pytest.raises(ValueError, match="non-finite"):
        study.paired(_study(ann=[0.05, np.nan], beacons=[0.09, 0.1]), "ann", "beacons",
                     "map_rmse_heldout")
    with pytest.raises(ValueError, match="unknown"):
        study.paired(_study(ann=[0.05], beacons=[0.09]), "ann", "nope", "map_rmse_heldout")


class _Run:
    def __init__(self, landmarks):
        self.landmarks = np.asarray(landmarks, dtype=float)


def test_heldout_map_error_aligned_removes_the_frame_only():
    rng = np.random.default_rng(1)
    beacons = rng.uniform(-20, 20, (15, 2))
    noisy = beacons + rng.normal(0, 0.03, beacons.shape)
    th = math.radians(0.5)
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    moved = noisy @ R.T + [0.2, -0.1]               # the same map in a frame 0.5 deg, 22 cm off
    held = [2, 7, 11]
    shape = summary.heldout_map_rmse(_Run(noisy), beacons, held, aligned=True)
    assert summary.heldout_map_rmse(_Run(moved), beacons, held, aligned=True) == \
        pytest.approx(shape, abs=1e-9)
    absolute = summary.heldout_map_rmse(_Run(moved), beacons, held)
    assert absolute > 0.15 > 0.06 > shape
    # by hand: align everything (Kabsch via scipy's orthogonal Procrustes), score the three
    a, b = noisy - noisy.mean(0), beacons - beacons.mean(0)
    Rp, _ = linalg.orthogonal_procrustes(a, b)
    fit = a @ Rp + beacons.mean(0)
    assert shape == pytest.approx(np.sqrt(np.mean(np.sum((fit - beacons)[held] ** 2, 1))), rel=1e-9)


# ------------------------------------------ the fold rule: corrected interval, TOST, words

# Fold sizes of the Car Park's time folds (paper.study.fold_study): held out, trained on.
N_TEST, N_TRAIN = [177, 176, 176, 175, 179], [680, 667, 675, 677, 689]


def _by_hand(d, ratio, q):
    """Mean and half-width of the corrected resampled t-interval, written out: sample
    variance with k - 1, times (1/k + n_test/n_train), Student's t quantile q, k - 1 dof."""
    k = len(d)
    m = sum(d) / k
    s2 = sum((x - m) ** 2 for x in d) / (k - 1)
    return m, stats.t.ppf(q, k - 1) * math.sqrt((1 / k + ratio) * s2)


def test_corrected_interval_is_nadeau_and_bengios():
    d = [0.009, 0.033, -0.025, 0.017, -0.033]
    ratio = sum(N_TEST) / sum(N_TRAIN)
    c = study.fold_comparison(d, np.zeros(5), n_test=N_TEST, n_train=N_TRAIN, margin=0.012)
    m, half = _by_hand(d, ratio, 0.975)
    assert c.test_train_ratio == pytest.approx(ratio, rel=1e-12)
    assert (c.mean, c.lo, c.hi) == pytest.approx((m, m - half, m + half), rel=1e-12, abs=1e-15)
    assert study.corrected_interval(d, ratio) == pytest.approx((m - half, m + half), rel=1e-12)
    # the old interval is scipy's one-sample t-interval, and strictly narrower
    ci = stats.ttest_1samp(d, 0.0).confidence_interval(0.95)
    assert (c.lo_naive, c.hi_naive) == pytest.approx((ci.low, ci.high), rel=1e-12)
    assert c.lo < c.lo_naive < c.hi_naive < c.hi
    assert (c.hi - c.lo) / (c.hi_naive - c.lo_naive) == pytest.approx(math.sqrt(1 + 5 * ratio))
    assert c.se == pytest.approx(study.corrected_se(d, ratio)) and c.se > c.se_naive
    # scalar sample counts are the same as constant per-fold ones
    same = study.fold_comparison(d, np.zeros(5), n_test=176, n_train=680, margin=0.012)
    assert same.test_train_ratio == pytest.approx(176 / 680)


def test_tost_is_two_one_sided_t_tests():
    d = np.array([-1.0, 0.0, 1.0, 0.0, 0.0])          # mean 0, s^2 = 0.5: se = sqrt(0.1) by hand
    assert study.tost_p(d, 1.0) == pytest.approx(stats.t.sf(1.0 / math.sqrt(0.1), 4), rel=1e-12)
    d = np.array([0.004, -0.002, 0.006, 0.001, 0.003])
    ratio = 0.25
    se = math.sqrt((1 / 5 + ratio) * np.var(d, ddof=1))
    for margin in (0.002, 0.005, 0.01):
        lower = stats.t.sf((d.mean() + margin) / se, 4)        # H0: mean <= -margin
        upper = stats.t.cdf((d.mean() - margin) / se, 4)       # H0: mean >= +margin
        p = study.tost_p(d, margin, ratio)
        assert p == pytest.approx(max(lower, upper), rel=1e-12)
        # at 5 %: the same as the corrected 90 % interval inside the margin
        lo, hi = study.corrected_interval(d, ratio, 0.90)
        assert (p < 0.05) == (-margin < lo and hi < margin)
    assert study.tost_p(np.full(4, 0.001), 0.01) == 0.0 and study.tost_p(np.full(4, 0.02), 0.01) == 1.0


@pytest.mark.parametrize("d, margin, word", [
    ([-0.05, -0.04, -0.06, -0.045, -0.055], 0.01, "better"),
    ([0.05, 0.04, 0.06, 0.045, 0.055], 0.01, "worse"),
    ([0.001, -0.001, 0.0005, -0.0005, 0.0], 0.01, "equivalent within the margin"),
    ([0.03, -0.03, 0.02, -0.025, 0.004], 0.01, "not demonstrated"),
    # equivalent if the folds were independent, not once their shared training data counts
    ([0.004, -0.004, 0.003, -0.003, 0.0], 0.004, "not demonstrated"),
    # a gain shown, smaller than the margin: 'better' is decided first
    ([-0.002, -0.0021, -0.0019, -0.002, -0.002], 0.01, "better"),
])
def test_fold_words_on_planted_differences(d, margin, word):
    c = study.fold_comparison(d, np.zeros(5), n_test=N_TEST, n_train=N_TRAIN, margin=margin)
    assert c.decision == word and word in study.FOLD_WORDS and word in study.FOLD_RULE
    assert word in c.text()
    if word == "equivalent within the margin":
        assert c.equivalence_bound < margin and c.p_equivalence < 0.05
    if word == "not demonstrated":
        assert c.lo < 0 < c.hi and c.p_equivalence >= 0.05 and c.equivalence_bound >= margin


def test_the_correction_is_what_turns_equivalent_into_not_demonstrated():
    d = [0.004, -0.004, 0.003, -0.003, 0.0]
    naive = study.fold_comparison(d, np.zeros(5), n_test=1e-9, n_train=1.0, margin=0.004)
    corrected = study.fold_comparison(d, np.zeros(5), n_test=N_TEST, n_train=N_TRAIN, margin=0.004)
    assert naive.decision == "equivalent within the margin"
    assert corrected.decision == "not demonstrated"


def test_the_claim_words():
    def comp(d):
        return study.fold_comparison(d, np.zeros(5), n_test=N_TEST, n_train=N_TRAIN, margin=0.01)
    better, worse = comp([-0.05, -0.04, -0.06, -0.045, -0.055]), comp([0.05, 0.04, 0.06, 0.045, 0.055])
    equal, unknown = comp([0.001, -0.001, 0.0005, -0.0005, 0.0]), comp([0.03, -0.03, 0.02, -0.025, 0.004])
    assert study.fold_claim(better, better) == "holds"
    assert study.fold_claim(better, equal) == "does not hold"          # its R' does it
    assert study.fold_claim(worse, unknown) == "does not hold"
    assert study.fold_claim(better, unknown) == "not demonstrated"
    assert study.fold_claim(unknown, unknown) == "not demonstrated"


@pytest.mark.parametrize("kwargs, match", [
    (dict(values_a=[0.1, np.nan, 0.2], values_b=[0.1, 0.1, 0.1]), "NaN"),
    (dict(values_a=[0.1, np.inf, 0.2], values_b=[0.1, 0.1, 0.1]), "NaN or infinite"),
    (dict(values_a=[0.1, 0.2, 0.3], values_b=[0.1, 0.1]), "one length"),
    (dict(values_a=np.zeros((3, 2)), values_b=np.zeros((3, 2))), "1-D"),
    (dict(values_a=[0.1], values_b=[0.2]), "at least 2"),
    (dict(margin=0.0), "margin must be > 0"),
    (dict(margin=-0.01), "margin must be > 0"),
    (dict(margin=float("nan")), "margin"),
    (dict(n_test=[10, 0, 10]), "n_test must be a positive"),
    (dict(n_train=[100, 100]), "n_train must be a positive"),
    (dict(n_test=[10, np.nan, 10]), "n_test"),
    (dict(prob=1.0), "prob"),
])
def test_fold_comparison_refuses_bad_input(kwargs, match):
    args = dict(values_a=[0.1, 0.2, 0.15], values_b=[0.12, 0.18, 0.2], n_test=10, n_train=40,
                margin=0.01)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        study.fold_comparison(args.pop("values_a"), args.pop("values_b"), **args)


def test_the_rule_states_its_margin_correction_and_words():
    assert study.FOLD_MARGIN == 0.10 and "10 % of the comparator's mean error" in study.FOLD_RULE
    assert "Nadeau and Bengio" in study.FOLD_RULE and "(1/k + n_test/n_train)" in study.FOLD_RULE
    assert all(w in study.FOLD_RULE for w in study.FOLD_WORDS)
    with pytest.raises(ValueError, match="margin"):
        study.tost_p([0.1, 0.2], 0.0)
    with pytest.raises(ValueError, match="test_train_ratio"):
        study.corrected_se([0.1, 0.2], -0.1)


def test_report_table_prints_a_rows_own_word():
    """A tested but undecided row says 'not demonstrated' in the reproduce report, not
    'not testable this way' (which is for rows the study cannot test)."""
    from annslam_lib.paper.report import verdict_markdown
    rows = [dict(claim="a", measured="m", holds=None, verdict="not demonstrated", why="w"),
            dict(claim="b", measured="m", holds=None, why="w"),
            dict(claim="c", measured="m", holds=True, verdict="holds", why="w")]
    lines = verdict_markdown(rows).splitlines()[2:]
    assert "**not demonstrated**" in lines[0] and "not testable this way" in lines[1]
    assert "**holds**" in lines[2]
