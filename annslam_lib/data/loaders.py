"""Loaders of the two real ACFR runs as :class:`annslam_lib.data.records.Dataset`.

Every stream of a run is put on ONE time base in seconds: the original clock minus
t0 = the earliest time of any stream, so the run starts at exactly 0.0;
``info['time_offset_s']`` keeps t0 (Car Park 45.024 s, Victoria Park 20.967 s).
Files are verified (sha256) by :mod:`annslam_lib.data.fetch` before they are parsed;
a damaged file raises :class:`~annslam_lib.data.fetch.DataError` naming file and variable.
The loaded datasets are cached and shared: their arrays are read-only.
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import scipy.io

from . import fetch
from . import registry
from .fetch import DataError
from .records import LASER_ANGLES, Dataset, Detections, Gps, Laser, Odometry
from ..models.vehicle import ACFR_UTE

#: Car Park intensity: level k (0..4) is stored as k * 2**13.
_INTENSITY_SHIFT = 13


def load(name: str) -> Dataset:
    """Load a real run by name: 'car_park' or 'victoria_park'."""
    if name not in _PARSERS:
        raise ValueError(f"cannot load dataset {name!r}; loadable datasets: {', '.join(_PARSERS)}")
    return _load_cached(name, str(fetch.ensure(name)))


def load_car_park() -> Dataset:
    """ACFR Car Park (about 125 s): odometry 40 Hz, raw laser scans with intensity
    (beacon tape), GPS 5 Hz, and the 15 surveyed beacons (East, North in metres)."""
    return load("car_park")


def load_victoria_park() -> Dataset:
    """ACFR Victoria Park (about 26 min): odometry 40 Hz, patchy GPS, and tree
    detections per laser scan (range m, bearing rad 0..pi from the right, diameter m).
    No raw laser and no true map."""
    return load("victoria_park")


@functools.lru_cache(maxsize=None)
def _load_cached(name: str, folder: str) -> Dataset:
    # Keyed on the folder only: fetch.ensure verified the hashes, so the content is fixed.
    return _freeze(_PARSERS[name](Path(folder)))


def _mat(p: Path) -> dict:
    try:
        return scipy.io.loadmat(p)
    except Exception as e:  # scipy raises several types for truncated / non-MAT files
        raise DataError(f"{p}: not a readable MATLAB file ({e})") from e


def _var(m: dict, p: Path, var: str, shape: tuple) -> np.ndarray:
    """Variable ``var`` of MAT file ``p``; ``shape`` entries of None accept any length.
    A 1-D ``shape`` accepts a row or column vector and returns it flat."""
    if var not in m:
        raise DataError(f"{p.name}: variable {var!r} is missing (file {p})")
    a = np.asarray(m[var])
    if len(shape) == 1:
        a = a.ravel() if a.ndim == 2 and 1 in a.shape else a
    if a.ndim != len(shape) or any(n is not None and n != k for n, k in zip(shape, a.shape)):
        want = " x ".join("any" if n is None else str(n) for n in shape)
        raise DataError(f"{p.name}: variable {var!r} has shape {a.shape}, expected {want} (file {p})")
    if a.size == 0:
        raise DataError(f"{p.name}: variable {var!r} is empty (file {p})")
    return a


def _build(name: str, folder: Path, t0: float, *, odometry: dict, gps: dict, laser: dict | None = None,
           detections: dict | None = None, **fields) -> Dataset:
    """The Dataset; the records' own validation errors (NaN, unsorted time...) name the folder."""
    entry = registry.get(name)
    info = {"time_offset_s": t0, "citation": entry.citation, "licence": entry.licence,
            "source": entry.source, "folder": str(folder)}
    try:
        return Dataset(name=name, vehicle=ACFR_UTE, info=info, odometry=Odometry(**odometry),
                       gps=Gps(**gps), laser=None if laser is None else Laser(**laser),
                       detections=None if detections is None else Detections(**detections), **fields)
    except ValueError as e:
        raise DataError(f"dataset {name!r} in {folder}: {e}") from e


def _parse_car_park(folder: Path) -> Dataset:
    """Parse data_set.mat + beac_juan3.mat in ``folder`` (no hash check)."""
    p, pb = folder / "data_set.mat", folder / "beac_juan3.mat"
    m, mb = _mat(p), _mat(pb)
    t_odo = _var(m, p, "Time_VS", (None,)).astype(float)
    t_gps = _var(m, p, "TimeGPS", (None,)).astype(float)
    t_lsr = _var(m, p, "TimeLaser", (None,)).astype(float)
    scans = (t_lsr.size, LASER_ANGLES.size)
    raw = _var(m, p, "Intensity", scans)
    if np.any(raw % (1 << _INTENSITY_SHIFT)) or raw.min() < 0 or raw.max() > 4 << _INTENSITY_SHIFT:
        raise DataError(f"{p.name}: variable 'Intensity' must hold levels 0..4 times 8192, "
                        f"got values {np.unique(raw)[:8]} ... (file {p})")
    t0 = float(min(t_odo.min(), t_gps.min(), t_lsr.min()))
    odo = dict(t=t_odo - t0, speed=_var(m, p, "Velocity", t_odo.shape),
               steering=_var(m, p, "Steering", t_odo.shape))
    gps = dict(t=t_gps - t0, east=_var(m, p, "GPSLon", t_gps.shape),
               north=_var(m, p, "GPSLat", t_gps.shape))
    laser = dict(t=t_lsr - t0, ranges=_var(m, p, "Laser", scans),
                 intensity=raw.astype(np.int64) >> _INTENSITY_SHIFT)
    return _build("car_park", folder, t0, odometry=odo, gps=gps, laser=laser,
                  beacons=_var(mb, pb, "estbeac", (None, 2)), landmark_kind="beacons")


def _parse_victoria_park(folder: Path) -> Dataset:
    """Parse aa3_dr.mat, aa3_gpsx.mat, VictoriaParkSinSincronizar.mat in ``folder``
    (no hash check). The aa3 files count milliseconds, the tree file seconds."""
    pd, pg, pz = (folder / n for n in ("aa3_dr.mat", "aa3_gpsx.mat", "VictoriaParkSinSincronizar.mat"))
    dr, g, z = _mat(pd), _mat(pg), _mat(pz)
    t_odo = _var(dr, pd, "time", (None,)) / 1000.0
    t_gps = _var(g, pg, "timeGps", (None,)) / 1000.0
    t_lsr = _var(z, pz, "TLsr", (None,)).astype(float)
    # The tree file carries its own copy of the odometry clock: it must be the same run.
    z_time = _var(z, pz, "time", t_odo.shape)
    if np.max(np.abs(z_time - t_odo)) > 1e-6:
        raise DataError(f"{pz.name}: variable 'time' differs from {pd.name} 'time'/1000 by up to "
                        f"{np.max(np.abs(z_time - t_odo)):.3g} s: the files are not from the same run")
    cells = _var(z, pz, "zt", t_lsr.shape)
    if cells.dtype != object:
        raise DataError(f"{pz.name}: variable 'zt' must be a cell array of 3 x N matrices (file {pz})")
    bad = [k for k, c in enumerate(cells) if c.size and (c.ndim != 2 or c.shape[0] != 3)]
    if bad:
        raise DataError(f"{pz.name}: variable 'zt' scan {bad[0]} has shape {cells[bad[0]].shape}, "
                        f"expected 3 x N [range; bearing; diameter] (file {pz})")
    counts = np.fromiter((c.shape[1] if c.size else 0 for c in cells), np.int64, cells.size)
    trees = np.concatenate([c for c in cells if c.size], axis=1) if counts.any() else np.empty((3, 0))
    t0 = float(min(t_odo.min(), t_gps.min(), t_lsr.min()))
    return _build(
        "victoria_park", folder, t0,
        odometry=dict(t=t_odo - t0, speed=_var(dr, pd, "speed", t_odo.shape),
                      steering=_var(dr, pd, "steering", t_odo.shape)),
        gps=dict(t=t_gps - t0, east=_var(g, pg, "Lo_m", t_gps.shape),
                 north=_var(g, pg, "La_m", t_gps.shape)),
        detections=dict(t=t_lsr - t0, offsets=np.concatenate([[0], np.cumsum(counts)]),
                        range=trees[0], bearing=trees[1], diameter=trees[2]),
        beacons=None, landmark_kind="trees")


def _freeze(ds: Dataset) -> Dataset:
    """Make every array of the (shared, cached) dataset read-only."""
    for part in (ds.odometry, ds.gps, ds.laser, ds.detections):
        for v in vars(part).values() if part is not None else ():
            if isinstance(v, np.ndarray):
                v.flags.writeable = False
    if ds.beacons is not None:
        ds.beacons.flags.writeable = False
    return ds


_PARSERS = {"car_park": _parse_car_park, "victoria_park": _parse_victoria_park}
