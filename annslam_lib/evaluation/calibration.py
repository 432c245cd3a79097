"""Noise values from the data (issue 13; notebook 06 "the GPS", chapter 05).

A filter's GPS noise is a claim about the receiver. :func:`gps_sigma_from_scatter` reads it
off the receiver's own fixes: for fixes at a steady rate dt, the second difference
x_{k+1} - 2 x_k + x_{k-1} of a smooth track is about a dt^2 (centimetres at 5 Hz for a car),
while independent noise of standard deviation s per axis gives it the variance 6 s^2. So
sqrt(mean(second difference^2) / 6) per axis estimates the fix-to-fix noise. It is a LOWER
bound on what a filter should assume: an error that drifts slowly (multipath, a changing
constellation) hardly shows in a second difference, and it is exactly the error that makes
many fixes at a small sigma over-confident (chapter 05: with 5 cm per fix the Car Park map's
ellipses miss half of the surveyed beacons).
"""
from __future__ import annotations

import math

import numpy as np

from .. import _checks
from ..data.records import Gps

__all__ = ["gps_sigma_from_scatter"]


def gps_sigma_from_scatter(gps: Gps, *, span: float = 60.0, rate_tolerance: float = 0.2,
                           floor: float = 0.05) -> float:
    """GPS noise per axis (m) from the fix-to-fix scatter of the first ``span`` seconds
    (module docstring): sqrt(mean over both axes of the squared second differences / 6),
    using only triples of fixes whose two steps are within ``rate_tolerance`` of the median
    step; at least ``floor`` m (the receiver's nominal accuracy: the car's own motion sets
    a limit below which the estimate says nothing). Raises ValueError with fewer than 10
    usable triples."""
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
