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
"""
from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import _checks
from ..data.records import Dataset, Detections, Laser
from ..models.geometry import wrap_angle
from ..models.observation import inverse_observe, observe

__all__ = ["BeaconConfig", "BeaconScan", "beacons_from_scan", "extract_beacons",
           "beacon_config_for", "ExtractionResiduals", "extraction_residuals", "point_features"]


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
        R = diag(sigma_range^2, sigma_bearing^2): ACFR's 0.1 m and 1 deg, the values every
        filter of the course uses on the Car Park (``SlamConfig``) until chapter 05
        calibrates them. Measured against the surveyed beacons from the GPS laser
        position (chapter 04): range residual std 3.8 cm (GPS and survey errors
        included), so 0.1 m over-states the range noise about 2.5 times (chapter 04a's
        NIS shows it); bearing 0.5 deg per beacon from the heading-free differences of
        two beacons in one scan, 0.7 deg mean and 1.2 deg std against the GPS heading.
    """

    min_range: float = 1.0
    max_range: float = 30.0
    min_level: int = 1
    pole_radius: float = 0.0
    max_gap_beams: int = 2
    max_range_jump: float = 0.5
    drop_edge: bool = True
    drop_occluded: bool = True
    sigma_range: float = 0.1
    sigma_bearing: float = math.radians(1.0)

    def __post_init__(self) -> None:
        o = "BeaconConfig"
        _checks.real(f"{o}.min_range", self.min_range, lo=0.0)
        _checks.real(f"{o}.max_range", self.max_range, lo=0.0, strict=True)
        if self.max_range <= self.min_range:
            raise ValueError(f"{o}.max_range ({self.max_range}) must exceed min_range "
                             f"({self.min_range})")
        _checks.integer(f"{o}.min_level", self.min_level, lo=1)
        _checks.integer(f"{o}.max_gap_beams", self.max_gap_beams, lo=0)
        _checks.real(f"{o}.pole_radius", self.pole_radius, lo=0.0)
        _checks.real(f"{o}.max_range_jump", self.max_range_jump, lo=0.0, strict=True)
        _checks.real(f"{o}.sigma_range", self.sigma_range, lo=0.0, strict=True)
        _checks.real(f"{o}.sigma_bearing", self.sigma_bearing, lo=0.0, strict=True)
        for name in ("drop_edge", "drop_occluded"):
            _checks.flag(f"{o}.{name}", getattr(self, name))

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
    ranges = _checks.array("ranges", ranges)
    angles = _checks.array("angles", angles)
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
        raise TypeError(f"config must be a BeaconConfig, got {type(config).__name__}")
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
        raise TypeError(f"laser must be an annslam_lib.data.records.Laser, got {type(laser).__name__}")
    if not isinstance(config, BeaconConfig):
        raise TypeError(f"config must be a BeaconConfig, got {type(config).__name__}")
    c = _clusters(laser.ranges, laser.intensity, laser.angles, config)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(c.scan, minlength=len(laser)))])
    return Detections(t=laser.t, offsets=offsets.astype(np.int64), range=c.range,
                      bearing=c.bearing, diameter=c.width,
                      landmark_id=np.full(c.range.size, -1), intensity=c.level)



def simulator_config(dataset: Dataset):
    cfg = dataset.info.get("config") if isinstance(dataset.info, dict) else None
    return cfg if hasattr(cfg, "pole_radius") and hasattr(cfg, "sigma_range") else None



def beacon_config_for(dataset: Dataset) -> BeaconConfig:
    """The default extractor settings for ``dataset``: BeaconConfig() for the real runs;
    for a simulated run, BeaconConfig(pole_radius=<the simulator's pole radius>)."""
    sim = simulator_config(dataset)
    return BeaconConfig() if sim is None else BeaconConfig(pole_radius=float(sim.pole_radius))



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
        raise TypeError(f"detections must be a records.Detections, got {type(detections).__name__}")
    poses = _checks.array("poses", poses, (3,))
    valid = np.asarray(valid, dtype=bool)
    beacons = _checks.array("beacons", beacons, (2,))
    if poses.shape != (len(detections), 3) or valid.shape != (len(detections),):
        raise ValueError(f"poses must be ({len(detections)}, 3) and valid ({len(detections)},), "
                         f"got {poses.shape} and {valid.shape}")
    if beacons.ndim != 2 or beacons.shape[0] == 0:
        raise ValueError(f"beacons must be a non-empty (M, 2) array, got {beacons.shape}")
    _checks.real("extraction_residuals.max_distance", max_distance, lo=0.0, strict=True)
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
        raise TypeError(f"laser must be an annslam_lib.data.records.Laser, got {type(laser).__name__}")
    w = _checks.real("max_width", max_width, lo=0.0, strict=True)
    jump = _checks.real("max_range_jump", max_range_jump, lo=0.0, strict=True)
    hi = _checks.real("max_range", max_range, lo=0.0, strict=True)
    if isinstance(min_range, bool) or not isinstance(min_range, numbers.Real) \
            or not 0 <= min_range < hi:
        raise ValueError(f"min_range must be a number in [0, max_range), got {min_range!r}")
    if not isinstance(exclude_tape, bool):
        raise TypeError(f"exclude_tape must be a bool, got {exclude_tape!r}")
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
