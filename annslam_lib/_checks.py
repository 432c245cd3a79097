"""One set of validators for the whole library, so bad input fails here with a clear message.

Rules, everywhere:

- a value of the wrong **type** (a string, None, a bool or a complex number where a real
  number is asked, text in an array) raises ``TypeError``;
- a value of the right type that is out of range, not finite, or of the wrong **shape**
  raises ``ValueError``;
- every message names the argument (``Owner.field`` for a dataclass field) and what it got.

NumPy scalars count as numbers (``np.int64(2)``, ``np.float32(2.0)``).
"""
from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["real", "integer", "choice", "flag", "probability", "array", "points",
           "covariance", "trajectory", "instance", "broadcast", "COV_RTOL"]

#: Relative tolerance for "symmetric" and "positive semi-definite" of a covariance.
COV_RTOL = 1e-9


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def real(name: str, value, *, lo: float | None = None, hi: float | None = None,
         strict: bool = False, finite: bool = True) -> float:
    """``value`` as a float: a real number (not a bool), finite unless ``finite=False``
    (NaN is never accepted), >= ``lo`` (> with ``strict``) and <= ``hi``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {type(value).__name__} {_shown(value)}")
    v = float(value)
    if math.isnan(v) or (finite and math.isinf(v)):
        raise ValueError(f"{name} must be a {'finite ' if finite else ''}number, got {v!r}")
    if lo is not None and (v <= lo if strict else v < lo):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {lo:g}, got {v!r}")
    if hi is not None and v > hi:
        raise ValueError(f"{name} must be <= {hi:g}, got {v!r}")
    return v


def integer(name: str, value, *, lo: int | None = None, hi: int | None = None) -> int:
    """``value`` as an int: an integer (not a bool), within [lo, hi]."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__} {_shown(value)}")
    v = int(value)
    if lo is not None and v < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {v}")
    if hi is not None and v > hi:
        raise ValueError(f"{name} must be an integer <= {hi}, got {v}")
    return v


def choice(name: str, value, options) -> str:
    """``value``, a string among ``options``."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be one of {tuple(options)}, got {type(value).__name__} "
                        f"{_shown(value)}")
    if value not in options:
        raise ValueError(f"{name} must be one of {tuple(options)}, got {value!r}")
    return value


def flag(name: str, value) -> bool:
    """``value``, a bool (or NumPy bool)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} "
                        f"{_shown(value)}")
    return bool(value)


def probability(name: str, value, *, closed_top: bool = False) -> float:
    """``value`` as a probability in (0, 1), or (0, 1] with ``closed_top``."""
    v = real(name, value)
    if not (0.0 < v < 1.0 or (closed_top and v == 1.0)):
        raise ValueError(f"{name} must be a probability in (0, 1{']' if closed_top else ')'}, "
                         f"got {v!r}")
    return v


def array(name: str, value, tail: tuple[int, ...] = (), *, finite: bool = True) -> np.ndarray:
    """``value`` as a float array whose trailing dimensions are ``tail`` (leading, batch
    dimensions are free); finite unless ``finite=False``."""
    if value is None or isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be numeric, got {type(value).__name__} {_shown(value)}")
    try:
        raw = np.asarray(value)
    except ValueError as exc:                       # ragged nested sequences
        raise ValueError(f"{name} must be a regular numeric array: {exc}") from None
    if raw.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be numeric (real numbers), got an array of dtype "
                        f"{raw.dtype}")
    arr = raw.astype(float, copy=False)
    n = len(tail)
    if arr.ndim < n or (n and arr.shape[-n:] != tuple(tail)):
        want = "(..., " + ", ".join(map(str, tail)) + ")" if n else "scalar or array"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return arr


def points(name: str, value) -> np.ndarray:
    """``value`` as a finite (M, 2) array of points."""
    arr = array(name, value, (2,))
    if arr.ndim != 2:
        raise ValueError(f"{name} must be an (M, 2) array of points, got shape {arr.shape}")
    return arr


def covariance(name: str, P, n: int | None = None) -> np.ndarray:
    """``P`` as a float (n, n) covariance: square, finite, symmetric to ``COV_RTOL`` of its
    largest entry, no eigenvalue below -``COV_RTOL`` times that scale. Returns the
    symmetrised matrix (P + P^T) / 2."""
    P = array(name, P)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise ValueError(f"{name} must be a square matrix, got shape {P.shape}")
    if n is not None and P.shape[0] != n:
        raise ValueError(f"{name} must be {n} x {n}, got {P.shape}")
    scale = max(float(np.max(np.abs(P))) if P.size else 0.0, 1e-300)
    asym = float(np.max(np.abs(P - P.T))) if P.size else 0.0
    if asym > COV_RTOL * scale:
        raise ValueError(f"{name} is not symmetric (largest asymmetry {asym:.3g})")
    P = 0.5 * (P + P.T)
    if P.size:
        lowest = float(np.min(np.linalg.eigvalsh(P)))
        if lowest < -COV_RTOL * scale:
            raise ValueError(f"{name} is not positive semi-definite (eigenvalue {lowest:.3g})")
    return P


def trajectory(name: str, traj) -> np.ndarray:
    """``traj`` as a finite float (K, 4) array of rows (t, x, y, phi), K >= 1, times
    non-decreasing."""
    arr = array(name, traj, (4,))
    if arr.ndim != 2 or arr.shape[0] < 1:
        raise ValueError(f"{name} must have shape (K, 4) with K >= 1 rows (t, x, y, phi), "
                         f"got {arr.shape}")
    if np.any(np.diff(arr[:, 0]) < 0):
        raise ValueError(f"{name} times (column 0) must be non-decreasing")
    return arr


def instance(name: str, value, cls, what: str | None = None):
    """``value`` if it is a ``cls``, else TypeError naming ``what`` (default the class)."""
    if not isinstance(value, cls):
        want = what or (cls.__name__ if isinstance(cls, type) else
                        " or ".join(c.__name__ for c in cls))
        raise TypeError(f"{name} must be a {want}, got {type(value).__name__}")
    return value


def broadcast(**shapes) -> tuple[int, ...]:
    """The common batch shape of the named arguments, or ValueError naming them and their
    shapes."""
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        desc = ", ".join(f"{k} {tuple(v)}" for k, v in shapes.items())
        raise ValueError(f"shapes do not broadcast: {desc}") from None
