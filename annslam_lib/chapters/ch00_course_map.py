"""Chapter 00 companion: the tour's figures and the scan scrubber."""
from __future__ import annotations

import numpy as np
from ipywidgets import IntSlider, interactive

from ..data.records import Dataset, Laser
from ..plots.data import plot_detections_polar, plot_gps_gaps, plot_map, plot_scan_vehicle_frame
from ..plots.style import GREEN, ORANGE, RED, figure, show_widget_figure, widget_figure
from ..plots.style import keyboard_ready
from ..plots.style import notebook_setup as setup

__all__ = ["setup", "scan_summary", "scan_readout", "scan_scrubber", "car_park_figure",
           "scan_figure", "gps_gaps_figure", "trees_figure", "simulated_run_figure"]


def car_park_figure(car: Dataset):
    """The Car Park run: its GPS track and surveyed beacons, and the speed and steering
    the car logged over the same two minutes."""
    fig, axs = figure(2, 2, height=5.5, width_ratios=[1, 1.5])
    gs = axs[0, 0].get_gridspec()
    for ax in axs[:, 0]:
        ax.remove()
    ax_map = fig.add_subplot(gs[:, 0])
    plot_map(car, ax=ax_map)
    ax_map.legend(loc="lower right")
    ax_map.set(xlim=(-10, 20), ylim=(-25, 20), title="GPS track and surveyed beacons")
    odo = car.odometry
    axs[0, 1].plot(odo.t, odo.speed, lw=0.8)
    axs[0, 1].set(ylabel="encoder speed [m/s]", title="what the car logged")
    axs[1, 1].plot(odo.t, np.degrees(odo.steering), lw=0.8, color=ORANGE)
    axs[1, 1].set(xlabel="time [s]", ylabel="steering [deg]")
    for ax in axs[:, 1]:
        ax.grid(True, alpha=0.3)
    return fig


def scan_figure(laser: Laser, k: int, vehicle, *, max_range: float = 20.0):
    """Scan ``k`` in the vehicle frame (left) and beam by beam (right: range against the
    beam's angle, tape returns in red, "no return" left out)."""
    fig, (ax0, ax1) = figure(1, 2, height=4.8, width_ratios=[1.1, 1])
    plot_scan_vehicle_frame(laser, k, vehicle, ax=ax0, max_range=max_range)
    r, level = laser.ranges[k], laser.intensity[k]
    ok = r < laser.max_range
    deg = np.degrees(laser.angles)
    ax1.plot(deg[ok], r[ok], ".", ms=3, color="0.5", label="return")
    ax1.scatter(deg[ok & (level > 0)], r[ok & (level > 0)], s=14, color=RED, zorder=4,
                label="high intensity (tape)")
    ax1.set(xlabel="beam angle [deg] (0 = right, 90 = ahead)", ylabel="range [m]",
            xlim=(0, 180), title=f"the same scan, {np.count_nonzero(ok)} of {r.size} beams return")
    ax1.grid(True, alpha=0.3)
    ax1.legend(loc="upper right")
    return fig


def gps_gaps_figure(ds: Dataset, *, min_gap: float = 2.0):
    """GPS with its gaps: the track broken at every gap longer than ``min_gap`` seconds
    (left) and the time between fixes along the run (right)."""
    fig, (ax0, ax1) = figure(1, 2, height=5.0, width_ratios=[1, 1.2])
    plot_gps_gaps(ds, ax=ax0, min_gap=min_gap)
    ax0.set_title("the track, broken at its gaps")
    dt = np.diff(ds.gps.t)
    ax1.semilogy(ds.gps.t[1:], dt, ".", ms=2)
    ax1.axhline(min_gap, color=RED, ls=":", label=f"{min_gap:g} s")
    ax1.set(xlabel="time [s]", ylabel="time since the previous fix [s]",
            title="time between GPS fixes")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(loc="upper left")
    return fig


def trees_figure(ds: Dataset, k: int = 0):
    """The trees of scan ``k`` in the laser frame (marker area ~ trunk diameter), and how
    many trees each scan of the run holds."""
    fig, (ax0, ax1) = figure(1, 2, height=4.5, width_ratios=[1.2, 1])
    det = ds.trees
    z = det[k]
    d = det.diameter[det.offsets[k]:det.offsets[k + 1]]
    plot_detections_polar(z[:, 0], z[:, 1], ax=ax0, sizes=2000 * d,
                          title=f"scan {k}: {len(z)} trees (marker area ~ trunk diameter)")
    per = det.per_scan()
    ax1.hist(per, bins=np.arange(per.max() + 2) - 0.5, color=GREEN, alpha=0.8)
    ax1.set(xlabel="trees in a scan", ylabel="scans", title=f"{len(det)} scans")
    ax1.grid(True, alpha=0.3)
    return fig


def simulated_run_figure(sim: Dataset):
    """A simulated run: true path, noisy GPS and true beacons (left), and the beacon
    detections per scan along the run (right)."""
    fig, (ax0, ax1) = figure(1, 2, height=4.8, width_ratios=[1.5, 1])
    plot_map(sim, ax=ax0, gps_label="GPS (noisy)", beacon_label="true beacons")
    ax0.plot(sim.truth.poses[:, 1], sim.truth.poses[:, 2], "k-", lw=0.8, label="true path")
    ax0.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=4)
    ax0.set_title("true path, GPS, beacons")
    ax1.plot(sim.detections.t, sim.detections.per_scan(), ".", ms=3)
    ax1.set(xlabel="time [s]", ylabel="beacons detected", title="detections per scan")
    ax1.grid(True, alpha=0.3)
    return fig


def scan_summary(laser: Laser, k: int, *, max_range: float = 30.0) -> dict:
    """What scan ``k`` holds: its time, the number of returns within ``max_range``,
    and the number of high-intensity (tape) beams with their range span."""
    if not 0 <= k < len(laser):
        raise IndexError(f"scan index {k} outside 0..{len(laser) - 1}")
    r = laser.ranges[k]
    bright = (laser.intensity[k] > 0) & (r < laser.max_range)
    return {
        "scan": int(k),
        "t": float(laser.t[k]),
        "returns": int(np.count_nonzero(r < min(max_range, laser.max_range))),
        "bright_beams": int(np.count_nonzero(bright)),
        "bright_range": (float(r[bright].min()), float(r[bright].max())) if bright.any() else None,
    }


def scan_readout(summary: dict) -> str:
    """One line of text for a :func:`scan_summary`, printed under the scrubber's slider
    (so a reader, or a browser test, can read what the current scan holds)."""
    line = (f"scan {summary['scan']}  t = {summary['t']:.2f} s  returns {summary['returns']}  "
            f"bright beams {summary['bright_beams']}")
    if summary["bright_range"] is not None:
        line += f" ({summary['bright_range'][0]:.2f}-{summary['bright_range'][1]:.2f} m)"
    return line


def scan_scrubber(ds: Dataset, *, max_range: float = 20.0, start: int = 0):
    """A time slider over the raw laser scans of ``ds`` drawing each in the vehicle frame,
    under a one-line :func:`scan_readout`. The latest summary is in ``widget.holder["summary"]``,
    its readout in ``holder["readout"]``."""
    if ds.laser is None:
        raise ValueError(f"dataset {ds.name!r} has no raw laser scans to scrub through")
    holder = {}

    def draw(k: int) -> None:
        holder["summary"] = s = scan_summary(ds.laser, k, max_range=max_range)
        holder["readout"] = scan_readout(s)
        print(holder["readout"])
        # Not pyplot: a kernel subshell thread may flush pyplot figures mid-draw (widget_figure).
        fig, ax = widget_figure(figsize=(7, 5))
        plot_scan_vehicle_frame(ds.laser, k, ds.vehicle, ax=ax, max_range=max_range)
        show_widget_figure(fig)

    slider = IntSlider(value=start, min=0, max=len(ds.laser) - 1, step=1,
                       description="scan", continuous_update=False)
    widget = interactive(draw, k=slider)
    widget.holder = holder
    return keyboard_ready(widget)
