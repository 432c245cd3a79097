"""Chapter 04 explorers and figures: beacons extracted scan by scan, and gating.

``beacon_scan_summary`` (pure) says what the extractor finds in one scan and, where
the run has a surveyed map and a GPS reference pose, where the surveyed beacons
should appear; ``draw_beacon_scan`` draws it in the laser frame; ``beacon_scrubber``
puts both behind a scan slider. ``draw_gates`` draws the chi-square gates of
predicted landmarks in measurement space (bearing, range) with the observations
and their association; ``gate_explorer`` varies the gate probability on a crafted
scene (notebook 04 "gating and association").
"""
from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
from ipywidgets import IntSlider, SelectionSlider, interactive

from ..perception.association import (NEW, NEW_LANDMARK_PROB, REJECTED, associate,
                                      gate_threshold, mahalanobis)
from ..perception.beacons import BeaconConfig, beacon_config_for, beacons_from_scan
from ..slam.dead_reckoning import gps_scan_poses
from ..models.geometry import wrap_angle
from ..models.observation import observe
from ..plots.style import figure, show_widget_figure, widget_figure
from ..data.records import Dataset
from ..models.uncertainty import ellipse_points
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup
from ..plots.style import BLACK, BLUE, GREEN, GREY, ORANGE, PURPLE, RED, SKY

#: Colours of the association outcomes in :func:`draw_gates`.
OUTCOME_STYLE = {NEW: (GREEN, "new landmark"), REJECTED: (RED, "rejected")}
#: Colours of the gates (none of them green or red, the outcome colours).
GATE_COLORS = (BLUE, ORANGE, PURPLE, RED, SKY, GREEN, BLACK, GREY)

__all__ = ["setup", "beacon_scans_figure", "tape_levels_figure", "residuals_figure", "extracted_map_figure",
           "tree_detections_figure", "gates_figure", "gate_sweep_figure", "beacon_scan_summary", "draw_beacon_scan", "beacon_scrubber", "draw_gates",
           "crafted_scene", "gate_explorer"]


def _laser_xy(r, b):
    """Laser-frame points (x forward, y left) of ranges and laser bearings."""
    return np.stack([r * np.sin(b), -r * np.cos(b)], -1)


def beacon_scan_summary(ds: Dataset, k: int, config: BeaconConfig | None = None) -> dict:
    """What the beacon extractor finds in scan ``k`` of ``ds`` (raw laser needed).

    Keys: scan, t, bright_beams (high-intensity beams), beacons (count), z (n, 2), level,
    width, n_beams, beams (first/last beam); and ``reference``: None, or for a run with
    surveyed beacons and a valid GPS pose at this scan (``dead_reckoning.gps_scan_poses``) a
    dict with the surveyed beacons' predicted ``z`` (those 1..30 m away in the 0..pi field
    of view) and ``residuals`` (n, 2) of each beacon against the nearest prediction
    (range m, bearing rad; NaN beyond 1 m)."""
    if ds.laser is None:
        raise ValueError(f"dataset {ds.name!r} has no raw laser scans")
    if not 0 <= k < len(ds.laser):
        raise IndexError(f"scan index {k} outside 0..{len(ds.laser) - 1}")
    cfg = beacon_config_for(ds) if config is None else config
    laser = ds.laser
    s = beacons_from_scan(laser.ranges[k], laser.intensity[k], laser.angles, cfg)
    out = {"scan": int(k), "t": float(laser.t[k]),
           "bright_beams": int(np.count_nonzero((laser.intensity[k] > 0) & laser.valid[k])),
           "beacons": int(s.z.shape[0]), "z": s.z, "level": s.level, "width": s.width,
           "n_beams": s.n_beams, "beams": s.beams, "R": cfg.R, "reference": None}
    if ds.beacons is not None and len(ds.gps) >= 3:
        poses, valid = gps_scan_poses(ds)
        if valid[k]:
            zt, _, _ = observe(poses[k], ds.beacons)
            seen = (zt[:, 0] >= cfg.min_range) & (zt[:, 0] <= cfg.max_range) \
                & (zt[:, 1] >= 0) & (zt[:, 1] <= np.pi)
            zt = zt[seen]
            res = np.full(s.z.shape, np.nan)
            if zt.shape[0] and s.z.shape[0]:
                d = np.linalg.norm(_laser_xy(s.z[:, None, 0], s.z[:, None, 1])
                                   - _laser_xy(zt[None, :, 0], zt[None, :, 1]), axis=-1)
                j = np.argmin(d, axis=1)
                near = d[np.arange(j.size), j] <= 1.0
                res[near, 0] = s.z[near, 0] - zt[j[near], 0]
                res[near, 1] = wrap_angle(s.z[near, 1] - zt[j[near], 1])
            out["reference"] = {"pose": poses[k], "z": zt, "ids": np.flatnonzero(seen),
                                "residuals": res}
    return out


def draw_beacon_scan(ds: Dataset, summary: dict, ax=None, *, max_range: float = 20.0,
                     n_sigma: float = 3.0):
    """Scan ``summary['scan']`` in the laser frame: ordinary returns (grey), tape beams
    (red, sized by level), extracted centres (black +) with the ``n_sigma`` ellipse of R
    mapped to x, y, and the surveyed beacons predicted from the GPS pose (blue circles)."""
    if ax is None:
        _, ax = figure(height=5.0)
    laser, k = ds.laser, summary["scan"]
    r, b, lv = laser.ranges[k], laser.angles, laser.intensity[k]
    keep = r < min(max_range, laser.max_range)
    p = _laser_xy(r, b)
    ax.plot(*p[keep & (lv == 0)].T, ".", ms=3, color="0.6", label="return")
    bright = keep & (lv > 0)
    ax.scatter(*p[bright].T, s=10 + 10 * lv[bright], color=RED, zorder=3, label="tape beams")
    z = summary["z"]
    if z.shape[0]:
        c = _laser_xy(z[:, 0], z[:, 1])
        ax.plot(*c.T, "k+", ms=12, mew=2, zorder=5, label="beacon centre")
        for (ri, bi), ci in zip(z, c):
            J = np.array([[math.sin(bi), ri * math.cos(bi)], [-math.cos(bi), ri * math.sin(bi)]])
            e = ellipse_points(ci, J @ summary["R"] @ J.T, n_sigma)
            ax.plot(*e.T, "k-", lw=0.8)
    ref = summary.get("reference")
    if ref is not None and ref["z"].shape[0]:
        q = _laser_xy(ref["z"][:, 0], ref["z"][:, 1])
        ax.scatter(*q.T, s=160, facecolors="none", edgecolors=BLUE, lw=1.5, zorder=4,
                   label="surveyed (GPS pose)")
    ax.plot(0, 0, "k^", ms=8, label="laser")
    ax.set(xlabel="x forward [m]", ylabel="y left [m]", aspect="equal",
           xlim=(-0.2 * max_range, max_range), ylim=(-0.8 * max_range, 0.8 * max_range),
           title=f"scan {k} at t = {summary['t']:.2f} s: {summary['bright_beams']} tape beams, "
                 f"{summary['beacons']} beacons")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left")
    return ax


def beacon_scrubber(ds: Dataset, *, config: BeaconConfig | None = None, start: int = 0,
                    max_range: float = 20.0):
    """Sliders for the scan and ``max_gap_beams``: the extracted beacons of each scan,
    drawn with :func:`draw_beacon_scan`; the summary in ``widget.holder['summary']``."""
    if ds.laser is None:
        raise ValueError(f"dataset {ds.name!r} has no raw laser scans to scrub through")
    base = beacon_config_for(ds) if config is None else config
    holder = {}

    def draw(k: int, max_gap_beams: int) -> None:
        from dataclasses import replace

        s = beacon_scan_summary(ds, k, replace(base, max_gap_beams=max_gap_beams))
        holder["summary"] = s
        res = "" if s["reference"] is None else "; vs surveyed: " + ", ".join(
            f"{100 * dr:+.0f} cm / {math.degrees(db):+.1f} deg" for dr, db in s["reference"]["residuals"]
            if np.isfinite(dr))
        print(f"scan {k}: {s['beacons']} beacons at "
              + ", ".join(f"({r:.2f} m, {math.degrees(b):.1f} deg)" for r, b in s["z"]) + res)
        # Taller than wide (equal aspect, more to the sides than ahead): 7 in tall to be read.
        fig, ax = widget_figure(figsize=(9, 7))  # not pyplot: see widget_figure
        draw_beacon_scan(ds, s, ax, max_range=max_range)
        show_widget_figure(fig)

    widget = interactive(
        draw,
        k=IntSlider(value=start, min=0, max=len(ds.laser) - 1, step=1, description="scan",
                    continuous_update=False),
        max_gap_beams=IntSlider(value=base.max_gap_beams, min=0, max=4, step=1,
                                description="max gap", continuous_update=False))
    widget.holder = holder
    return keyboard_ready(widget)


# ------------------------------------------------------------------ gates in measurement space

def _gate_outlines(zhat, S, gate: float):
    """Per predicted landmark, its centre and gate outline in measurement space (x: bearing
    in degrees, y: range in m)."""
    deg = np.diag([180.0 / math.pi, 1.0])
    for m, Sj in zip(zhat, S):
        centre = np.array([math.degrees(m[1]), m[0]])
        yield centre, ellipse_points(centre, deg @ Sj[::-1, ::-1] @ deg, math.sqrt(gate))


def draw_gates(ax, zhat, S, z=None, assign=None, *, gate: float | None = None,
               names=None, title: str = ""):
    """The gates {z : d2(z, zhat_j) <= gate} of predicted landmarks ``zhat`` (m, 2) with
    innovation covariances ``S`` (m, 2, 2), drawn in measurement space (x: bearing in
    degrees, y: range in m), and observations ``z`` (n, 2) coloured by ``assign``
    (a line to the landmark they were matched to). ``gate`` defaults to 99 %."""
    gate = gate_threshold(0.99) if gate is None else gate
    zhat, S = np.asarray(zhat, float), np.asarray(S, float)
    for j, (centre, e) in enumerate(_gate_outlines(zhat, S, gate)):
        color = GATE_COLORS[j % len(GATE_COLORS)]
        ax.plot(*e.T, "-", lw=1.5, color=color)
        ax.plot(*centre, "s", color=color, ms=6)
        name = names[j] if names is not None else f"landmark {j}"
        ax.annotate(name, centre, xytext=(6, 2), textcoords="offset points", fontsize=8,
                    color=color)
    if z is not None:
        z = np.asarray(z, float)
        assign = np.full(z.shape[0], REJECTED) if assign is None else np.asarray(assign)
        for i, (zi, a) in enumerate(zip(z, assign)):
            p = np.array([math.degrees(zi[1]), zi[0]])
            color, _ = OUTCOME_STYLE.get(int(a), ("k", "matched"))
            ax.plot(*p, "o", color=color, ms=7, mec="k")
            ax.annotate(f"z{i}", p, xytext=(5, -10), textcoords="offset points", fontsize=8)
            if a >= 0:
                m = zhat[a]
                ax.plot([p[0], math.degrees(m[1])], [p[1], m[0]], "k--", lw=1.2, zorder=4)
    handles = [plt.Line2D([], [], marker="o", ls="", color=c, mec="k", label=lab)
               for c, lab in [("k", "matched"), *OUTCOME_STYLE.values()]]
    ax.legend(handles=handles, loc="best")
    ax.set(xlabel="bearing [deg]", ylabel="range [m]", title=title)
    ax.grid(True, alpha=0.3)
    return ax


def crafted_scene() -> dict:
    """Four predicted landmarks and five observations (notebook 04): z0 sits between
    landmarks 0 and 1, nearer to 0 in metres but to 1 in Mahalanobis distance; z1 and z2
    compete for landmark 2; z3 lies just outside landmark 3's 99 % gate (rejected); z4 is
    far from everything (new)."""
    sb = math.radians(1.0)
    zhat = np.array([[10.3, 1.00], [10.8, 1.00], [6.0, 1.60], [14.0, 2.30]])
    S = np.stack([np.diag([0.1**2, (0.5 * sb) ** 2]), np.diag([0.5**2, (1.5 * sb) ** 2]),
                  np.array([[0.2**2, 0.5 * 0.2 * 2 * sb], [0.5 * 0.2 * 2 * sb, (2 * sb) ** 2]]),
                  np.diag([0.3**2, (2 * sb) ** 2])])
    z = np.array([[10.0, 1.00], [6.1, 1.61], [5.8, 1.58], [14.0 + 3.5 * 0.3, 2.30], [8.0, 2.00]])
    return {"zhat": zhat, "S": S, "z": z}


def gate_explorer(*, prob: float = 0.99, new_prob: float = NEW_LANDMARK_PROB):
    """A slider over the gate probability on :func:`crafted_scene`: watch observations
    move between matched, rejected and new. ``widget.holder['summary']`` holds d2,
    the gate and the assignment."""
    scene = crafted_scene()
    d2 = mahalanobis(scene["z"], scene["zhat"], scene["S"])
    holder = {}
    new = gate_threshold(new_prob)
    options = [0.5, 0.9, 0.95, 0.99, 0.999, 0.9999, 0.999999]
    # One view for every gate (that of the widest): the gates grow and shrink in place,
    # and the figure keeps one layout (plots.style.render_png).
    widest = _gate_outlines(scene["zhat"], scene["S"], gate_threshold(max(options)))
    pts = np.vstack([e for _, e in widest]
                    + [np.column_stack([np.degrees(scene["z"][:, 1]), scene["z"][:, 0]])])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.08 * (hi - lo)
    view = dict(xlim=(lo[0] - pad[0], hi[0] + 2 * pad[0]), ylim=(lo[1] - pad[1], hi[1] + pad[1]))

    def draw(prob: float) -> None:
        g = gate_threshold(prob)
        a = associate(d2, gate=g, new_landmark=max(new, g))
        holder["summary"] = {"prob": prob, "gate": g, "d2": d2, "assign": a}
        print(f"gate {100 * prob:g} %: d2 <= {g:.2f}; assignment {a.tolist()} "
              "(-1 new, -2 rejected)")
        fig, ax = widget_figure(figsize=(7, 5))  # not pyplot: see widget_figure
        draw_gates(ax, scene["zhat"], scene["S"], scene["z"], a, gate=g,
                   title=f"{100 * prob:g} % gates")
        ax.set(**view)
        show_widget_figure(fig)

    if prob not in options:
        raise ValueError(f"prob must be one of {options}, got {prob!r}")
    widget = interactive(draw, prob=SelectionSlider(options=options, value=prob,
                                                    description="gate prob",
                                                    continuous_update=False))
    widget.holder = holder
    return keyboard_ready(widget)


def tape_levels_figure(ranges, levels):
    """Tape beams of a run by range, stacked by intensity level 1-4."""
    ranges, levels = np.asarray(ranges), np.asarray(levels)
    fig, ax = figure(height=3.6)
    ax.hist([ranges[levels == lv] for lv in range(1, 5)], bins=np.arange(0, 17, 0.5),
            stacked=True, label=[f"level {lv}" for lv in range(1, 5)])
    ax.set(xlabel="range [m]", ylabel="tape beams",
           title="Car Park: tape beams by range and intensity level")
    ax.legend(loc="upper right")
    ax.grid(True, alpha=0.3)
    return fig


def _normal(x, sd):
    return np.exp(-0.5 * (x / sd) ** 2) / (sd * math.sqrt(2 * math.pi))


def residuals_figure(res, stats: dict, config: BeaconConfig):
    """Range and bearing residuals of the extracted beacons against the survey seen from
    GPS, with the normal densities of the chosen sigma_r and sigma_beta."""
    fig, (a1, a2) = figure(1, 2, height=3.8)
    m = res.matched
    a1.hist(100 * res.range[m], bins=np.arange(-15, 16, 1), density=True, color=BLUE, alpha=0.7)
    x = np.linspace(-15, 15, 200)
    sr = 100 * config.sigma_range
    a1.plot(x, _normal(x, sr), "k-", label=f"N(0, {sr:.0f} cm): the chosen σ_r")
    a1.set(xlabel="range residual [cm]", ylabel="density",
           title=f"range: mean {100 * stats['range_mean']:+.1f} cm, sd {100 * stats['range_std']:.1f} cm")
    a1.legend(loc="upper left")
    a2.hist(np.degrees(res.bearing[m]), bins=np.arange(-4, 4.25, 0.25), density=True,
            color=ORANGE, alpha=0.7)
    x = np.linspace(-4, 4, 200)
    sb = math.degrees(config.sigma_bearing)
    a2.plot(x, _normal(x, sb), "k-", label=f"N(0, {sb:.0f}°): the chosen σ_β")
    a2.set(xlabel="bearing residual [deg]",
           title=f"bearing vs GPS heading: mean {math.degrees(stats['bearing_mean']):+.2f}°, "
                 f"sd {math.degrees(stats['bearing_std']):.2f}°")
    a2.legend(loc="upper left")
    for a in (a1, a2):
        a.grid(True, alpha=0.3)
    return fig


def extracted_map_figure(ds: Dataset, world, ok, intensity):
    """Every extracted beacon placed in the world from the GPS pose of its scan (colour:
    intensity level) against 1 m circles around the surveyed beacons; right, a zoom on
    the busiest beacon."""
    world, ok = np.asarray(world), np.asarray(ok, dtype=bool)
    fig, axs = figure(1, 2, height=5.6, width_ratios=[1, 1])
    near = np.hypot(*(world[ok, None, :] - ds.beacons[None]).transpose(2, 0, 1)) < 1.0
    busiest = int(np.argmax(near.sum(axis=0)))
    for ax, zoom in zip(axs, (False, True)):
        ax.plot(ds.gps.east, ds.gps.north, "-", color="0.7", lw=1, label="GPS track")
        for n_, b_ in enumerate(ds.beacons):
            ax.add_patch(plt.Circle(b_, 1.0, fill=False, color=RED,
                                    label="1 m around a surveyed beacon" if n_ == 0 else None))
        sc = ax.scatter(*world[ok].T, s=5 if not zoom else 12, c=np.asarray(intensity)[ok],
                        cmap="viridis", label="extracted beacons (colour: level)")
        ax.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal")
        ax.grid(True, alpha=0.3)
        if zoom:
            bx, by = ds.beacons[busiest]
            ax.set(xlim=(bx - 1.5, bx + 1.5), ylim=(by - 1.5, by + 1.5),
                   title=f"beacon {busiest}: {near[:, busiest].sum()} extractions")
            fig.colorbar(sc, ax=ax, label="intensity level")
        else:
            ax.set(xlim=(-10, 20), ylim=(-25, 20), title=f"{ok.sum()} beacons placed from the GPS pose")
            ax.legend(loc="lower left")
    return fig


def tree_detections_figure(trees):
    """Victoria Park's tree detections: ranges, bearings, and diameter against range with
    the chord of one beam."""
    fig, axs = figure(1, 3, height=3.6)
    axs[0].hist(trees.range, bins=np.arange(0, 80, 2), color=GREEN)
    axs[0].set(xlabel="range [m]", ylabel="detections")
    axs[1].hist(np.degrees(trees.bearing), bins=np.arange(0, 181, 5), color=GREEN)
    axs[1].set(xlabel="bearing [deg] (90 = ahead)")
    axs[2].scatter(trees.range[::5], trees.diameter[::5], s=1, alpha=0.3, color=GREEN,
                   label="trees (every 5th)")
    rr = np.linspace(0, 80, 50)
    axs[2].plot(rr, rr * math.radians(0.5), "k-", label="one beam chord, r × 0.5°")
    axs[2].set(xlabel="range [m]", ylabel="diameter [m]", ylim=(0, 1.5))
    axs[2].legend(loc="upper left")
    for a in axs:
        a.grid(True, alpha=0.3)
    fig.suptitle("Victoria Park tree detections")
    return fig


def gates_figure(scene: dict, assign, zoom=((54, 61), (9.2, 12.4))):
    """The crafted scene's 99 % gates in measurement space, and a zoom on ``zoom``."""
    fig, (a1, a2) = figure(1, 2, height=5.0, width_ratios=[3, 2])
    draw_gates(a1, scene["zhat"], scene["S"], scene["z"], assign, title="99 % gates in measurement space")
    draw_gates(a2, scene["zhat"], scene["S"], scene["z"], assign, title="zoom on z0 (dashed: the match)")
    a2.set(xlim=zoom[0], ylim=zoom[1])
    return fig


def gate_sweep_figure(probs, table):
    """Correct, missed and wrong associations against the gate probability (log scale)."""
    fig, ax = figure(height=4.0)
    x = np.arange(len(probs))
    for key, color, style in (("correct", GREEN, "o-"), ("missed", ORANGE, "s--"),
                              ("wrong", RED, "^:")):
        ax.plot(x, [row[key] for row in table], style, color=color, label=key)
    ax.set_yscale("log")
    ax.set_xticks(x, [f"{p:.8g}" for p in probs])
    ax.set(xlabel="gate probability p", ylabel="measurements", title="too small: missed; too large: wrong")
    ax.legend(loc="center right")
    ax.grid(True, alpha=0.3)
    return fig


def beacon_scans_figure(ds: Dataset, scans, *, max_range: float = 16.0):
    """:func:`draw_beacon_scan` of several scans side by side (the explorer's frames)."""
    fig, axs = figure(1, len(scans), height=5.2)
    for ax, k in zip(np.atleast_1d(axs), scans):
        draw_beacon_scan(ds, beacon_scan_summary(ds, k), ax=ax, max_range=max_range)
    return fig
