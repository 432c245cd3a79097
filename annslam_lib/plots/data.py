"""Figures of the runs themselves (chapters 00-04): the map of a run, a scan in the
vehicle frame, the car's outline, GPS gaps, detections in polar form."""
from __future__ import annotations

import numpy as np

from ..data.records import Dataset, Laser
from ..models.vehicle import Vehicle
from .style import BEACON_STYLE, BLUE, GREEN, RED, axes

__all__ = ["plot_map", "car_outline", "plot_scan_vehicle_frame", "plot_gps_gaps",
           "plot_detections_polar"]


def plot_map(ds: Dataset, ax=None, *, gps_label: str = "GPS track (laser point)",
             beacon_label: str = "surveyed beacons"):
    """GPS track and, where the run has them, the surveyed beacons."""
    ax = axes(ax)
    ax.plot(ds.gps.east, ds.gps.north, ".", ms=2, color=BLUE, label=gps_label)
    ax.plot(ds.gps.east[0], ds.gps.north[0], "o", color=GREEN, ms=8, label="start")
    if ds.beacons is not None:
        ax.scatter(ds.beacons[:, 0], ds.beacons[:, 1], label=beacon_label, **BEACON_STYLE)
        for i, (x, y) in enumerate(ds.beacons):
            ax.annotate(str(i), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=8)
    ax.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return ax



def car_outline(vehicle: Vehicle, length_rear: float = 0.9, width: float = 1.9) -> np.ndarray:
    """Closed polygon (n, 2) of the car body in the rear-axle frame (x forward, y left).

    The body is drawn symmetric about the axle centre; the laser sits at (a, b)."""
    front = vehicle.a + 0.3
    half = width / 2
    return np.array([[-length_rear, -half], [front, -half], [front, half],
                     [-length_rear, half], [-length_rear, -half]])



def plot_scan_vehicle_frame(laser: Laser, k: int, vehicle: Vehicle, ax=None, *,
                            max_range: float = 30.0):
    """Scan ``k`` in the vehicle (rear-axle) frame: x forward, y left, metres.

    Ordinary returns in grey, high-intensity (beacon tape) returns in red, sized by
    their intensity level; the car and the laser's position drawn for scale."""
    ax = axes(ax, figsize=(7, 5))
    r, beta, level = laser.ranges[k], laser.angles, laser.intensity[k]
    keep = r < min(max_range, laser.max_range)
    x = vehicle.a + r * np.sin(beta)
    y = vehicle.b - r * np.cos(beta)
    ordinary = keep & (level == 0)
    bright = keep & (level > 0)
    ax.plot(x[ordinary], y[ordinary], ".", ms=3, color="0.5", label="return")
    ax.scatter(x[bright], y[bright], s=12 + 12 * level[bright], color=RED, zorder=4,
               label="high intensity (tape)")
    body = car_outline(vehicle)
    ax.fill(body[:, 0], body[:, 1], color=BLUE, alpha=0.3, label="car")
    ax.plot(0, 0, "k+", ms=10, label="rear-axle centre")
    ax.plot(vehicle.a, vehicle.b, "k^", ms=8, label="laser")
    ax.set(xlabel="x forward [m]", ylabel="y left [m]", aspect="equal",
           xlim=(-2, max_range), ylim=(-0.6 * max_range, 0.6 * max_range),
           title=f"scan {k} at t = {laser.t[k]:.2f} s")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left")
    return ax



def plot_gps_gaps(ds: Dataset, ax=None, *, min_gap: float = 2.0):
    """GPS fixes with the track broken at every gap longer than ``min_gap`` seconds."""
    ax = axes(ax, figsize=(7, 6))
    gaps = np.flatnonzero(np.diff(ds.gps.t) > min_gap)
    pieces = np.split(np.arange(len(ds.gps)), gaps + 1)
    for j, idx in enumerate(pieces):
        ax.plot(ds.gps.east[idx], ds.gps.north[idx], "-", lw=1, color=BLUE,
                label="GPS (continuous stretches)" if j == 0 else None)
    ends = np.column_stack([ds.gps.xy[gaps], ds.gps.xy[gaps + 1]])
    for j, (x0, y0, x1, y1) in enumerate(ends):
        ax.plot([x0, x1], [y0, y1], ":", color=RED, lw=1,
                label=f"gap > {min_gap:g} s" if j == 0 else None)
    ax.set(xlabel="East x [m]", ylabel="North y [m]", aspect="equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    return ax



def plot_detections_polar(ranges: np.ndarray, bearings: np.ndarray, ax=None, *,
                          sizes: np.ndarray | None = None, title: str = ""):
    """Point detections (range, bearing with pi/2 straight ahead) in the laser frame."""
    ax = axes(ax, figsize=(6, 5))
    x, y = ranges * np.sin(bearings), -ranges * np.cos(bearings)
    ax.scatter(x, y, s=20 if sizes is None else sizes, color=GREEN, edgecolor="k", zorder=4)
    ax.plot(0, 0, "k^", ms=8, label="laser")
    ax.set(xlabel="x forward [m]", ylabel="y left [m]", aspect="equal", title=title)
    ax.grid(True, alpha=0.3)
    return ax
