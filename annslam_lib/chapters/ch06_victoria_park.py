"""Chapter 06 explorer and figures: one EKF-SLAM run over Victoria Park, scrubbed in time.

Everything is read from ONE stored :class:`~annslam_lib.slam.SlamResult` (no
re-running): the filter's pose after every scan (``trajectory``, ``pose_cov``), the final
map (``landmarks``, ``landmark_cov``) and, per landmark, the scans that observed it. The
map "at time t" is therefore the FINAL estimate of every landmark first seen by t
(:func:`landmark_first_seen`): the run does not store the map as it was at t.

``gps_outliers`` flags the GPS fixes no car could have reached; ``run_snapshot`` (pure) says where the car is at t, how uncertain, how many landmarks it
has mapped, and how far it is from the nearest GPS fix; ``draw_run`` draws the map and
track up to t; ``draw_gps_errors`` the error at every GPS fix (dots only: never a line
across a GPS gap); ``run_scrubber`` puts them behind a time slider (notebook 06).
"""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import IntSlider, interactive
from matplotlib.collections import LineCollection

from ..data.records import Gps
from ..evaluation.trajectory import TrajectoryErrors, trajectory_errors
from ..evaluation.residuals import ROUNDING, bound_text
from ..models.uncertainty import ellipse_curves
from ..plots.blit import Blit, drawn_by
from ..plots.alt import alt_text
from ..plots.style import BLUE, FIG_WIDTH, GREEN, ORANGE, RED, figure, show_png, widget_figure
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup
from ..slam.results import SlamResult

__all__ = ["setup", "map_figure", "semi_axis_figure", "gps_errors_figure", "slam_vs_dead_reckoning_figure",
           "health_figure", "cost_figure", "landmark_first_seen", "run_snapshot", "draw_run",
           "draw_gps_errors", "run_scrubber"]


def _check(result, gps) -> None:
    if not isinstance(result, SlamResult):
        raise TypeError(f"result must be an slam.results.SlamResult, got {type(result).__name__}")
    if not isinstance(gps, Gps):
        raise TypeError(f"gps must be a records.Gps, got {type(gps).__name__}")
    if result.trajectory.shape[0] < 1:
        raise ValueError("the run processed no scan: nothing to show")


def landmark_first_seen(result: SlamResult) -> np.ndarray:
    """(M,) time (s) of the scan that first observed each landmark of the final map (the
    scan that created it), from ``result.landmark_observations``."""
    if not isinstance(result, SlamResult):
        raise TypeError(f"result must be an slam.results.SlamResult, got {type(result).__name__}")
    first = np.array([obs.min() if obs.size else -1 for obs in result.landmark_observations],
                     dtype=np.int64)
    if np.any(first < 0):
        raise ValueError("a landmark of the map has no observation: not a result of slam.runner.run")
    rows = np.searchsorted(result.scan_index, first)
    return result.trajectory[rows, 0]


def run_snapshot(result: SlamResult, gps: Gps, t: float, *, errors: TrajectoryErrors | None = None,
                 fix_window: float = 1.0, first_seen: np.ndarray | None = None) -> dict:
    """The state of the run at time ``t`` (s, inside the span of the processed scans).

    Keys: t; row (index of the last trajectory row at or before t) and scan (its scan);
    pose (3,) and pose_cov (3, 3) after that scan's update; sigma_xy (m): square root of
    the largest eigenvalue of the position covariance; landmarks: how many landmarks of
    the final map had been seen by t; fixes: GPS fixes up to t; since_fix (s): time since
    the last fix (inf before the first); fix: None if no fix lies within ``fix_window`` s
    of t (a GPS gap), else a dict with the nearest fix's t, xy and error (m) of the
    filtered track (``odometry_trajectory``) against it (as ``evaluation.trajectory.trajectory_errors``).
    ``errors`` and ``first_seen`` may be passed precomputed."""
    _check(result, gps)
    if not (isinstance(t, (int, float, np.floating, np.integer)) and np.isfinite(t)):
        raise ValueError(f"t must be a finite number of seconds, got {t!r}")
    traj = result.trajectory
    t0, t1 = float(traj[0, 0]), float(traj[-1, 0])
    if not t0 <= t <= t1:
        raise ValueError(f"t = {t} s is outside the run's scans ({t0:.3f}..{t1:.3f} s)")
    if not (np.isfinite(fix_window) and fix_window >= 0):
        raise ValueError(f"fix_window must be a non-negative number, got {fix_window!r}")
    errors = trajectory_errors(result.odometry_trajectory, gps) if errors is None else errors
    first_seen = landmark_first_seen(result) if first_seen is None else first_seen
    row = int(np.searchsorted(traj[:, 0], t, side="right") - 1)
    cov = result.pose_cov[row]
    n_fix = int(np.searchsorted(gps.t, t, side="right"))
    fix = None
    if errors.t.size:
        i = int(np.argmin(np.abs(errors.t - t)))
        if abs(errors.t[i] - t) <= fix_window:
            j = int(np.searchsorted(gps.t, errors.t[i]))
            fix = {"t": float(errors.t[i]), "xy": gps.xy[j].copy(), "error": float(errors.error[i])}
    return {"t": float(t), "row": row, "scan": int(result.scan_index[row]),
            "pose": traj[row, 1:4].copy(), "pose_cov": cov.copy(),
            "sigma_xy": float(np.sqrt(np.linalg.eigvalsh(cov[:2, :2])[-1])),
            "landmarks": int(np.count_nonzero(first_seen <= t)), "fixes": n_fix,
            "since_fix": float(t - gps.t[n_fix - 1]) if n_fix else float("inf"), "fix": fix}


def draw_run(result: SlamResult, gps: Gps, t: float | None = None, ax=None, *,
             n_sigma: float = 2.0, first_seen: np.ndarray | None = None,
             outliers: np.ndarray | None = None):
    """The map and track up to ``t`` (default: the end of the run): GPS fixes (blue dots;
    those flagged in the boolean ``outliers`` as red crosses), the filter's track (black),
    the landmarks of the final map first seen by t (green) with their ``n_sigma``
    ellipses, and the pose at t (orange triangle with its position ellipse). The axes
    frame the whole run (without the outliers), so they do not change with t."""
    _check(result, gps)
    traj = result.trajectory
    t = float(traj[-1, 0]) if t is None else t
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 7))
    first_seen = landmark_first_seen(result) if first_seen is None else first_seen
    upto = int(np.searchsorted(traj[:, 0], t, side="right"))
    g = gps.t <= t
    ok = g if outliers is None else g & ~outliers
    ax.plot(gps.east[ok], gps.north[ok], ".", ms=2, color=BLUE, label="GPS fixes")
    if outliers is not None and np.any(g & outliers):
        ax.plot(gps.east[g & outliers], gps.north[g & outliers], "x", ms=9, mew=2, color=RED,
                label="GPS outlier")
    ax.plot(traj[:upto, 1], traj[:upto, 2], "-", lw=0.7, color="k", label="EKF-SLAM track")
    seen = first_seen <= t
    if np.any(seen):
        curves = ellipse_curves(result.landmarks[seen], result.landmark_cov[seen], n_sigma)
        ax.add_collection(LineCollection(curves, colors=GREEN, linewidths=0.7))
        ax.plot(result.landmarks[seen, 0], result.landmarks[seen, 1], "+", ms=4,
                color=GREEN, label=f"landmarks ({seen.sum()}), {n_sigma:g}-sigma")
    if upto:
        x, y, phi = traj[upto - 1, 1:4]
        ax.plot(x, y, marker=(3, 0, np.degrees(phi) - 90), ms=12, color=ORANGE,
                mec="k", ls="", label="pose", zorder=6)
        e = ellipse_curves([x, y], result.pose_cov[upto - 1][:2, :2], n_sigma)[0]
        ax.plot(e[:, 0], e[:, 1], "-", color=ORANGE, lw=1.2)
    # Frame the whole run (track, map, GPS without its outliers), whatever t is, so that
    # the view does not jump while the slider moves; a far outlier stays off the figure.
    pts = [traj[:, 1:3], result.landmarks, gps.xy if outliers is None else gps.xy[~outliers]]
    lo = np.min([p.min(axis=0) for p in pts if p.size], axis=0) - 5.0
    hi = np.max([p.max(axis=0) for p in pts if p.size], axis=0) + 5.0
    ax.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal", xlim=(lo[0], hi[0]),
           ylim=(lo[1], hi[1]))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center")
    return ax


def draw_gps_errors(errors: TrajectoryErrors, ax=None, *, t: float | None = None,
                    outliers: np.ndarray | None = None, ylim=(0.0, 16.0)):
    """Error (m) of the track at every GPS fix against time, as dots (a gap in GPS stays a
    gap); fixes flagged in ``outliers`` (boolean, one per error) as red crosses, clipped to
    the top of ``ylim``; a vertical line at ``t``."""
    if not isinstance(errors, TrajectoryErrors):
        raise TypeError(f"errors must be a metrics.TrajectoryErrors, got {type(errors).__name__}")
    if ax is None:
        _, ax = plt.subplots(figsize=(9, 3))
    bad = np.zeros(errors.t.size, bool) if outliers is None else np.asarray(outliers, bool)
    if bad.shape != errors.t.shape:
        raise ValueError(f"outliers must flag each of the {errors.t.size} errors, got {bad.shape}")
    ax.plot(errors.t[~bad], errors.error[~bad], ".", ms=2, color=BLUE, label="error at a fix")
    if bad.any():
        ax.plot(errors.t[bad], np.minimum(errors.error[bad], ylim[1] * 0.97), "x", ms=9, mew=2,
                color=RED, label="GPS outlier (clipped)")
    if t is not None:
        ax.axvline(t, color=ORANGE, lw=1.5)
    ax.set(xlabel="t [s]", ylabel="|track - GPS| [m]", ylim=ylim)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left")
    return ax


def run_scrubber(result: SlamResult, gps: Gps, *, start: float | None = None, step: int = 5,
                 outliers: np.ndarray | None = None):
    """A time slider (whole seconds, ``step`` apart) over one stored run: the map and
    track up to t (:func:`draw_run`) beside the error at every GPS fix with t marked
    (:func:`draw_gps_errors`). The latest :func:`run_snapshot` is in
    ``widget.holder['summary']``. ``outliers``: boolean per GPS fix, drawn as crosses."""
    _check(result, gps)
    if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 1:
        raise ValueError(f"step must be an integer >= 1 (seconds), got {step!r}")
    errors = trajectory_errors(result.odometry_trajectory, gps)
    first_seen = landmark_first_seen(result)
    lo, hi = int(np.ceil(result.trajectory[0, 0])), int(np.floor(result.trajectory[-1, 0]))
    start = hi if start is None else int(round(start))
    if not lo <= start <= hi:
        raise ValueError(f"start = {start} s is outside the run's scans ({lo}..{hi} s)")
    err_outliers = None
    if outliers is not None:
        outliers = np.asarray(outliers, bool)
        if outliers.shape != gps.t.shape:
            raise ValueError(f"outliers must flag each of the {gps.t.size} GPS fixes, got {outliers.shape}")
        err_outliers = outliers[np.searchsorted(gps.t, errors.t)]
    holder = {}
    views = []                  # the blitted figure (plots.blit.Blit), made at the first draw

    def draw(t: int) -> None:
        s = run_snapshot(result, gps, float(t), errors=errors, first_seen=first_seen)
        holder["summary"] = s
        fix = ("no GPS fix within 1 s (gap: last fix {:.1f} s ago)".format(s["since_fix"])
               if s["fix"] is None else f"error vs GPS {s['fix']['error']:.2f} m")
        print(f"t = {t} s, scan {s['scan']}: {s['landmarks']} landmarks mapped, position "
              f"sigma {s['sigma_xy']:.2f} m; {fix}")
        # Both views are fixed (the map frames the whole run, the errors panel every fix):
        # a step draws the map up to t and moves the time line over the kept picture.
        if not views:
            fig, (a1, a2) = widget_figure(1, 2, figsize=(FIG_WIDTH, 5.2), width_ratios=[1, 1.2],
                                          layout="constrained")  # not pyplot: see widget_figure
            _, moving = drawn_by([a1], lambda: draw_run(result, gps, float(t), a1,
                                                        first_seen=first_seen, outliers=outliers))
            draw_gps_errors(errors, a2, t=float(t), outliers=err_outliers)
            views[:] = [Blit(fig, moving + [a2.lines[-1]])]      # the time line drawn last
        else:
            view = views[0]
            a1, a2 = view.fig.axes
            line = view.moving[-1]
            view.clear(keep=(line,))
            _, moving = drawn_by([a1], lambda: draw_run(result, gps, float(t), a1,
                                                        first_seen=first_seen, outliers=outliers))
            line.set_xdata([float(t), float(t)])
            view.set_moving(moving + [line])
        show_png(views[0].png(), alt_text(views[0].fig))

    slider = IntSlider(value=start, min=lo, max=hi, step=step, description="t [s]",
                       continuous_update=False)
    widget = interactive(draw, t=slider)
    widget.holder = holder
    widget.views = views
    return keyboard_ready(widget)


def map_figure(result: SlamResult, gps: Gps, first_seen, outliers):
    """The whole run's map with 2-sigma ellipses and the track (:func:`draw_run`)."""
    fig, ax = figure(height=8.0)
    draw_run(result, gps, ax=ax, first_seen=first_seen, outliers=outliers)
    ax.set_title("Victoria Park: EKF-SLAM map (2-sigma ellipses) and track")
    return fig


def semi_axis_figure(first_seen, semi):
    """Each landmark's largest 2-sigma semi-axis against the time it was first seen."""
    fig, ax = figure(height=3.2)
    ax.semilogy(first_seen, semi, ".", ms=4)
    ax.set(xlabel="time the landmark was first seen [s]", ylabel="2-sigma semi-axis [m]",
           title="a landmark inherits the car's uncertainty of the moment it was first seen")
    ax.grid(True, alpha=0.3, which="both")
    return fig


def gps_errors_figure(errors: TrajectoryErrors, outliers, first_seen):
    """The track's error at every GPS fix (:func:`draw_gps_errors`) and the map's growth."""
    fig, ax = figure(height=3.8)
    draw_gps_errors(errors, ax, outliers=outliers)
    ax2 = ax.twinx()
    ax2.plot(np.sort(first_seen), np.arange(1, len(first_seen) + 1), color=GREEN, lw=1.5)
    ax2.set_ylabel("landmarks mapped so far", color=GREEN)
    ax.set_title("error of the track at every GPS fix (dots; gaps stay gaps), and the growing map")
    return fig


def slam_vs_dead_reckoning_figure(gps: Gps, outliers, dead_reckoned, result: SlamResult,
                                  dr_errors: TrajectoryErrors, dr_keep,
                                  errors: TrajectoryErrors, err_outliers):
    """The tracks of dead reckoning and EKF-SLAM against GPS (left), and their errors at the
    GPS fixes on a log scale (right); GPS outliers left out."""
    fig, (a1, a2) = figure(1, 2, height=5.5, width_ratios=[1, 1.3])
    ok = ~np.asarray(outliers, bool)
    a1.plot(gps.east[ok], gps.north[ok], ".", ms=2, color=BLUE, label="GPS")
    a1.plot(dead_reckoned[:, 1], dead_reckoned[:, 2], "-", lw=0.8, color=RED, label="dead reckoning")
    a1.plot(result.trajectory[:, 1], result.trajectory[:, 2], "-", lw=0.7, color="k", label="EKF-SLAM")
    a1.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal", title="the tracks")
    a1.legend(loc="lower left")
    a1.grid(True, alpha=0.3)
    a2.semilogy(dr_errors.t[dr_keep], dr_errors.error[dr_keep], ".", ms=2, color=RED,
                label="dead reckoning")
    a2.semilogy(errors.t[~err_outliers], errors.error[~err_outliers], ".", ms=2, color="k",
                label="EKF-SLAM")
    a2.set(xlabel="t [s]", ylabel="error at GPS fixes [m]", title="error against GPS (log scale)")
    a2.legend(loc="lower right")
    a2.grid(True, alpha=0.3, which="both")
    return fig


def health_figure(health: dict, steps):
    """Asymmetry and smallest eigenvalue of P over the steps, one line per update form.
    Asymmetry below ``residuals.ROUNDING`` is rounding, whose digits depend on the CPU: it
    is drawn as the grey band it lies in, not as points."""
    fig, (a1, a2) = figure(1, 2, height=3.8)
    a1.axhspan(1e-15, ROUNDING, color="0.92", zorder=0)
    for name, hist in health.items():
        (line,) = a1.semilogy(steps, np.where(hist[:, 0] < ROUNDING, np.nan, hist[:, 0]), "o-",
                              ms=3, label=name)
        a2.plot(steps, hist[:, 1], "o-", ms=3, label=name)
        if np.all(hist[:, 0] < ROUNDING):
            a1.text(np.mean(steps), 1e-13, f"{name}: below {bound_text(ROUNDING)} at every "
                    "step\n(rounding: its digits depend on the CPU)", color=line.get_color(),
                    ha="center", va="center", fontsize=8)
    a1.set_ylim(1e-15, None)
    a1.set(xlabel="steps", ylabel="max |P - P^T|", title="asymmetry")
    a2.axhline(0, color="k", lw=0.8)
    a2.set(xlabel="steps", ylabel="smallest eigenvalue of (P + P^T)/2", title="positive definiteness")
    for a in (a1, a2):
        a.grid(True, alpha=0.3)
        a.legend()
    return fig


def cost_figure(costs, n_map: int):
    """Seconds per predict and update of the efficient filter, and per step of the dense
    one, against the number of landmarks, with slopes 1-3 for reference."""
    N_all = np.array([row.N for row in costs])
    dense = [row for row in costs if row.dense is not None]
    fig, ax = figure(height=4.5)
    ax.loglog(N_all, [row.efficient.predict for row in costs], "o-", label="efficient: predict")
    ax.loglog(N_all, [row.efficient.update for row in costs], "s-", label="efficient: update")
    ax.loglog([row.N for row in dense], [row.dense.step for row in dense], "^-", color=RED,
              label="dense: step")
    for p, ls in ((1, ":"), (2, "--"), (3, "-.")):
        ax.loglog(N_all, 2e-4 * (N_all / 300.0) ** p, ls, color="0.5", lw=1, label=f"slope {p}")
    ax.axvline(n_map, color=GREEN, lw=1)
    ax.annotate("Victoria Park map", (n_map, 2e-5), rotation=90, color=GREEN, fontsize=8)
    ax.set(xlabel="landmarks N", ylabel="seconds", title="cost of one step as the map grows")
    ax.grid(True, alpha=0.3, which="both")
    ax.legend(loc="upper left", ncol=2)
    return fig

