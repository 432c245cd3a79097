"""Chapter 03 companion: a landmark's predicted measurement and its uncertainty (the
explorer), and the chapter's figures.

The laser sits at the origin of the world, heading East (phi = 0), so the world
frame is the laser frame: x forward, y left. The pose is uncertain (position
sigma, heading sigma), so is the landmark, and the laser adds its own noise R.
The EKF's prediction of the measurement is z = h(pose, landmark) with the
innovation covariance S = H P H^T + R (notebook 03, "the predicted measurement
and its uncertainty"); the plot sets it against a Monte-Carlo cloud of the true
nonlinear h, so a student can see where the linearisation stops being honest.
"""
from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import FloatSlider, interactive

from .. import _checks
from ..models.geometry import wrap_angle
from ..evaluation.residuals import ROUNDING
from ..models.observation import observe
from ..plots.blit import Blit, drawn_by
from ..plots.alt import alt_text, describe
from ..plots.style import BLUE, GREEN, ORANGE, PURPLE, RED, figure, show_png, widget_figure
from ..models.uncertainty import coverage, draw_ellipse, expected_coverage, monte_carlo, propagate
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup

#: The laser pose of the explorer: origin, heading East.
POSE = np.array([0.0, 0.0, 0.0])
#: Laser noise of the Car Park program (as simulate.SimConfig): 0.1 m, 1 degree.
SIGMA_RANGE = 0.1
SIGMA_BEARING = math.radians(1.0)
#: Size of the two panels of :func:`draw_prediction`.
PREDICTION_FIGSIZE = (11, 4.5)

__all__ = ["setup", "measurement_prediction", "draw_prediction", "measurement_explorer",
           "jacobian_sparsity_figure", "printed_bearing_figure", "edge_frame_figure",
           "linearisation_figure", "banana_figure"]


def measurement_prediction(landmark_x: float, landmark_y: float, *, sigma_xy: float,
                           sigma_phi: float, sigma_landmark: float = 0.0,
                           sigma_range: float = SIGMA_RANGE,
                           sigma_bearing: float = SIGMA_BEARING, pose=POSE) -> dict:
    """Predicted measurement of the landmark (landmark_x, landmark_y) from ``pose``,
    and its linearised covariance S = H P H^T + R.

    P = diag(sigma_xy^2, sigma_xy^2, sigma_phi^2, sigma_landmark^2, sigma_landmark^2)
    is the covariance of (pose, landmark); R = diag(sigma_range^2, sigma_bearing^2);
    H = [H_pose, H_landmark] from ``observation.observe`` (angles in radians).
    Returns a dict with floats ``range``, ``bearing``, ``sigma_range``,
    ``sigma_bearing``, ``correlation`` and arrays ``z``, ``H``, ``P``, ``R``, ``S``,
    ``pose``, ``landmark``.
    Raises ValueError for a negative sigma or a landmark on the sensor.
    """
    s_xy = _checks.real("sigma_xy", sigma_xy, lo=0.0)
    s_phi = _checks.real("sigma_phi", sigma_phi, lo=0.0)
    s_lm = _checks.real("sigma_landmark", sigma_landmark, lo=0.0)
    s_r = _checks.real("sigma_range", sigma_range, lo=0.0)
    s_b = _checks.real("sigma_bearing", sigma_bearing, lo=0.0)
    pose = np.asarray(pose, dtype=float)
    landmark = np.array([landmark_x, landmark_y], dtype=float)
    z, H_pose, H_lm = observe(pose, landmark)
    H = np.concatenate([H_pose, H_lm], axis=1)
    P = np.diag([s_xy**2, s_xy**2, s_phi**2, s_lm**2, s_lm**2])
    R = np.diag([s_r**2, s_b**2])
    S = propagate(H, P, R)
    sd = np.sqrt(np.diag(S))
    corr = float(S[0, 1] / (sd[0] * sd[1])) if sd[0] > 0 and sd[1] > 0 else 0.0
    return {"range": float(z[0]), "bearing": float(z[1]), "sigma_range": float(sd[0]),
            "sigma_bearing": float(sd[1]), "correlation": corr,
            "z": z, "H": H, "P": P, "R": R, "S": S, "pose": pose, "landmark": landmark}


def _sample_measurements(summary: dict, n: int, seed: int):
    """Monte-Carlo measurements: sample (pose, landmark), apply the true h, add R noise."""
    mean = np.concatenate([summary["pose"], summary["landmark"]])

    def h(x):
        return observe(x[:, :3], x[:, 3:])[0]

    _, _, z = monte_carlo(h, mean, summary["P"], n, seed=seed, angle_outputs=[1])
    noise = np.random.default_rng(seed + 1).standard_normal((n, 2)) * np.sqrt(np.diag(summary["R"]))
    return z + noise


def draw_prediction(summary: dict, *, n_samples: int = 2000, seed: int = 3, axes=None):
    """Two panels: the scene (pose, its 2-sigma position ellipse and heading fan, the
    landmark and its ellipse) and measurement space (bearing in degrees, range) with
    a Monte-Carlo cloud of the true h and the linearised 2-sigma ellipse of S.
    Adds to ``summary``: ``mc_coverage``, the fraction of the cloud inside that ellipse,
    and ``mc_sd_ratio``, the cloud's (range, bearing) standard deviations divided by the
    linearised ones (1 where the linearisation is honest). ``axes``: the two axes to draw
    on (default: a new pyplot figure). Returns the Figure."""
    pose, lm = summary["pose"], summary["landmark"]
    z_mc = _sample_measurements(summary, n_samples, seed)
    summary["mc_coverage"] = coverage(z_mc, summary["z"], summary["S"], 2.0, angle_columns=[1])
    err = z_mc - summary["z"]
    err[:, 1] = wrap_angle(err[:, 1])
    lin_sd = np.sqrt(np.diag(summary["S"]))
    summary["mc_sd_ratio"] = np.std(err, axis=0, ddof=1) / np.where(lin_sd > 0, lin_sd, np.nan)
    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=PREDICTION_FIGSIZE)
    a1, a2 = axes
    fig = a1.figure
    P = summary["P"]
    a1.plot(*pose[:2], "k^", ms=9, label="laser (mean pose)")
    if P[0, 0] > 0:
        draw_ellipse(a1, pose[:2], P[:2, :2], 2.0, color=BLUE, label="2σ position")
    fan = 2.0 * math.sqrt(P[2, 2])
    reach = 1.1 * summary["range"]
    for d in (-fan, 0.0, fan):
        a1.plot([pose[0], pose[0] + reach * math.cos(pose[2] + d)],
                [pose[1], pose[1] + reach * math.sin(pose[2] + d)],
                "-" if d == 0 else ":", color=BLUE, lw=1)
    a1.plot(*lm, "*", color=RED, ms=14, label="landmark")
    if P[3, 3] > 0:
        draw_ellipse(a1, lm, P[3:, 3:], 2.0, color=RED, label="2σ landmark")
    a1.set(xlabel="x forward [m]", ylabel="y left [m]", aspect="equal",
           title="scene (dotted: heading ±2σ)")
    a1.grid(True, alpha=0.3)
    a1.legend(loc="best")
    deg = np.diag([180.0 / math.pi, 1.0])
    a2.plot(np.degrees(z_mc[::2, 1]), z_mc[::2, 0], ".", ms=2, color="0.7",
            label="Monte Carlo (true h)")
    zb = np.array([math.degrees(summary["bearing"]), summary["range"]])
    S_deg = deg @ summary["S"][::-1, ::-1] @ deg
    draw_ellipse(a2, zb, S_deg, 2.0, color=GREEN, lw=2, label="2σ of S = HPHᵀ + R")
    a2.plot(*zb, "+", color=GREEN, ms=12)
    ratio = summary["mc_sd_ratio"]
    a2.set(xlabel="bearing [deg] (90 = straight ahead)", ylabel="range [m]",
           title=f"Monte-Carlo sd / linearised sd: range {ratio[0]:.2f}, bearing {ratio[1]:.2f}\n"
                 f"inside the 2σ ellipse: {100 * summary['mc_coverage']:.1f}% "
                 f"(a Gaussian: {100 * expected_coverage(2.0):.1f}%)")
    a2.grid(True, alpha=0.3)
    a2.legend(loc="best")
    if fig.get_layout_engine() is None:   # the course style lays out already
        fig.tight_layout()
    return fig


def measurement_explorer(*, landmark=(10.0, 3.0), sigma_xy: float = 0.3,
                         sigma_phi_deg: float = 5.0, sigma_landmark: float = 0.0,
                         n_samples: int = 2000):
    """Sliders for the landmark position, the pose's position and heading sigmas and the
    landmark's sigma; shows the predicted measurement, S and a Monte-Carlo cloud."""
    holder = {}
    views = []                  # the blitted figure (plots.blit.Blit), made at the first draw

    def draw(landmark_x: float, landmark_y: float, sigma_xy: float, sigma_phi_deg: float,
             sigma_landmark: float) -> None:
        try:
            s = measurement_prediction(landmark_x, landmark_y, sigma_xy=sigma_xy,
                                       sigma_phi=math.radians(sigma_phi_deg),
                                       sigma_landmark=sigma_landmark)
        except ValueError as exc:      # e.g. the landmark dragged onto the sensor
            holder["summary"] = {"error": str(exc)}
            print(f"cannot predict: {exc}")
            return
        if views:
            # a step: the scene keeps its view (the sliders' reach); measurement space keeps
            # its view while the cloud and ellipse stay inside it and fill half of it
            view = views[0]
            axes = view.fig.axes
            view.clear(keep=(axes[1].title,))
            view.set_moving(_draw_prediction_data(s, axes, n_samples))
            if not _holds(view.limits, _line_limits(axes[1])):
                views.clear()
        if not views:
            fig, axes = widget_figure(1, 2, figsize=PREDICTION_FIGSIZE)  # not pyplot: see widget_figure
            # one view of the scene for every landmark position (the sliders' reach): the
            # landmark moves in a still frame
            axes[0].set(xlim=(-7.0, 42.0), ylim=(-22.0, 22.0))
            moving = _draw_prediction_data(s, axes, n_samples)
            limits = _measurement_view(_line_limits(axes[1]), s["range"])
            axes[1].set(xlim=limits[0], ylim=limits[1])
            views[:] = [Blit(fig, moving)]
            views[0].limits = limits
        holder["summary"] = s
        print(f"z = (range {s['range']:.2f} m, bearing {math.degrees(s['bearing']):.1f} deg); "
              f"sigma_range {s['sigma_range']:.3f} m, sigma_bearing "
              f"{math.degrees(s['sigma_bearing']):.2f} deg, correlation {s['correlation']:+.2f}; "
              f"Monte Carlo: sd ratios {s['mc_sd_ratio'][0]:.2f} (range), "
              f"{s['mc_sd_ratio'][1]:.2f} (bearing), {100 * s['mc_coverage']:.1f}% inside 2σ")
        show_png(views[0].png(), alt_text(views[0].fig))

    slider = dict(continuous_update=False, readout_format=".1f")
    widget = interactive(
        draw,
        landmark_x=FloatSlider(value=landmark[0], min=-5.0, max=40.0, step=0.5,
                               description="landmark x", **slider),
        landmark_y=FloatSlider(value=landmark[1], min=-20.0, max=20.0, step=0.5,
                               description="landmark y", **slider),
        sigma_xy=FloatSlider(value=sigma_xy, min=0.0, max=2.0, step=0.05,
                             description="σ position", **dict(slider, readout_format=".2f")),
        sigma_phi_deg=FloatSlider(value=sigma_phi_deg, min=0.0, max=30.0, step=0.5,
                                  description="σ heading°", **slider),
        sigma_landmark=FloatSlider(value=sigma_landmark, min=0.0, max=2.0, step=0.05,
                                   description="σ landmark", **dict(slider, readout_format=".2f")),
    )
    widget.holder = holder
    widget.views = views
    return keyboard_ready(widget)


def _draw_prediction_data(summary: dict, axes, n_samples: int) -> list:
    """:func:`draw_prediction` on axes whose views are fixed; returns what it drew (with the
    legends and the measurement-space title), for a blitted step to replace."""
    _, drawn = drawn_by(axes, lambda: draw_prediction(summary, n_samples=n_samples, axes=axes))
    return drawn + [axes[1].title]


def _line_limits(ax):
    """((x min, x max), (y min, y max)) of the finite points of the lines on ``ax``."""
    pts = np.vstack([line.get_xydata() for line in ax.lines])
    pts = pts[np.isfinite(pts).all(axis=1)]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


def _measurement_view(limits, range_m: float):
    """Measurement space's view around data of these limits ((bearing deg), (range m)): half
    their span on each side, and room for the landmark to move 1.5 m (three slider steps)."""
    (x0, x1), (y0, y1) = limits
    px = 0.5 * (x1 - x0) + math.degrees(1.5 / max(range_m, 1.5))
    py = 0.5 * (y1 - y0) + 1.5
    return (x0 - px, x1 + px), (y0 - py, y1 + py)


def _holds(view, limits) -> bool:
    """Whether a view shows data of these limits well: inside it, and on each axis at least
    a quarter of its span (else measurement space is drawn anew around them)."""
    return all(v0 <= d0 and d1 <= v1 and (d1 - d0) >= 0.25 * (v1 - v0)
               for (v0, v1), (d0, d1) in zip(view, limits))


def jacobian_sparsity_figure(H_full, n_landmarks: int, seen: int):
    """Which entries of the full observation Jacobian dh/dX are non-zero for a sighting of
    landmark ``seen`` (numbered from 1) in a state of ``n_landmarks`` landmarks. An entry
    at rounding level (below ``residuals.ROUNDING`` times the largest) is a structural zero
    (d range / d phi computes to 0 or to 1e-17, depending on the CPU): drawn as zero."""
    H = np.abs(np.asarray(H_full, dtype=float))
    fig, ax = figure(height=2.4)
    nonzero = H > ROUNDING * H.max()
    ax.imshow(nonzero, cmap="Greys", vmin=0, vmax=1.6, aspect="equal")
    labels = ["x", "y", "φ"] + [f"{c}{k}" for k in range(1, n_landmarks + 1) for c in ("x", "y")]
    ax.set_xticks(range(len(labels)), labels)
    ax.set_yticks([0, 1], ["range", "bearing"])
    ax.set_xticks(np.arange(-0.5, len(labels)), minor=True)
    ax.set_yticks([-0.5, 0.5, 1.5], minor=True)
    ax.grid(which="minor", color="0.7")
    ax.tick_params(which="minor", length=0)
    ax.set_title(f"∂h/∂X for a sighting of landmark {seen}: dark = non-zero")
    columns = [labels[c] for c in np.flatnonzero(nonzero.any(axis=0))]
    return describe(fig, f"A grid of the Jacobian's 2 rows (range, bearing) and {len(labels)} "
                         f"columns: only the columns {', '.join(columns)} are non-zero, every "
                         f"column of the other {n_landmarks - 1} landmarks is zero")


def printed_bearing_figure(landmarks, off, heading: float):
    """Landmarks on a ring around the laser (at the origin, heading ``heading``), marked
    where the printed bearing (an atan of a ratio) is off by pi."""
    landmarks, off = np.asarray(landmarks), np.asarray(off, dtype=bool)
    fig, (ax0, ax1) = figure(1, 2, height=4.8)
    ax0.scatter(*landmarks[~off].T, s=12, color=GREEN, label="printed bearing right")
    ax0.scatter(*landmarks[off].T, s=12, color=RED, marker="x",
                label="printed bearing off by π")
    ax0.plot(0, 0, "k^", ms=10)
    ax0.annotate("", xy=(6 * math.cos(heading), 6 * math.sin(heading)), xytext=(0, 0),
                 arrowprops=dict(arrowstyle="->", lw=2))
    ax0.axvline(0, color="k", lw=0.8, ls=":")
    ax0.set(xlabel="x [m]", ylabel="y [m]", aspect="equal",
            title="atan of a ratio: wrong for every landmark with x_i < x_L")
    ax0.legend(loc="lower left")
    ang = np.degrees(np.arctan2(landmarks[:, 1], landmarks[:, 0]))
    ax1.hist([ang[~off], ang[off]], bins=36, range=(-180, 180), stacked=True,
             color=[GREEN, RED], hatch=["", "xx"], edgecolor="white", linewidth=0.3,
             label=["right", "off by π"])
    ax1.set(xlabel="direction of the landmark from the laser [deg]", ylabel="landmarks",
            title="which directions the print gets wrong")
    ax1.legend(loc="upper right")
    return fig


def edge_frame_figure(points, segment, beams, p_right, p_left, frame, origin_printed):
    """A straight edge in one scan and the landmark frame the two-point construction puts on
    it (corrected), against the origin the printed transform implies."""
    fig, ax = figure(height=5.5)
    ax.plot(*np.asarray(points).T, ".", ms=3, color="0.6", label="the scan")
    ax.plot(*np.asarray(segment).T, ".", ms=5, color=BLUE, label=f"beams {beams[0]}..{beams[1]}")
    ax.plot(*p_right, "o", color=ORANGE, ms=9, label="P_r (right end)")
    ax.plot(*p_left, "s", color=PURPLE, ms=9, label="P_l (left end, origin)")
    c, s = math.cos(frame[2]), math.sin(frame[2])
    p_left = np.asarray(p_left, dtype=float)
    for vec, colour, name in (((c, s), RED, "landmark x"), ((-s, c), GREEN, "landmark y")):
        ax.annotate("", xy=p_left + 2.0 * np.array(vec), xytext=p_left,
                    arrowprops=dict(arrowstyle="->", color=colour, lw=2))
        ax.text(*(p_left + 2.3 * np.array(vec)), name, color=colour, fontsize=9)
    ax.plot(*origin_printed, "x", color=RED, ms=10, mew=2, label="origin implied by the print")
    ax.annotate("", xy=np.asarray(origin_printed) + 2.0 * np.array([c, s]), xytext=origin_printed,
                arrowprops=dict(arrowstyle="->", color=RED, lw=1, ls="--"))
    ax.plot(0, 0, "k^", ms=9, label="laser")
    ax.set(xlabel="x forward [m]", ylabel="y left [m]", aspect="equal", xlim=(-8, 10), ylim=(-4, 11),
           title="the landmark frame of a straight edge")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="center left", bbox_to_anchor=(1.02, 0.5))
    return fig


def linearisation_figure(cases: dict):
    """Monte Carlo against the linearised 2-sigma ellipse in measurement space (bearing,
    range) for each {range: (centre, S, mc_mean, mc_cov, samples)}."""
    ncols = min(3, len(cases))
    nrows = -(-len(cases) // ncols)
    fig, axes = figure(nrows, ncols, height=3.4 * nrows, squeeze=False)
    for ax in axes.flat[len(cases):]:
        ax.set_visible(False)
    to_deg = np.diag([180 / math.pi, 1.0])
    for k, (ax, (rr, (centre, S, m, C, samples))) in enumerate(zip(axes.flat, cases.items())):
        ax.plot(np.degrees(samples[::16, 1]), samples[::16, 0], ".", ms=2, color="0.7",
                label="Monte Carlo (true h)")
        draw_ellipse(ax, [math.degrees(centre[1]), centre[0]], to_deg @ S[::-1, ::-1] @ to_deg,
                     2.0, color=GREEN, lw=2, label="2σ of H P Hᵀ")
        draw_ellipse(ax, [math.degrees(m[1]), m[0]], to_deg @ C[::-1, ::-1] @ to_deg, 2.0,
                     color=RED, ls="--", label="2σ of the Monte-Carlo covariance")
        ax.set(xlabel="bearing [deg]", ylabel="range [m]", title=f"landmark at {rr:g} m")
        ax.grid(True, alpha=0.3)
        if k == 0:                # one legend: the panels share their three entries
            ax.legend(loc="upper right")
    return fig


def banana_figure(cases: dict):
    """A new landmark at 20 m from an uncertain heading: Monte Carlo of the inverse model
    against its linearised 2-sigma ellipse, for each {heading sd (deg): (centre, S, mc_mean,
    mc_cov, samples)}; small spreads zoomed with x stretched to show the bend."""
    ncols = min(2, len(cases))
    nrows = -(-len(cases) // ncols)
    fig, axes = figure(nrows, ncols, height=4.0 * nrows, squeeze=False)
    for ax in axes.flat[len(cases):]:
        ax.set_visible(False)
    fig.suptitle("a new landmark at 20 m ahead, seen from an uncertain heading")
    for k, (ax, (sd_deg, (centre, S, m, C, samples))) in enumerate(zip(axes.flat, cases.items())):
        ax.plot(*samples[::16].T, ".", ms=2, color="0.7", label="Monte Carlo (true g)")
        draw_ellipse(ax, centre, S, 2.0, color=GREEN, lw=2, label="2σ of G P Gᵀ")
        ax.plot(*centre, "+", color=GREEN, ms=12, label="g(mean)")
        ax.plot(*m, "x", color=RED, ms=10, label="Monte-Carlo mean")
        ax.plot(0, 0, "k^", ms=9, label="laser")
        ax.set(xlabel="x forward [m]", ylabel="y left [m]", title=f"heading sd {sd_deg:g}°")
        ax.grid(True, alpha=0.3)
        if sd_deg < 10:       # zoomed, x stretched, to show the bend
            ax.set(xlim=(18.6, 20.6), ylim=(-8, 8), title=ax.get_title() + " (zoomed, x stretched)")
        else:
            ax.set(aspect="equal")
        if k == len(cases) - 1:   # one legend: the panels share their entries
            ax.legend(loc="center left")
    return fig
