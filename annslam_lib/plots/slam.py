"""Figures of the SLAM chapters (05 EKF-SLAM, 06 Victoria Park, 08 the verdict).

- :func:`plot_true_vs_mapped`: the paper's Figure 5 (true path, mapped path, true
  landmarks, mapped landmarks) with the landmarks' n-sigma ellipses;
- :func:`plot_landmark_zooms`: each mapped landmark next to its true position, at true
  scale, with its n-sigma ellipse;
- :func:`plot_correlation`: the final covariance as a correlation image;
- :func:`plot_consistency`: a NEES or NIS statistic over time with its chi-square band
  (``evaluation.consistency``).
"""
from __future__ import annotations

import numbers

import matplotlib.pyplot as plt
import numpy as np

from ..evaluation.consistency import Consistency, correlation_matrix
from ..models.uncertainty import ellipse_points
from .style import BEACON_STYLE, BLUE, FIG_WIDTH, axes

__all__ = ["CAR_PARK_LIMITS", "plot_consistency", "plot_correlation", "true_path",
           "plot_true_vs_mapped", "plot_landmark_zooms"]

#: Axis limits of the paper's Figure 5 (Car Park): x -10..20 m, y -25..20 m.
CAR_PARK_LIMITS = ((-10.0, 20.0), (-25.0, 20.0))


def plot_consistency(stats: Consistency, ax=None, *, expected: float | None = 1.0,
                     color: str = BLUE, label: str | None = None, title: str | None = None):
    """The statistic over time with its band shaded and the expected value dashed
    (``expected``: dof for a NEES average, 1 for NIS / dof; None: not drawn)."""
    ax = axes(ax, figsize=(FIG_WIDTH, 3.5))
    ax.fill_between(stats.t, stats.lo, stats.hi, color="0.85", step="mid",
                    label=f"{100 * stats.prob:.0f} % band")
    ax.plot(stats.t, stats.value, "-", lw=0.9, color=color,
            label=label or f"{stats.name}: mean {stats.mean:.2f}, {100 * stats.inside:.0f} % inside")
    if expected is not None:
        ax.axhline(expected, color="k", ls="--", lw=0.8, label=f"expected {expected:g}")
    ax.set(xlabel="t [s]", ylabel=stats.name, title=title or "")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right")
    return ax



def plot_correlation(P, ax=None, *, n_pose: int = 3, title: str = "correlation of the final state",
                     colorbar: bool = True):
    """The correlation matrix of ``P`` as an image (-1 blue .. +1 red), with lines between
    the pose block (first ``n_pose`` variables) and the landmarks' (x, y) pairs."""
    C = correlation_matrix(P)
    ax = axes(ax, figsize=(6.5, 5.5))
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
    ax.set_xticks(ticks, names, fontsize=8)
    ax.set_yticks(ticks, names, fontsize=8)
    ax.set_title(title)
    if colorbar:
        ax.figure.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="correlation")
    return ax



def true_path(dataset) -> tuple[np.ndarray, str]:
    """The reference path of a run and its name: the simulator's true laser poses, else
    the GPS fixes (the antenna is at the laser)."""
    if dataset.truth is not None:
        return np.asarray(dataset.truth.poses)[:, 1:3], "true path"
    return dataset.gps.xy, "true path (GPS)"



def plot_true_vs_mapped(result, dataset=None, ax=None, *, n_sigma: float = 2.0,
                        ellipse_scale: float = 1.0, limits=None, color: str = BLUE,
                        label: str = "mapped", show_truth: bool = True, title: str | None = None,
                        legend: str | None = "below"):
    """The paper's Figure 5: true path and landmarks against the mapped ones, each mapped
    landmark with its ``n_sigma`` ellipse (from ``result.landmark_cov``).

    result: an ``slam.results.SlamResult`` (its ``trajectory`` is the mapped path);
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
    ax = axes(ax, figsize=(6, 8))
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
    if len(lm) == 0:            # the legend names the ellipses before the first landmark
        ax.plot([], [], "-", color=color, lw=0.9, label=f"{label} {tag}")
    ax.set(xlabel="x East [m]", ylabel="y North [m]", aspect="equal")
    if limits is not None:
        (x0, x1), (y0, y1) = limits
        ax.set(xlim=(x0, x1), ylim=(y0, y1))
    if title is not None:
        ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if legend == "below":
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=2)
    elif legend is not None:
        ax.legend(loc=legend)
    return ax



def plot_landmark_zooms(landmarks, landmark_cov, true_landmarks, i_mapped, j_true, *,
                        n_sigma: float = 2.0, half_width: float = 0.25, ncols: int = 5,
                        color: str = BLUE, axes=None):
    """One small panel per matched pair (``evaluation.map.match_landmarks``): the true
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
