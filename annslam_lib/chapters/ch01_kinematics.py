"""Chapter 01 explorer and figures: the exact turning arc against Euler steps, and
dead-reckoned paths against GPS.

``arc_vs_euler`` is the pure computation behind the explorer (testable headless);
``kinematics_explorer`` wraps it in speed / steering / dt sliders and keeps the
latest result in ``widget.holder["summary"]``.
"""
from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import FloatSlider, interactive

from ..models.motion import axle_pose, predict, predict_exact
from ..evaluation.trajectory import TrajectoryErrors
from ..plots.data import car_outline
from ..models.vehicle import ACFR_UTE, Vehicle
from ..plots.blit import Blit, drawn_by
from ..plots.alt import alt_text
from ..plots.style import BLUE, FIG_WIDTH, GREEN, ORANGE, RED, figure, show_png, widget_figure
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup

__all__ = ["setup", "circumradius", "arc_vs_euler", "plot_arc_vs_euler", "kinematics_readout",
           "kinematics_explorer",
           "plot_turning_geometry", "plot_paths", "plot_errors", "turning_geometry_figure",
           "euler_error_figure", "dead_reckoning_figure", "heading_sensitivity_figure",
           "heading_drift_figure"]


def circumradius(p1, p2, p3) -> float:
    """Radius (m) of the circle through three points (inf if they are collinear):
    R = |p1 p2| |p2 p3| |p3 p1| / (4 * triangle area)."""
    p1, p2, p3 = (np.asarray(p, dtype=float) for p in (p1, p2, p3))
    a, b, c = np.linalg.norm(p2 - p1), np.linalg.norm(p3 - p2), np.linalg.norm(p1 - p3)
    u, v = p2 - p1, p3 - p1
    area2 = abs(u[0] * v[1] - u[1] * v[0])            # twice the triangle's area
    if area2 <= 1e-14 * max(a, b, c) ** 2:
        return math.inf
    return float(a * b * c / (2.0 * area2))


def arc_vs_euler(speed: float, steering: float, dt: float, vehicle: Vehicle = ACFR_UTE, *,
                 horizon: float = 3.0, samples: int = 121) -> dict:
    """The constant-control motion of the car over ``horizon`` s from the origin heading
    East (notebook 01, "Euler versus the exact arc").

    Returns a dict with: 'exact_laser', 'exact_axle' (samples, 3) poses along the exact
    arc; 'euler_laser' (n + 1, 3) chained ``motion.predict`` steps of ``dt`` for the
    laser model and 'euler_axle' the same for the rear-axle model (the laser model
    with a = b = 0, i.e. the paper's section 2.2 discrete model); 'steps' n =
    round(horizon / dt); 'radius_axle' and 'radius_laser' measured as the circumradius
    of three points of each exact path (inf when driving straight); 'radius_formula'
    L / |tan(alpha)|; 'error_laser', 'error_axle': distance (m) between the Euler end
    point and the exact pose at n dt.
    """
    for name, val in (("speed", speed), ("steering", steering), ("dt", dt), ("horizon", horizon)):
        if not (isinstance(val, (int, float)) and math.isfinite(val)):
            raise ValueError(f"{name} must be a finite number, got {val!r}")
    if dt <= 0 or horizon <= 0:
        raise ValueError(f"dt and horizon must be > 0, got dt = {dt}, horizon = {horizon}")
    n = max(1, int(round(horizon / dt)))
    if n > 10_000:
        raise ValueError(f"horizon / dt = {horizon / dt:.0f} steps is too many to draw (max 10000)")
    rear = Vehicle(L=vehicle.L, H=vehicle.H, a=0.0, b=0.0)
    u = np.array([speed, steering])
    laser0 = np.array([vehicle.a, vehicle.b, 0.0])          # laser pose with the axle at the origin
    ts = np.linspace(0.0, n * dt, samples)
    exact_laser = predict_exact(laser0, u, ts, vehicle)
    exact_axle, _ = axle_pose(exact_laser, vehicle)
    out = {"steps": n, "dt": float(dt), "horizon": float(n * dt)}
    for name, veh, p in (("laser", vehicle, laser0), ("axle", rear, np.zeros(3))):
        path = [p]
        for _ in range(n):
            path.append(predict(path[-1], u, dt, veh)[0])
        out[f"euler_{name}"] = np.array(path)
    out["exact_laser"], out["exact_axle"] = exact_laser, exact_axle
    for name in ("laser", "axle"):
        ex = out[f"exact_{name}"]
        i = [0, samples // 2, samples - 1]
        out[f"radius_{name}"] = circumradius(*ex[i, :2])
        out[f"error_{name}"] = float(np.linalg.norm(out[f"euler_{name}"][-1, :2] - ex[-1, :2]))
    t = abs(math.tan(steering))
    out["radius_formula"] = vehicle.L / t if t > 0 else math.inf
    return out


def plot_arc_vs_euler(summary: dict, ax=None):
    """Draw a result of :func:`arc_vs_euler`: exact arcs as lines, Euler steps as dots."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 6))
    for name, color in (("laser", RED), ("axle", BLUE)):
        ex, eu = summary[f"exact_{name}"], summary[f"euler_{name}"]
        ax.plot(ex[:, 0], ex[:, 1], "-", color=color, lw=1.5, label=f"{name}: exact arc")
        ax.plot(eu[:, 0], eu[:, 1], "o--", color=color, ms=4, lw=0.8, alpha=0.7,
                label=f"{name}: Euler, {summary['steps']} steps "
                      f"(end off by {100 * summary[f'error_{name}']:.1f} cm)")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return ax


def kinematics_explorer(vehicle: Vehicle = ACFR_UTE, *, speed: float = 2.0,
                        steering: float = 0.3, dt: float = 0.2, horizon: float = 4.0):
    """Sliders for speed (m/s), steering (rad) and dt (s) drawing the exact arcs of the
    laser and the rear axle against their Euler steps (notebook 01)."""
    holder = {}
    views = []                  # the blitted figure (plots.blit.Blit) of the current view

    def draw(speed: float, steering: float, dt: float) -> None:
        s = arc_vs_euler(speed, steering, dt, vehicle, horizon=horizon)
        holder["summary"] = s
        holder["text"] = kinematics_readout(s)
        print(holder["text"])
        r = s["radius_axle"]
        title = (f"rear-axle radius {r:.2f} m (L / tan(alpha) = {s['radius_formula']:.2f} m)"
                 if math.isfinite(r) else "straight ahead: infinite radius")
        limits = _scene_limits(s)
        if not views or not _holds(views[0].limits, limits):
            # the first draw, or paths that left the view (or shrank to a corner of it): a
            # new view around them, with room for the next steps
            fig, ax = widget_figure(figsize=(6, 6))  # not pyplot: see widget_figure
            (x0, x1), (y0, y1) = limits
            pad = 0.25 * max(x1 - x0, y1 - y0, 1.0)
            view = ((x0 - pad, x1 + pad), (y0 - pad, y1 + pad))
            ax.set(xlim=view[0], ylim=view[1])
            moving = _draw_arcs(s, ax, title)
            views[:] = [Blit(fig, moving)]
            views[0].limits = view
        else:
            ax = views[0].fig.axes[0]
            views[0].clear(keep=(ax.title,))
            views[0].set_moving(_draw_arcs(s, ax, title))
        show_png(views[0].png(), alt_text(views[0].fig))

    sliders = dict(
        speed=FloatSlider(value=speed, min=0.0, max=5.0, step=0.1, description="speed [m/s]",
                          continuous_update=False),
        steering=FloatSlider(value=steering, min=-0.6, max=0.6, step=0.01,
                             description="steer [rad]", continuous_update=False),
        dt=FloatSlider(value=dt, min=0.025, max=1.0, step=0.025, description="dt [s]",
                       continuous_update=False, readout_format=".3f"))
    widget = interactive(draw, **sliders)
    widget.holder = holder
    widget.views = views
    return keyboard_ready(widget)


def _scene_limits(s: dict):
    """((x min, x max), (y min, y max)) of every path of an :func:`arc_vs_euler` summary."""
    pts = np.vstack([s[k][:, :2] for k in ("exact_laser", "exact_axle", "euler_laser",
                                           "euler_axle")])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


def _holds(view, limits) -> bool:
    """Whether a view shows paths of these limits well: inside it, and not shrunk to under
    half its size (else the scene is drawn anew around them)."""
    (vx0, vx1), (vy0, vy1) = view
    (x0, x1), (y0, y1) = limits
    inside = vx0 <= x0 and x1 <= vx1 and vy0 <= y0 and y1 <= vy1
    return inside and max(x1 - x0, y1 - y0, 1.0) >= 0.5 * max(vx1 - vx0, vy1 - vy0) - 1e-9


def _draw_arcs(s: dict, ax, title: str) -> list:
    """:func:`plot_arc_vs_euler` and the title on an axes whose view is fixed; returns what
    it drew (with the legend and the title), for a blitted step to replace."""
    _, drawn = drawn_by([ax], lambda: plot_arc_vs_euler(s, ax))
    ax.set_title(title, fontsize=10)
    return drawn + [ax.title]


def kinematics_readout(s: dict) -> str:
    """The explorer's line for an :func:`arc_vs_euler` summary: steps, radius, Euler errors."""
    r = s["radius_axle"]
    radius = f"rear-axle radius {r:.2f} m" if math.isfinite(r) else "straight ahead"
    return (f"{s['steps']} Euler steps of {s['dt']:.3f} s over {s['horizon']:.2f} s; {radius}; "
            f"Euler end-point error: laser {100 * s['error_laser']:.1f} cm, rear axle "
            f"{100 * s['error_axle']:.1f} cm")


def plot_turning_geometry(vehicle: Vehicle = ACFR_UTE, steering: float = 0.35, ax=None):
    """The turning circle in the rear-axle frame (notebook 01): the car, its steered front
    wheel, the instantaneous centre of rotation (ICR) at (0, R), R = L / tan(alpha), and
    the circles of the axle centre C (R), the encoder wheel (R - H) and the laser."""
    if not 0.05 <= steering < math.pi / 2:
        raise ValueError(f"steering must be in [0.05, pi/2) rad for this drawing, got {steering!r}")
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 7))
    L, H, a, b = vehicle.L, vehicle.H, vehicle.a, vehicle.b
    R = L / math.tan(steering)
    body = car_outline(vehicle)
    ax.fill(body[:, 0], body[:, 1], color="0.9", ec="0.5", lw=1)
    wheel = np.array([[-0.35, 0.0], [0.35, 0.0]])
    for x, y, ang in ((0, H, 0.0), (0, -H, 0.0), (L, H, steering), (L, -H, steering)):
        c, s = math.cos(ang), math.sin(ang)
        w = wheel @ np.array([[c, s], [-s, c]]) + [x, y]
        ax.plot(w[:, 0], w[:, 1], "k-", lw=5, solid_capstyle="butt")
    ax.plot([0, 0], [-H, R], "k:", lw=0.8)                        # rear-axle line
    ax.plot([L, 0], [0, R], "k:", lw=0.8)                         # normal to the front wheel
    ang = np.linspace(-math.pi / 2 - 0.35, -math.pi / 2 + 0.55, 60)
    marks = (("C (axle centre)", (0.0, 0.0), BLUE, "o"),
             ("encoder wheel", (0.0, H), GREEN, "s"),
             ("laser", (a, b), RED, "^"))
    for label, (x, y), color, marker in marks:
        r = math.hypot(x, R - y)
        ax.plot(r * np.cos(ang), R + r * np.sin(ang), "-", color=color, lw=1, marker=marker,
                markevery=[len(ang) - 1], ms=6, label=f"{label}: radius {r:.2f} m")
        ax.plot([0, x], [R, y], "--", color=color, lw=0.8)
        ax.plot(x, y, marker, color=color, ms=6)
    ax.plot(0, R, "k+", ms=12, mew=2)
    ax.annotate(f"ICR (0, R), R = L / tan(alpha) = {R:.2f} m", (0, R), xytext=(6, -4),
                textcoords="offset points", fontsize=9)
    ax.set(xlabel="x forward [m]", ylabel="y left [m]", aspect="equal",
           xlim=(-3, a + 2.5), ylim=(-2.5, R + 1.5),
           title=f"Turning circle at steering alpha = {steering:.2f} rad")
    ax.legend(loc="lower right")
    return ax


def plot_paths(gps, paths: dict, ax=None, *, title: str = ""):
    """GPS fixes (dots) against trajectories (K, 4) given as {label: traj}."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 7))
    ax.plot(gps.east, gps.north, ".", ms=2, color="k", label="GPS (laser point)")
    for label, traj in paths.items():
        ax.plot(traj[:, 1], traj[:, 2], "-", lw=1.2, label=label)
    ax.plot(gps.east[0], gps.north[0], "o", color=GREEN, ms=8, label="start")
    ax.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal", title=title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return ax


def plot_errors(errors: dict[str, TrajectoryErrors], ax=None, *, title: str = ""):
    """Position error against GPS over time, one line per {label: TrajectoryErrors}."""
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 3.5))
    for label, e in errors.items():
        ax.plot(e.t, e.error, lw=1.2, label=f"{label} (RMSE {e.rmse:.2f} m)")
    ax.set(xlabel="time [s]", ylabel="position error [m]", title=title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return ax


def turning_geometry_figure(vehicle: Vehicle = ACFR_UTE, steering: float = 0.35):
    """The turning circle at ``steering`` (left) and, for every steering angle of the car,
    the radii of the circles its axle centre, encoder wheel and laser run on (right)."""
    fig, (ax0, ax1) = figure(1, 2, height=5.5, width_ratios=[1, 1.1])
    plot_turning_geometry(vehicle, steering, ax=ax0)
    alpha = np.linspace(0.05, 0.6, 200)
    R = vehicle.L / np.tan(alpha)
    for label, r, color, style in (("C (axle centre): R", R, BLUE, "-"),
                                   ("encoder wheel: R - H", R - vehicle.H, GREEN, "--"),
                                   ("laser", np.hypot(vehicle.a, R - vehicle.b), RED, "-.")):
        ax1.semilogy(alpha, r, style, color=color, label=label)
    ax1.axvline(steering, color="0.5", ls=":", label=f"the drawing, {steering:.2f} rad")
    ax1.set(xlabel="steering alpha [rad] (left turn)", ylabel="radius [m]",
            title="every point of the car on its own circle")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(loc="upper right")
    return fig


def euler_error_figure(dts, local, horizon_error, *, speed: float = 2.0, steering: float = 0.3,
                       vehicle: Vehicle = ACFR_UTE, horizon: float = 4.0):
    """Euler against the exact arc: the laser position error of one step and after
    ``horizon`` seconds against the step (left, log-log with fitted slopes over the
    smaller half of the steps), and the two paths at dt = 0.2 s (right)."""
    dts, local, horizon_error = (np.asarray(v, dtype=float) for v in (dts, local, horizon_error))
    half = slice(0, max(2, dts.size // 2))
    fig, (ax0, ax1) = figure(1, 2, height=4.8, width_ratios=[1.2, 1])
    for err, style, what in ((local, "o-", "one step (local)"),
                             (horizon_error, "s-", f"after {horizon:g} s (global)")):
        slope = np.polyfit(np.log(dts[half]), np.log(err[half]), 1)[0]
        ax0.loglog(dts, err, style, ms=3, label=f"{what}, slope {slope:.2f}")
    for d, lab in ((0.025, "odometry 25 ms"), (0.2, "0.2 s")):
        ax0.axvline(d, color="0.6", ls=":")
        ax0.annotate(lab, (d, float(np.min(local))), rotation=90, fontsize=8, xytext=(3, 0),
                     textcoords="offset points")
    ax0.set(xlabel="dt [s]", ylabel="laser position error [m]",
            title=f"Euler vs exact arc, {speed:g} m/s, steering {steering:g} rad")
    ax0.grid(True, which="both", alpha=0.3)
    ax0.legend(loc="lower right")
    s = arc_vs_euler(speed, steering, 0.2, vehicle, horizon=horizon)
    plot_arc_vs_euler(s, ax1)
    ax1.set_title(f"the paths at dt = 0.2 s over {horizon:g} s")
    ax1.legend(loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2)
    return fig


def dead_reckoning_figure(gps, paths: dict, errors: dict, *, limits=None, title: str = ""):
    """Dead-reckoned paths against GPS, one map per {label: trajectory} (top), and their
    position errors against GPS over time (bottom, {label: TrajectoryErrors})."""
    n = len(paths)
    fig = plt.figure(figsize=(FIG_WIDTH, 8.5))
    gs = fig.add_gridspec(2, n, height_ratios=[1.7, 1])
    for j, (label, traj) in enumerate(paths.items()):
        ax = fig.add_subplot(gs[0, j])
        plot_paths(gps, {label: traj}, ax=ax, title=label)
        if limits is not None:
            ax.set(xlim=limits[0], ylim=limits[1])
    plot_errors(errors, ax=fig.add_subplot(gs[1, :]), title=title)
    return fig


def heading_sensitivity_figure(headings_deg, rmse, marks):
    """Whole-run RMSE of dead reckoning against its initial heading, with ``marks``
    (label, heading_deg, rmse) for the headings the chapter compares."""
    fig, ax = figure(height=3.8)
    ax.plot(headings_deg, rmse, "-")
    for label, h, r in marks:
        ax.plot(h, r, "o", ms=7, label=f"{label}: {h:.0f} deg, RMSE {r:.1f} m")
    ax.set(xlabel="initial heading [deg]", ylabel="RMSE vs GPS [m]",
           title="Dead reckoning against its initial heading")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right")
    return fig


def heading_drift_figure(t_gps, heading_error_deg, odometry):
    """Dead-reckoned minus slip-corrected GPS heading along the run (top) above the
    steering (bottom), so that the turns where the heading is lost line up."""
    fig, (ax0, ax1) = figure(2, 1, height=5.0, sharex=True, height_ratios=[1.4, 1])
    ax0.plot(t_gps, heading_error_deg, ".", ms=3)
    ax0.set(ylabel="heading error [deg]",
            title="Heading drift of dead reckoning (dead-reckoned minus GPS heading)")
    ax1.plot(odometry.t, odometry.steering, color=ORANGE, lw=0.8)
    ax1.axhline(0.59, color="0.5", ls=":", lw=0.8)
    ax1.set(xlabel="time [s]", ylabel="steering [rad]")
    for ax in (ax0, ax1):
        ax.grid(True, alpha=0.3)
    return fig

