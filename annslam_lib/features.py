"""Landmark extraction: beacons from raw laser scans, and the trees of Victoria Park
(notebook 04 "landmark extraction and data association").

Beacons (Car Park run, simulator). Poles wrapped in reflective tape return a
non-zero *intensity level* (1..4). A beacon is a cluster of such beams:

1. keep the beams with level >= ``min_level`` and a range inside
   [``min_range``, ``max_range``] (the ACFR program's 1..30 m window);
2. consecutive kept beams of one scan belong to the same cluster when at most
   ``max_gap_beams`` beams lie between them (the tape does not reflect evenly:
   at 1-3 m a pole shows ordinary beams in the middle of its bright ones) and
   their ranges differ by at most ``max_range_jump`` (two poles seen side by side);
3. drop clusters that may show only part of a pole: touching the first or last
   beam of the scan (the pole may continue outside the field of view) or next to
   a beam that returned from something nearer (partly hidden);
4. the pole's centre: bearing = midpoint of the first and last beam of the
   cluster (as ACFR's ``getdata``); range = mean range of the cluster's bright
   beams + ``pole_radius`` (the beams hit the pole's near surface).

All steps run on the flat list of bright beams of all scans at once (``np.diff``
on beam and scan indices marks where clusters break), so the 586 Car Park
scans take about 2 ms. See :class:`BeaconConfig` for the defaults
and the measurements behind them.

Trees (Victoria Park). ACFR's own extraction is provided per scan (range,
bearing, trunk diameter); :func:`trees_filter` removes the far detections that
are rarely seen again in the next scan (:func:`next_scan_match`).
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .geometry import as_array, wrap_angle
from .observation import inverse_observe, observe
from .records import Dataset, Detections, Laser

__all__ = ["BeaconConfig", "BeaconScan", "beacons_from_scan", "extract_beacons", "beacon_config_for",
           "detections_for", "measurement_sigmas", "trees_filter", "TreeFilter",
           "gps_scan_poses", "ExtractionResiduals", "extraction_residuals",
           "next_scan_match", "NextScanMatch", "repeatability", "SOURCES"]

#: Accepted values of ``source`` in :func:`detections_for`.
SOURCES = ("auto", "laser", "detections")


def _real(owner: str, name: str, value, *, lo: float | None = None, strict: bool = False,
          finite: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or math.isnan(value) \
            or (finite and math.isinf(value)):
        raise ValueError(f"{owner}.{name} must be a {'finite ' if finite else ''}number, "
                         f"got {value!r}")
    if lo is not None and (value <= lo if strict else value < lo):
        raise ValueError(f"{owner}.{name} must be {'>' if strict else '>='} {lo}, got {value!r}")
    return float(value)


def _int(owner: str, name: str, value, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < lo:
        raise ValueError(f"{owner}.{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class BeaconConfig:
    """Parameters of the beacon extractor (module docstring, steps 1-4).

    min_range, max_range (m): range window of the bright beams, 1..30 m as in the
        ACFR program. (Its MATLAB test ``min_range<RR(i)<max_range`` reads as
        ``(min_range<RR(i))<max_range``, always true: the original never applied
        the window. On the Car Park run it only matters below 1 m.)
    min_level: lowest intensity level (1..4) counted as tape.
    pole_radius (m): added to the surface range to reach the pole's centre. Default 0:
        against the surveyed beacons seen from GPS the uncorrected range is already
        1.0 cm LONG on average (std 4.1 cm, 605 detections; notebook 04), so adding
        the poles' nominal 3 cm radius would make it 4 cm long. Use the true radius
        for the simulator's ray-cast poles (:func:`detections_for` does).
    max_gap_beams: ordinary beams allowed inside one cluster (0 = strictly contiguous).
        2 as in ACFR's ``getdata``; on the Car Park 1- and 2-beam gaps occur (72 times)
        only at 1-3.5 m, at the same range on both sides: one pole, not two.
    max_range_jump (m): largest range step between neighbouring bright beams of one
        cluster, and the margin by which a neighbouring beam must be nearer to count
        as occluding. 0.5 m: a cluster's own beams agree to 6 cm on the Car Park
        (their spread) and to ~0.3 m in the simulator with 0.1 m per-beam noise.
    drop_edge: drop clusters touching beam 0 or the last beam (a pole cut by the edge
        of the field of view: its midpoint is not its centre).
    drop_occluded: drop clusters whose neighbouring beam returned nearer by more than
        ``max_range_jump`` (the pole may be partly hidden).
    sigma_range (m), sigma_bearing (rad): measurement noise attached to every beacon,
        R = diag(sigma_range^2, sigma_bearing^2). Measured on the Car Park against the
        surveyed beacons from the GPS laser position: range residual std 4.1 cm
        (which includes the GPS and survey errors), so 0.05 m (ACFR used 0.1 m);
        bearing: 0.5 deg per beacon from the heading-free differences of two beacons in
        one scan, but 0.7 deg mean and 1.2 deg std against the GPS-derived heading, so
        we keep ACFR's 1 deg.
    """

    min_range: float = 1.0
    max_range: float = 30.0
    min_level: int = 1
    pole_radius: float = 0.0
    max_gap_beams: int = 2
    max_range_jump: float = 0.5
    drop_edge: bool = True
    drop_occluded: bool = True
    sigma_range: float = 0.05
    sigma_bearing: float = math.radians(1.0)

    def __post_init__(self) -> None:
        o = "BeaconConfig"
        _real(o, "min_range", self.min_range, lo=0.0)
        _real(o, "max_range", self.max_range, lo=0.0, strict=True)
        if self.max_range <= self.min_range:
            raise ValueError(f"{o}.max_range ({self.max_range}) must exceed min_range "
                             f"({self.min_range})")
        _int(o, "min_level", self.min_level, 1)
        _int(o, "max_gap_beams", self.max_gap_beams, 0)
        _real(o, "pole_radius", self.pole_radius, lo=0.0)
        _real(o, "max_range_jump", self.max_range_jump, lo=0.0, strict=True)
        _real(o, "sigma_range", self.sigma_range, lo=0.0, strict=True)
        _real(o, "sigma_bearing", self.sigma_bearing, lo=0.0, strict=True)
        for name in ("drop_edge", "drop_occluded"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{o}.{name} must be a bool, got {getattr(self, name)!r}")

    @property
    def R(self) -> np.ndarray:
        """Measurement noise covariance diag(sigma_range^2, sigma_bearing^2) (2, 2)."""
        return np.diag([self.sigma_range**2, self.sigma_bearing**2])


class BeaconScan(NamedTuple):
    """Beacons of one scan: z (n, 2) (range, bearing) of the pole centres (laser
    convention, bearing 0..pi from the right); R (n, 2, 2) their noise; level (n,)
    highest intensity level; width (n,) chord width (m): the angular span of the
    cluster (last - first + 1 beams) times its range; n_beams (n,) bright beams;
    beams (n, 2) first and last beam index."""

    z: np.ndarray
    R: np.ndarray
    level: np.ndarray
    width: np.ndarray
    n_beams: np.ndarray
    beams: np.ndarray


class _Clusters(NamedTuple):
    scan: np.ndarray
    first: np.ndarray
    last: np.ndarray
    range: np.ndarray
    bearing: np.ndarray
    level: np.ndarray
    width: np.ndarray
    n_beams: np.ndarray


def _beam_step(angles: np.ndarray) -> float:
    """The (uniform, increasing) beam spacing of ``angles``, or ValueError."""
    if angles.size < 2:
        raise ValueError(f"angles must hold at least 2 beams, got {angles.size}")
    d = np.diff(angles)
    step = float(d.mean())
    if step <= 0 or np.max(np.abs(d - step)) > 1e-9 * max(1.0, abs(step)):
        raise ValueError("angles must be uniformly spaced and increasing")
    return step


def _clusters(ranges: np.ndarray, intensity: np.ndarray, angles: np.ndarray,
              cfg: BeaconConfig) -> _Clusters:
    """Steps 1-4 of the module docstring on (S, N) scans at once."""
    n_scans, n_beams = ranges.shape
    step = _beam_step(angles)
    keep = (intensity >= cfg.min_level) & (ranges >= cfg.min_range) & (ranges <= cfg.max_range)
    scan, beam = np.nonzero(keep)                      # row-major: sorted by scan, then beam
    r = ranges[scan, beam]
    if scan.size == 0:
        e = np.empty(0)
        ei = np.empty(0, dtype=np.int64)
        return _Clusters(ei, ei, ei, e, e, np.empty(0, np.uint8), e, ei)
    # A new cluster starts at the first bright beam, at a new scan, after a gap of more
    # than max_gap_beams beams, or after a range jump.
    start = np.ones(scan.size, dtype=bool)
    start[1:] = ((np.diff(scan) != 0) | (np.diff(beam) - 1 > cfg.max_gap_beams)
                 | (np.abs(np.diff(r)) > cfg.max_range_jump))
    cid = np.cumsum(start) - 1
    first = beam[start]
    last = np.append(beam[np.flatnonzero(start)[1:] - 1], beam[-1])
    count = np.bincount(cid)
    surface = np.bincount(cid, weights=r) / count
    level = np.zeros(count.size, dtype=np.uint8)
    np.maximum.at(level, cid, intensity[scan, beam].astype(np.uint8))
    cscan = scan[start]
    ok = np.ones(count.size, dtype=bool)
    if cfg.drop_edge:
        ok &= (first > 0) & (last < n_beams - 1)
    if cfg.drop_occluded:
        # The beams just outside the cluster: a return nearer than the cluster (by more
        # than max_range_jump) may hide part of the pole. No-return beams never occlude.
        for side in (first - 1, last + 1):
            inside = (side >= 0) & (side < n_beams)
            nb = ranges[cscan, np.clip(side, 0, n_beams - 1)]
            ok &= ~(inside & (nb < surface - cfg.max_range_jump))
    rng = surface + cfg.pole_radius
    bearing = 0.5 * (angles[first] + angles[last])
    width = (last - first + 1) * step * rng
    return _Clusters(cscan[ok], first[ok], last[ok], rng[ok], bearing[ok], level[ok],
                     width[ok], count[ok])


def _check_scans(ranges, intensity, angles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ranges = as_array("ranges", ranges)
    angles = as_array("angles", angles)
    if angles.ndim != 1:
        raise ValueError(f"angles must be one-dimensional, got shape {angles.shape}")
    try:
        level = np.asarray(intensity, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"intensity must be numeric, got {intensity!r}") from exc
    if ranges.shape[-1:] != angles.shape or level.shape != ranges.shape:
        raise ValueError(f"ranges {ranges.shape}, intensity {level.shape} and angles "
                         f"{angles.shape} must share the beam dimension")
    if np.any(ranges < 0):
        raise ValueError("ranges must be non-negative")
    if not np.all(np.isfinite(level)) or np.any(level < 0) or np.any(level > 255) \
            or np.any(level != np.round(level)):
        raise ValueError("intensity must hold integer levels 0..255")
    return ranges, level.astype(np.int64), angles


def beacons_from_scan(ranges, intensity, angles, config: BeaconConfig = BeaconConfig()) -> BeaconScan:
    """Beacon measurements of ONE scan (notebook 04 "from beams to beacons").

    ranges, intensity, angles: (N,) beam ranges (m), intensity levels, beam angles
    (rad, uniformly increasing, laser convention). Returns a :class:`BeaconScan`
    ordered by bearing. Raises ValueError for mismatched shapes, NaN, negative
    ranges or non-integer levels.
    """
    if not isinstance(config, BeaconConfig):
        raise ValueError(f"config must be a BeaconConfig, got {type(config).__name__}")
    ranges, level, angles = _check_scans(ranges, intensity, angles)
    if ranges.ndim != 1:
        raise ValueError(f"ranges must be one scan (N,), got shape {ranges.shape}; "
                         "use extract_beacons for many scans")
    c = _clusters(ranges[None], level[None], angles, config)
    n = c.range.size
    return BeaconScan(z=np.column_stack([c.range, c.bearing]).reshape(n, 2),
                      R=np.broadcast_to(config.R, (n, 2, 2)).copy(), level=c.level,
                      width=c.width, n_beams=c.n_beams,
                      beams=np.column_stack([c.first, c.last]).reshape(n, 2))


def extract_beacons(laser: Laser, config: BeaconConfig = BeaconConfig()) -> Detections:
    """Beacon detections of every scan of ``laser`` (notebook 04), vectorised over the
    whole (S, N) array: range and bearing of the pole centres, diameter = the cluster's
    chord width (m), intensity = its highest level, landmark_id = -1 (unknown)."""
    if not isinstance(laser, Laser):
        raise ValueError(f"laser must be an annslam_lib.records.Laser, got {type(laser).__name__}")
    if not isinstance(config, BeaconConfig):
        raise ValueError(f"config must be a BeaconConfig, got {type(config).__name__}")
    c = _clusters(laser.ranges, laser.intensity, laser.angles, config)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(c.scan, minlength=len(laser)))])
    return Detections(t=laser.t, offsets=offsets.astype(np.int64), range=c.range,
                      bearing=c.bearing, diameter=c.width,
                      landmark_id=np.full(c.range.size, -1), intensity=c.level)


def _sim_config(dataset: Dataset):
    cfg = dataset.info.get("config") if isinstance(dataset.info, dict) else None
    return cfg if hasattr(cfg, "pole_radius") and hasattr(cfg, "sigma_range") else None


def beacon_config_for(dataset: Dataset) -> BeaconConfig:
    """The default extractor settings for ``dataset``: BeaconConfig() for the real runs;
    for a simulated run, BeaconConfig(pole_radius=<the simulator's pole radius>)."""
    sim = _sim_config(dataset)
    return BeaconConfig() if sim is None else BeaconConfig(pole_radius=float(sim.pole_radius))


def _resolve(dataset: Dataset, source: str) -> str:
    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be an annslam_lib.records.Dataset, got {type(dataset).__name__}")
    if source not in SOURCES:
        raise ValueError(f"unknown source {source!r}; choose one of {SOURCES}")
    if source == "auto":
        if dataset.detections is not None:
            return "detections"
        if dataset.laser is not None:
            return "laser"
        raise ValueError(f"dataset {dataset.name!r} has neither detections nor raw laser scans")
    if source == "laser" and dataset.laser is None:
        raise ValueError(f"dataset {dataset.name!r} has no raw laser scans to extract beacons "
                         "from (source='laser'); use source='detections'")
    if source == "detections" and dataset.detections is None:
        raise ValueError(f"dataset {dataset.name!r} has no provided detections "
                         "(source='detections'); use source='laser'")
    return source


def detections_for(dataset: Dataset, source: str = "auto", *, config: BeaconConfig | None = None,
                   tree_filter: TreeFilter | None = None) -> Detections:
    """The point-landmark measurements a filter consumes for ``dataset``.

    source: 'auto' = the provided detections if the dataset has them (Victoria Park's
    trees, the simulator's beacons), else beacons extracted from the raw laser (Car
    Park); 'laser' forces extraction (e.g. the simulator's raw laser); 'detections'
    forces the provided ones. ``config`` (extraction only) defaults to BeaconConfig(),
    with the simulator's ``pole_radius`` for a simulated run. ``tree_filter``, if given,
    is applied to provided tree detections (see :func:`trees_filter`); by default
    nothing is filtered. Raises ValueError if the requested source is unavailable.
    """
    src = _resolve(dataset, source)
    if src == "laser":
        return extract_beacons(dataset.laser, beacon_config_for(dataset) if config is None else config)
    det = dataset.detections
    if tree_filter is not None and dataset.landmark_kind == "trees":
        det = trees_filter(det, tree_filter)
    return det


def measurement_sigmas(dataset: Dataset, source: str = "auto", *,
                       config: BeaconConfig | None = None) -> tuple[float, float]:
    """(sigma_range m, sigma_bearing rad) that goes with :func:`detections_for`.

    Extracted beacons: the config's (default BeaconConfig()). The simulator's own
    detections: the simulator's true noise. Victoria Park's trees: TreeFilter's
    sigma_range and sigma_bearing defaults (see there).
    """
    src = _resolve(dataset, source)
    if src == "laser":
        cfg = beacon_config_for(dataset) if config is None else config
        return cfg.sigma_range, cfg.sigma_bearing
    sim = _sim_config(dataset)
    if sim is not None:
        return float(sim.sigma_range), float(sim.sigma_bearing)
    if dataset.landmark_kind == "trees":
        t = TreeFilter()
        return t.sigma_range, t.sigma_bearing
    cfg = BeaconConfig() if config is None else config
    return cfg.sigma_range, cfg.sigma_bearing


# ------------------------------------------------------------------ trees (Victoria Park)

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
        _real(o, "min_range", self.min_range, lo=0.0)
        _real(o, "max_range", self.max_range, lo=0.0, strict=True, finite=False)
        _real(o, "min_diameter", self.min_diameter, lo=0.0)
        _real(o, "max_diameter", self.max_diameter, lo=0.0, strict=True, finite=False)
        _real(o, "sigma_range", self.sigma_range, lo=0.0, strict=True)
        _real(o, "sigma_bearing", self.sigma_bearing, lo=0.0, strict=True)
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
        raise ValueError(f"detections must be a records.Detections, got {type(detections).__name__}")
    if not isinstance(tree_filter, TreeFilter):
        raise ValueError(f"tree_filter must be a TreeFilter, got {type(tree_filter).__name__}")
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
        raise ValueError(f"detections must be a records.Detections, got {type(detections).__name__}")
    poses = as_array("poses", poses, (3,))
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
    lag = _int("next_scan_match", "lag", lag, 1)
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
    _real("repeatability", "max_distance", max_distance, lo=0.0, strict=True)
    m = next_scan_match(detections, poses, lag=lag)
    rows = np.flatnonzero(m.distance <= max_distance)
    later = np.repeat(np.arange(len(detections)), detections.per_scan())[m.index[rows]]
    zhat, _, _ = observe(poses[later], world[rows]) if rows.size else (np.zeros((0, 2)), 0, 0)
    res = np.column_stack([detections.range[m.index[rows]], detections.bearing[m.index[rows]]]) - zhat
    res[:, 1] = wrap_angle(res[:, 1]) if rows.size else res[:, 1]
    return rows, res


# ------------------------------------------------------------------ accuracy against GPS

def gps_scan_poses(dataset: Dataset, *, max_heading_gap: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Reference laser poses at the scan times from GPS alone (notebook 04 "how good
    are the beacons?"): position = GPS interpolated at the scan time (the antenna is at
    the laser), heading = ``dead_reckoning.gps_heading`` (GPS track direction corrected
    for the laser point's side-slip) interpolated at the scan time.

    Returns (poses (S, 3), valid (S,)): valid where the scan lies inside the GPS span and
    a GPS heading exists within ``max_heading_gap`` seconds (the car moving)."""
    from .dead_reckoning import gps_heading

    if not isinstance(dataset, Dataset):
        raise ValueError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    t, gps = dataset.scan_times, dataset.gps
    if len(gps) < 3:
        raise ValueError(f"dataset {dataset.name!r} has {len(gps)} GPS fixes: need at least 3")
    heading = gps_heading(gps, dataset.odometry, dataset.vehicle)
    x = np.interp(t, gps.t, gps.east)
    y = np.interp(t, gps.t, gps.north)
    if heading.shape[0] == 0:
        return np.column_stack([x, y, np.zeros_like(t)]), np.zeros(t.size, dtype=bool)
    ht = heading[:, 0]
    phi = wrap_angle(np.interp(t, ht, np.unwrap(heading[:, 1])))
    k = np.searchsorted(ht, t)
    near = np.minimum(np.abs(t - ht[np.clip(k - 1, 0, ht.size - 1)]),
                      np.abs(t - ht[np.clip(k, 0, ht.size - 1)]))
    valid = (near <= max_heading_gap) & (t >= gps.t[0]) & (t <= gps.t[-1])
    return np.column_stack([x, y, np.atleast_1d(phi)]), valid


@dataclass(frozen=True)
class ExtractionResiduals:
    """Extracted beacons against the surveyed ones (:func:`extraction_residuals`).

    matched (n,) bool: the detection's world position (from the reference pose) lies
    within ``max_distance`` of a surveyed beacon; landmark (n,) that beacon (-1 if not
    matched); range, bearing (n,): measured minus predicted from the reference pose,
    bearing wrapped (NaN where not matched or no valid pose); distance (n,) world
    distance to the nearest beacon (NaN without a valid pose)."""

    matched: np.ndarray
    landmark: np.ndarray
    range: np.ndarray
    bearing: np.ndarray
    distance: np.ndarray

    def stats(self) -> dict:
        """Mean and standard deviation of the matched residuals (m, rad) and counts."""
        m = self.matched
        return {"n": int(m.sum()), "range_mean": float(np.mean(self.range[m])),
                "range_std": float(np.std(self.range[m])),
                "bearing_mean": float(np.mean(self.bearing[m])),
                "bearing_std": float(np.std(self.bearing[m]))}


def extraction_residuals(detections: Detections, poses, valid, beacons, *,
                         max_distance: float = 1.0) -> ExtractionResiduals:
    """Residuals of ``detections`` against the true map ``beacons`` (M, 2), seen from
    reference laser ``poses`` (S, 3) at the scans flagged ``valid`` (S,) (notebook 04).

    Each detection is placed in the world with ``inverse_observe``, matched to the
    nearest beacon if within ``max_distance`` m, and compared with ``observe`` of that
    beacon. The bearing residual inherits the reference heading's error; the range
    residual does not (it depends on the position only)."""
    if not isinstance(detections, Detections):
        raise ValueError(f"detections must be a records.Detections, got {type(detections).__name__}")
    poses = as_array("poses", poses, (3,))
    valid = np.asarray(valid, dtype=bool)
    beacons = as_array("beacons", beacons, (2,))
    if poses.shape != (len(detections), 3) or valid.shape != (len(detections),):
        raise ValueError(f"poses must be ({len(detections)}, 3) and valid ({len(detections)},), "
                         f"got {poses.shape} and {valid.shape}")
    if beacons.ndim != 2 or beacons.shape[0] == 0:
        raise ValueError(f"beacons must be a non-empty (M, 2) array, got {beacons.shape}")
    _real("extraction_residuals", "max_distance", max_distance, lo=0.0, strict=True)
    n = detections.count
    scan = np.repeat(np.arange(len(detections)), detections.per_scan())
    z = np.column_stack([detections.range, detections.bearing])
    world, _, _ = inverse_observe(poses[scan], z)
    d = np.hypot(world[:, None, 0] - beacons[None, :, 0], world[:, None, 1] - beacons[None, :, 1])
    j = np.argmin(d, axis=1) if n else np.zeros(0, dtype=np.int64)
    dist = d[np.arange(n), j]
    ok = valid[scan]
    matched = ok & (dist <= max_distance)
    zhat, _, _ = observe(poses[scan], beacons[j]) if n else (np.zeros((0, 2)), None, None)
    res = z - zhat
    res[:, 1] = wrap_angle(res[:, 1]) if n else res[:, 1]
    res[~matched] = np.nan
    return ExtractionResiduals(matched=matched, landmark=np.where(matched, j, -1),
                               range=res[:, 0], bearing=res[:, 1],
                               distance=np.where(ok, dist, np.nan))


def _positive(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 < value < math.inf:
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


# --------------------------------------------------------------------------- natural point features

def point_features(laser: Laser, *, max_width: float = 0.4, max_range_jump: float = 0.3,
                   min_range: float = 1.0, max_range: float = 30.0,
                   exclude_tape: bool = False) -> Detections:
    """Point landmarks from the RANGES of raw scans, intensity ignored (chapter 08: natural features on the Car Park).

    A scan is cut into segments wherever neighbouring beams differ by more than
    ``max_range_jump`` m (or one returns nothing). A segment is a point feature if it is
    at most ``max_width`` m wide (beams x 0.5 deg x mean range), stands in front of both
    neighbours (each farther by more than ``max_range_jump`` or no return) and does not
    touch the edge of the field of view. Its beams are then handed to the beacon
    extractor (:func:`extract_beacons`, contiguous clusters only), which gives the
    same range (mean) and bearing (midpoint of the first and last beam) as for a beacon.
    ``exclude_tape``: drop segments with a bright (tape) beam: only non-beacon returns.
    Returns Detections with intensity 0 (not used) and diameter = the chord width.
    """
    if not isinstance(laser, Laser):
        raise ValueError(f"laser must be an annslam_lib.records.Laser, got {type(laser).__name__}")
    w, jump = _positive("max_width", max_width), _positive("max_range_jump", max_range_jump)
    hi = _positive("max_range", max_range)
    if isinstance(min_range, bool) or not isinstance(min_range, numbers.Real) \
            or not 0 <= min_range < hi:
        raise ValueError(f"min_range must be a number in [0, max_range), got {min_range!r}")
    if not isinstance(exclude_tape, bool):
        raise ValueError(f"exclude_tape must be a bool, got {exclude_tape!r}")
    S, N = laser.ranges.shape
    ok = laser.valid
    r = np.where(ok, laser.ranges, 0.0)
    same = np.zeros((S, N), dtype=bool)              # beam continues the previous one's segment
    same[:, 1:] = ok[:, 1:] & ok[:, :-1] & (np.abs(np.diff(r, axis=1)) <= jump)
    start = ~same.ravel()
    seg = np.cumsum(start) - 1                       # segment id of every beam (row-major)
    count = np.bincount(seg)
    mean = np.bincount(seg, weights=r.ravel()) / count
    first = np.flatnonzero(start)
    last = np.append(first[1:] - 1, S * N - 1)
    flat = np.where(ok, laser.ranges, np.inf).ravel()
    left = np.where(first % N > 0, flat[np.maximum(first - 1, 0)], -np.inf)
    right = np.where(last % N < N - 1, flat[np.minimum(last + 1, S * N - 1)], -np.inf)
    width = count * np.mean(np.diff(laser.angles)) * mean
    keep = (ok.ravel()[first] & (width <= w) & (left > mean + jump) & (right > mean + jump))
    if exclude_tape:
        keep &= np.bincount(seg, weights=(laser.intensity.ravel() > 0), minlength=count.size) == 0
    marked = Laser(t=laser.t, ranges=laser.ranges, intensity=keep[seg].reshape(S, N).astype(np.uint8),
                   max_range=laser.max_range, angles=laser.angles)
    det = extract_beacons(marked, BeaconConfig(
        min_range=float(min_range), max_range=hi, max_gap_beams=0, max_range_jump=jump))
    return dataclasses.replace(det, intensity=np.zeros(det.count, dtype=np.uint8))


def with_detections(dataset: Dataset, detections: Detections, kind: str = "points") -> Dataset:
    """A copy of ``dataset`` whose point detections are ``detections`` (use with
    ``SlamConfig(feature_source='detections')``); the raw laser, GPS and true map stay."""
    if not isinstance(dataset, Dataset) or not isinstance(detections, Detections):
        raise ValueError("with_detections needs a records.Dataset and a records.Detections")
    if detections.t.shape != dataset.scan_times.shape or np.any(detections.t != dataset.scan_times):
        raise ValueError("detections must have one entry per scan of the dataset, same times")
    return dataclasses.replace(dataset, detections=detections, landmark_kind=kind)
