"""Accuracy of an estimated map against a surveyed one (notebook 05 "the Car Park map").

Mapped landmarks are matched one-to-one to the true ones by the assignment that
minimises the total distance (Hungarian algorithm, ``scipy.optimize.linear_sum_assignment``);
a pair farther apart than ``max_distance`` is not a match. :func:`map_errors` matches INSIDE
an alignment loop (align first): a map whose frame is off (rotated, shifted: SLAM cannot
observe its frame) is matched in the frame that fits it best, so its aligned error covers
every landmark and does not depend on the frame. The loop starts from the map as it is
and, when that matches too few landmarks, from the best of the rigid motions that carry a
pair of mapped landmarks onto a pair of true ones with the same separation (a RANSAC-like
search over pairs); then it alternates matching and :func:`rigid_align` until the matches
stop changing. Two errors are reported for the final pairs:

- absolute: the distances of the matched pairs as they are (the map in the GPS frame);
- aligned: after the best rigid 2-D motion (rotation + translation, no scale) applied to
  the mapped landmarks, the Kabsch / Umeyama least-squares solution: with centroids
  a_bar, b_bar and the cross-covariance C = sum (a_i - a_bar)(b_i - b_bar)^T,
  R = V diag(1, det(V U^T)) U^T from C = U Sigma V^T, t = b_bar - R a_bar.
  This is the map's shape error, free of the frame error that SLAM cannot observe.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _checks
from scipy.optimize import linear_sum_assignment


__all__ = ["point_rmse", "rigid_align", "match_landmarks", "MapErrors", "map_errors", "aligned_rmse"]


def rigid_align(a, b) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R (2, 2) and translation t (2,) minimising sum |R a_i + t - b_i|^2
    (Kabsch, no scale, reflections excluded).

    Parameters
    ----------
    a : array_like, shape (K, 2)
        The points to move, K >= 2 and not all coincident.
    b : array_like, shape (K, 2)
        Their partners, paired row by row.

    Returns
    -------
    R : ndarray, shape (2, 2)
        The rotation.
    t : ndarray, shape (2,)
        The translation, in the units of the points.

    Raises
    ------
    ValueError
        For shapes that differ, fewer than 2 pairs, points that all coincide, or
        non-finite values.
    """
    a, b = _checks.points("a", a), _checks.points("b", b)
    if a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape, got {a.shape} and {b.shape}")
    if a.shape[0] < 2:
        raise ValueError(f"rigid alignment needs at least 2 point pairs, got {a.shape[0]}")
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    da, db = a - ca, b - cb
    for name, dd in (("a", da), ("b", db)):
        if np.max(np.abs(dd)) == 0.0:
            raise ValueError(f"the points of {name} all coincide: the rotation is undefined "
                             "(every rotation fits equally well)")
    U, _, Vt = np.linalg.svd(da.T @ db)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, d]) @ U.T
    return R, cb - R @ ca


def match_landmarks(mapped, true, max_distance: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one matching (Hungarian, minimum total distance) of mapped (M, 2) to true
    (T, 2) landmarks; pairs farther than ``max_distance`` metres are dropped.
    Returns (i_mapped, j_true), index arrays of equal length."""
    mapped, true = _checks.points("mapped", mapped), _checks.points("true", true)
    max_distance = _checks.real("max_distance", max_distance, lo=0.0, strict=True, finite=False)
    if mapped.shape[0] == 0 or true.shape[0] == 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    d = np.hypot(mapped[:, None, 0] - true[None, :, 0], mapped[:, None, 1] - true[None, :, 1])
    i, j = linear_sum_assignment(d)
    ok = d[i, j] <= max_distance
    return i[ok].astype(np.int64), j[ok].astype(np.int64)


@dataclass(frozen=True)
class MapErrors:
    """Result of :func:`map_errors`.

    i_mapped, j_true: the matched pairs; error (K,): their distances (m) as mapped;
    error_aligned (K,): after the best rigid alignment; rmse, rmse_aligned, max,
    max_aligned (m); rotation (rad) and translation (2,) of that alignment (mapped ->
    true); missed: true landmarks without a match; spurious: mapped landmarks without a
    match; duplicates: the spurious ones lying within ``max_distance`` of a true
    landmark (a second copy of a mapped landmark).
    """

    i_mapped: np.ndarray
    j_true: np.ndarray
    error: np.ndarray
    error_aligned: np.ndarray
    rmse: float
    rmse_aligned: float
    max: float
    max_aligned: float
    rotation: float
    translation: np.ndarray
    missed: int
    spurious: int
    duplicates: int

    def summary(self) -> str:
        return (f"{self.i_mapped.size} matched, {self.missed} missed, {self.spurious} spurious "
                f"({self.duplicates} duplicates); RMSE {self.rmse:.3f} m absolute, "
                f"{self.rmse_aligned:.3f} m after alignment "
                f"({math.degrees(self.rotation):.2f} deg, {np.hypot(*self.translation):.3f} m)")


def _pair_hypotheses(mapped, true, max_distance: float, max_pairs: int = 3000,
                     max_hypotheses: int = 20000) -> list[tuple[np.ndarray, np.ndarray]]:
    """Rigid motions carrying a pair of mapped landmarks onto a pair of true ones whose
    separation agrees within 2 max_distance (and exceeds it, for a well-defined rotation),
    the best first by the number of mapped landmarks they bring within max_distance of a
    true one (ties: the smaller sum of squared, capped distances). Seeded subsampling keeps
    large maps cheap; the result is deterministic."""
    M, T = mapped.shape[0], true.shape[0]
    if M < 2 or T < 2:
        return []
    rng = np.random.default_rng(0)
    i1, i2 = np.triu_indices(M, 1)
    if i1.size > max_pairs:
        k = np.sort(rng.choice(i1.size, max_pairs, replace=False))
        i1, i2 = i1[k], i2[k]
    j1, j2 = np.nonzero(~np.eye(T, dtype=bool))         # ordered: both directions
    vm, vt = mapped[i2] - mapped[i1], true[j2] - true[j1]
    dm, dt = np.hypot(*vm.T), np.hypot(*vt.T)
    a, b = np.nonzero((np.abs(dm[:, None] - dt[None, :]) <= 2.0 * max_distance)
                      & (dm[:, None] > 2.0 * max_distance))
    if a.size == 0:
        return []
    if a.size > max_hypotheses:
        k = np.sort(rng.choice(a.size, max_hypotheses, replace=False))
        a, b = a[k], b[k]
    th = np.arctan2(vt[b, 1], vt[b, 0]) - np.arctan2(vm[a, 1], vm[a, 0])
    c, s = np.cos(th), np.sin(th)
    pm = 0.5 * (mapped[i1[a]] + mapped[i2[a]])
    pt = 0.5 * (true[j1[b]] + true[j2[b]])
    tx, ty = pt[:, 0] - (c * pm[:, 0] - s * pm[:, 1]), pt[:, 1] - (s * pm[:, 0] + c * pm[:, 1])
    cap = max_distance ** 2
    score, cost = np.empty(a.size), np.empty(a.size)
    for lo in range(0, a.size, 1000):                   # chunks: (H, M, T) distances
        h = slice(lo, lo + 1000)
        x = c[h, None] * mapped[None, :, 0] - s[h, None] * mapped[None, :, 1] + tx[h, None]
        y = s[h, None] * mapped[None, :, 0] + c[h, None] * mapped[None, :, 1] + ty[h, None]
        d2 = ((x[..., None] - true[None, None, :, 0]) ** 2
              + (y[..., None] - true[None, None, :, 1]) ** 2).min(axis=2)
        score[h] = np.sum(d2 <= cap, axis=1)
        cost[h] = np.sum(np.minimum(d2, cap), axis=1)
    best = np.lexsort((cost, -score))[:5]
    return [(np.array([[c[k], -s[k]], [s[k], c[k]]]), np.array([tx[k], ty[k]])) for k in best]


def _refine(mapped, true, R, t, max_distance: float, max_iter: int = 30):
    """Alternate matching (in the frame R, t) and rigid alignment until the matches repeat.
    Returns (i, j, R, t) or None when fewer than 2 landmarks match."""
    seen = None
    for _ in range(max_iter):
        i, j = match_landmarks(mapped @ R.T + t, true, max_distance)
        if i.size < 2:
            return None
        key = (tuple(i.tolist()), tuple(j.tolist()))
        if key == seen:
            break
        seen = key
        R, t = rigid_align(mapped[i], true[j])
    return i, j, R, t


def _align_and_match(mapped, true, max_distance: float):
    """The matches and rigid motion of :func:`map_errors` (module docstring), or None."""
    eye = (np.eye(2), np.zeros(2))
    out = _refine(mapped, true, *eye, max_distance)
    enough = 0.8 * min(mapped.shape[0], true.shape[0])
    if out is not None and out[0].size >= enough:
        return out
    best = out
    for R, t in _pair_hypotheses(mapped, true, max_distance):
        cand = _refine(mapped, true, R, t, max_distance)
        if cand is None:
            continue
        if best is None or cand[0].size > best[0].size or (
                cand[0].size == best[0].size
                and _sse(mapped, true, *cand) < _sse(mapped, true, *best) - 1e-12):
            best = cand
    return best


def _sse(mapped, true, i, j, R, t) -> float:
    d = mapped[i] @ R.T + t - true[j]
    return float(np.sum(d * d))


def map_errors(mapped, true, *, max_distance: float = 1.0) -> MapErrors:
    """Match ``mapped`` (M, 2) to ``true`` (T, 2) landmarks inside an alignment loop (module
    docstring: align first, so the result does not depend on the map's frame) and measure
    the errors of the matched pairs absolute and after the best rigid alignment. A pair is
    a match when it lies within ``max_distance`` metres in the aligned frame.

    Parameters
    ----------
    mapped : array_like, shape (M, 2)
        The estimated landmarks, m.
    true : array_like, shape (T, 2)
        The surveyed (or true) landmarks, m.
    max_distance : float, optional
        Largest distance of a match in the aligned frame, m, > 0.

    Returns
    -------
    MapErrors
        The matched pairs, their errors absolute and aligned (RMSE, max), the
        alignment, and the missed, spurious and duplicate landmarks.

    Raises
    ------
    ValueError
        When fewer than 2 landmarks can be matched in any frame, or for bad points or
        a bad ``max_distance``.
    """
    mapped, true = _checks.points("mapped", mapped), _checks.points("true", true)
    max_distance = _checks.real("max_distance", max_distance, lo=0.0, strict=True)
    found = _align_and_match(mapped, true, max_distance)
    if found is None:
        raise ValueError(f"fewer than 2 of the {mapped.shape[0]} mapped landmarks can be matched "
                         f"within max_distance = {max_distance} m to the {true.shape[0]} true "
                         "ones in any rigid frame: need 2 to align")
    i, j, R, t = found
    a, b = mapped[i], true[j]
    err = np.hypot(*(a - b).T)
    err_al = np.hypot(*(a @ R.T + t - b).T)
    rest = np.setdiff1d(np.arange(mapped.shape[0]), i)
    near = 0
    if rest.size:
        moved = mapped[rest] @ R.T + t
        d = np.hypot(moved[:, None, 0] - true[None, :, 0], moved[:, None, 1] - true[None, :, 1])
        near = int(np.sum(d.min(axis=1) <= max_distance))
    return MapErrors(i_mapped=i, j_true=j, error=err, error_aligned=err_al,
                     rmse=float(np.sqrt(np.mean(err**2))),
                     rmse_aligned=float(np.sqrt(np.mean(err_al**2))),
                     max=float(err.max()), max_aligned=float(err_al.max()),
                     rotation=float(math.atan2(R[1, 0], R[0, 0])), translation=t,
                     missed=int(true.shape[0] - i.size), spurious=int(rest.size), duplicates=near)


def point_rmse(a, b=None) -> float:
    """Root mean square of the Euclidean lengths of the rows of ``a - b`` (or of ``a``)
    (K, 2), in the units of the points: the RMSE of K position estimates against their
    truths (notebook 07).

    Parameters
    ----------
    a : array_like, shape (K, 2)
        Points (e.g. estimates).
    b : array_like, shape (K, 2), optional
        Their partners (e.g. truths); None: the lengths of the rows of ``a``.

    Returns
    -------
    float
        sqrt(mean over the rows of |a_k - b_k|^2).

    Raises
    ------
    ValueError
        For no rows, a wrong shape or a non-finite value.
    """
    a = np.asarray(a, dtype=float)
    pairs = [("a", a)] if b is None else [("a", a), ("b", np.asarray(b, dtype=float))]
    for name, v in pairs:
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] == 0:
            raise ValueError(f"points {name} must be a non-empty (K, 2) array, got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"points {name} contain NaN or infinite values")
    if b is not None and pairs[1][1].shape != a.shape:
        raise ValueError(f"a and b must pair up point by point, got shapes {a.shape} and "
                         f"{pairs[1][1].shape}")
    d = a if b is None else a - pairs[1][1]
    if not np.all(np.isfinite(d)):                  # a difference beyond the float range
        s = np.max(np.abs(d[np.isfinite(d)]), initial=1.0)
        raise ValueError(f"the differences of a and b overflow (beyond {s:.3g})")
    m = np.max(np.abs(d), initial=0.0)
    if 1e-150 < m < 1e150 or m == 0.0:
        return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))
    d = d / m                                       # scaled: d * d would over- or underflow
    return float(m * np.sqrt(np.mean(np.sum(d * d, axis=1))))


def aligned_rmse(a, b) -> float:
    """Root mean square of the Euclidean distances |R a_i + t - b_i| after the best rigid
    alignment (:func:`rigid_align`) of the paired points a, b (K, 2), K >= 2 (m):
    :func:`map_errors` ``.rmse_aligned`` without the matching (notebook 08,
    exercise 8.2). Raises ValueError for fewer than 2 pairs."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    R, t = rigid_align(a, b)
    return point_rmse(a @ R.T + t, b)
