"""Plots for the SLAM chapters (05 EKF-SLAM, 06 Victoria Park, 08 ANN-enhanced SLAM), and
the small statistics they draw.

- :func:`plot_true_vs_mapped`: the paper's Figure 5 (true path, mapped path, true
  landmarks, mapped landmarks) with the landmarks' n-sigma ellipses.
- :func:`plot_landmark_zooms`: each mapped landmark next to its true position, at true
  scale, with its n-sigma ellipse.
- :func:`correlation_matrix`, :func:`plot_correlation`: the final covariance as a
  correlation image, the pose block separated from the map.
- :func:`chi2_band`, :func:`nees_consistency`, :func:`nis_consistency`,
  :func:`plot_consistency`: Monte-Carlo consistency of a filter (notebook 05,
  "is the filter honest?"). For N runs of a d-dof statistic that is chi-square
  distributed when the filter is consistent, the run average is chi2(N d) / N, so its
  two-sided band is ``chi2.ppf([a/2, 1 - a/2], N d) / N`` (Bar-Shalom, Li and
  Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 5.4).

Every plotting function draws on an ``ax`` it is given (or a new one) and returns it.
"""
from __future__ import annotations

import numbers
from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
from scipy.stats import chi2

from .plotting import BEACON_STYLE
from .uncertainty import ellipse_points

__all__ = ["chi2_band", "Consistency", "nees_consistency", "scan_nis", "nis_consistency",
           "plot_consistency", "correlation_matrix", "plot_correlation", "true_path",
           "plot_true_vs_mapped", "plot_landmark_zooms", "CAR_PARK_LIMITS"]

#: Axis limits of the paper's Figure 5 (Car Park): x -10..20 m, y -25..20 m.
CAR_PARK_LIMITS = ((-10.0, 20.0), (-25.0, 20.0))


def _axes(ax=None, figsize=(6, 6)):
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def _prob(prob) -> float:
    if isinstance(prob, bool) or not isinstance(prob, numbers.Real) or not 0.0 < prob < 1.0:
        raise ValueError(f"prob must be a probability in (0, 1), got {prob!r}")
    return float(prob)


# --------------------------------------------------------------------------- consistency

def chi2_band(dof, n=1, prob: float = 0.95) -> tuple[np.ndarray | float, np.ndarray | float]:
    """Two-sided ``prob`` band (lo, hi) of the AVERAGE of ``n`` independent chi-square
    values of ``dof`` degrees of freedom: chi2.ppf([(1 - prob)/2, (1 + prob)/2], n dof) / n.

    The NEES band of N Monte-Carlo runs (3 dof) is ``chi2_band(3, N)``; the band of a
    normalised NIS, total NIS / total dof D, is ``chi2_band(1, D)``. ``dof`` and ``n``
    may be arrays (broadcast); both must be positive. Notebook 05.
    """
    p = _prob(prob)
    d, k = np.asarray(dof, dtype=float), np.asarray(n, dtype=float)
    if not (np.all(np.isfinite(d)) and np.all(d > 0) and np.all(np.isfinite(k)) and np.all(k > 0)):
        raise ValueError(f"dof and n must be positive and finite, got {dof!r} and {n!r}")
    lo = chi2.ppf(0.5 * (1.0 - p), k * d) / k
    hi = chi2.ppf(0.5 * (1.0 + p), k * d) / k
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


def _stack(name: str, runs) -> np.ndarray:
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
    same K scans in each, e.g. ``ekf_slam.pose_nees``), against the band of the average
    of N chi2(dof) values (:func:`chi2_band`). ``mean`` is the time average (ANEES)."""
    X = _stack("nees_runs", nees_runs)
    n, K = X.shape
    value = X.mean(axis=0)
    lo, hi = chi2_band(dof, n, prob)
    lo_a, hi_a = np.full(K, lo), np.full(K, hi)
    return Consistency(name=f"average NEES ({dof} dof)", t=_times(t, K), value=value,
                       lo=lo_a, hi=hi_a, dof=np.full(K, float(n * dof)), mean=float(value.mean()),
                       inside=float(np.mean((value >= lo) & (value <= hi))), n_runs=n,
                       prob=_prob(prob))


def scan_nis(result, n_scans: int) -> tuple[np.ndarray, np.ndarray]:
    """The laser-update NIS and its dof of every scan 0..n_scans-1 of an
    ``ekf_slam.SlamResult`` (0 and 0 where a scan had no update; GPS updates left out)."""
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
    the total NIS over the total dof."""
    S, D = _stack("nis_runs", nis_runs), _stack("dof_runs", dof_runs)
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
                       n_runs=S.shape[0], prob=_prob(prob))


def plot_consistency(stats: Consistency, ax=None, *, expected: float | None = 1.0,
                     color: str = "tab:blue", label: str | None = None, title: str | None = None):
    """The statistic over time with its band shaded and the expected value dashed
    (``expected``: dof for a NEES average, 1 for NIS / dof; None: not drawn)."""
    ax = _axes(ax, figsize=(9, 3.5))
    ax.fill_between(stats.t, stats.lo, stats.hi, color="0.85", step="mid",
                    label=f"{100 * stats.prob:.0f} % band")
    ax.plot(stats.t, stats.value, "-", lw=0.9, color=color,
            label=label or f"{stats.name}: mean {stats.mean:.2f}, {100 * stats.inside:.0f} % inside")
    if expected is not None:
        ax.axhline(expected, color="k", ls="--", lw=0.8, label=f"expected {expected:g}")
    ax.set(xlabel="t [s]", ylabel=stats.name, title=title or "")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    return ax


# --------------------------------------------------------------------------- correlations

def correlation_matrix(P) -> np.ndarray:
    """Correlation coefficients C_ij = P_ij / sqrt(P_ii P_jj) of a covariance (n, n).
    Raises ValueError for a non-square, non-finite or non-symmetric P, or a diagonal
    entry <= 0 (a variable without uncertainty has no correlation)."""
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


def plot_correlation(P, ax=None, *, n_pose: int = 3, title: str = "correlation of the final state",
                     colorbar: bool = True):
    """The correlation matrix of ``P`` as an image (-1 blue .. +1 red), with lines between
    the pose block (first ``n_pose`` variables) and the landmarks' (x, y) pairs."""
    C = correlation_matrix(P)
    ax = _axes(ax, figsize=(6.5, 5.5))
    n = C.shape[0]
    im = ax.imshow(C, cmap="RdBu_r", vmin=-1.0, vmax=1.0, interpolation="nearest")
    for k in range(n_pose, n + 1, 2):
        lw = 1.2 if k == n_pose else 0.3
        ax.axhline(k - 0.5, color="k", lw=lw)
        ax.axvline(k - 0.5, color="k", lw=lw)
    m = (n - n_pose) // 2
    step = max(1, m // 8)
    ticks = list(range(n_pose)) + [n_pose + 2 * j + 0.5 for j in range(0, m, step)]
    names = ["x", "y", "φ"][:n_pose] + [f"L{j}" for j in range(0, m, step)]
    ax.set_xticks(ticks, names, fontsize=7)
    ax.set_yticks(ticks, names, fontsize=7)
    ax.set_title(title)
    if colorbar:
        ax.figure.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="correlation")
    return ax


# --------------------------------------------------------------------------- Figure 5

def true_path(dataset) -> tuple[np.ndarray, str]:
    """The reference path of a run and its name: the simulator's true laser poses, else
    the GPS fixes (the antenna is at the laser)."""
    if dataset.truth is not None:
        return np.asarray(dataset.truth.poses)[:, 1:3], "true path"
    return dataset.gps.xy, "true path (GPS)"


def plot_true_vs_mapped(result, dataset=None, ax=None, *, n_sigma: float = 2.0,
                        ellipse_scale: float = 1.0, limits=None, color: str = "tab:blue",
                        label: str = "mapped", show_truth: bool = True, title: str | None = None,
                        legend: str | None = "below"):
    """The paper's Figure 5: true path and landmarks against the mapped ones, each mapped
    landmark with its ``n_sigma`` ellipse (from ``result.landmark_cov``).

    result: an ``ekf_slam.SlamResult`` (its ``trajectory`` is the mapped path);
    dataset: the run, for the truth (:func:`true_path`; true landmarks =
    ``dataset.beacons``); show_truth False draws only the mapped part (to overlay a
    second filter on the same axes). ellipse_scale: magnifies the ellipses about their
    centres (centimetre ellipses vanish on a 40 m map; the legend says so).
    limits: ((xmin, xmax), (ymin, ymax)), e.g. :data:`CAR_PARK_LIMITS`.
    legend: 'below' (outside the axes, so it hides no landmark), a matplotlib location
    such as 'lower left', or None (no legend).
    """
    if not (isinstance(n_sigma, numbers.Real) and n_sigma > 0):
        raise ValueError(f"n_sigma must be positive, got {n_sigma!r}")
    if not (isinstance(ellipse_scale, numbers.Real) and ellipse_scale > 0):
        raise ValueError(f"ellipse_scale must be positive, got {ellipse_scale!r}")
    ax = _axes(ax, figsize=(6, 8))
    if show_truth and dataset is not None:
        path, name = true_path(dataset)
        ax.plot(path[:, 0], path[:, 1], "-", color="0.45", lw=1.2, label=name)
        true_lm = dataset.beacons
        if true_lm is not None:
            ax.scatter(true_lm[:, 0], true_lm[:, 1], label="true landmarks", **BEACON_STYLE)
    traj = result.trajectory
    ax.plot(traj[:, 1], traj[:, 2], "--", color=color, lw=1.0, label=f"{label} path")
    lm = result.landmarks
    ax.plot(lm[:, 0], lm[:, 1], "+", color=color, ms=9, mew=1.6, zorder=6,
            label=f"{label} landmarks")
    tag = f"{n_sigma:g}σ ellipses" + (f" ×{ellipse_scale:g}" if ellipse_scale != 1 else "")
    for j, (m, P) in enumerate(zip(lm, result.landmark_cov)):
        pts = ellipse_points(m, P, n_sigma)
        pts = m + ellipse_scale * (pts - m)
        ax.plot(pts[:, 0], pts[:, 1], "-", color=color, lw=0.9,
                label=f"{label} {tag}" if j == 0 else None)
    ax.set(xlabel="x East [m]", ylabel="y North [m]", aspect="equal")
    if limits is not None:
        (x0, x1), (y0, y1) = limits
        ax.set(xlim=(x0, x1), ylim=(y0, y1))
    if title is not None:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if legend == "below":
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2)
    elif legend is not None:
        ax.legend(fontsize=8, loc=legend)
    return ax


def plot_landmark_zooms(landmarks, landmark_cov, true_landmarks, i_mapped, j_true, *,
                        n_sigma: float = 2.0, half_width: float = 0.25, ncols: int = 5,
                        color: str = "tab:blue", axes=None):
    """One small panel per matched pair (``map_metrics.match_landmarks``): the true
    landmark (star), the mapped one (cross) and its ``n_sigma`` ellipse, at TRUE scale in
    a square of +-``half_width`` m around the true position. Each title gives the error
    (cm) and its squared Mahalanobis distance d2 under the mapped covariance (inside the
    ellipse iff d2 <= n_sigma^2). Returns the array of axes (spare panels switched off)."""
    lm = np.asarray(landmarks, dtype=float)
    cov = np.asarray(landmark_cov, dtype=float)
    true = np.asarray(true_landmarks, dtype=float)
    i_mapped, j_true = np.asarray(i_mapped, dtype=int), np.asarray(j_true, dtype=int)
    if i_mapped.shape != j_true.shape or i_mapped.ndim != 1 or i_mapped.size == 0:
        raise ValueError("i_mapped and j_true must be equal-length non-empty 1-D index arrays")
    if cov.shape != (lm.shape[0], 2, 2):
        raise ValueError(f"landmark_cov must be ({lm.shape[0]}, 2, 2), got {cov.shape}")
    k = i_mapped.size
    if axes is None:
        nrows = -(-k // ncols)
        _, axes = plt.subplots(nrows, ncols, figsize=(2.2 * ncols, 2.3 * nrows), squeeze=False)
    axes = np.asarray(axes).ravel()
    if axes.size < k:
        raise ValueError(f"{k} panels needed, {axes.size} axes given")
    for ax, i, j in zip(axes, i_mapped, j_true):
        e = lm[i] - true[j]
        d2 = float(e @ np.linalg.solve(cov[i], e))
        pts = ellipse_points(lm[i], cov[i], n_sigma)
        ax.plot(pts[:, 0], pts[:, 1], "-", color=color, lw=1.0)
        ax.plot(*lm[i], "+", color=color, ms=10, mew=1.8)
        ax.scatter(*true[j], **{**BEACON_STYLE, "s": 90})
        ax.set(xlim=(true[j, 0] - half_width, true[j, 0] + half_width),
               ylim=(true[j, 1] - half_width, true[j, 1] + half_width), aspect="equal")
        ax.set_title(f"#{j}: {100 * np.hypot(*e):.1f} cm, d² {d2:.1f}", fontsize=8)
        ax.tick_params(labelsize=6)
        ax.grid(True, alpha=0.3)
    for ax in axes[k:]:
        ax.set_axis_off()
    return axes
