"""The statistics of the ANN verdict over folds of data (chapter 08): the decision rule
:data:`FOLD_RULE`, its margin of practical equivalence, the corrected resampled t-interval of
Nadeau and Bengio (2003) for folds that share training data, two one-sided tests (TOST) and the
exact sign-flip p-value; :func:`fold_comparison` applies them to two configurations' values
fold by fold. Pure numbers: the folds themselves are computed by ``paper.study.fold_study``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _checks

__all__ = ["FOLD_RULE", "FOLD_MARGIN", "FOLD_WORDS", "FOLD_METRICS", "sign_flip_p",
           "corrected_se", "corrected_interval", "tost_p", "FoldComparison", "fold_comparison"]


#: The margin of practical equivalence of :data:`FOLD_RULE`: a share of the comparator's
#: mean error over the folds (0.10: a tenth; the rule says why).
FOLD_MARGIN = 0.10

#: The words of :data:`FOLD_RULE`, in the order they are decided (:attr:`FoldComparison.decision`).
FOLD_WORDS = ("better", "worse", "equivalent within the margin", "not demonstrated")

#: The decision rule of :func:`fold_study`'s comparisons: the design fixed before any result,
#: the margin of practical equivalence added after a first reading (said in the rule).
FOLD_RULE = (
    "Five contiguous time folds (equal numbers of training samples): for each, networks "
    "trained outside the window +- 2 s (early stopping on a seeded random 15 % of those), "
    "seeds 0, 1, 2; the fold's value is the mean over the seeds of the trajectory RMSE "
    "against GPS inside the window. Five leave-beacons-out folds, the same three seeds: the "
    "map RMSE over the fold's held-out beacons (absolute, and with the whole map aligned). "
    "For each fold the ANN filter's value minus the comparator's on the same window or "
    "beacons. The five differences are not independent: any two folds' networks share most "
    "of their training data. So the 95 % interval of the mean difference is the corrected "
    "resampled t-interval of Nadeau and Bengio (2003): the sample variance of the "
    "differences times (1/k + n_test/n_train) instead of 1/k, with k = 5 folds, n_test/n_train "
    "the study's mean held-out over mean training samples per fold, and Student's t with 4 "
    "dof. Margin of practical equivalence: 10 % of the comparator's mean error over the "
    "folds. Why 10 %: the paper offers the network as a gain in accuracy, worth a trained "
    "network and a surveyed map; a gain smaller than a tenth of the error would not change "
    "what a user of the track or the map can do with it, so it is no improvement in "
    "practice. The margin was added to this rule after a first reading of the results; its "
    "reason is that claim, and the smallest margin that would change any word is printed "
    "beside the results. 'better' if the whole "
    "interval is below 0, 'worse' if above; otherwise 'equivalent within the margin' if two "
    "one-sided t-tests (TOST, the same corrected variance and dof) each put the mean "
    "difference inside +- the margin at the 5 % level (the corrected 90 % interval lies "
    "inside the margin); otherwise 'not demonstrated'. The exact sign-flip p-value is shown "
    "beside it as a description only: it treats the folds as independent too, and with five "
    "folds it cannot fall below 2/32 = 0.0625, so it never decides. The claim 'thanks to "
    "the ANN' holds with 'better' against both the plain filter and the control with the "
    "network's R'; it does not hold if the ANN is 'equivalent within the margin' or 'worse' "
    "against either; otherwise it is 'not demonstrated'.")

#: Metrics of :class:`FoldStudy`: name -> (fold kind, what it measures).
FOLD_METRICS = {
    "traj_rmse": ("time", "trajectory RMSE against GPS inside the fold's window, m"),
    "map_rmse": ("beacons", "map RMSE over the fold's held-out beacons, m"),
    "map_rmse_aligned": ("beacons", "the same with the whole map aligned onto the survey, m"),
}


def sign_flip_p(differences) -> float:
    """Exact two-sided sign-flip (paired permutation) p-value of the mean of
    ``differences``: the share of the 2^n sign patterns whose mean is at least as far from
    0 as the observed one (n <= 20)."""
    d = np.asarray(differences, dtype=float).ravel()
    if d.size == 0 or d.size > 20 or not np.all(np.isfinite(d)):
        raise ValueError(f"sign_flip_p needs 1 to 20 finite differences, got {d}")
    signs = 1 - 2 * ((np.arange(2 ** d.size)[:, None] >> np.arange(d.size)) & 1)
    means = np.abs(signs @ d) / d.size
    return float(np.mean(means >= abs(d.mean()) * (1 - 1e-12)))


def _fold_differences(differences, name: str = "differences") -> np.ndarray:
    """``differences`` as a finite 1-D float array of at least 2 values (ValueError otherwise)."""
    d = _checks.array(name, differences)
    if d.ndim != 1 or d.size < 2:
        raise ValueError(f"{name} must be a 1-D array of at least 2 fold values, got shape "
                         f"{d.shape}")
    return d


def _ratio(test_train_ratio) -> float:
    return _checks.real("test_train_ratio", test_train_ratio, lo=0.0)


def corrected_se(differences, test_train_ratio: float) -> float:
    """Standard error of the mean of k fold ``differences`` whose models share training
    data: the corrected resampled t-test of Nadeau and Bengio (2003, Machine Learning 52,
    eq. for the variance of the CV estimate; notebook 08 section 4, :data:`FOLD_RULE`)

        se = sqrt((1/k + n_test/n_train) * s^2),   s^2 the sample variance (ddof 1),

    instead of the independent-folds sqrt(s^2 / k) (``test_train_ratio`` = 0 gives that).
    ``test_train_ratio``: n_test / n_train, held-out over training samples of one fold."""
    d = _fold_differences(differences)
    r = _ratio(test_train_ratio)
    return float(math.sqrt((1.0 / d.size + r) * float(np.var(d, ddof=1))))


def corrected_interval(differences, test_train_ratio: float, prob: float = 0.95) -> tuple:
    """The ``prob`` interval (lo, hi) of the mean of k fold ``differences``: mean +- t *
    :func:`corrected_se`, t the two-sided Student quantile with k - 1 dof (Nadeau and
    Bengio 2003; notebook 08 section 4). ``test_train_ratio`` = 0: the ordinary t-interval,
    which treats the folds as independent and is narrower whenever n_test/n_train > 0."""
    from scipy.stats import t as student_t
    p = _checks.probability("prob", prob)
    d = _fold_differences(differences)
    half = float(student_t.ppf(0.5 * (1 + p), d.size - 1)) * corrected_se(d, test_train_ratio)
    m = float(d.mean())
    return m - half, m + half


def tost_p(differences, margin: float, test_train_ratio: float = 0.0) -> float:
    """p-value of equivalence within +- ``margin`` by two one-sided t-tests (TOST,
    Schuirmann 1987; notebook 08 section 4, :data:`FOLD_RULE`): H0 is |mean| >= margin;

        p = max(P(T >= (mean + margin) / se), P(T <= (mean - margin) / se)),

    T Student's t with k - 1 dof, se :func:`corrected_se` (``test_train_ratio`` = 0: the
    independent-folds one). p < alpha means equivalence at level alpha, the same as the
    1 - 2 alpha interval lying inside +- margin. With se = 0 (identical differences) p is
    0 inside the margin and 1 on or outside it. ``margin`` must be positive and finite."""
    from scipy.stats import t as student_t
    d = _fold_differences(differences)
    delta = _checks.real("margin", margin, lo=0.0, strict=True)
    se = corrected_se(d, test_train_ratio)
    m = float(d.mean())
    if se == 0.0:
        return 0.0 if abs(m) < delta else 1.0
    dof = d.size - 1
    p_low = float(student_t.sf((m + delta) / se, dof))     # H0: mean <= -margin
    p_high = float(student_t.cdf((m - delta) / se, dof))   # H0: mean >= +margin
    return max(p_low, p_high)


@dataclass(frozen=True)
class FoldComparison:
    """``a`` minus ``b`` over k folds by :data:`FOLD_RULE` (:func:`fold_comparison`).

    values (k,) the per-fold differences, mean; test_train_ratio n_test / n_train; se and
    (lo, hi) the corrected standard error and ``prob`` interval (Nadeau and Bengio 2003);
    se_naive, (lo_naive, hi_naive) the same treating the folds as independent (narrower);
    margin (> 0, in the metric's unit) and p_equivalence, the TOST p-value against it;
    p_sign_flip the exact sign-flip p-value (:func:`sign_flip_p`, a description only)."""

    a: str
    b: str
    metric: str
    values: np.ndarray
    mean: float
    test_train_ratio: float
    se: float
    lo: float
    hi: float
    se_naive: float
    lo_naive: float
    hi_naive: float
    margin: float
    p_equivalence: float
    p_sign_flip: float
    prob: float

    @property
    def decision(self) -> str:
        """The word of :data:`FOLD_RULE` (:data:`FOLD_WORDS`): 'better' if the corrected
        interval is below 0, 'worse' if above, else 'equivalent within the margin' if the
        TOST p-value is below 1 - prob, else 'not demonstrated'."""
        if self.hi < 0:
            return "better"
        if self.lo > 0:
            return "worse"
        if self.p_equivalence < 1 - self.prob:
            return "equivalent within the margin"
        return "not demonstrated"

    @property
    def equivalence_bound(self) -> float:
        """The smallest margin the folds would call equivalent at level 1 - prob: |mean| +
        t * se, t the one-sided 1 - (1 - prob) quantile with k - 1 dof (the far end of the
        corrected 1 - 2 (1 - prob) interval)."""
        from scipy.stats import t as student_t
        t1 = float(student_t.ppf(self.prob, self.values.size - 1))
        return abs(self.mean) + t1 * self.se

    def text(self, unit: str = "m") -> str:
        """mean [corrected interval] (independent folds: [interval]), margin, TOST p: word."""
        return (f"{self.mean:+.3f} {unit} [{self.lo:+.3f}, {self.hi:+.3f}] (as if independent: "
                f"[{self.lo_naive:+.3f}, {self.hi_naive:+.3f}]), margin ±{self.margin:.3f} "
                f"{unit}, TOST p {self.p_equivalence:.2f}: {self.decision}")


def fold_comparison(values_a, values_b, *, n_test, n_train, margin: float, a: str = "a",
                    b: str = "b", metric: str = "", prob: float = 0.95) -> FoldComparison:
    """``values_a - values_b`` fold by fold (k >= 2 folds, paired element by element) by
    :data:`FOLD_RULE` (notebook 08 section 4): the corrected resampled t-interval of
    Nadeau and Bengio (2003, :func:`corrected_interval`) with n_test / n_train =
    mean(``n_test``) / mean(``n_train``) (samples held out and trained on per fold: (k,)
    arrays or numbers), the TOST p-value against +- ``margin`` (:func:`tost_p`, same units
    as the values), the interval as if the folds were independent, and the sign-flip
    p-value. Raises ValueError for NaN or infinite values, arrays of other shapes or
    lengths, sample counts that are not positive, or a margin <= 0."""
    p = _checks.probability("prob", prob)
    va, vb = _checks.array("values_a", values_a), _checks.array("values_b", values_b)
    if va.ndim != 1 or va.shape != vb.shape:
        raise ValueError(f"values_a and values_b must be 1-D arrays of one length (a value "
                         f"per fold), got shapes {va.shape} and {vb.shape}")
    d = _fold_differences(va - vb, f"{metric or 'values'}: {a} - {b}")
    delta = _checks.real("margin", margin, lo=0.0, strict=True)
    sizes = {}
    for name, n in (("n_test", n_test), ("n_train", n_train)):
        arr = np.atleast_1d(_checks.array(name, n))
        if arr.ndim != 1 or arr.size not in (1, d.size) or np.any(arr <= 0):
            raise ValueError(f"{name} must be a positive number or {d.size} positive numbers "
                             f"(one per fold), got {arr}")
        sizes[name] = float(arr.mean())
    r = sizes["n_test"] / sizes["n_train"]
    lo, hi = corrected_interval(d, r, p)
    lo0, hi0 = corrected_interval(d, 0.0, p)
    return FoldComparison(a=a, b=b, metric=metric, values=d, mean=float(d.mean()),
                          test_train_ratio=r, se=corrected_se(d, r), lo=lo, hi=hi,
                          se_naive=corrected_se(d, 0.0), lo_naive=lo0, hi_naive=hi0,
                          margin=delta, p_equivalence=tost_p(d, delta, r),
                          p_sign_flip=sign_flip_p(d) if d.size <= 20 else math.nan, prob=p)
