"""Noise values from the data (notebook 06 "the GPS", chapter 05).

A filter's GPS noise is a claim about the receiver. :func:`gps_sigma_from_scatter` reads it
off the receiver's own fixes: for fixes at a steady rate dt, the second difference
x_{k+1} - 2 x_k + x_{k-1} of a smooth track is about a dt^2 (centimetres at 5 Hz for a car),
while independent noise of standard deviation s per axis gives it the variance 6 s^2. So
sqrt(mean(second difference^2) / 6) per axis estimates the fix-to-fix noise. It is a LOWER
bound on what a filter should assume: an error that drifts slowly (multipath, a changing
constellation) hardly shows in a second difference, and it is exactly the error that makes
many fixes at a small sigma over-confident.

:func:`laser_calibration` reads a laser's systematic errors off a surveyed map: the mean
range and bearing residual of the extracted beacons seen from the GPS poses (chapter 04's
measurement), to be subtracted from every detection (``SlamConfig.range_bias``,
``bearing_offset``). The bearing offset is measured against the GPS heading, so it carries
that heading's own bias; the nearest-beacon matching trims the residuals' tails, so an offset
is recovered in part where the heading is noisy (on the simulator with a 1 cm GPS, 75-90 %
of an injected one; on the Car Park every detection matches within 1 m and 2 m alike).
Two numbers fitted to hundreds of residuals cannot learn the map, but
a map judged against the same survey afterwards is no longer an independent check of
them: chapter 05 says so where it uses them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..data.records import Dataset, Gps

__all__ = ["gps_sigma_from_scatter", "LaserCalibration", "laser_calibration"]


def gps_sigma_from_scatter(gps: Gps, *, span: float = 60.0, rate_tolerance: float = 0.2,
                           floor: float = 0.05) -> float:
    """GPS noise per axis (m) from the fix-to-fix scatter of the first ``span`` seconds
    (module docstring): sqrt(mean over both axes of the squared second differences / 6),
    using only triples of fixes whose two steps are within ``rate_tolerance`` of the median
    step; at least ``floor`` m (the receiver's nominal accuracy: the car's own motion sets
    a limit below which the estimate says nothing).

    Parameters
    ----------
    gps : records.Gps
        The fixes: times ``t`` (s) and positions ``xy`` (m).
    span : float, optional
        Length of the stretch used, s, from the first fix.
    rate_tolerance : float, optional
        Largest relative deviation of a step from the median step.
    floor : float, optional
        Smallest value returned, m.

    Returns
    -------
    float
        The noise standard deviation per axis, m.

    Raises
    ------
    TypeError
        If ``gps`` is not a records.Gps or a setting is not a number.
    ValueError
        With fewer than 3 fixes or 10 usable triples, or a setting out of range.
    """
    _checks.instance("gps", gps, Gps, "records.Gps")
    span = _checks.real("span", span, lo=0.0, strict=True)
    _checks.real("rate_tolerance", rate_tolerance, lo=0.0, strict=True)
    _checks.real("floor", floor, lo=0.0)
    if len(gps) < 3:
        raise ValueError(f"need at least 3 GPS fixes, got {len(gps)}")
    dt = np.diff(gps.t)
    step = float(np.median(dt))
    steady = np.abs(dt - step) <= rate_tolerance * step
    ok = steady[:-1] & steady[1:] & (gps.t[2:] <= gps.t[0] + span)
    if ok.sum() < 10:
        raise ValueError(f"only {int(ok.sum())} triples of fixes at a steady rate in the first "
                         f"{span} s: cannot estimate the GPS noise")
    xy = gps.xy
    d2 = (xy[2:] - 2.0 * xy[1:-1] + xy[:-2])[ok]
    return max(float(math.sqrt(np.mean(d2 * d2) / 6.0)), float(floor))


@dataclass(frozen=True)
class LaserCalibration:
    """A laser's systematic errors against a survey (:func:`laser_calibration`): range_bias
    (m) and bearing_offset (rad), the mean residuals (measured minus expected), their
    standard errors, and n, the matched detections used."""

    range_bias: float
    bearing_offset: float
    range_se: float
    bearing_se: float
    n: int


def laser_calibration(dataset: Dataset) -> LaserCalibration:
    """Range bias and bearing offset of the beacons extracted from ``dataset``'s raw laser
    (``perception.sources.detections_for(dataset, 'laser')``, as the filter extracts
    them), against its surveyed beacons seen from the GPS poses of the scans (``slam.dead_reckoning.gps_scan_poses``): the means of the matched residuals.
    Chapter 04 measures them, chapter 05 uses them.

    Parameters
    ----------
    dataset : records.Dataset
        A real run with its raw laser, surveyed beacons and GPS.

    Returns
    -------
    LaserCalibration
        ``range_bias`` (m) and ``bearing_offset`` (rad), their standard errors and the
        number ``n`` of matched detections.

    Raises
    ------
    TypeError
        If ``dataset`` is not a records.Dataset.
    ValueError
        Without a raw laser, a surveyed map or GPS poses, or with fewer than 10 matched
        detections.
    """
    from ..perception import beacons, sources
    from ..slam.dead_reckoning import gps_scan_poses

    if not isinstance(dataset, Dataset):
        raise TypeError(f"dataset must be a records.Dataset, got {type(dataset).__name__}")
    if dataset.laser is None or dataset.beacons is None:
        raise ValueError("laser_calibration needs a raw laser and a surveyed map")
    poses, valid = gps_scan_poses(dataset)
    det = sources.detections_for(dataset, "laser")          # the extractor the filter uses
    res = beacons.extraction_residuals(det, poses, valid, dataset.beacons)
    m = res.matched
    if m.sum() < 10:
        raise ValueError(f"only {int(m.sum())} detections match a surveyed beacon: no calibration")
    r, b = res.range[m], res.bearing[m]
    return LaserCalibration(float(r.mean()), float(b.mean()), float(r.std(ddof=1) / math.sqrt(r.size)),
                            float(b.std(ddof=1) / math.sqrt(b.size)), int(m.sum()))
