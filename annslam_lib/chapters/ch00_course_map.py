"""Chapter 00 explorers: scrubbing through the raw laser scans of a run."""
from __future__ import annotations

import numpy as np
from ipywidgets import IntSlider, interactive

from ..plots.data import plot_scan_vehicle_frame
from ..plots.style import show_widget_figure, widget_figure
from ..data.records import Dataset, Laser
from ..plots.style import notebook_setup as setup

__all__ = ["setup", "scan_summary", "scan_readout", "scan_scrubber"]


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
    return widget
