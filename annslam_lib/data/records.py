"""The dataset object shared by the real loaders and the simulator.

Every stream is on one time base, in seconds, shared by all streams of a run.
Arrays are float64 NumPy arrays unless noted; all constructors validate
shapes and finiteness so a damaged file fails loudly, here, not later.

Conventions (both ACFR runs and the simulator):
- world frame: x = East, y = North, metres;
- laser bearings: 0 .. pi, counted from the vehicle's right, pi/2 straight ahead;
- ``speed`` in :class:`Odometry` is the raw back-left *encoder* speed; translating
  it to the rear-axle centre is a modelling step (``annslam_lib.models.motion``).
"""
from __future__ import annotations

import dataclasses
import heapq
from dataclasses import dataclass, field
from typing import Iterator, NamedTuple

import numpy as np

from .._checks import real
from ..models.vehicle import Vehicle

#: Beam angles of the SICK LMS: 361 beams, 0 to 180 degrees in 0.5 degree steps.
LASER_ANGLES = np.deg2rad(np.arange(361) * 0.5)


def _as_1d(name: str, values, length: int | None = None, *, finite: bool = True) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if length is not None and arr.shape[0] != length:
        raise ValueError(f"{name} must have {length} entries, got {arr.shape[0]}")
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


def _check_time(name: str, t: np.ndarray) -> None:
    if t.size > 1 and np.any(np.diff(t) < 0):
        raise ValueError(f"{name} is not sorted in time (non-decreasing seconds expected)")


@dataclass(frozen=True)
class Odometry:
    """Dead-reckoning samples: time (s), encoder speed (m/s), steering angle (rad)."""

    t: np.ndarray
    speed: np.ndarray
    steering: np.ndarray

    def __post_init__(self) -> None:
        t = _as_1d("odometry.t", self.t)
        _check_time("odometry.t", t)
        if t.size > 1 and t[-1] == t[0]:
            raise ValueError(f"odometry.t: all {t.size} samples have the same time "
                             f"({t[0]:g} s): the odometry clock is not running, so nothing can "
                             "be integrated (check the odometry file's time column)")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "speed", _as_1d("odometry.speed", self.speed, t.size))
        object.__setattr__(self, "steering", _as_1d("odometry.steering", self.steering, t.size))

    def __len__(self) -> int:
        return self.t.size


@dataclass(frozen=True)
class Gps:
    """GPS fixes of the laser point (the antenna is mounted with the laser): time (s),
    East and North (m) in the same local frame as the landmarks."""

    t: np.ndarray
    east: np.ndarray
    north: np.ndarray

    def __post_init__(self) -> None:
        t = _as_1d("gps.t", self.t)
        _check_time("gps.t", t)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "east", _as_1d("gps.east", self.east, t.size))
        object.__setattr__(self, "north", _as_1d("gps.north", self.north, t.size))

    def __len__(self) -> int:
        return self.t.size

    @property
    def xy(self) -> np.ndarray:
        """Fixes as an (K, 2) array of (East, North)."""
        return np.column_stack([self.east, self.north])

    def gaps(self, min_gap: float = 2.0) -> np.ndarray:
        """Intervals longer than ``min_gap`` seconds without a fix, as (G, 2) [start, end]."""
        dt = np.diff(self.t)
        i = np.flatnonzero(dt > min_gap)
        return np.column_stack([self.t[i], self.t[i + 1]])


@dataclass(frozen=True)
class Laser:
    """Raw laser scans: time (s), ranges (S x 361, metres), intensity level (S x 361,
    integers 0..4: 0 = ordinary return, 1..4 = high-reflectivity tape).

    A range >= ``max_range`` means no return."""

    t: np.ndarray
    ranges: np.ndarray
    intensity: np.ndarray
    max_range: float = 81.0
    angles: np.ndarray = field(default_factory=lambda: LASER_ANGLES.copy())

    def __post_init__(self) -> None:
        t = _as_1d("laser.t", self.t)
        _check_time("laser.t", t)
        angles = _as_1d("laser.angles", self.angles)
        shape = (t.size, angles.size)
        ranges = np.asarray(self.ranges, dtype=float)
        intensity = np.asarray(self.intensity)
        if ranges.shape != shape:
            raise ValueError(f"laser.ranges must have shape {shape} (scans x beams), got {ranges.shape}")
        if intensity.shape != shape:
            raise ValueError(f"laser.intensity must have shape {shape}, got {intensity.shape}")
        if not np.all(np.isfinite(ranges)) or np.any(ranges < 0):
            raise ValueError("laser.ranges must be finite and non-negative")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "angles", angles)
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "intensity", intensity.astype(np.uint8))

    def __len__(self) -> int:
        return self.t.size

    @property
    def valid(self) -> np.ndarray:
        """Boolean (S x 361) mask of beams that returned."""
        return self.ranges < self.max_range

    def points(self, k: int, *, only_valid: bool = True) -> np.ndarray:
        """Scan ``k`` as (n, 2) Cartesian points in the laser frame
        (x forward, y left): x = r sin(beta), y = -r cos(beta)."""
        r = self.ranges[k]
        mask = self.valid[k] if only_valid else np.ones_like(r, dtype=bool)
        beta = self.angles[mask]
        return np.column_stack([r[mask] * np.sin(beta), -r[mask] * np.cos(beta)])


@dataclass(frozen=True)
class Detections:
    """Point-feature detections, a ragged list of scans stored flat (CSR style).

    Scan ``k`` owns rows ``offsets[k]:offsets[k+1]`` of ``range`` (m), ``bearing``
    (rad, 0..pi from the vehicle's right) and ``diameter`` (m: trunk diameter, or
    the chord width of a beacon's cluster; NaN where the source has none).
    ``landmark_id`` is the true landmark of each detection where it is known
    (simulator), else -1; ``intensity`` the reflectivity level 0..4 where the
    source has one (beacons extracted from raw laser), else 0.
    """

    t: np.ndarray
    offsets: np.ndarray
    range: np.ndarray
    bearing: np.ndarray
    diameter: np.ndarray
    landmark_id: np.ndarray | None = None
    intensity: np.ndarray | None = None

    def __post_init__(self) -> None:
        t = _as_1d("detections.t", self.t)
        _check_time("detections.t", t)
        offsets = np.asarray(self.offsets)
        if offsets.shape != (t.size + 1,) or not np.issubdtype(offsets.dtype, np.integer):
            raise ValueError(f"detections.offsets must be {t.size + 1} integers, got {offsets.shape} {offsets.dtype}")
        if offsets[0] != 0 or np.any(np.diff(offsets) < 0):
            raise ValueError("detections.offsets must start at 0 and be non-decreasing")
        n = int(offsets[-1])
        rng = _as_1d("detections.range", self.range, n)
        if np.any(rng <= 0):
            raise ValueError("detections.range must be positive")
        ids = np.full(n, -1, dtype=np.int64) if self.landmark_id is None else np.asarray(self.landmark_id, dtype=np.int64)
        if ids.shape != (n,):
            raise ValueError(f"detections.landmark_id must have {n} entries, got {ids.shape}")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "offsets", offsets.astype(np.int64))
        object.__setattr__(self, "range", rng)
        object.__setattr__(self, "bearing", _as_1d("detections.bearing", self.bearing, n))
        object.__setattr__(self, "diameter", _as_1d("detections.diameter", self.diameter, n, finite=False))
        object.__setattr__(self, "landmark_id", ids)
        level = np.zeros(n, dtype=np.uint8) if self.intensity is None else np.asarray(self.intensity)
        if level.shape != (n,):
            raise ValueError(f"detections.intensity must have {n} entries, got {level.shape}")
        object.__setattr__(self, "intensity", level.astype(np.uint8))

    def __len__(self) -> int:
        """Number of scans."""
        return self.t.size

    @property
    def count(self) -> int:
        """Total number of detections over all scans."""
        return int(self.offsets[-1])

    def __getitem__(self, k: int) -> np.ndarray:
        """Detections of scan ``k`` as an (n, 2) array of (range, bearing)."""
        s = slice(self.offsets[k], self.offsets[k + 1])
        return np.column_stack([self.range[s], self.bearing[s]])

    def per_scan(self) -> np.ndarray:
        """Number of detections in each scan."""
        return np.diff(self.offsets)


@dataclass(frozen=True)
class Truth:
    """Ground truth of a simulated run.

    ``poses``: (K, 4) rows of (t, x, y, phi) of the laser pose at every odometry
    sample; ``landmarks``: (M, 2) true landmark positions."""

    poses: np.ndarray
    landmarks: np.ndarray


class Event(NamedTuple):
    """One sensor event: time (s), sensor name ('odometry', 'laser', 'gps'), and the
    index of the sample in that sensor's arrays."""

    t: float
    sensor: str
    index: int


#: Order used when two sensors share a time stamp: the order of the Car Park
#: file's own event list (GPS, then dead reckoning, then laser). A filter
#: predicts up to every event's time anyway, so ties need no other rule.
SENSOR_NAMES = ("gps", "odometry", "laser")
_SENSOR_ORDER = {name: code for code, name in enumerate(SENSOR_NAMES)}


@dataclass(frozen=True)
class Dataset:
    """A run of the car: the streams a filter consumes, plus what is known about it.

    ``laser`` holds raw scans (Car Park, simulator), ``detections`` point features
    already extracted per scan (Victoria Park's trees, the simulator's beacons);
    ``beacons`` is the true (surveyed) map, ``None`` where none exists;
    ``truth`` is set by the simulator only.
    """

    name: str
    odometry: Odometry
    gps: Gps
    vehicle: Vehicle
    laser: Laser | None = None
    detections: Detections | None = None
    beacons: np.ndarray | None = None
    truth: Truth | None = None
    landmark_kind: str = "beacons"
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.beacons is not None:
            b = np.asarray(self.beacons, dtype=float)
            if b.ndim != 2 or b.shape[1] != 2 or not np.all(np.isfinite(b)):
                raise ValueError(f"beacons must be a finite (M, 2) array, got shape {b.shape}")
            object.__setattr__(self, "beacons", b)

    @property
    def trees(self) -> Detections | None:
        """Tree detections per scan (Victoria Park), else ``None``."""
        return self.detections if self.landmark_kind == "trees" else None

    @property
    def scan_times(self) -> np.ndarray:
        """Times of the exteroceptive scans (raw laser, else the detections)."""
        if self.laser is not None:
            return self.laser.t
        if self.detections is not None:
            return self.detections.t
        return np.empty(0)

    @property
    def t0(self) -> float:
        """Time of the first event of the run."""
        starts = [self.odometry.t[0], self.gps.t[0] if len(self.gps) else np.inf]
        if self.scan_times.size:
            starts.append(self.scan_times[0])
        return float(min(starts))

    def events(self) -> Iterator[Event]:
        """All sensor events in time order (ties: odometry, then GPS, then laser).

        'laser' events index the scans (``laser`` or, where there is no raw laser,
        ``detections``)."""
        def stream(name: str, times: np.ndarray):
            return ((float(t), _SENSOR_ORDER[name], i, name) for i, t in enumerate(times))

        merged = heapq.merge(stream("odometry", self.odometry.t), stream("gps", self.gps.t),
                             stream("laser", self.scan_times))
        for t, _, i, name in merged:
            yield Event(t, name, i)

    def event_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The event sequence as arrays (t, sensor code, index), sorted like
        :meth:`events`; the code indexes :data:`SENSOR_NAMES`. Fast for long runs."""
        ts = [self.gps.t, self.odometry.t, self.scan_times]
        t = np.concatenate(ts)
        code = np.concatenate([np.full(x.size, c) for x, c in zip(ts, (0, 1, 2))])
        idx = np.concatenate([np.arange(x.size) for x in ts])
        order = np.lexsort((code, t))
        return t[order], code[order], idx[order]


def truncate(dataset: Dataset, t_end: float) -> Dataset:
    """The run up to and including time ``t_end`` (s): odometry, GPS, raw laser scans,
    detections (whole scans), and the simulator's truth and scan poses.
    Raises ValueError for a non-finite ``t_end`` or one before the first odometry sample."""
    if not isinstance(dataset, Dataset):
        raise TypeError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    t_end = real("t_end", t_end)
    odo = dataset.odometry
    if len(odo) == 0 or t_end < odo.t[0]:
        raise ValueError(f"t_end = {t_end} s lies before the first odometry sample")
    k = odo.t <= t_end
    odometry = Odometry(t=odo.t[k], speed=odo.speed[k], steering=odo.steering[k])
    g = dataset.gps.t <= t_end
    gps = Gps(t=dataset.gps.t[g], east=dataset.gps.east[g], north=dataset.gps.north[g])
    laser = None
    if dataset.laser is not None:
        s = dataset.laser.t <= t_end
        laser = dataclasses.replace(dataset.laser, t=dataset.laser.t[s],
                                    ranges=dataset.laser.ranges[s],
                                    intensity=dataset.laser.intensity[s])
    det = dataset.detections
    detections = None
    if det is not None:
        n = int(np.count_nonzero(det.t <= t_end))
        rows = slice(0, int(det.offsets[n]))
        detections = Detections(t=det.t[:n], offsets=det.offsets[:n + 1], range=det.range[rows],
                                bearing=det.bearing[rows], diameter=det.diameter[rows],
                                landmark_id=det.landmark_id[rows], intensity=det.intensity[rows])
    truth = None
    info = dict(dataset.info)
    if dataset.truth is not None:
        p = dataset.truth.poses
        truth = Truth(poses=p[p[:, 0] <= t_end], landmarks=dataset.truth.landmarks)
        if "scan_poses" in info:
            info["scan_poses"] = np.asarray(info["scan_poses"])[:len(dataset.scan_times)][
                dataset.scan_times <= t_end]
    return dataclasses.replace(dataset, odometry=odometry, gps=gps, laser=laser,
                               detections=detections, truth=truth, info=info)
