"""Checks of notebook 05's graded exercises (EKF-SLAM): landmark augmentation (section 1)
and the measurement update in Joseph form (section 3).

The references are the plain functions of :mod:`annslam_lib.slam.dense`
(:func:`~annslam_lib.slam.dense.augment_landmark`,
:func:`~annslam_lib.slam.dense.joseph_covariance`,
:func:`~annslam_lib.slam.dense.range_bearing_update`), tested there against the dense filter.
The cases are SLAM states of realistic size (3 + 2N with N up to 10 landmarks, covariances
with strong correlations), plus the edge cases that catch real mistakes: a heading near
+-pi, a landmark straight to the left of the laser where the bearing wraps, arbitrary
(non-optimal) gains, and singular innovation covariances.

Each case is passed to :func:`~annslam_lib.grading.core.check_function` by a short label
(``case='#3: N = 6 landmarks, ...'``), so a failure names the case in words instead of
printing a 23 x 23 matrix.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np

from ..slam import dense as ekf_dense
from ..models.geometry import wrap_angle
from ..models.observation import inverse_observe, observe
from .core import (forbids, NOT_WRITTEN, GradingError, Mistake, Passed, call, check_function, check_raises,
                   fmt, labelled)

__all__ = ["check_augment", "check_joseph_covariance", "check_ekf_update"]

_SYM_RTOL = 1e-9   # a covariance must be symmetric to this, relative to its largest entry


# ------------------------------------------------------------------------------ cases

def _slam_state(rng, N: int, heading: float | None = None):
    """A SLAM state of size 3 + 2N and a covariance with realistic scales (pose cm to dm,
    heading a few degrees, landmarks cm to m) and strong random correlations."""
    phi = rng.uniform(-math.pi, math.pi) if heading is None else heading
    pose = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), phi])
    ang, r = rng.uniform(-math.pi, math.pi, N), rng.uniform(3.0, 30.0, N)
    lms = pose[:2] + r[:, None] * np.c_[np.cos(ang), np.sin(ang)]
    n = 3 + 2 * N
    sd = np.concatenate([rng.uniform(0.05, 0.5, 2), [math.radians(rng.uniform(0.5, 3.0))],
                         rng.uniform(0.05, 1.0, 2 * N)])
    A = rng.normal(size=(n, n))
    C = A @ A.T + 0.5 * n * np.eye(n)
    d = np.sqrt(np.diag(C))
    P = (C / np.outer(d, d)) * np.outer(sd, sd)
    return np.concatenate([pose, lms.ravel()]), 0.5 * (P + P.T)


def _names(n: int, extra: int = 0) -> list[str]:
    """Names of the state entries: x, y, phi, x_0, y_0, ... (and the new landmark's)."""
    names = ["x", "y", "phi"] + [f"{c}_{j}" for j in range((n - 3) // 2) for c in "xy"]
    return names + ["new landmark x", "new landmark y"][:extra]


def _pair(i: int, name: str, what: str) -> Callable:
    """Output extractor for functions returning (x_new, P_new)."""
    def part(out):
        if not (isinstance(out, (tuple, list)) and len(out) == 2):
            got = (f"a {len(out)}-{type(out).__name__}" if isinstance(out, (tuple, list))
                   else "None (did you forget `return`?)" if out is None
                   else f"{type(out).__name__} of shape {np.shape(out)}")
            raise GradingError(f"{name} must return the pair (x_new, P_new), got {got}")
        return out[i]
    part.__doc__ = what
    return part


def _first_is_pair(fn, table, name: str) -> None:
    """The function must return a pair (x_new, P_new): said before any comparison."""
    label = next(iter(table))
    _pair(0, name, "")(call(labelled(fn, table), (label,), name=name, arg_names=["case"]))


def _returned(fn, table):
    """fn by case label, its result shown in words (check_raises prints what came back)."""
    def by_label(label):
        out = fn(*table[label])
        if isinstance(out, (tuple, list)) and len(out) == 2:
            P = np.asarray(out[1], dtype=float)
            big = float(np.max(np.abs(P))) if P.size and np.all(np.isfinite(P)) else float("nan")
            return f"a pair (x_new, P_new) with largest |P_new| entry {big:.3g}"
        return f"a {type(out).__name__}"
    return by_label


def _trim(message: str, keep: int = 5) -> str:
    """At most ``keep`` lines of per-entry notes (a 23 x 23 covariance has many entries)."""
    lines = message.split("\n")
    if len(lines) <= keep + 1:
        return message
    return "\n".join(lines[:keep] + [f"... and {len(lines) - keep} more lines like these"])


def _groups(table, key) -> list[list[str]]:
    """Case labels grouped by output shape (check_function compares equal shapes)."""
    out: dict = {}
    for label, args in table.items():
        out.setdefault(key(args), []).append(label)
    return list(out.values())


def _asymmetry(M) -> float:
    M = np.asarray(M, dtype=float)
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        return 0.0
    return float(np.max(np.abs(M - M.T)) / max(np.max(np.abs(M)), 1e-300))


def _check_symmetric(fn, table, *, name: str, part=lambda out: out, hint: str) -> None:
    """The covariance a function returns must be symmetric: names the first case and entry."""
    for label in table:
        M = np.asarray(part(call(labelled(fn, table), (label,), name=name, arg_names=["case"])),
                       dtype=float)
        if _asymmetry(M) > _SYM_RTOL:
            i, j = np.unravel_index(np.argmax(np.abs(M - M.T)), M.shape)
            fail = (f"the covariance {name} returns is not symmetric at case '{label}': entry "
                    f"[{i}, {j}] = {fmt(M[i, j])} but [{j}, {i}] = {fmt(M[j, i])}. {hint}")
            raise GradingError(fail)


def _is_known(e: GradingError, mistakes: Sequence[Mistake]) -> bool:
    msg = str(e)
    return NOT_WRITTEN in msg or any(msg == m.text for m in mistakes)


# ------------------------------------------------------------------------------ augmentation

def _augment_cases(seed: int, n: int) -> dict:
    rng = np.random.default_rng(seed)
    table = {}

    def add(N, z, *, heading=None, R=None, note=""):
        x, P = _slam_state(rng, N, heading)
        if R is None:
            R = np.diag([rng.uniform(0.05, 0.3)**2, math.radians(rng.uniform(0.5, 2.0))**2])
        label = (f"#{len(table)}: N = {N} landmarks, heading {x[2]:.3f} rad, "
                 f"z = ({z[0]:.3g} m, {z[1]:.3g} rad){note}")
        table[label] = (x, P, np.array(z, dtype=float), R)

    # N = 3 first: the cross covariances with old landmarks are what most often goes wrong
    add(3, (8.0, 1.2))
    add(3, (25.0, math.pi - 0.01), heading=math.pi - 0.02,
        note=" (landmark to the left, heading near pi: the direction wraps)")
    add(3, (4.0, 0.0), heading=-math.pi + 0.01, note=" (straight to the right)")
    add(0, (12.0, math.pi / 2), note=" (straight ahead, no landmark yet)")
    add(0, (6.0, 2.6))
    add(1, (15.0, 0.4), R=np.array([[0.02, 0.001], [0.001, 3e-4]]),
        note=" (correlated range and bearing noise)")
    for _ in range(max(n, 0)):
        N = int(rng.choice([1, 3, 6, 10]))
        add(N, (rng.uniform(1.0, 40.0), rng.uniform(0.0, math.pi)))
    return table


def _aug_ref(x, P, z, R):
    return ekf_dense.augment_landmark(x, P, z, R)


def _aug_parts(x, P, z, R):
    lm, Gv, Gz = inverse_observe(x[:3], z)
    return lm, Gv, Gz


def _aug_wrong_cov(kind: str):
    def wrong(x, P, z, R):
        x_new, P_new = _aug_ref(x, P, z, R)
        _, Gv, Gz = _aug_parts(x, P, z, R)
        n = x.size
        W = P_new.copy()
        if kind == "no-old-cross":
            W[n:, 3:n] = 0.0
            W[3:n, n:] = 0.0
        elif kind == "no-noise":
            W[n:, n:] -= Gz @ R @ Gz.T
        elif kind == "raw-R":
            W[n:, n:] += R - Gz @ R @ Gz.T
        elif kind == "no-pose":
            W[n:, n:] -= Gv @ P[:3, :3] @ Gv.T
        elif kind == "no-cross":
            W[n:, :n] = 0.0
            W[:n, n:] = 0.0
        return W
    return wrong


def _aug_wrong_mean(kind: str):
    def wrong(x, P, z, R):
        r, b = z
        phi = x[2]
        if kind == "ahead":                 # bearing counted from straight ahead
            d = (math.cos(phi + b), math.sin(phi + b))
        elif kind == "mirror":              # vector landmark -> sensor, as printed in 4.1
            d = (-math.cos(phi + b - math.pi / 2), -math.sin(phi + b - math.pi / 2))
        else:                               # heading left out: the laser frame taken as the world
            d = (math.cos(b - math.pi / 2), math.sin(b - math.pi / 2))
        return np.concatenate([x, [x[0] + r * d[0], x[1] + r * d[1]]])
    return wrong


# (kind, message, answer): the message names the kind of mistake and where to look; the
# answer (what would hand the exercise over) is shown only in the instructor's feedback.
_AUG_MEAN_MISTAKES = [
    ("ahead", "the new landmark is placed 90° off: the bearing was counted from straight "
              "ahead. The ACFR laser counts it from the vehicle's RIGHT (0 = right, pi/2 = "
              "ahead): see chapter 03's inverse observation.",
     "The direction in the world is phi + beta - pi/2: inverse_observe(x[:3], z) does it "
     "for you."),
    ("mirror", "the new landmark is on the wrong side of the car, mirrored through the laser: "
               "you went from the landmark to the sensor. That is the direction of the paper's "
               "printed bearing (section 4.1, erratum 4.1-bearing).",
     "The landmark is the laser position PLUS r (cos, sin)(phi + beta - pi/2)."),
    ("no-heading", "the new landmark ignores the car's heading: the bearing is measured in the "
                   "laser's frame, not in the world's.",
     "The world direction is phi + beta - pi/2, not beta - pi/2."),
]

_AUG_COV_MISTAKES = [
    ("no-old-cross", "the new landmark's cross covariance with the landmarks already in the "
                     "map is zero. The new landmark inherits the pose's correlation with EVERY "
                     "state entry, not only with the pose: look at which columns of P the new "
                     "rows are built from.",
     "The new rows are G_v P_{v,:}, all columns of the pose rows P[:3, :]."),
    ("no-cross", "the new landmark is uncorrelated with the rest of the state: it was placed "
                 "from an uncertain pose, so it shares that pose's error.",
     "Its rows and columns are G_v P_{v,:} and its transpose."),
    ("no-noise", "the new landmark's own 2x2 block lacks the measurement noise.",
     "It is G_v P_vv G_v^T + G_z R G_z^T."),
    ("raw-R", "the measurement noise enters the new landmark's block as R itself; R is the "
              "covariance of (range, bearing), in m^2 and rad^2, not of (x, y): it has to be "
              "carried into (x, y) first.",
     "Map it with the Jacobian: G_z R G_z^T."),
    ("no-pose", "the new landmark's own 2x2 block lacks the pose's uncertainty.",
     "It is G_v P_vv G_v^T + G_z R G_z^T."),
]


def _told(message: str, answer: str) -> str:
    """``message``, with ``answer`` added in the instructor's full feedback only."""
    return Mistake(message, None, answer).text


def _block_note(fn, reference, table, *, name) -> str:
    """Which block of P_new is wrong at the first failing case (augmentation layout)."""
    for label, args in table.items():
        out = call(labelled(fn, table), (label,), name=name, arg_names=["case"])
        got = np.asarray(_pair(1, name, "")(out), dtype=float)
        exp = reference(*args)[1]
        if got.shape != exp.shape:
            return ""
        bad = ~(np.abs(got - exp) <= 1e-8 + 1e-6 * np.abs(exp))
        if not bad.any():
            continue
        n = exp.shape[0] - 2
        full = bool(_told("", "-").strip())     # the instructor's feedback: with formulas
        blocks = [("the old covariance P (rows and columns 0..n-1, which must not change)",
                   bad[:n, :n]),
                  ("the new landmark's cross covariance with the pose"
                   + (", G_v P_vv" if full else "") + " (rows n, n+1; columns 0-2) or its "
                   "transpose", bad[n:, :3] | bad[:3, n:].T),
                  ("the new landmark's cross covariance with the old landmarks"
                   + (", G_v P_{v,L}" if full else "") + " (rows n, n+1; columns 3..n-1) or "
                   "its transpose", bad[n:, 3:n] | bad[3:n, n:].T),
                  ("the new landmark's own block" + (" G_v P_vv G_v^T + G_z R G_z^T" if full
                                                    else "") + " (rows and columns n, n+1)",
                   bad[n:, n:])]
        wrong = [b for b, m in blocks if m.any()]
        return (f"\n  At case '{label}' (n = {n}) the wrong part of P_new: "
                + "; ".join(wrong) + ".")
    return ""


@forbids(ekf_dense.augment_landmark)
def check_augment(fn: Callable, *, seed: int = 0, n: int = 6) -> str:
    """Exercise 5.1 (notebook 05 section 1, landmark augmentation): ``fn(x, P, z, R)`` must
    return (x_new, P_new) as :func:`annslam_lib.slam.dense.augment_landmark` for one new
    landmark, on SLAM states with 0 to 10 landmarks (6 fixed cases plus ``n`` seeded ones).
    Catches: a landmark placed with the wrong bearing convention (90° off, mirrored as in
    the paper's printed bearing, heading left out), missing cross covariances with the old
    landmarks, a missing G_z R G_z^T or G_v P_vv G_v^T, R used unmapped, an asymmetric
    P_new; names the wrong block otherwise."""
    name = "my_augment"
    table = _augment_cases(seed, n)
    by = labelled(fn, table)
    ref = labelled(_aug_ref, table)
    _first_is_pair(fn, table, name)
    groups = _groups(table, lambda a: a[0].size)
    x_mistakes = [Mistake(msg, labelled(_aug_wrong_mean(k), table), ans)
                  for k, msg, ans in _AUG_MEAN_MISTAKES]
    for labels in groups:
        n_state = table[labels[0]][0].size
        check_function(by, ref, [(lab,) for lab in labels], name=name,
                       arg_names=["case"], labels=_names(n_state, 2), angles=(2,),
                       output=_pair(0, name, "x_new"), mistakes=x_mistakes, quiet=True)
    p_mistakes = [Mistake(msg, labelled(_aug_wrong_cov(k), table), ans)
                  for k, msg, ans in _AUG_COV_MISTAKES]
    for labels in groups:
        try:
            check_function(by, ref, [(lab,) for lab in labels], name=f"{name} (P_new)",
                           arg_names=["case"], output=_pair(1, name, "P_new"),
                           mistakes=p_mistakes, quiet=True)
        except GradingError as e:
            if _is_known(e, p_mistakes):
                raise
            sub = {lab: table[lab] for lab in labels}
            _check_symmetric(fn, sub, name=name, part=_pair(1, name, "P_new"),
                             hint=_told("Build the new rows once and use their transpose "
                                             "for the new columns.",
                                             "The new rows are G_v P[:3, :]."))
            raise GradingError(_trim(str(e)) + _block_note(fn, _aug_ref, sub, name=name)) from None
    _check_symmetric(fn, table, name=name, part=_pair(1, name, "P_new"),
                     hint="The new columns are the transpose of the new rows.")
    ok = (f"✓ {name} agrees with the reference augmentation on {len(table)} SLAM states "
          f"(x_new and P_new, symmetric).")
    print(ok)
    return Passed(ok)


# ------------------------------------------------------------------------------ update

def _observed(rng, N: int, m: int, *, heading=None, left=False):
    """State, covariance and the dense H, z_hat of m observed landmarks (chapter 03's
    observe), optionally the first one moved straight to the left of the laser."""
    x, P = _slam_state(rng, N, heading)
    idx = rng.choice(N, size=m, replace=False)
    if left:     # bearing ~ pi: the laser's left edge, where a bearing wraps to -pi
        j = idx[0]
        r = rng.uniform(5.0, 20.0)
        a = x[2] + math.pi / 2 - 0.004          # bearing = pi - 0.004
        x[3 + 2 * j:5 + 2 * j] = x[:2] + r * np.array([math.cos(a), math.sin(a)])
    z_hat, Hp, Hl = observe(x[:3], x[3:].reshape(-1, 2)[idx])
    H = np.zeros((2 * m, x.size))
    for i, j in enumerate(idx):
        H[2 * i:2 * i + 2, :3] = Hp[i]
        H[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] = Hl[i]
    sr, sb = rng.uniform(0.05, 0.3), math.radians(rng.uniform(0.5, 2.0))
    R = np.diag(np.tile([sr**2, sb**2], m))
    return x, P, z_hat.ravel(), H, R, idx


def _measured(z_hat, nu) -> np.ndarray:
    """A measurement z = z_hat + nu as a laser reports it: bearings in (-pi, pi]."""
    z = z_hat + nu
    z[1::2] = wrap_angle(z[1::2])
    return z


def _joseph_cases(seed: int, n: int) -> dict:
    rng = np.random.default_rng(seed)
    table = {}

    def add(N, m, gain, note=""):
        x, P, _, H, R, idx = _observed(rng, N, m)
        K, _ = ekf_dense.kalman_gain(P, H, R)
        if gain == "scaled":
            K = K * rng.uniform(0.3, 0.8)
        elif gain == "perturbed":
            K = K * (1.0 + 0.5 * rng.normal(size=K.shape))
        elif gain == "random":
            K = rng.normal(scale=0.3, size=K.shape)
        label = (f"#{len(table)}: N = {N} landmarks (n = {x.size}), {m} observed "
                 f"{list(map(int, idx))}, {gain} gain{note}")
        table[label] = (P, H, R, K)

    add(5, 1, "perturbed")
    add(5, 1, "scaled", " (a cautious gain, 0.3-0.8 of the optimal)")
    add(5, 1, "optimal", " (here every form agrees)")
    add(5, 1, "random")
    add(8, 2, "perturbed")
    add(8, 2, "optimal")
    for _ in range(max(n, 0)):
        add(int(rng.choice([4, 10])), 2, str(rng.choice(["perturbed", "random"])))
    return table


def _joseph_wrong(kind: str):
    def wrong(P, H, R, K):
        I_KH = np.eye(P.shape[0]) - K @ H
        S = H @ P @ H.T + R
        if kind == "short":
            return I_KH @ P
        if kind == "kskt":
            return P - K @ S @ K.T
        if kind == "sym-short":
            A = I_KH @ P
            return 0.5 * (A + A.T)
        if kind == "no-krk":
            return I_KH @ P @ I_KH.T
        if kind == "transposed":
            return I_KH.T @ P @ I_KH + K @ R @ K.T
        return I_KH @ P @ I_KH.T + K @ S @ K.T          # "ksk"
    return wrong


_JOSEPH = "P_new = (I - K H) P (I - K H)^T + K R K^T (the Joseph form)."
_JOSEPH_MISTAKES = [
    ("short", "this is a short form, right only for the optimal gain K = P H^T S^-1; for any "
              "other gain (these cases use scaled, perturbed and random gains) it is not the "
              "covariance of x + K nu, and mostly not even symmetric. Derive the covariance "
              "of the error after the update for ANY K (section 3).", _JOSEPH),
    ("sym-short", "this is a short form, symmetrised. Symmetrising hides the asymmetry but "
                  "the numbers stay wrong for a non-optimal gain (these cases use scaled, "
                  "perturbed and random gains): derive the covariance of the error after the "
                  "update for ANY K (section 3).", _JOSEPH),
    ("kskt", "this is P - K S K^T, which is the covariance only for the optimal gain "
             "K = P H^T S^-1. Derive the covariance of the error after the update for an "
             "arbitrary K (section 3).", _JOSEPH),
    ("no-krk", "the measurement noise is missing: R enters the estimate through the gain "
               "(x + K nu, and nu carries the noise), so it must add a term of its own.",
     "The missing term is + K R K^T."),
    ("transposed", "the transposes are on the wrong side of P: write the error after the "
                   "update as a matrix times the error before it, and take the covariance of "
                   "that product.",
     "The error after the update is (I - K H) e + K eta, whose covariance is "
     "(I - K H) P (I - K H)^T + K R K^T."),
    ("ksk", "the noise term passes the innovation covariance S through the gain: only the "
            "measurement noise enters as extra noise; the state's part of S is already in the "
            "other term.", "The noise term is K R K^T, not K S K^T."),
]


@forbids(ekf_dense.joseph_covariance, ekf_dense.joseph_update)
def check_joseph_covariance(fn: Callable, *, seed: int = 0, n: int = 4) -> str:
    """Exercise 5.2 (notebook 05 section 3, the Joseph form): ``fn(P, H, R, K)`` must return
    (I - K H) P (I - K H)^T + K R K^T (:func:`annslam_lib.slam.dense.joseph_covariance`)
    for ANY gain K: optimal, scaled, perturbed and random gains on SLAM states with 4 to 10
    landmarks (6 fixed cases plus ``n`` seeded ones). Catches the short forms (I - K H) P
    and P - K S K^T (right only for the optimal gain), a missing K R K^T, K S K^T for
    K R K^T, misplaced transposes and an asymmetric result."""
    name = "my_joseph_covariance"
    table = _joseph_cases(seed, n)
    by = labelled(fn, table)
    ref = labelled(ekf_dense.joseph_covariance, table)
    mistakes = [Mistake(msg, labelled(_joseph_wrong(k), table), ans)
                for k, msg, ans in _JOSEPH_MISTAKES]
    for labels in _groups(table, lambda a: a[1].shape):
        try:
            check_function(by, ref, [(lab,) for lab in labels], name=name, arg_names=["case"],
                           mistakes=mistakes, quiet=True)
        except GradingError as e:
            if _is_known(e, mistakes):
                raise
            _check_symmetric(fn, {lab: table[lab] for lab in labels}, name=name,
                             hint=_told("The covariance after an update with any gain is a "
                                        "sum of terms A M A^T, symmetric for any K.",
                                        _JOSEPH))
            raise GradingError(_trim(str(e))) from None
    _check_symmetric(fn, table, name=name, hint="")
    ok = (f"✓ {name} agrees with the Joseph form on {len(table)} updates with optimal and "
          f"non-optimal gains (symmetric).")
    print(ok)
    return Passed(ok)


def _update_cases(seed: int, n: int) -> dict:
    rng = np.random.default_rng(seed)
    table = {}

    def add(N, m, *, heading=None, left=False, heading_wrap=False, note=""):
        x, P, z_hat, H, R, idx = _observed(rng, N, m, heading=heading, left=left)
        nu = rng.normal(size=2 * m) * np.sqrt(np.diag(R))
        if left:
            nu[1] = 0.01            # measured at pi + 0.006, reported as -pi + 0.006
        if heading_wrap:            # an innovation that turns the heading over +pi
            K, _ = ekf_dense.kalman_gain(P, H, R)
            nu = K[2] / np.linalg.norm(K[2])**2 * 0.01
        z = _measured(z_hat, nu)
        label = (f"#{len(table)}: N = {N} landmarks (n = {x.size}), heading {x[2]:.4f} rad, "
                 f"landmarks {list(map(int, idx))} observed{note}")
        table[label] = (x, P, z, z_hat, H, R)

    add(6, 1)
    add(6, 1, left=True, note=" (landmark 1st in the list straight to the LEFT: predicted "
                              "bearing pi - 0.004, measured -pi + 0.006)")
    add(6, 1, heading=math.pi - 0.003, heading_wrap=True,
        note=" (the update turns the heading past +pi)")
    add(10, 3)
    add(10, 2, left=True, note=" (first observed landmark straight to the left)")
    for _ in range(max(n, 0)):
        add(int(rng.choice([3, 6, 10])), int(rng.choice([1, 2, 3])))
    return table


def _update_wrong_mean(kind: str):
    def wrong(x, P, z, z_hat, H, R):
        K, S = ekf_dense.kalman_gain(P, H, R)
        if kind == "unwrapped":
            nu = z - z_hat
        elif kind == "reversed":
            nu = -ekf_dense.innovation(z, z_hat)
        else:                                   # "R-gain"
            nu = ekf_dense.innovation(z, z_hat)
            K = P @ H.T @ np.linalg.inv(R)
        x_new = x + K @ nu
        x_new[2] = float(wrap_angle(x_new[2]))
        return x_new
    return wrong


_UPDATE_MEAN_MISTAKES = [
    ("unwrapped", "the bearing innovation is not wrapped: for a landmark straight to the left "
                  "the bearing is predicted at pi - 0.004 and measured at -pi + 0.006, so "
                  "z - z_hat = -6.27 rad although the two directions are 0.01 rad apart.",
     "Wrap the bearing entries nu[1::2] into (-pi, pi], e.g. "
     "(a + np.pi) % (2 * np.pi) - np.pi."),
    ("reversed", "the innovation has the wrong sign: check which of the measured and the "
                 "predicted values comes first (step 3).",
     "nu = z - z_hat (then x_new = x + K nu)."),
    ("R-gain", "the gain weighs with the measurement noise alone: the innovation's covariance "
               "holds the measurement's AND the state's uncertainty (step 1).",
     "K = P H^T S^-1 with S = H P H^T + R."),
]


def _update_wrong_cov(kind: str):
    def wrong(x, P, z, z_hat, H, R):
        K, S = ekf_dense.kalman_gain(P, H, R)
        I_KH = np.eye(P.shape[0]) - K @ H
        if kind == "no-krk":
            return I_KH @ P @ I_KH.T
        return P + K @ S @ K.T                   # "plus"
    return wrong


_UPDATE_COV_MISTAKES = [
    ("no-krk", "P_new lacks the measurement noise's term (compare with exercise 5.2).",
     "The Joseph form is (I - K H) P (I - K H)^T + K R K^T."),
    ("plus", "P_new grows with the update; an observation can only reduce uncertainty.",
     "P - K S K^T, or better the Joseph form (I - K H) P (I - K H)^T + K R K^T."),
]


def _singular_cases(seed: int) -> list[tuple[str, tuple]]:
    rng = np.random.default_rng(seed + 1)
    x, P, z_hat, H, R, _ = _observed(rng, 3, 1)
    z = _measured(z_hat, np.array([0.05, 0.01]))
    cases = [("a perfectly known state (P = 0) measured without noise (R = 0): S = 0",
              (x, np.zeros_like(P), z, z_hat, H, np.zeros_like(R)))]
    # the same landmark listed twice, no noise: S is 4 x 4 of rank 2
    H2 = np.vstack([H, H])
    cases.append(("one landmark observed twice by a noiseless sensor: S has rank 2 of 4",
                  (x, P, np.tile(z, 2), np.tile(z_hat, 2), H2, np.zeros((4, 4)))))
    # a state known only along one direction: S = H P H^T has rank 1 (numerically ~1e-17)
    b = rng.normal(size=(x.size, 1)) * 0.1
    cases.append(("P = b b^T of rank 1 and R = 0: S has rank 1 (np.linalg.inv does not notice)",
                  (x, b @ b.T, z, z_hat, H, np.zeros_like(R))))
    return cases


@forbids(ekf_dense.range_bearing_update, ekf_dense.joseph_update, ekf_dense.kalman_gain)
def check_ekf_update(fn: Callable, *, seed: int = 0, n: int = 5) -> str:
    """Exercise 5.3 (notebook 05 section 3, the EKF update): ``fn(x, P, z, z_hat, H, R)`` must
    return (x_new, P_new) as :func:`annslam_lib.slam.dense.range_bearing_update`: the wrapped
    innovation, the optimal gain, the heading wrapped into (-pi, pi], the Joseph form; on
    SLAM states with 3 to 10 landmarks and 1 to 3 observed at once (5 fixed cases plus ``n``
    seeded ones), and a ValueError for a singular innovation covariance (three cases, one
    that np.linalg.inv does not notice). Catches an unwrapped bearing innovation, a
    reversed innovation, R^-1 for S^-1, an unwrapped heading, a missing K R K^T."""
    name = "my_ekf_update"
    table = _update_cases(seed, n)
    by = labelled(fn, table)
    ref = labelled(ekf_dense.range_bearing_update, table)
    _first_is_pair(fn, table, name)
    groups = _groups(table, lambda a: (a[0].size, a[2].size))
    x_mistakes = [Mistake(msg, labelled(_update_wrong_mean(k), table), ans)
                  for k, msg, ans in _UPDATE_MEAN_MISTAKES]
    p_mistakes = [Mistake(msg, labelled(_update_wrong_cov(k), table), ans)
                  for k, msg, ans in _UPDATE_COV_MISTAKES]
    for labels in groups:
        n_state = table[labels[0]][0].size
        check_function(by, ref, [(lab,) for lab in labels], name=name, arg_names=["case"],
                       labels=_names(n_state), angles=(2,), output=_pair(0, name, "x_new"),
                       mistakes=x_mistakes, quiet=True)
    for labels in groups:
        try:
            check_function(by, ref, [(lab,) for lab in labels], name=f"{name} (P_new)",
                           arg_names=["case"], output=_pair(1, name, "P_new"),
                           mistakes=p_mistakes, quiet=True)
        except GradingError as e:
            if _is_known(e, p_mistakes):
                raise
            _check_symmetric(fn, {lab: table[lab] for lab in labels}, name=name,
                             part=_pair(1, name, "P_new"),
                             hint=_told("The covariance of exercise 5.2 is symmetric by "
                                        "construction.", _JOSEPH))
            raise GradingError(_trim(str(e))) from None
    _check_symmetric(fn, table, name=name, part=_pair(1, name, "P_new"),
                     hint=_told("Use the covariance of exercise 5.2, symmetric by "
                                "construction.", _JOSEPH))
    singular = dict(_singular_cases(seed))
    for why in singular:
        check_raises(_returned(fn, singular), (why,), name=name, arg_names=["case"],
                     why="the innovation covariance S is singular: no gain exists. Test S "
                         "before inverting it, e.g. its smallest eigenvalue (np.linalg.eigvalsh)"
                         " against 1e-12 times its largest, and raise ValueError")
    ok = (f"✓ {name} agrees with the reference update on {len(table)} SLAM states (x_new and "
          f"P_new, symmetric) and rejects {len(singular)} singular innovation covariances.")
    print(ok)
    return Passed(ok)
