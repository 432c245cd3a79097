"""Sensor streams checked on entry to a filter run (``slam.runner.run`` calls
:func:`screen` first, and counts what it did in ``SlamResult.counts``).

A damaged stream must not diverge silently. The records already refuse what cannot be a
stream at all (NaN, time going backwards: ``data.records``). What remains are values a
stream can hold but a car cannot, and repeated samples. The rules, applied in this order:

1. repeated odometry samples: rows with the same time as an earlier row are dropped; those
   with the same speed and steering as it are counted as ``duplicates``, those with other
   values as ``conflicts`` (two readings for one instant: the first one is kept);
2. impossible odometry: a sample with |speed| > ``max_speed`` (m/s) or |steering| >
   ``max_steer`` (rad) is dropped (``impossible``), so the control before it is held over
   its interval;
3. clock jumps: an odometry interval longer than ``max_gap`` s is kept and counted
   (``gaps``, with the longest): the prediction over it takes the process noise of its
   length, so the covariance grows with it; nothing is invented for the missing samples;
4. repeated laser scans, detection scans and GPS fixes: a scan or fix with the same time as
   the one before is dropped, counted as a duplicate when its content is identical and as a
   conflict when not (the first one is kept).

The clean runs of the course (Car Park, Victoria Park, the simulator) trigger none of them.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .. import _checks
from .records import Dataset, Detections, Gps, Odometry

__all__ = ["Screening", "screen", "MAX_SPEED", "MAX_STEER", "MAX_GAP"]

#: |speed| above this (m/s) is not a car in a car park or a park (Victoria Park: 6.6 m/s).
MAX_SPEED = 15.0
#: |steering| above this (rad) is beyond any car's lock (the ACFR ute: 0.62 rad).
MAX_STEER = 1.0
#: An odometry interval longer than this (s) is a clock jump (the logs run at 40 Hz).
MAX_GAP = 1.0


@dataclass(frozen=True)
class Screening:
    """What :func:`screen` did (module docstring): counts per stream and rule, and the
    longest odometry gap (s)."""

    odometry_duplicates: int = 0
    odometry_conflicts: int = 0
    odometry_impossible: int = 0
    odometry_gaps: int = 0
    longest_gap: float = 0.0
    laser_duplicates: int = 0
    laser_conflicts: int = 0
    scan_duplicates: int = 0
    scan_conflicts: int = 0
    gps_duplicates: int = 0
    gps_conflicts: int = 0

    @property
    def changed(self) -> int:
        """Samples, scans and fixes dropped (gaps are kept, so not counted here)."""
        return sum(v for k, v in self.counts().items() if k != "screen_odometry_gaps")

    def counts(self) -> dict:
        """The integer counts, keyed ``screen_<field>`` (for ``SlamResult.counts``)."""
        return {f"screen_{f.name}": getattr(self, f.name) for f in dataclasses.fields(self)
                if f.name != "longest_gap"}

    def summary(self) -> str:
        parts = [f"{v} {k[7:].replace('_', ' ')}" for k, v in self.counts().items() if v]
        if not parts:
            return "sensor streams: nothing to repair"
        gap = f" (kept; the longest {self.longest_gap:.3g} s)" if self.odometry_gaps else ""
        return "sensor streams: " + ", ".join(parts) + gap


def _repeats(t: np.ndarray) -> np.ndarray:
    """Mask of the entries whose time equals an earlier entry's (times are sorted)."""
    rep = np.zeros(t.size, dtype=bool)
    if t.size > 1:
        rep[1:] = np.diff(t) == 0
    return rep


def _first_of(t: np.ndarray) -> np.ndarray:
    """Index of the first entry with the same time, for every entry (times sorted)."""
    start = np.ones(t.size, dtype=bool)
    if t.size > 1:
        start[1:] = np.diff(t) != 0
    return np.flatnonzero(start)[np.cumsum(start) - 1]


def _split(rep, same) -> tuple[int, int]:
    return int(np.sum(rep & same)), int(np.sum(rep & ~same))


def _odometry(odo: Odometry, max_speed: float, max_steer: float, max_gap: float):
    rep = _repeats(odo.t)
    first = _first_of(odo.t)
    same = (odo.speed == odo.speed[first]) & (odo.steering == odo.steering[first])
    dup, conf = _split(rep, same)
    bad = ~rep & ((np.abs(odo.speed) > max_speed) | (np.abs(odo.steering) > max_steer))
    keep = ~rep & ~bad
    if not keep.any():
        raise ValueError(f"no odometry sample is possible: every one has |speed| > {max_speed} "
                         f"m/s or |steering| > {max_steer} rad, or repeats a time")
    out = odo if keep.all() else Odometry(t=odo.t[keep], speed=odo.speed[keep],
                                          steering=odo.steering[keep])
    dt = np.diff(out.t)
    gaps = dt > max_gap
    return out, dict(odometry_duplicates=dup, odometry_conflicts=conf,
                     odometry_impossible=int(bad.sum()), odometry_gaps=int(gaps.sum()),
                     longest_gap=float(dt[gaps].max()) if gaps.any() else 0.0)


def _scan_same(det: Detections, first: np.ndarray) -> np.ndarray:
    same = np.ones(len(det), dtype=bool)
    for k in np.flatnonzero(first != np.arange(len(det))):
        a, b = slice(det.offsets[k], det.offsets[k + 1]), slice(det.offsets[first[k]],
                                                                 det.offsets[first[k] + 1])
        same[k] = (a.stop - a.start == b.stop - b.start
                   and np.array_equal(det.range[a], det.range[b])
                   and np.array_equal(det.bearing[a], det.bearing[b]))
    return same


def _detections(det: Detections):
    rep = _repeats(det.t)
    if not rep.any():
        return det, (0, 0), None
    first = _first_of(det.t)
    dup, conf = _split(rep, _scan_same(det, first))
    keep = np.flatnonzero(~rep)
    rows = np.concatenate([np.arange(det.offsets[k], det.offsets[k + 1]) for k in keep]
                          ) if keep.size else np.empty(0, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(np.diff(det.offsets)[keep])]).astype(np.int64)
    out = Detections(t=det.t[keep], offsets=offsets, range=det.range[rows],
                     bearing=det.bearing[rows], diameter=det.diameter[rows],
                     landmark_id=det.landmark_id[rows], intensity=det.intensity[rows])
    return out, (dup, conf), keep


def screen(dataset: Dataset, *, max_speed: float = MAX_SPEED, max_steer: float = MAX_STEER,
           max_gap: float = MAX_GAP) -> tuple[Dataset, Screening]:
    """The dataset with its streams repaired by the module's rules, and what was done.
    Returns the same object when nothing needed repair."""
    _checks.instance("dataset", dataset, Dataset, "records.Dataset")
    max_speed = _checks.real("max_speed", max_speed, lo=0.0, strict=True)
    max_steer = _checks.real("max_steer", max_steer, lo=0.0, strict=True)
    max_gap = _checks.real("max_gap", max_gap, lo=0.0, strict=True)
    odo, report = _odometry(dataset.odometry, max_speed, max_steer, max_gap)
    changes: dict = {}
    if odo is not dataset.odometry:
        changes["odometry"] = odo
    info = dict(dataset.info)
    laser = dataset.laser
    if laser is not None:
        rep = _repeats(laser.t)
        if rep.any():
            first = _first_of(laser.t)
            same = np.array([np.array_equal(laser.ranges[k], laser.ranges[first[k]])
                             and np.array_equal(laser.intensity[k], laser.intensity[first[k]])
                             for k in range(len(laser))])
            report["laser_duplicates"], report["laser_conflicts"] = _split(rep, same)
            changes["laser"] = dataclasses.replace(laser, t=laser.t[~rep], ranges=laser.ranges[~rep],
                                                   intensity=laser.intensity[~rep])
    if dataset.detections is not None:
        det, (dup, conf), keep = _detections(dataset.detections)
        report["scan_duplicates"], report["scan_conflicts"] = dup, conf
        if keep is not None:
            changes["detections"] = det
            if "scan_poses" in info:              # the simulator's truth per scan follows
                info["scan_poses"] = np.asarray(info["scan_poses"])[keep]
                changes["info"] = info
    gps = dataset.gps
    rep = _repeats(gps.t)
    if rep.any():
        first = _first_of(gps.t)
        same = (gps.east == gps.east[first]) & (gps.north == gps.north[first])
        report["gps_duplicates"], report["gps_conflicts"] = _split(rep, same)
        changes["gps"] = Gps(t=gps.t[~rep], east=gps.east[~rep], north=gps.north[~rep])
    out = dataclasses.replace(dataset, **changes) if changes else dataset
    return out, Screening(**report)
