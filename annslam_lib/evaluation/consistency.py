"""Is a filter consistent? NEES, NIS and their chi-square bands (notebook 05).

A consistent filter's normalised errors are chi-square distributed: the pose NEES
e^T P^-1 e (3 dof) against the simulator's truth, and the innovation NIS nu^T S^-1 nu (2 dof
per observation) on any run. A statistic is compared with the band of ITS OWN distribution:
the average of N independent runs at one scan with the band of an average of N chi-square
values (:func:`chi2_band`), scan by scan; a time average over hundreds of correlated scans
cannot be compared with a per-scan band. The map is judged as a whole: the NEES of all
landmarks together with their joint covariance (2 N dof per run), summed over runs.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _checks
from .._cache import memoize as _memoize
from ..data.records import Dataset
from ..models.geometry import wrap_angle
from ..models.uncertainty import chi2_quantile, mahalanobis2

__all__ = ["chi2_quantile", "chi2_band", "Consistency", "nees_consistency", "scan_nis",
           "nis_consistency", "pose_nees", "map_nees", "MapConsistency", "map_consistency",
           "correlation_matrix", "MonteCarlo", "monte_carlo", "MARGIN", "EFFECT_RULE",
           "Effect", "ratio_effect", "paired_effect", "run_ratios"]


def chi2_band(dof, n=1, prob: float = 0.95) -> tuple[np.ndarray | float, np.ndarray | float]:
    """Two-sided ``prob`` band (lo, hi) of the AVERAGE of ``n`` independent chi-square
    values of ``dof`` degrees of freedom: chi2.ppf([(1 - prob)/2, (1 + prob)/2], n dof) / n.

    The NEES band of N Monte-Carlo runs (3 dof) is ``chi2_band(3, N)``; the band of a
    normalised NIS, total NIS / total dof D, is ``chi2_band(1, D)``. ``dof`` and ``n``
    may be arrays (broadcast); both must be positive. Notebook 05.

    Parameters
    ----------
    dof : float or array_like
        Degrees of freedom of each chi-square value, > 0.
    n : int or array_like, optional
        Number of values averaged, > 0, broadcast with ``dof``.
    prob : float, optional
        Probability of the two-sided band, in (0, 1).

    Returns
    -------
    lo, hi : float or ndarray
        The band's ends: floats for scalar inputs, else arrays of the broadcast shape.

    Raises
    ------
    ValueError
        If ``dof`` or ``n`` is not positive and finite, or ``prob`` is outside (0, 1).
    """
    p = _checks.probability("prob", prob)
    d, k = np.asarray(dof, dtype=float), np.asarray(n, dtype=float)
    if not (np.all(np.isfinite(d)) and np.all(d > 0) and np.all(np.isfinite(k)) and np.all(k > 0)):
        raise ValueError(f"dof and n must be positive and finite, got {dof!r} and {n!r}")
    lo = chi2_quantile(0.5 * (1.0 - p), k * d) / k
    hi = chi2_quantile(0.5 * (1.0 + p), k * d) / k
    if lo.ndim == 0:
        return float(lo), float(hi)
    return lo, hi



@dataclass(frozen=True)
class Consistency:
    """A time-indexed Monte-Carlo consistency statistic and its band (notebook 05).

    t (K,): time of each row (s); value (K,): the run average (NEES) or the normalised
    sum over runs (NIS / dof); lo, hi (K,): its ``prob`` band; dof (K,): the degrees of
    freedom behind each row (all runs together); mean: the time average of ``value``
    (NEES) or total / total dof (NIS); inside: the fraction of rows inside their band;
    n_runs; prob; name."""

    name: str
    t: np.ndarray
    value: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    dof: np.ndarray
    mean: float
    inside: float
    n_runs: int
    prob: float

    def summary(self) -> str:
        return (f"{self.name}: time average {self.mean:.3f}, {100 * self.inside:.1f} % of "
                f"{self.t.size} scans inside the {100 * self.prob:.0f} % band "
                f"({self.n_runs} runs)")



def stack_runs(name: str, runs) -> np.ndarray:
    rows = [np.asarray(r, dtype=float) for r in runs]
    if not rows:
        raise ValueError(f"{name}: no runs given")
    if any(r.ndim != 1 for r in rows):
        raise ValueError(f"{name}: every run must be a one-dimensional array")
    lengths = {r.size for r in rows}
    if len(lengths) != 1:
        raise ValueError(f"{name}: the runs have different lengths {sorted(lengths)}; the "
                         "time-indexed average needs the same scans in every run")
    out = np.array(rows)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{name}: non-finite values")
    return out



def _times(t, K: int) -> np.ndarray:
    t = np.arange(K, dtype=float) if t is None else np.asarray(t, dtype=float)
    if t.shape != (K,):
        raise ValueError(f"t must have shape ({K},), got {t.shape}")
    return t



def nees_consistency(nees_runs, t=None, *, dof: int = 3, prob: float = 0.95) -> Consistency:
    """Average NEES over runs at each time (``nees_runs``: one (K,) array per run, the
    same K scans in each, e.g. ``evaluation.consistency.pose_nees``), against the band of the average
    of N chi2(dof) values (:func:`chi2_band`). ``mean`` is the time average (ANEES).

    Parameters
    ----------
    nees_runs : sequence of array_like, each shape (K,)
        The NEES of each of N runs, scan by scan.
    t : array_like, shape (K,), optional
        Time of each scan, s (default 0, 1, ..., K - 1).
    dof : int, optional
        Degrees of freedom of one NEES (3 for a pose).
    prob : float, optional
        Probability of the two-sided band, in (0, 1).

    Returns
    -------
    Consistency
        The average NEES at each scan with its band, the time average and the share of
        scans inside the band.

    Raises
    ------
    ValueError
        For no runs, runs of different lengths, non-finite values or a ``t`` of the
        wrong shape.
    """
    X = stack_runs("nees_runs", nees_runs)
    n, K = X.shape
    value = X.mean(axis=0)
    lo, hi = chi2_band(dof, n, prob)
    lo_a, hi_a = np.full(K, lo), np.full(K, hi)
    return Consistency(name=f"average NEES ({dof} dof)", t=_times(t, K), value=value,
                       lo=lo_a, hi=hi_a, dof=np.full(K, float(n * dof)), mean=float(value.mean()),
                       inside=float(np.mean((value >= lo) & (value <= hi))), n_runs=n,
                       prob=_checks.probability("prob", prob))



def scan_nis(result, n_scans: int) -> tuple[np.ndarray, np.ndarray]:
    """The laser-update NIS and its dof of every scan 0..n_scans-1 of an
    ``slam.results.SlamResult`` (0 and 0 where a scan had no update; GPS updates left out).

    Parameters
    ----------
    result : slam.results.SlamResult
        A run's result.
    n_scans : int
        Number of scans of the run.

    Returns
    -------
    nis : ndarray, shape (n_scans,)
        The NIS of each scan's laser update.
    dof : ndarray, shape (n_scans,)
        Its degrees of freedom (2 per associated observation).

    Raises
    ------
    ValueError
        If the result holds a scan index outside 0..n_scans-1.
    """
    nis = result.nis
    k = nis["kind"] == 0
    scans = nis["scan"][k]
    if scans.size and (scans.min() < 0 or scans.max() >= n_scans):
        raise ValueError(f"scan indices {scans.min()}..{scans.max()} outside 0..{n_scans - 1}")
    value, dof = np.zeros(n_scans), np.zeros(n_scans)
    value[scans] = nis["nis"][k]
    dof[scans] = nis["dof"][k]
    return value, dof



def nis_consistency(nis_runs, dof_runs, t=None, *, prob: float = 0.95) -> Consistency:
    """Normalised NIS at each scan: sum over runs of NIS / sum of dof, with the band
    ``chi2_band(1, D)`` for the D dof of that scan (one (K,) array per run each, as from
    :func:`scan_nis`). Scans without any update in any run are dropped. ``mean`` is
    the total NIS over the total dof.

    Parameters
    ----------
    nis_runs : sequence of array_like, each shape (K,)
        The NIS of each of N runs, scan by scan.
    dof_runs : sequence of array_like, each shape (K,)
        The matching degrees of freedom.
    t : array_like, shape (K,), optional
        Time of each scan, s (default 0, 1, ..., K - 1).
    prob : float, optional
        Probability of the two-sided band, in (0, 1).

    Returns
    -------
    Consistency
        NIS / dof at each scan with an update, with its band.

    Raises
    ------
    ValueError
        For no runs, runs of different lengths or shapes, non-finite values, no scan
        with an update, or a ``t`` of the wrong shape.
    """
    S, D = stack_runs("nis_runs", nis_runs), stack_runs("dof_runs", dof_runs)
    if S.shape != D.shape:
        raise ValueError(f"nis_runs {S.shape} and dof_runs {D.shape} differ in shape")
    s, d = S.sum(axis=0), D.sum(axis=0)
    keep = d > 0
    if not keep.any():
        raise ValueError("no scan has an update in any run")
    t = _times(t, S.shape[1])[keep]
    s, d = s[keep], d[keep]
    value = s / d
    lo, hi = chi2_band(1, d, prob)
    return Consistency(name="NIS / dof", t=t, value=value, lo=lo, hi=hi, dof=d,
                       mean=float(s.sum() / d.sum()),
                       inside=float(np.mean((value >= lo) & (value <= hi))),
                       n_runs=S.shape[0], prob=_checks.probability("prob", prob))



def correlation_matrix(P) -> np.ndarray:
    """Correlation coefficients C_ij = P_ij / sqrt(P_ii P_jj) of a covariance (n, n).

    Parameters
    ----------
    P : array_like, shape (n, n)
        A covariance matrix.

    Returns
    -------
    ndarray, shape (n, n)
        The correlation matrix, symmetric, ones on the diagonal, entries in [-1, 1].

    Raises
    ------
    ValueError
        For a non-square, non-finite or non-symmetric P, or a diagonal entry <= 0 (a
        variable without uncertainty has no correlation).
    """
    P = np.asarray(P, dtype=float)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"P must be a square matrix, got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError("P contains NaN or infinite values")
    scale = max(float(np.max(np.abs(P))), 1e-300) if P.size else 1.0
    if P.size and np.max(np.abs(P - P.T)) > 1e-9 * scale:
        raise ValueError("P is not symmetric")
    d = np.diag(P)
    if np.any(d <= 0):
        raise ValueError(f"P has a non-positive variance at index {int(np.argmin(d))}")
    s = np.sqrt(d)
    C = P / np.outer(s, s)
    return np.clip(0.5 * (C + C.T), -1.0, 1.0)


def pose_nees(result, dataset: Dataset) -> np.ndarray:
    """Normalised estimation error squared of the pose at every trajectory row (3 dof),
    e^T P^-1 e with e = estimate - truth (heading wrapped), against the simulator's true
    laser poses at the scan times (``dataset.info['scan_poses']``). Notebook 05.

    Parameters
    ----------
    result : slam.results.SlamResult
        A run on ``dataset``.
    dataset : records.Dataset
        A simulated dataset (with its truth).

    Returns
    -------
    ndarray, shape (K,)
        The NEES at each of the K rows of ``result.trajectory``.

    Raises
    ------
    ValueError
        If the dataset is not simulated (no ``info['scan_poses']``).
    """
    if dataset.truth is None or "scan_poses" not in dataset.info:
        raise ValueError("pose_nees needs a simulated dataset (with info['scan_poses'])")
    truth = np.asarray(dataset.info["scan_poses"])[result.scan_index]
    e = result.trajectory[:, 1:4] - truth
    e[:, 2] = wrap_angle(e[:, 2])
    return np.einsum("ki,ki->k", e, np.linalg.solve(result.pose_cov, e[..., None])[..., 0])


def map_nees(result, dataset: Dataset) -> tuple[float, int]:
    """NEES of the whole final map of a simulated run and its dof: e^T P_mm^-1 e with
    e the stacked landmark errors (estimate - the true beacon each landmark was made
    from, ``result.landmark_true_id``) and P_mm the landmarks' JOINT covariance (their
    block of ``result.covariance``, cross terms included); dof = 2 N. A consistent
    filter's map NEES is chi2(2 N). Raises ValueError without truth, or when a
    landmark has no true beacon (a spurious landmark has no error to normalise).
    Notebook 05."""
    beacons = getattr(dataset, "beacons", None)
    if dataset.truth is None or beacons is None:
        raise ValueError("map_nees needs a simulated dataset (with its true beacons)")
    ids = np.asarray(result.landmark_true_id)
    if ids.size == 0:
        raise ValueError("the run mapped no landmark")
    if np.any(ids < 0):
        raise ValueError(f"{int(np.sum(ids < 0))} landmark(s) match no true beacon: "
                         "the map NEES is defined for a map without spurious landmarks")
    est, truth = np.asarray(result.landmarks).ravel(), np.asarray(beacons)[ids].ravel()
    P = np.asarray(result.covariance)[3:, 3:]
    if P.shape != (est.size, est.size):
        raise ValueError(f"covariance block {P.shape} does not match {ids.size} landmarks")
    return float(mahalanobis2(est[None], truth, P)[0]), int(est.size)


#: The practical margin of the consistency verdicts, chosen before any result: a NEES ratio
#: within 1 +- MARGIN means standard deviations off by about 2.5 % or less (were S off by the
#: same ratio, a 99 % gate would pass 98.75 to 99.2 % of correct sightings).
MARGIN = 0.05

#: The decision rule of :func:`ratio_effect` and :func:`paired_effect`, fixed before any result.
EFFECT_RULE = (
    "One value per run (each run a new scene: its own beacon layout and noise), e.g. the "
    "run's time-averaged pose NEES divided by its 3 dof, or its map NEES per dof; the "
    "effect is the mean over the runs with its 95 % t-interval (the runs' own spread, so "
    "scene-to-scene variation is inside the interval). Words: 'over-confident' if the whole "
    "interval is above 1, 'under-confident' if below, otherwise 'no detectable difference'; "
    "and 'within the 5 % margin' if the interval lies inside [0.95, 1.05]. Two filters on "
    "the same runs: the mean of their per-run difference with its t-interval, 'higher' or "
    "'lower' if the interval excludes 0, otherwise 'no detectable difference'. The power "
    "is the chance that the rule calls a filter with ratio 1.05 (P / 1.05) over-confident, "
    "from the runs' own spread.")


def run_ratios(nees_runs, dof: int = 3) -> np.ndarray:
    """Each run's time-averaged NEES per degree of freedom (N,), from the pose NEES of N
    runs scan by scan (N, K) (``MonteCarlo.nees_runs``): 1 for a consistent filter.
    Chapters 04a and 05."""
    a = stack_runs("nees", nees_runs)
    _checks.integer("dof", dof, lo=1)
    return a.mean(axis=1) / dof


def _t_crit(n: int, prob: float) -> float:
    from scipy.stats import t as student_t
    return float(student_t.ppf(0.5 * (1 + prob), n - 1))


def _values(name: str, values) -> np.ndarray:
    v = np.asarray(values, dtype=float)
    if v.ndim != 1 or v.size < 3:
        raise ValueError(f"{name} must be one value per run, at least 3 runs, got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} holds {int(np.sum(~np.isfinite(v)))} non-finite value(s)")
    return v


@dataclass(frozen=True)
class Effect:
    """A consistency effect over independent runs (:data:`EFFECT_RULE`, chapters 04a, 05).

    name; n: runs; mean, lo, hi: the mean over the runs and its ``prob`` t-interval; sd: the
    runs' standard deviation; null: 1 for a ratio, 0 for a paired difference; word: the
    verdict (:data:`EFFECT_RULE`); within_margin: the interval inside null +- ``margin``
    (ratios only; None for a difference); power: the chance that the rule resolves an effect
    of ``margin`` (a ratio of 1 + margin, or a difference of +- margin) at this n and sd."""

    name: str
    n: int
    mean: float
    lo: float
    hi: float
    sd: float
    null: float
    word: str
    within_margin: bool | None
    power: float
    margin: float
    prob: float

    @property
    def half_width(self) -> float:
        """Half the interval's width: the smallest effect this study resolves."""
        return 0.5 * (self.hi - self.lo)

    def summary(self) -> str:
        pct = 100 * (self.mean - self.null)
        if self.null == 1.0:
            head = (f"{self.name}: {self.mean:.3f} [{self.lo:.3f}, {self.hi:.3f}] over {self.n} runs "
                    f"({pct:+.1f} %): {self.word}, "
                    f"{'within' if self.within_margin else 'not within'} the {100 * self.margin:.0f} % margin")
        else:
            head = (f"{self.name}: {self.mean:+.4f} [{self.lo:+.4f}, {self.hi:+.4f}] over {self.n} "
                    f"paired runs: {self.word}")
        return f"{head} (power against {100 * self.margin:.0f} %: {100 * self.power:.0f} %)"


def _effect(name: str, v: np.ndarray, null: float, words: tuple[str, str], margin: float,
            prob: float) -> Effect:
    from scipy.stats import t as student_t
    p = _checks.probability("prob", prob)
    m = _checks.real("margin", margin, lo=0.0, strict=True)
    n, mean, sd = v.size, float(v.mean()), float(v.std(ddof=1))
    tc = _t_crit(n, p)
    half = tc * sd / np.sqrt(n)
    lo, hi = mean - half, mean + half
    word = words[0] if lo > null else words[1] if hi < null else "no detectable difference"
    within = bool(null - m <= lo and hi <= null + m) if null == 1.0 else None
    se = sd / np.sqrt(n)
    power = 1.0 if se == 0 else float(1 - student_t.cdf(tc - m / se, n - 1))
    return Effect(name=name, n=n, mean=mean, lo=float(lo), hi=float(hi), sd=sd, null=null,
                  word=word, within_margin=within, power=power, margin=m, prob=p)


def ratio_effect(values, name: str = "NEES / dof", *, margin: float = MARGIN,
                 prob: float = 0.95) -> Effect:
    """The consistency ratio of independent runs, one value per run (a run's ANEES per dof,
    :func:`run_ratios`, or its map NEES per dof), as an :class:`Effect` around 1 with its
    t-interval, its word ('over-confident', 'under-confident' or 'no detectable
    difference'), whether it is within 1 +- ``margin``, and the power of the rule against a
    ratio of 1 + ``margin`` (:data:`EFFECT_RULE`; chapters 04a and 05).

    Parameters
    ----------
    values : (N,) array_like, N >= 3, finite
    name : str, the label of the summary line
    margin : float > 0, the practical margin (default :data:`MARGIN`)
    prob : float in (0, 1), the interval's probability

    Returns
    -------
    Effect

    Raises
    ------
    ValueError
        For fewer than 3 values, a non-finite or negative value, ``margin`` <= 0 or
        ``prob`` outside (0, 1).
    """
    v = _values("values", values)
    if np.any(v < 0):
        raise ValueError("a NEES ratio cannot be negative")
    return _effect(name, v, 1.0, ("over-confident", "under-confident"), margin, prob)


def paired_effect(a, b, name: str = "difference", *, margin: float = MARGIN,
                  prob: float = 0.95) -> Effect:
    """Two filters on the same runs: the per-run difference ``a - b`` as an :class:`Effect`
    around 0 ('higher', 'lower' or 'no detectable difference'; the power is against a
    difference of ``margin``). Pairing removes the scene-to-scene variation both share, so
    it resolves far smaller differences than two separate intervals (chapter 04a).

    Parameters
    ----------
    a : array_like, shape (N,)
        One value per run of the first filter, N >= 3, finite.
    b : array_like, shape (N,)
        The second filter's values on the same runs.
    name : str, optional
        The label of the summary line.
    margin : float, optional
        The practical margin, > 0 (default :data:`MARGIN`).
    prob : float, optional
        The interval's probability, in (0, 1).

    Returns
    -------
    Effect
        The mean difference with its t-interval, its word and the power of the rule.

    Raises
    ------
    ValueError
        For fewer than 3 values, a non-finite value, ``a`` and ``b`` of different
        lengths, ``margin`` <= 0 or ``prob`` outside (0, 1).
    """
    va, vb = _values("a", a), _values("b", b)
    if va.shape != vb.shape:
        raise ValueError(f"a and b must hold the same runs, got {va.size} and {vb.size} values")
    return _effect(name, va - vb, 0.0, ("higher", "lower"), margin, prob)


@dataclass(frozen=True)
class MapConsistency:
    """Map NEES of N runs (notebook 05): per_dof = total NEES / total dof, its ``prob``
    band (``chi2_band(1, dof)``), inside (per_dof within it), and each run's NEES / dof."""

    per_dof: float
    lo: float
    hi: float
    dof: int
    inside: bool
    runs: np.ndarray
    prob: float

    def summary(self) -> str:
        return (f"map NEES / dof: {self.per_dof:.3f} over {self.runs.size} runs ({self.dof} dof), "
                f"{100 * self.prob:.0f} % band [{self.lo:.3f}, {self.hi:.3f}]: "
                f"{'inside' if self.inside else 'OUTSIDE'}")


def map_consistency(values, dofs, *, prob: float = 0.95) -> MapConsistency:
    """The map NEES of independent runs together (``values``, ``dofs``: one
    :func:`map_nees` pair per run): their sum is chi2(sum of dof) for a consistent filter,
    so the total per dof is judged against ``chi2_band(1, total dof)``.

    Parameters
    ----------
    values : array_like, shape (N,)
        The map NEES of each run, >= 0.
    dofs : array_like, shape (N,)
        Its degrees of freedom (2 per landmark), > 0.
    prob : float, optional
        Probability of the two-sided band, in (0, 1).

    Returns
    -------
    MapConsistency
        The total NEES per dof with its band, whether it is inside, and each run's
        NEES per dof.

    Raises
    ------
    ValueError
        For empty or unequal inputs, a negative or non-finite NEES or a dof <= 0.
    """
    v, d = np.asarray(values, dtype=float).ravel(), np.asarray(dofs, dtype=float).ravel()
    if v.size == 0 or v.shape != d.shape:
        raise ValueError(f"values and dofs must be non-empty and of one length, got {v.size} "
                         f"and {d.size}")
    if not (np.all(np.isfinite(v)) and np.all(v >= 0) and np.all(d > 0)):
        raise ValueError("map NEES values must be finite and >= 0, dofs positive")
    total = float(d.sum())
    lo, hi = chi2_band(1, total, prob)
    per = float(v.sum() / total)
    return MapConsistency(per_dof=per, lo=lo, hi=hi, dof=int(total), inside=bool(lo <= per <= hi),
                          runs=v / d, prob=_checks.probability("prob", prob))


@dataclass(frozen=True)
class MonteCarlo:
    """The simulated filter on N runs (:func:`monte_carlo`): per-scan pose NEES and NIS
    judged scan by scan, the landmarks each run mapped, the final map's NEES, every
    run's pose NEES (N, K) (for ``scan_null.null_test`` and for rescaled filters), and the
    number of detections each scan of each run rejected (N, K) (neither associated nor
    new: on the simulator without clutter, correct sightings the gate refused)."""

    nees: Consistency
    nis: Consistency
    mapped: tuple
    map: MapConsistency | None          # None for a known map (EKF localisation)
    nees_runs: np.ndarray
    rejected_runs: np.ndarray | None = None


@_memoize
def monte_carlo(seeds, motion_model: str = "euler", route: str = "loop", laps: int = 2,
                draw_initial: bool = False, **config) -> MonteCarlo:
    """Run the simulated filter (``SlamConfig.for_dataset('simulated')`` with
    ``motion_model`` and any other ``config`` field) on the simulator's runs ``seeds`` on
    ``route`` for ``laps`` laps (laser detections only) and judge it
    (notebook 05): the pose NEES and the NIS scan by scan over the runs, the landmarks
    mapped per run, and the NEES of each final map with its joint covariance, summed over
    the runs (not with ``map_mode='known'``, EKF localisation: ``map`` is then None). Every
    run must keep every scan. ``draw_initial``: each run's filter starts at the true
    initial pose plus a draw from its own prior N(0, diag(initial_sigma_xy^2,
    initial_sigma_xy^2, initial_sigma_phi^2)) (seeded by the run's seed), so that a prior
    of nonzero width is honest (the standard filter's spurious heading information shows
    there: ``SlamConfig.first_estimates``); by default every run starts at the true pose.
    With such a start the world-frame map NEES also judges the rotation of the whole map by
    the start's heading error, which a covariance holds only to first order (a landmark 20 m
    away moves sideways by 20 m x the error and inwards by half of 20 m x its square):
    measured on 30 runs at 2 deg, map NEES per dof 2.2 (standard filter) and 3.6 (FEJ), 0.96
    and 0.93 once each map is rigidly aligned to the truth and the three global directions
    are left out; read the pose NEES there, or the aligned map.
    The runs gate with the compiled loop (``slam.compiled``) when all of them together are
    long enough to win back loading it (``compiled.use_compiled`` of the study's scans: nine
    or more of the simulator's two-lap runs); its distances equal the numpy code's to
    rounding.
    Computed once per machine (``annslam_lib._cache``).

    Parameters
    ----------
    seeds : iterable of int
        The simulator's seeds, one run each.
    motion_model : {'euler', 'midpoint'}, optional
        The filter's motion model (``SlamConfig.motion_model``).
    route : {'loop', 'figure8', 'hairpin'}, optional
        The simulator's route (``data.simulate.ROUTES``).
    laps : int, optional
        Laps of the route per run.
    draw_initial : bool, optional
        Start each run at the true pose plus a draw from the prior.
    **config
        Other :class:`SlamConfig` fields.

    Returns
    -------
    MonteCarlo
        The per-scan NEES and NIS judgements, landmarks mapped per run, the map
        judgement (None with a known map), every run's pose NEES (N, K) and rejected
        detections (N, K).

    Raises
    ------
    ValueError
        For no seed or an unknown configuration field.
    RuntimeError
        If a simulated run skipped a scan.
    """
    from ..data import simulate
    from ..slam import compiled
    from ..slam.config import SlamConfig
    from ..slam.results import STATUS
    from ..slam.runner import run

    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("monte_carlo needs at least one seed")
    cfg = SlamConfig.for_dataset("simulated", motion_model=motion_model, **config)
    nees, nis, dof, mapped, maps, rejected = [], [], [], [], [], []
    _checks.flag("draw_initial", draw_initial)
    t_scan, gating = None, "numpy"
    for seed in seeds:                     # one run in memory at a time (studies of hundreds)
        ds = simulate.simulate(seed=seed, route=route, laps=laps, raw_laser=False)
        if t_scan is None:
            t_scan = ds.detections.t
            if compiled.use_compiled(len(seeds) * len(ds.detections)):   # the whole study's
                gating = "compiled"
        run_cfg = cfg
        if draw_initial:
            sd = np.array([cfg.initial_sigma_xy, cfg.initial_sigma_xy, cfg.initial_sigma_phi])
            eps = np.random.default_rng([int(seed), 25]).standard_normal(3) * sd
            run_cfg = cfg.replace(initial_pose=tuple(ds.truth.poses[0, 1:4] + eps))
        r = run(ds, run_cfg, progress=False, gating=gating)
        if not np.array_equal(r.scan_index, np.arange(len(ds.detections))):
            raise RuntimeError("a simulated run skipped a scan: the per-scan statistics need all")
        nees.append(pose_nees(r, ds))
        s, d = scan_nis(r, len(ds.detections))
        nis.append(s)
        dof.append(d)
        mapped.append(int(r.counts["landmarks"]))
        refused = r.observations.status == STATUS["rejected"]
        rejected.append(np.bincount(r.observations.scan[refused], minlength=len(ds.detections)))
        if cfg.map_mode == "slam":             # a known map is the truth: nothing to judge
            maps.append(map_nees(r, ds))
    return MonteCarlo(nees=nees_consistency(nees, t_scan), nis=nis_consistency(nis, dof, t_scan),
                      mapped=tuple(mapped), map=map_consistency(*zip(*maps)) if maps else None,
                      nees_runs=stack_runs("nees", nees), rejected_runs=np.array(rejected))
