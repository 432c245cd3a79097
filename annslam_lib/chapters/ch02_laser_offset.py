"""Chapter 02 explorer: where the laser offset (a, b) puts the laser's path, against GPS.

A stretch of the Car Park run is dead-reckoned once with the rear-axle model
(the laser model with a = b = 0, notebook 01). For any trial offset (a, b) the
axle poses are moved to the laser with ``motion.laser_pose``,
P_l = P_c + a T(phi) + b T(phi + pi/2) (notebook 02, section 4.1), and compared
with GPS, whose antenna sits at the real laser point. Both paths are anchored at
the GPS fix of the stretch's first instant; the dead-reckoned initial heading
(a 1 s GPS chord) is only good to a degree or two, so by default the trial path
is also rotated about that anchor by the angle that fits GPS best.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import Checkbox, FloatSlider, interactive

from ..models import motion as kinematics
from ..slam.dead_reckoning import dead_reckon
from ..models.geometry import rot
from ..models.geometry import interpolate_poses
from ..plots.data import car_outline
from ..plots.blit import Blit, drawn_by
from ..plots.alt import alt_text
from ..plots.style import BLUE, GREEN, PURPLE, RED, figure, show_png, widget_figure
from ..data.records import Dataset, Odometry
from ..models.vehicle import Vehicle
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup

__all__ = ["setup", "offset_geometry_figure", "slip_figure", "Stretch", "car_park_stretch", "offset_paths", "offset_summary", "best_offset",
           "rms_surface", "plot_offset_geometry", "plot_offset_stretch", "plot_rms_surface", "offset_explorer"]

#: A right turn of about 200 degrees at full lock, entered from a near-straight (seconds).
TURN = (6.0, 21.0)
#: Layout of the two panels of :func:`plot_offset_stretch`.
STRETCH_LAYOUT = dict(figsize=(11, 4.8), gridspec_kw={"width_ratios": [1.1, 1]})


@dataclass(frozen=True)
class Stretch:
    """A piece of a run for the offset experiments.

    ``axle``: (K, 4) rows (t, x, y, phi) of the dead-reckoned rear-axle path, started at
    (0, 0, phi0); ``axle_at_gps``: (G, 3) the same poses interpolated at the GPS times;
    ``gps_t``, ``gps_xy``: the fixes inside the stretch; ``anchor``: GPS position
    interpolated at the first axle time; ``vehicle``: the car (L, H, a, b)."""

    axle: np.ndarray
    axle_at_gps: np.ndarray
    gps_t: np.ndarray
    gps_xy: np.ndarray
    anchor: np.ndarray
    vehicle: Vehicle


def car_park_stretch(ds: Dataset, t0: float = TURN[0], t1: float = TURN[1], *,
                     heading_window: float = 1.0) -> Stretch:
    """Dead-reckon the rear axle of ``ds`` from ``t0`` to ``t1`` seconds.

    The initial heading is the direction of the GPS chord over the first
    ``heading_window`` seconds; speeds are moved from the encoder to the axle
    centre (``encoder_correction=True``)."""
    o, g = ds.odometry, ds.gps
    if not (np.isfinite(t0) and np.isfinite(t1)) or t1 - t0 < 2 * heading_window:
        raise ValueError(f"stretch [{t0}, {t1}] s must be finite and longer than "
                         f"{2 * heading_window} s")
    if t0 < o.t[0] or t1 > o.t[-1]:
        raise ValueError(f"stretch [{t0}, {t1}] s is outside the odometry "
                         f"[{o.t[0]:.3f}, {o.t[-1]:.3f}] s")
    i0, i1 = np.searchsorted(o.t, [t0, t1])
    odo = Odometry(o.t[i0:i1 + 1], o.speed[i0:i1 + 1], o.steering[i0:i1 + 1])
    ta, tb = odo.t[0], odo.t[-1]
    east = lambda t: np.interp(t, g.t, g.east)  # noqa: E731
    north = lambda t: np.interp(t, g.t, g.north)  # noqa: E731
    chord = np.array([east(ta + heading_window) - east(ta), north(ta + heading_window) - north(ta)])
    if np.hypot(*chord) < 0.2:
        raise ValueError(f"the car moves less than 0.2 m in the first {heading_window} s of the "
                         "stretch: no GPS heading to start from")
    phi0 = float(np.arctan2(chord[1], chord[0]))
    axle_vehicle = replace(ds.vehicle, a=0.0, b=0.0)   # the laser model at the axle = axle model
    axle = np.asarray(dead_reckon(odo, np.array([0.0, 0.0, phi0]), axle_vehicle,
                                  encoder_correction=True), dtype=float)
    m = (g.t >= ta) & (g.t <= tb)
    if np.count_nonzero(m) < 5:
        raise ValueError(f"fewer than 5 GPS fixes in [{ta:.3f}, {tb:.3f}] s")
    return Stretch(axle, interpolate_poses(axle, g.t[m]), g.t[m], g.xy[m],
                   np.array([east(ta), north(ta)]), ds.vehicle)


def _laser_xy(poses: np.ndarray, vehicle: Vehicle, a: float, b: float) -> np.ndarray:
    """Laser positions (..., 2) of axle ``poses`` (..., 3) for the trial offset (a, b)."""
    return kinematics.laser_pose(poses, replace(vehicle, a=float(a), b=float(b)))[0][..., :2]


def _best_rotation(p: np.ndarray, q: np.ndarray, centre: np.ndarray) -> float:
    """Angle of the rotation about ``centre`` that brings points ``p`` closest to ``q``
    (least squares, 2-D Procrustes without translation)."""
    u, w = p - centre, q - centre
    return float(np.arctan2(np.sum(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]), np.sum(u * w)))


def offset_paths(stretch: Stretch, a: float, b: float, *, align: bool = True) -> dict:
    """The axle and laser paths (world xy, (K, 2) each) for a trial offset (a, b).

    Both are shifted by the same vector so the laser starts at the anchor fix and,
    with ``align``, rotated about it by ``heading_correction`` (rad), the angle that
    best fits the laser positions at the GPS times to GPS. Also returns those
    positions (``laser_at_gps``, (G, 2)) and the errors to GPS (``error``, (G,) m)."""
    for name, v in (("a", a), ("b", b)):
        if not np.isfinite(v):
            raise ValueError(f"offset {name} must be finite, got {v!r}")
    # One shift for both paths, so that the laser starts at the anchor fix.
    shift = stretch.anchor - _laser_xy(stretch.axle[0, 1:], stretch.vehicle, a, b)
    laser = _laser_xy(stretch.axle[:, 1:], stretch.vehicle, a, b) + shift
    axle = stretch.axle[:, 1:3] + shift
    at_gps = _laser_xy(stretch.axle_at_gps, stretch.vehicle, a, b) + shift
    delta = _best_rotation(at_gps, stretch.gps_xy, stretch.anchor) if align else 0.0
    R = rot(delta)
    turn = lambda p: (p - stretch.anchor) @ R.T + stretch.anchor  # noqa: E731
    laser, axle, at_gps = turn(laser), turn(axle), turn(at_gps)
    return {"t": stretch.axle[:, 0], "axle": axle, "laser": laser, "laser_at_gps": at_gps,
            "error": np.hypot(*(at_gps - stretch.gps_xy).T), "heading_correction": delta}


def offset_summary(stretch: Stretch, a: float, b: float, *, align: bool = True) -> dict:
    """How well the laser path for offset (a, b) matches GPS over the stretch: RMS and
    largest distance (m), the heading correction (deg) and the lever arm |(a, b)| (m)."""
    p = offset_paths(stretch, a, b, align=align)
    return {"a": float(a), "b": float(b), "rms": float(np.sqrt(np.mean(p["error"] ** 2))),
            "max": float(np.max(p["error"])), "heading_correction_deg": np.degrees(p["heading_correction"]),
            "lever_arm": float(np.hypot(a, b)), "fixes": int(p["error"].size)}


def best_offset(stretch: Stretch, *, align: bool = True, tol: float = 1e-10,
                max_iter: int = 200) -> tuple[float, float]:
    """The (a, b) whose laser path fits GPS best (least squares over the stretch's fixes).

    Laser displacement = axle displacement + (R(phi) - R(phi0)) (a, b) is linear in
    (a, b); with ``align`` the fit alternates that linear solve with the best rotation
    about the anchor until (a, b) moves less than ``tol`` m."""
    q = stretch.axle_at_gps
    M = rot(q[:, 2]) - rot(stretch.axle[0, 3])                  # (G, 2, 2)
    D = q[:, :2] - stretch.axle[0, 1:3]
    G = stretch.gps_xy - stretch.anchor
    ab, delta = np.zeros(2), 0.0
    for _ in range(max_iter):
        target = G @ rot(delta)                                   # R(delta)^T G, row-wise
        new, *_ = np.linalg.lstsq(M.reshape(-1, 2), (target - D).reshape(-1), rcond=None)
        done = np.max(np.abs(new - ab)) < tol
        ab = new
        if not align or done:
            break
        delta = _best_rotation(D + M @ ab, G, np.zeros(2))
    return float(ab[0]), float(ab[1])


def plot_offset_geometry(vehicle: Vehicle, phi: float = np.radians(30.0), ax=None):
    """The car seen from above at heading ``phi``: rear-axle centre C, laser point,
    the lever arm a T(phi) + b T(phi + pi/2) and the heading arc (section 4.1, Figure 4)."""
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    R = rot(phi)
    body = car_outline(vehicle) @ R.T
    ax.fill(body[:, 0], body[:, 1], color=BLUE, alpha=0.2, label="car body")
    ends = np.array([[0.0, -0.85], [0.0, 0.85], [vehicle.L, -0.85], [vehicle.L, 0.85]]) @ R.T
    ax.plot(ends[:2, 0], ends[:2, 1], "k-", lw=2)
    ax.plot(ends[2:, 0], ends[2:, 1], "k-", lw=2, label=f"axles (L = {vehicle.L} m)")
    tip_a = vehicle.a * R[:, 0]
    laser = tip_a + vehicle.b * R[:, 1]
    arrow = dict(length_includes_head=True, head_width=0.12, lw=1.5)
    ax.arrow(0, 0, *tip_a, color=GREEN, **arrow)
    ax.arrow(*tip_a, *(laser - tip_a), color=PURPLE, **arrow)
    ax.annotate(r"$a\,T(\phi)$", tip_a / 2, xytext=(6, -14), textcoords="offset points",
                color=GREEN)
    ax.annotate(r"$b\,T(\phi+\pi/2)$", laser, xytext=(-40, 10), textcoords="offset points",
                color=PURPLE)
    ax.plot(0, 0, "k+", ms=12, mew=2, label="C (rear-axle centre)")
    ax.plot(*laser, "^", color=RED, ms=9, label="laser (and GPS antenna)")
    arc = np.linspace(0, phi, 30)
    ax.plot([0, 2.0], [0, 0], "k:", lw=1)
    ax.plot(1.6 * np.cos(arc), 1.6 * np.sin(arc), "k-", lw=1)
    ax.annotate(r"$\phi$", (1.75 * np.cos(phi / 2), 1.75 * np.sin(phi / 2)))
    ax.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal",
           title=f"laser offset: a = {vehicle.a} m ahead, b = {vehicle.b} m left of C")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right")
    return ax


def plot_offset_stretch(stretch: Stretch, a: float, b: float, *, align: bool = True,
                        axes=None) -> dict:
    """Two panels: the axle path, the laser path for offset (a, b) and GPS on the map
    (purple: the lever arm at six instants); the laser path's distance to GPS over time,
    with the best-fitting offset in the title. ``axes``: the two axes to draw on (default: a
    new pyplot figure). Returns the :func:`offset_summary`."""
    s = offset_summary(stretch, a, b, align=align)
    p = offset_paths(stretch, a, b, align=align)
    best = best_offset(stretch, align=align)
    best_rms = offset_summary(stretch, *best, align=align)["rms"]
    if axes is None:
        _, axes = plt.subplots(1, 2, **STRETCH_LAYOUT)
    ax, ax2 = axes
    fig = ax.figure
    ax.plot(p["axle"][:, 0], p["axle"][:, 1], "-", color="0.4", label="rear axle (dead reckoning)")
    ax.plot(p["laser"][:, 0], p["laser"][:, 1], "-", color=RED,
            label=f"laser for a = {a:.2f}, b = {b:.2f}")
    ax.plot(stretch.gps_xy[:, 0], stretch.gps_xy[:, 1], ".", ms=4, color=BLUE, label="GPS")
    for k in np.linspace(0, len(p["t"]) - 1, 6).astype(int):
        ax.plot([p["axle"][k, 0], p["laser"][k, 0]], [p["axle"][k, 1], p["laser"][k, 1]],
                "-", color=PURPLE, lw=0.8)
    ax.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal",
           title=f"t = {p['t'][0]:.1f} .. {p['t'][-1]:.1f} s (purple: lever arm)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    ax2.plot(stretch.gps_t, p["error"], "-", color=RED)
    ax2.set(xlabel="time [s]", ylabel="distance laser path - GPS [m]",
            title=f"RMS {s['rms']:.3f} m; best fit a = {best[0]:.2f}, b = {best[1]:.2f}: "
                  f"{best_rms:.3f} m")
    ax2.grid(True, alpha=0.3)
    if fig.get_layout_engine() is None:   # the course style lays out already
        fig.tight_layout()
    return s


def rms_surface(stretch: Stretch, a_values, b_values, *, align: bool = True) -> np.ndarray:
    """RMS distance (m) between laser path and GPS for every trial offset of a grid:
    array (len(b_values), len(a_values)), rows b, columns a (the layout of plt.contour)."""
    return np.array([[offset_summary(stretch, a, b, align=align)["rms"] for a in a_values]
                     for b in b_values])


def plot_rms_surface(stretch: Stretch, a_values, b_values, *, vehicle: Vehicle | None = None,
                     align: bool = True, ax=None):
    """Contours of :func:`rms_surface`, with the best fit (black dot) and the nominal
    offset of ``vehicle`` (red triangle). Returns the axes."""
    if ax is None:
        _, ax = figure(height=4.5)
    rms = rms_surface(stretch, a_values, b_values, align=align)
    levels = np.array([0.05, 0.1, 0.2, 0.3, 0.5, 1.0, 2.0])
    cs = ax.contour(a_values, b_values, rms, levels=levels[levels > rms.min()], cmap="viridis")
    ax.clabel(cs, fmt="%.2f m", fontsize=8)
    best = best_offset(stretch, align=align)
    ax.plot(*best, "ko", label=f"best fit ({best[0]:.2f}, {best[1]:.2f})")
    if vehicle is not None:
        ax.plot(vehicle.a, vehicle.b, "^", color=RED, ms=9, label=f"ACFR ({vehicle.a}, {vehicle.b})")
    ax.set(xlabel="a [m] (ahead of the rear axle)", ylabel="b [m] (to the left)",
           title="RMS distance laser path - GPS")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right")
    return ax


def offset_explorer(ds: Dataset, t0: float = TURN[0], t1: float = TURN[1]):
    """Sliders for a and b (and the heading alignment) drawing the laser's path against
    the axle's and GPS on a stretch of ``ds``; the latest :func:`offset_summary` is kept
    in ``widget.holder["summary"]`` (and the paths in ``holder["paths"]``)."""
    stretch = car_park_stretch(ds, t0, t1)
    holder = {"stretch": stretch}
    v = ds.vehicle
    # One map view for every offset (the nominal one's, with room): the laser path moves in
    # a still frame, so a step redraws only the paths over the kept picture (plots.blit).
    p0 = offset_paths(stretch, v.a, v.b)
    pts = np.vstack([p0["axle"][:, :2], p0["laser"][:, :2], stretch.gps_xy])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.15 * (hi - lo).max()
    view = dict(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad))

    views = []                  # the blitted figure (plots.blit.Blit), made at the first draw

    def draw(a: float, b: float, align: bool) -> None:
        p = offset_paths(stretch, a, b, align=align)
        if not views or np.max(p["error"]) > views[0].fig.axes[1].get_ylim()[1]:
            # the first draw, or an offset whose distance to GPS leaves the right panel's
            # range: drawn anew, that range half as high again as this offset's largest
            fig, axes = widget_figure(1, 2, **STRETCH_LAYOUT)  # not pyplot: see widget_figure
            axes[1].set_ylim(0.0, 1.5 * max(float(np.max(p["error"])), 0.01))
            axes[0].set(**view)
            s, moving = _draw_stretch(stretch, a, b, align, axes)
            views[:] = [Blit(fig, moving)]
        else:
            axes = views[0].fig.axes
            views[0].clear(keep=(axes[0].title, axes[1].title))
            s, moving = _draw_stretch(stretch, a, b, align, axes)
            views[0].set_moving(moving)
        holder["summary"] = s
        holder["paths"] = p
        print(f"a = {a:.2f} m, b = {b:.2f} m: laser path to GPS RMS {s['rms']:.3f} m, "
              f"max {s['max']:.3f} m over {s['fixes']} fixes; heading correction "
              f"{s['heading_correction_deg']:.2f} deg")
        show_png(views[0].png(), alt_text(views[0].fig))

    widget = interactive(
        draw,
        a=FloatSlider(value=v.a, min=-1.0, max=6.0, step=0.01, description="a [m]",
                      continuous_update=False),
        b=FloatSlider(value=v.b, min=-2.0, max=2.0, step=0.01, description="b [m]",
                      continuous_update=False),
        align=Checkbox(value=True, description="fit initial heading"))
    widget.holder = holder
    widget.views = views
    return keyboard_ready(widget)


def _draw_stretch(stretch: Stretch, a: float, b: float, align: bool, axes):
    """:func:`plot_offset_stretch` on axes whose views are fixed; returns its summary and the
    artists it drew (with both titles and the legend), for a blitted step to replace."""
    s, drawn = drawn_by(axes, lambda: plot_offset_stretch(stretch, a, b, align=align, axes=axes))
    return s, drawn + [axes[0].title, axes[1].title]


def offset_geometry_figure(vehicle: Vehicle, headings_deg=(30.0, 150.0)):
    """The lever arm at two headings side by side: a and b stay fixed in the car, so the
    laser's offset from C turns with the heading (section 4.1, Figure 4)."""
    fig, axs = figure(1, len(headings_deg), height=4.8)
    for ax, h in zip(np.atleast_1d(axs), headings_deg):
        plot_offset_geometry(vehicle, phi=np.radians(h), ax=ax)
        ax.set_title(f"heading {h:g} deg: a = {vehicle.a} m ahead, b = {vehicle.b} m left of C")
    return fig


def slip_figure(t_gps, slip_gps_deg, t_model, slip_model_deg):
    """The laser's slip angle (course minus heading) along a turn: measured by GPS and
    predicted by the model, against zero (the offset ignored)."""
    fig, ax = figure(height=3.8)
    ax.plot(t_gps, slip_gps_deg, ".", color=BLUE, label="GPS course − heading (measured)")
    ax.plot(t_model, slip_model_deg, "-", color=RED, label="model, a = 3.78, b = 0.50")
    ax.axhline(0, color="0.4", lw=1.5, label="model with the offset ignored (a = b = 0)")
    ax.set(xlabel="time [s]", ylabel="slip angle of the laser [deg]",
           title="The laser point side-slips in a turn; the rear axle does not")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower left")
    return fig

