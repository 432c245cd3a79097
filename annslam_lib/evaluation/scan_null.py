"""A consistent filter's Monte-Carlo statistics when scans are correlated (notebook 05).

The per-scan band of the average NEES of N runs (``consistency.chi2_band(3, N)``) holds at
each scan with probability ``prob``. Two statistics summarise a run of K scans: the share of
scans inside that band, and the time average (ANEES). Neither has a textbook distribution:
consecutive scans share most of their error (the NEES autocorrelation is still about 0.5
ten scans apart on the simulator), so the share is not Binomial(K, prob) and the ANEES is
not an average of N K independent chi-square values. :func:`null_test` simulates both
under the null hypothesis, a consistent filter with the runs' own scan-to-scan correlation,
and returns the decision rule: pass if the share is at least its ``level`` quantile under
the null and the ANEES is within its two-sided ``1 - level`` band. The ANEES band needs no
model: the N runs are independent, so the spread of their own time averages gives the
standard error of their mean (a t-test of mean = dof with N - 1 dof, "batch means").

The model of the null: each of the ``dof`` error components of each run is a stationary
Gaussian path with autocorrelation rho(h), and the NEES is their sum of squares; then
corr(NEES_k, NEES_k+h) = rho(h)^2 (Isserlis), so rho is the square root of the NEES
autocorrelation measured on the runs (pooled over runs, around the per-scan mean, cut where
it falls into its own noise, with a Tukey-Hanning taper, up to K // 4 lags: the square root of the NEES autocorrelation is
not itself a valid autocorrelation at long lags, so the model is kept where it is one).
A correlation coefficient does not depend on the scale of P, so an over- or
under-confident filter measures the same rho; the check that the model holds is
``acf_simulated`` against ``acf``. Its limit, measured: on the simulator's runs the NEES
autocorrelation is still about 0.1 at K // 4, so the model is less correlated than the runs
(its closed-form ANEES spread is about 70 % of the runs' own); its share threshold is
then too high rather than too low: it errs towards failing a consistent filter.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scipy.stats import t as student_t

from .. import _checks
from .._cache import memoize as _memoize
from .consistency import stack_runs, chi2_band

__all__ = ["scan_autocorrelation", "correlated_paths", "NullTest", "Verdict", "null_test"]


def scan_autocorrelation(nees_runs, max_lag: int) -> np.ndarray:
    """Autocorrelation r[0..max_lag] (r[0] = 1) of the runs' per-scan NEES around its
    per-scan mean, pooled over runs. ``nees_runs``: one (K,) array per run, K > max_lag."""
    X = stack_runs("nees_runs", nees_runs)
    K = X.shape[1]
    max_lag = _checks.integer("max_lag", max_lag, lo=0)
    if max_lag >= K:
        raise ValueError(f"max_lag must be below the number of scans {K}, got {max_lag}")
    D = X - X.mean(axis=0)
    if not np.any(D):
        raise ValueError("nees_runs: the runs do not vary, no correlation can be measured")
    r = np.array([np.mean(D[:, :K - h] * D[:, h:]) for h in range(max_lag + 1)])
    return r / r[0]


def correlated_paths(rho, K: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` stationary standard Gaussian paths (n, K) with autocorrelation ``rho`` (lags
    0, 1, ...; zero beyond), by circulant embedding (Dietrich and Newsam 1997): the
    circulant's negative eigenvalues, if any, are set to zero."""
    K, n = _checks.integer("K", K, lo=2), _checks.integer("n", n, lo=1)
    r = np.zeros(K)
    rho = np.asarray(rho, dtype=float)[:K]
    r[:rho.size] = rho
    c = np.r_[r, r[-2:0:-1]]
    lam = np.clip(np.fft.fft(c).real, 0.0, None)
    scale = np.sqrt(lam / c.size)
    out = np.empty((n, K))
    k = 0
    while k < n:
        m = min((n - k + 1) // 2, 1000)
        xi = rng.standard_normal((m, c.size)) + 1j * rng.standard_normal((m, c.size))
        y = np.fft.fft(scale * xi, axis=1)[:, :K]
        both = np.concatenate([y.real, y.imag])[:n - k]   # real and imaginary parts: independent
        out[k:k + both.shape[0]] = both
        k += both.shape[0]
    return out


@dataclass(frozen=True)
class Verdict:
    """A Monte-Carlo NEES judged by a :class:`NullTest`: the share of scans inside the
    per-scan band and the ANEES, each with its pass."""

    share: float
    share_passes: bool
    anees: float
    anees_passes: bool

    @property
    def passes(self) -> bool:
        return self.share_passes and self.anees_passes

    def summary(self) -> str:
        return (f"{100 * self.share:.1f} % of scans inside ({'pass' if self.share_passes else 'FAIL'}), "
                f"ANEES {self.anees:.3f} ({'pass' if self.anees_passes else 'FAIL'})")


@dataclass(frozen=True)
class NullTest:
    """The null distribution of the per-scan statistics of ``runs`` runs of ``scans`` scans
    (:func:`null_test`), and the decision rule it gives.

    band: the per-scan band of the run average; share_threshold: the ``level`` quantile of
    the share of scans inside it under the null; anees_band: dof +- t_crit anees_sd, the
    two-sided ``1 - level`` band of the ANEES of these runs, anees_sd the standard error of
    their mean time average (model-free: the runs are independent); anees_model_sd: the
    same under the Gaussian-path model, in closed form (smaller: the model keeps only the
    first K // 4 lags of the correlation); shares, anees: the simulated null samples;
    acf: the NEES autocorrelation measured on the runs, acf_simulated: the same on the
    simulated null (the model's check)."""

    runs: int
    scans: int
    dof: int
    prob: float
    level: float
    band: tuple
    share_threshold: float
    t_crit: float
    anees_band: tuple
    anees_sd: float
    anees_model_sd: float
    shares: np.ndarray
    anees: np.ndarray
    acf: np.ndarray
    acf_simulated: np.ndarray

    def judge(self, nees_runs, scale: float = 1.0) -> Verdict:
        """Judge runs of the same shape; ``scale`` multiplies every NEES (a filter that
        reported P / scale)."""
        X = stack_runs("nees_runs", nees_runs) * float(scale)
        if X.shape != (self.runs, self.scans):
            raise ValueError(f"nees_runs must be {self.runs} runs of {self.scans} scans, got {X.shape}")
        avg = X.mean(axis=0)
        share = float(np.mean((avg >= self.band[0]) & (avg <= self.band[1])))
        anees = float(avg.mean())
        sd = float(X.mean(axis=1).std(ddof=1) / np.sqrt(self.runs))     # these runs' own spread
        return Verdict(share, share >= self.share_threshold, anees,
                       abs(anees - self.dof) <= self.t_crit * sd)

    def summary(self) -> str:
        return (f"under the null ({self.shares.size} simulated sets of {self.runs} runs x "
                f"{self.scans} correlated scans): share inside >= {100 * self.share_threshold:.1f} % "
                f"(its {100 * self.level:.0f} % quantile), ANEES in [{self.anees_band[0]:.3f}, "
                f"{self.anees_band[1]:.3f}]")


@_memoize
def null_test(nees_runs, *, dof: int = 3, prob: float = 0.95, level: float = 0.05,
              n_sim: int = 500, seed: int = 0, max_lag: int | None = None) -> NullTest:
    """Simulate the null distribution of the share of scans inside the per-scan ``prob``
    band and of the ANEES, for runs shaped and correlated like ``nees_runs`` (one (K,)
    array per run), ``n_sim`` times from ``seed``; the measured autocorrelation is used up
    to ``max_lag`` (default K // 4). Notebook 05. Computed once per machine.

    Parameters
    ----------
    nees_runs : sequence of array_like, each shape (K,)
        The per-scan NEES of N >= 3 runs.
    dof : int, optional
        Degrees of freedom of one NEES.
    prob : float, optional
        Probability of the per-scan band.
    level : float, optional
        Level of the test, in (0, 1).
    n_sim : int, optional
        Number of simulated sets of runs, >= 20.
    seed : int, optional
        Seed of the simulation.
    max_lag : int, optional
        Longest lag of the autocorrelation used, < K.

    Returns
    -------
    NullTest
        The per-scan band, the share threshold, the ANEES band, the simulated null
        samples and the measured and simulated autocorrelations.

    Raises
    ------
    ValueError
        For fewer than 3 runs, runs of different lengths, runs that do not vary, or a
        setting out of range.
    """
    X = stack_runs("nees_runs", nees_runs)
    runs, K = X.shape
    dof = _checks.integer("dof", dof, lo=1)
    level = _checks.probability("level", level)
    n_sim = _checks.integer("n_sim", n_sim, lo=20)
    max_lag = K // 4 if max_lag is None else max_lag
    acf = scan_autocorrelation(X, max_lag)
    # beyond the first lag where the estimate is within its noise (2 / sqrt(N K)) it is
    # taken as zero: a square root of noise would add correlation that is not there
    below = np.flatnonzero(acf[1:] < 2.0 / np.sqrt(runs * K))
    cut = below[0] + 1 if below.size else acf.size
    taper = 0.5 * (1.0 + np.cos(np.pi * np.arange(cut) / cut))
    rho = np.sqrt(np.clip(acf[:cut] * taper, 0.0, None))
    lo, hi = chi2_band(dof, runs, prob)
    # The model's ANEES spread in closed form: since cov(NEES_j, NEES_k) = 2 dof rho(j - k)^2,
    # variance 2 dof / (N K^2) sum_h (K - |h|) rho(h)^2 (the simulation below checks it).
    lags = np.arange(1, rho.size)
    model_var = 2.0 * dof / (runs * K**2) * (K + 2.0 * np.sum((K - lags) * rho[1:] ** 2))
    rng = np.random.default_rng(seed)
    shares, anees = np.empty(n_sim), np.empty(n_sim)
    acf_sim = np.zeros(min(max_lag, 30) + 1)
    for i in range(n_sim):
        nees = (correlated_paths(rho, K, runs * dof, rng).reshape(runs, dof, K) ** 2).sum(axis=1)
        avg = nees.mean(axis=0)
        shares[i] = np.mean((avg >= lo) & (avg <= hi))
        anees[i] = avg.mean()
        if i < 20:
            acf_sim += scan_autocorrelation(nees, acf_sim.size - 1) / 20
    if runs < 3:
        raise ValueError("null_test needs at least 3 runs (the ANEES band comes from their spread)")
    t_crit = float(student_t.ppf(1 - level / 2, runs - 1))
    sd = float(X.mean(axis=1).std(ddof=1) / np.sqrt(runs))
    return NullTest(runs=runs, scans=K, dof=dof, prob=prob, level=level, band=(lo, hi),
                    share_threshold=float(np.quantile(shares, level)), t_crit=t_crit,
                    anees_band=(dof - t_crit * sd, dof + t_crit * sd), anees_sd=sd,
                    anees_model_sd=float(np.sqrt(model_var)),
                    shares=shares, anees=anees, acf=acf, acf_simulated=acf_sim)
