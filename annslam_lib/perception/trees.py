"""The trees of Victoria Park (notebooks 04 and 06).

ACFR's own extraction is provided per scan (range, bearing, trunk diameter);
:func:`trees_filter` removes the far detections that are rarely seen again in the next
scan (:func:`next_scan_match`, :func:`repeatability`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import _checks
from ..data.records import Detections
from ..models.geometry import wrap_angle
from ..models.observation import inverse_observe, observe

__all__ = ["TreeFilter", "trees_filter", "NextScanMatch", "next_scan_match", "repeatability"]


@dataclass(frozen=True)
class TreeFilter:
    """Which of Victoria Park's tree detections to keep, and their noise.

    min_range, max_range (m), min_diameter, max_diameter (m): kept detections satisfy
    min <= value <= max. Defaults from the next-scan confirmation rate (notebook 04,
    :func:`next_scan_match`): 68-85 % of the trees in each 10 m band from 5 to 40 m
    are seen again within 1 m in the next scan, but only 48 % at 40-50 m and 38 % beyond; the 23 trunks thinner
    than 5 cm are confirmed 35 % of the time. Hence 40 m and 5 cm.
    sigma_range (m), sigma_bearing (rad): a starting point for R (no true map exists to
        measure it). From :func:`repeatability` with dead-reckoned poses, trees at 5-40 m:
        views one scan apart agree to 3-8 cm and 0.2 deg (per view); views ten scans
        (2 s) apart, which add the change of viewpoint and 2 s of dead-reckoning drift,
        to 11-12 cm and 0.5-1.1 deg. Hence 0.15 m and 1 deg.
    """

    min_range: float = 1.0
    max_range: float = 40.0
    min_diameter: float = 0.05
    max_diameter: float = math.inf
    sigma_range: float = 0.15
    sigma_bearing: float = math.radians(1.0)

    def __post_init__(self) -> None:
        o = "TreeFilter"
        _checks.real(f"{o}.min_range", self.min_range, lo=0.0)
        _checks.real(f"{o}.max_range", self.max_range, lo=0.0, strict=True, finite=False)
        _checks.real(f"{o}.min_diameter", self.min_diameter, lo=0.0)
        _checks.real(f"{o}.max_diameter", self.max_diameter, lo=0.0, strict=True, finite=False)
        _checks.real(f"{o}.sigma_range", self.sigma_range, lo=0.0, strict=True)
        _checks.real(f"{o}.sigma_bearing", self.sigma_bearing, lo=0.0, strict=True)
        if self.max_range <= self.min_range or self.max_diameter <= self.min_diameter:
            raise ValueError(f"{o}: need min_range < max_range and min_diameter < max_diameter, "
                             f"got {self.min_range}..{self.max_range} m, "
                             f"{self.min_diameter}..{self.max_diameter} m")



def _subset(det: Detections, keep: np.ndarray) -> Detections:
    scan = np.repeat(np.arange(len(det)), det.per_scan())
    offsets = np.concatenate([[0], np.cumsum(np.bincount(scan[keep], minlength=len(det)))])
    return Detections(t=det.t, offsets=offsets.astype(np.int64), range=det.range[keep],
                      bearing=det.bearing[keep], diameter=det.diameter[keep],
                      landmark_id=det.landmark_id[keep], intensity=det.intensity[keep])



def trees_filter(detections: Detections, tree_filter: TreeFilter = TreeFilter(), **overrides) -> Detections:
    """The detections inside the range and diameter windows of ``tree_filter`` (every
    scan kept, possibly empty). Keyword overrides replace TreeFilter fields, e.g.
    ``trees_filter(vp.trees, max_range=30)``. NaN diameters are dropped."""
    if not isinstance(detections, Detections):
        raise TypeError(f"detections must be a records.Detections, got {type(detections).__name__}")
    if not isinstance(tree_filter, TreeFilter):
        raise TypeError(f"tree_filter must be a TreeFilter, got {type(tree_filter).__name__}")
    if overrides:
        from dataclasses import fields, replace
        unknown = sorted(set(overrides) - {f.name for f in fields(TreeFilter)})
        if unknown:
            raise ValueError(f"unknown TreeFilter field(s): {', '.join(unknown)}")
        tree_filter = replace(tree_filter, **overrides)
    f, r, d = tree_filter, detections.range, detections.diameter
    with np.errstate(invalid="ignore"):
        keep = (r >= f.min_range) & (r <= f.max_range) & (d >= f.min_diameter) & (d <= f.max_diameter)
    return _subset(detections, keep)



class NextScanMatch(NamedTuple):
    """:func:`next_scan_match`: for each detection, the world distance (m) to the nearest
    detection ``lag`` scans later (inf if none) and that detection's row (-1 if none)."""

    distance: np.ndarray
    index: np.ndarray



def _world(detections: Detections, poses) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(detections, Detections):
        raise TypeError(f"detections must be a records.Detections, got {type(detections).__name__}")
    poses = _checks.array("poses", poses, (3,))
    if poses.shape != (len(detections), 3):
        raise ValueError(f"poses must be ({len(detections)}, 3), one per scan, got {poses.shape}")
    scan = np.repeat(np.arange(len(detections)), detections.per_scan())
    world, _, _ = inverse_observe(poses[scan], np.column_stack([detections.range, detections.bearing]))
    return world, poses



def next_scan_match(detections: Detections, poses, *, lag: int = 1) -> NextScanMatch:
    """For every detection of scan k, the nearest detection of scan k + ``lag`` in the
    world, both placed with ``inverse_observe`` from ``poses`` (S, 3), one laser pose per
    scan.

    With dead-reckoned poses, accurate over a few scan intervals, this needs neither GPS
    nor a map (notebook 04, "which trees are real?"): a tree seen again within ~1 m is
    probably real."""
    world, poses = _world(detections, poses)
    lag = _checks.integer("next_scan_match.lag", lag, lo=1)
    n = detections.count
    dist, index = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
    off, count = detections.offsets, detections.per_scan()
    # One small (n_k x n_k+lag) distance table per pair of scans: ~7 trees a scan.
    for k in np.flatnonzero((count[:-lag] > 0) & (count[lag:] > 0)) if n else ():
        a, b = world[off[k]:off[k + 1]], world[off[k + lag]:off[k + lag + 1]]
        d = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
        j = np.argmin(d, axis=1)
        dist[off[k]:off[k + 1]] = d[np.arange(j.size), j]
        index[off[k]:off[k + 1]] = off[k + lag] + j
    return NextScanMatch(dist, index)



def repeatability(detections: Detections, poses, *, lag: int = 1,
                  max_distance: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Scan-to-scan residuals of re-seen landmarks (notebook 04, trees' noise).

    Each detection of scan k matched by :func:`next_scan_match` within ``max_distance``
    is predicted from scan k + ``lag``'s pose (``observe`` of its world position) and
    compared with its match there. Returns (rows (p,) of the scan-k detections,
    residuals (p, 2) = matched minus predicted (range m, bearing rad, wrapped)).
    Both measurements are noisy, so the residual's variance is twice the noise
    variance, plus the pose error accumulated over ``lag`` scans."""
    world, poses = _world(detections, poses)
    _checks.real("repeatability.max_distance", max_distance, lo=0.0, strict=True)
    m = next_scan_match(detections, poses, lag=lag)
    rows = np.flatnonzero(m.distance <= max_distance)
    later = np.repeat(np.arange(len(detections)), detections.per_scan())[m.index[rows]]
    zhat, _, _ = observe(poses[later], world[rows]) if rows.size else (np.zeros((0, 2)), 0, 0)
    res = np.column_stack([detections.range[m.index[rows]], detections.bearing[m.index[rows]]]) - zhat
    res[:, 1] = wrap_angle(res[:, 1]) if rows.size else res[:, 1]
    return rows, res
