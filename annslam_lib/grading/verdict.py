"""Checks for the graded exercises of notebook 08 "ANN-enhanced SLAM: the verdict".

The verdict rests on error metrics; the exercises grade three of them:

- :func:`check_rigid_align`: the best rigid 2-D motion of the mapped landmarks onto the
  surveyed ones (Kabsch without scale, no reflection), against ``evaluation.map.rigid_align``;
- :func:`check_aligned_rmse`: the map RMSE after that alignment (:func:`aligned_rmse`, the
  ``map_rmse_aligned`` of ``evaluation.summary.METRICS``);
- :func:`check_regression`: nntool's regression line and correlation coefficient R of the
  paper's Figure 8 (:func:`regression_line`, what ``ann.regression`` computes per part).

The paper prints no equation for any of them (sections 4.3 and 5 make claims, see
``paper.ERRATA``), so the known mistakes are the usual ones: no alignment, a reflection or a
scale allowed, the mean instead of the root mean square, R^2 for R, the regression the wrong
way round.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .. import ann
from ..ann.evaluation import regression_line
from ..evaluation.map import aligned_rmse, map_errors, rigid_align
from .core import forbids, Passed, GradingError, Mistake, check_function, check_raises, copying

__all__ = ["check_rigid_align", "aligned_rmse", "check_aligned_rmse", "regression_line",
           "check_regression"]

_RT_LABELS = ("R[0, 0]", "R[0, 1]", "R[1, 0]", "R[1, 1]", "t_x", "t_y")


def _rot(a: float) -> np.ndarray:
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def _pairs(seed: int, n: int) -> list[tuple]:
    """(a, b) paired landmark sets: the cases that separate the known mistakes first (two
    points only, collinear points, a mirrored map where a reflection would fit better, a
    shrunken one where a scale would), then b = R a + t + noise for ``n`` seeded motions,
    the first a rotation near 180 degrees."""
    rng = np.random.default_rng(seed)
    cases = []
    a = rng.uniform(-20, 20, (2, 2))
    cases.append((a, a @ _rot(0.7).T + np.array([3.0, -1.0]) + rng.normal(0, 0.2, (2, 2))))
    t = np.linspace(-10, 10, 4)
    a = np.c_[t, 0.5 * t + 2]
    cases.append((a, a @ _rot(-1.2).T + np.array([-4.0, 6.0]) + rng.normal(0, 0.1, (4, 2))))
    a = rng.uniform(-15, 15, (4, 2))
    cases.append((a, a * np.array([1.0, -1.0]) @ _rot(0.4).T + rng.normal(0, 0.3, (4, 2))))
    a = rng.uniform(-15, 15, (4, 2))
    cases.append((a, 0.8 * a @ _rot(2.0).T + np.array([1.0, 2.0]) + rng.normal(0, 0.05, (4, 2))))
    for k in range(n):
        K = int(rng.integers(3, 9))
        a = rng.uniform(-25, 25, (K, 2))
        ang = rng.uniform(-np.pi, np.pi) if k else np.pi - 0.01
        b = a @ _rot(ang).T + rng.uniform(-10, 10, 2) + rng.normal(0, 0.1, (K, 2))
        cases.append((a, b))
    return cases


def _svd(a, b, center=True):
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    da, db = (a - ca, b - cb) if center else (a, b)
    U, S, Vt = np.linalg.svd(da.T @ db)
    return ca, cb, da, U, S, Vt


def _wrong_rt_packed(kind: str):
    """:func:`_wrong_rt` as the 6-vector the check compares."""
    def f(a, b):
        R, t = _wrong_rt(kind)(a, b)
        return np.concatenate([R.ravel(), t])
    return f


def _wrong_rt(kind: str):
    """The known wrong alignments (each returns (R, t))."""
    def f(a, b):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        ca, cb, da, U, S, Vt = _svd(a, b, center=(kind != "uncentred"))
        if kind == "reflection":
            R = Vt.T @ U.T
        elif kind == "scale":
            R0, _ = rigid_align(a, b)
            s = np.trace(np.diag(S) @ np.diag([1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])) \
                / np.sum(da ** 2)
            R = s * R0
        else:
            d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
            R = Vt.T @ np.diag([1.0, d]) @ U.T
        if kind == "transposed":
            R = R.T
        if kind == "reversed":
            R, t = rigid_align(b, a)
            return R, t
        t = cb - ca if kind == "no_rotation_in_t" else cb - R @ ca
        return R, t
    return f


def _packed(fn: Callable, name: str) -> Callable:
    """``fn(a, b)``'s (R, t) as the 6-vector the check compares; a result that is not such a
    pair is reported as what it is (raised inside the call, so the message stays ours)."""
    def packed(a, b):
        o = fn(a.copy(), b.copy())
        if isinstance(o, np.ndarray) or not isinstance(o, (tuple, list)) or len(o) != 2:
            raise GradingError(f"{name} must return a pair (R, t): R of shape (2, 2) and t of "
                               f"shape (2,); got {type(o).__name__} {o!r:.80}")
        try:
            R, t = np.asarray(o[0], dtype=float), np.asarray(o[1], dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise GradingError(f"{name} must return (R, t) as numbers; got {o!r:.80}") from None
        if R.shape != (2, 2) or t.shape != (2,):
            raise GradingError(f"{name} must return (R, t) with R of shape (2, 2) and t of "
                               f"shape (2,); got {R.shape} and {t.shape}")
        return np.concatenate([R.ravel(), t])
    return packed


@forbids(rigid_align)
def check_rigid_align(fn: Callable, *, seed: int = 0, n: int = 6, quiet: bool = False) -> str:
    """Exercise 8.1 (notebook 08, section 4): ``fn(a, b)`` returns the rotation R (2, 2) and
    translation t (2,) minimising sum |R a_i + t - b_i|^2 (Kabsch without scale, no
    reflection; ``evaluation.map.rigid_align``) on seeded point sets and the edge cases of
    :func:`_pairs`."""
    name = getattr(fn, "__name__", "my_rigid_align")
    msg_ok = check_function(
        _packed(fn, name), _packed(rigid_align, "rigid_align"), _pairs(seed, n), name=name,
        arg_names=["a", "b"], labels=_RT_LABELS, atol=1e-7, rtol=1e-6, quiet=True,
        what="evaluation.map.rigid_align",
        mistakes=[
            Mistake(f"{name} returns a REFLECTION (det R = -1) where a mirror image fits better: "
                    "step 3 of the algorithm is there to prevent it. A map may be rotated and "
                    "shifted into the survey's frame, never mirrored.",
                    _wrong_rt_packed("reflection"),
                    "R = V U^T must be corrected to V diag(1, det(V U^T)) U^T."),
            Mistake(f"{name} includes a SCALE factor in R (Umeyama's similarity): the rigid "
                    "alignment is a rotation and a translation only; a map's size is part of "
                    "its error, not of its frame.", _wrong_rt_packed("scale")),
            Mistake(f"{name} returns R transposed (the rotation the other way): check which of "
                    "the SVD's factors goes on which side.", _wrong_rt_packed("transposed"),
                    "With C = sum (a_i - a_bar)(b_i - b_bar)^T = U S V^T, R = V diag(1, d) U^T, "
                    "not U diag(1, d) V^T."),
            Mistake(f"{name} aligns b onto a (the true landmarks onto the map); the map a is "
                    "the one to move.", _wrong_rt_packed("reversed"), "R a_i + t ~ b_i."),
            Mistake(f"{name} forgets the centroids when forming the cross-covariance (step 1).",
                    _wrong_rt_packed("uncentred"),
                    "C = sum (a_i - a_bar)(b_i - b_bar)^T."),
            Mistake(f"{name} has the right R but the wrong translation: the translation moves "
                    "the ROTATED centroid.", _wrong_rt_packed("no_rotation_in_t"),
                    "t = b_bar - R a_bar."),
        ])
    ok = msg_ok.replace(" inputs.", " inputs (a near-180° rotation, 2 points, collinear, "
                                   "mirrored and shrunken maps included).")
    if not quiet:
        print(ok)
    return Passed(ok)


def _wrong_rmse(kind: str):
    def f(a, b):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        if kind in ("reflection", "scale"):
            R, t = _wrong_rt(kind)(a, b)
        else:
            R, t = rigid_align(a, b)
        if kind == "absolute":
            R, t = np.eye(2), np.zeros(2)
        if kind == "centroid":
            R, t = np.eye(2), b.mean(axis=0) - a.mean(axis=0)
        d = (a @ R if kind == "transposed" else a @ R.T) + t - b
        e2 = np.sum(d * d, axis=1)
        return {"mean": float(np.mean(np.sqrt(e2))), "coords": float(np.sqrt(np.mean(d * d))),
                "mse": float(np.mean(e2))}.get(kind, float(np.sqrt(np.mean(e2))))
    return f


_E_MIN = ("With the centred points a_i', b_i' and the singular values s_1, s_2 of "
          "C = sum a_i' b_i'^T: E_min = sum |a_i'|^2 + sum |b_i'|^2 - 2 (s_1 + d s_2), "
          "d = sign det(V U^T), and the aligned RMSE is sqrt(E_min / K).")


@forbids(aligned_rmse, map_errors, rigid_align)
def check_aligned_rmse(fn: Callable, *, seed: int = 0, n: int = 6, quiet: bool = False) -> str:
    """Exercise 8.2 (notebook 08, section 4): ``fn(mapped, true)`` returns the map RMSE after
    the best rigid alignment (:func:`aligned_rmse`) for paired landmarks, from the singular
    values of the cross-covariance (the exercise derives the minimum; ``rigid_align`` is
    forbidden), and raises ValueError for fewer than 2 pairs."""
    name = getattr(fn, "__name__", "my_aligned_rmse")
    msg_ok = check_function(
        copying(fn), aligned_rmse, _pairs(seed, n), name=name, arg_names=["mapped", "true"],
        atol=1e-9, rtol=1e-7, quiet=True, what="the aligned map RMSE (evaluation.map)",
        mistakes=[
            Mistake(f"{name} returns the RMSE WITHOUT the alignment (the absolute error, "
                    "reproduce's map_rmse): the map's frame is still in it.",
                    _wrong_rmse("absolute"), _E_MIN),
            Mistake(f"{name} only removes the translation; the best alignment also rotates: "
                    "the cross term must be taken at the best rotation.",
                    _wrong_rmse("centroid"), _E_MIN),
            Mistake(f"{name} returns the MEAN distance; the RMSE is the root of the mean "
                    "SQUARED distance, which weighs large errors more.", _wrong_rmse("mean"),
                    "sqrt(mean(|e_i|^2)) = sqrt(E_min / K)."),
            Mistake(f"{name} averages the squared errors over the 2K coordinates (a factor "
                    "1/sqrt(2) too small); the map RMSE averages the squared Euclidean "
                    "distances over the K landmarks.", _wrong_rmse("coords"),
                    "sqrt(E_min / K), not sqrt(E_min / (2 K))."),
            Mistake(f"{name} returns the mean squared error (m^2): take its square root.",
                    _wrong_rmse("mse")),
            Mistake(f"{name} rotates with R transposed (the rotation the other way): for points "
                    "stored as rows, check on which side R multiplies.",
                    _wrong_rmse("transposed"), "The rotated points are a @ R.T (R a_i for "
                    "every row), then + t."),
            Mistake(f"{name} lets the alignment mirror the map (det R = -1), which hides a "
                    "real error: look at the sign d of step 3.", _wrong_rmse("reflection"),
                    "Subtract 2 (s_1 + d s_2) with d = sign det(V U^T), not 2 (s_1 + s_2)."),
            Mistake(f"{name} lets the alignment scale the map, which hides a real error (a "
                    "map that is too small); rotation and translation only.",
                    _wrong_rmse("scale"), _E_MIN),
        ])
    check_raises(fn, (np.array([[1.0, 2.0]]), np.array([[0.0, 1.0]])), name=name,
                 arg_names=["mapped", "true"],
                 why="one landmark pair cannot be aligned (the rotation is undefined)")
    if not quiet:
        print(msg_ok)
    return msg_ok


def _reg_cases(seed: int, n: int) -> list[tuple]:
    """(outputs, targets) pairs: landmark positions tens of metres apart with errors of
    centimetres (R ~ 1), corrections of centimetres learned partly (R ~ 0.5), one learned
    the wrong way (R < 0), and outputs with a bias and a gain."""
    rng = np.random.default_rng(seed)
    cases = []
    for k in range(n):
        m = 6
        if k % 3 == 0:
            tgt = rng.uniform(-23, 17, (m, 2))
            out = tgt + rng.normal(0, 0.1, (m, 2))
        elif k % 3 == 1:
            tgt = rng.normal(0, 0.1, (m, 2))
            out = 0.5 * tgt + rng.normal(0, 0.06, (m, 2))
        else:
            tgt = rng.normal(0, 0.1, (m, 2))
            out = -0.4 * tgt + 0.02 + rng.normal(0, 0.05, (m, 2))
        cases.append((out, tgt))
    tgt = rng.uniform(-5, 5, (6, 2))
    cases.append((1.3 * tgt + 0.7 + rng.normal(0, 0.5, (6, 2)), tgt))
    return cases


def _wrong_reg(kind: str):
    def f(o, g):
        o, g = np.asarray(o, dtype=float), np.asarray(g, dtype=float)
        if kind == "x_only":
            return regression_line(o[:, 0], g[:, 0])
        s, c, r = regression_line(o, g)
        if kind == "r2":
            return s, c, r * r
        if kind == "swapped":
            s2, c2, _ = regression_line(g, o)
            return s2, c2, r
        if kind == "ddof":
            n = o.size
            return s, c, r * n / (n - 1)
        return s, c, r
    return f


@forbids(regression_line, ann.regression)
def check_regression(fn: Callable, *, seed: int = 0, n: int = 6, quiet: bool = False) -> str:
    """Exercise 8.3 (notebook 08, section 5): ``fn(outputs, targets)`` returns (slope,
    intercept, R) of :func:`regression_line`: both coordinates pooled, output = slope *
    target + intercept, R the correlation coefficient."""
    name = getattr(fn, "__name__", "my_regression")
    return check_function(
        copying(fn), regression_line, _reg_cases(seed, n), name=name,
        arg_names=["outputs", "targets"],
        labels=("slope", "intercept", "R"), atol=1e-9, rtol=1e-7,
        what="nntool's regression (ann.regression)", quiet=quiet,
        mistakes=[
            Mistake(f"{name} returns R^2 (the coefficient of determination) as R; nntool's "
                    "regression plot shows R, the correlation coefficient, which is negative "
                    "when the outputs go the wrong way.", _wrong_reg("r2"),
                    "R = S_go / sqrt(S_gg S_oo), with the sign of the slope."),
            Mistake(f"{name} fits the line the wrong way round (targets on outputs): which "
                    "distances does nntool's line minimise, and which variable is on the "
                    "x-axis?", _wrong_reg("swapped"),
                    "Output = slope * Target + intercept: slope = S_go / S_gg, "
                    "intercept = o_bar - slope g_bar."),
            Mistake(f"{name} uses the x coordinates only; nntool pools every output value.",
                    _wrong_reg("x_only"), "Flatten both (n, 2) arrays (.ravel()) first."),
            Mistake(f"{name}'s R is n / (n - 1) times too large: the covariance and the "
                    "standard deviations must use the same normalisation.", _wrong_reg("ddof"),
                    "np.cov has ddof=1, np.std ddof=0; R = S_go / sqrt(S_gg S_oo) avoids "
                    "the issue."),
        ])
