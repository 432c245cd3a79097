"""Data association: which landmark of the map did each measurement come from?
(notebook 04 "gating and association").

For a predicted measurement zhat_j of landmark j with innovation covariance
S_j = H P H^T + R (notebook 03), a measurement z from landmark j gives an
innovation nu = z - zhat_j (bearing wrapped) whose squared Mahalanobis distance

    d2 = nu^T S_j^-1 nu

is chi-square distributed with 2 degrees of freedom. The **gate** accepts j if
d2 <= chi2.ppf(p, 2): a measurement that truly comes from j falls outside with
probability 1 - p. Among the landmarks in the gate the **nearest neighbour** (in
d2, not in metres) wins, and one landmark receives at most one measurement per
scan (**mutual exclusion**). A measurement far outside every gate
(d2 > the ``new_landmark`` threshold for every j) starts a new landmark; one in
between is rejected as ambiguous, so that a badly predicted old landmark does
not become a duplicate.
"""
from __future__ import annotations

import numpy as np

from .. import _checks
from ..models.geometry import wrap_angle, wrap_difference
from ..models.uncertainty import chi2_quantile

__all__ = ["gate_threshold", "GATE", "NEW_LANDMARK", "NEW_LANDMARK_PROB", "NEW", "REJECTED", "mahalanobis",
           "associate", "score_association", "gate_experiment", "mahalanobis_fast",
           "associate_fast"]

#: Codes of :func:`associate` for measurements not matched to a landmark.
NEW, REJECTED = -1, -2


def gate_threshold(prob: float = 0.99, dof: int = 2) -> float:
    """The chi-square quantile chi2.ppf(prob, dof): the d2 below which a measurement of
    the landmark falls with probability ``prob`` (9.21 for 99 %, 2 dof)."""
    prob = _checks.probability("prob", prob)
    dof = _checks.integer("dof", dof, lo=1)
    return float(chi2_quantile(prob, dof))


#: Default gate: 99 % (d2 <= 9.21).
GATE = gate_threshold(0.99)
#: Default new-landmark probability, 99.999 %: the one threshold of every chapter and of
#: ``SlamConfig.new_landmark_prob``. A measurement of a known landmark lands beyond it once
#: in 100,000 times, about once in a hundred Car Park runs (883 beacon detections each):
#: duplicates stay rare.
NEW_LANDMARK_PROB = 0.99999
#: Default new-landmark threshold, d2 > 23.03 to every landmark.
NEW_LANDMARK = gate_threshold(NEW_LANDMARK_PROB)


def mahalanobis(z, zhat, S) -> np.ndarray:
    """Squared Mahalanobis distances d2 (n, m) between measurements ``z`` (n, 2) and the
    predicted measurements ``zhat`` (m, 2) with innovation covariances ``S`` (m, 2, 2):
    d2[i, j] = nu^T S_j^-1 nu, nu = z_i - zhat_j with the bearing difference wrapped to
    (-pi, pi].

    Vectorised with the Cholesky factor of each symmetric 2 x 2 matrix [[a, b], [b, c]]
    = L L^T, L = [[l11, 0], [l21, l22]], l11 = sqrt(a), l21 = b / l11, l22^2 = c - l21^2, so
    d2 = |L^-1 nu|^2 (no determinant: a c overflows or underflows at scales such as 1e200 I
    or 1e-170 I, which are valid covariances). Raises ValueError naming the landmark index
    if an S_j is not symmetric or not positive definite (l22^2 must exceed 1e-12 c: the
    same test as a c - b^2 > 1e-12 a c; a singular S has no Mahalanobis distance).
    """
    z = _checks.array("z", z, (2,))
    zhat = _checks.array("zhat", zhat, (2,))
    S = _checks.array("S", S, (2, 2))
    if z.ndim != 2 or zhat.ndim != 2 or S.ndim != 3 or S.shape[0] != zhat.shape[0]:
        raise ValueError(f"need z (n, 2), zhat (m, 2) and S (m, 2, 2), got {z.shape}, "
                         f"{zhat.shape}, {S.shape}")
    a, b, b2, c = S[:, 0, 0], S[:, 0, 1], S[:, 1, 0], S[:, 1, 1]
    scale = np.maximum(np.max(np.abs(S), axis=(1, 2)), 1e-300)
    asym = np.flatnonzero(np.abs(b - b2) > 1e-9 * scale)
    if asym.size:
        j = int(asym[0])
        raise ValueError(f"innovation covariance S of landmark {j} is not symmetric "
                         f"(S[0,1] = {b[j]:.6g}, S[1,0] = {b2[j]:.6g})")
    b = 0.5 * (b + b2)
    with np.errstate(invalid="ignore", divide="ignore"):
        l11 = np.sqrt(a)
        l21 = b / l11
        l22sq = c - l21 * l21
    bad = np.flatnonzero(~((a > 0) & (c > 0) & (l22sq > 1e-12 * c) & np.isfinite(l22sq)))
    if bad.size:
        j = int(bad[0])
        raise ValueError(f"innovation covariance S of landmark {j} is not positive definite "
                         f"(diagonal {a[j]:.6g}, {c[j]:.6g}; off-diagonal {b[j]:.6g})")
    l22 = np.sqrt(l22sq)
    nu_r = z[:, None, 0] - zhat[None, :, 0]
    nu_b = wrap_angle(z[:, None, 1] - zhat[None, :, 1])
    e1 = nu_r / l11
    e2 = (nu_b - l21 * e1) / l22
    return e1 * e1 + e2 * e2


def associate(d2, gate: float = GATE, new_landmark: float = NEW_LANDMARK) -> np.ndarray:
    """Nearest-neighbour association with mutual exclusion (notebook 04).

    d2 (n, m): squared Mahalanobis distances of n measurements to m landmarks
    (``mahalanobis``; +inf allowed, e.g. for landmarks not worth testing).
    Returns assign (n,) int: j >= 0 the landmark of measurement i; ``NEW`` (-1) a new
    landmark: d2 > ``new_landmark`` for every landmark (all new when m = 0);
    ``REJECTED`` (-2): in no gate but not far enough to be new, or in a gate but
    every landmark of its gate was taken by a nearer measurement.

    Mutual exclusion is greedy: all (i, j) pairs inside the gate (d2 <= ``gate``) are
    taken in increasing d2 (ties: lower i, then lower j) and a pair is accepted if
    neither its measurement nor its landmark is used yet. Greedy is not the optimal
    assignment in general (the Hungarian algorithm is), but with gates this small two
    measurements rarely compete, and the nearest pair is always right to win.
    """
    try:
        d2 = np.asarray(d2, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"d2 must be a numeric (n, m) matrix, got {d2!r}") from exc
    if d2.ndim != 2:
        raise ValueError(f"d2 must be a (n, m) matrix, got shape {d2.shape}")
    if np.any(np.isnan(d2)) or np.any(d2 < 0):
        raise ValueError("d2 must hold non-negative distances (no NaN; +inf is allowed)")
    for name, v in (("gate", gate), ("new_landmark", new_landmark)):
        _checks.real(name, v, lo=0.0, strict=True)
    if new_landmark < gate:
        raise ValueError(f"new_landmark ({new_landmark}) must be >= gate ({gate}): a measurement "
                         "inside a gate cannot be a new landmark")
    n, m = d2.shape
    if m == 0:
        return np.full(n, NEW, dtype=np.int64)
    assign = np.where(np.min(d2, axis=1) > new_landmark, NEW, REJECTED).astype(np.int64)
    i, j = np.nonzero(d2 <= gate)
    order = np.lexsort((j, i, d2[i, j]))
    used = np.zeros(m, dtype=bool)
    done = np.zeros(n, dtype=bool)
    for k in order:                    # only the pairs inside a gate: a few per scan
        a, b = i[k], j[k]
        if not done[a] and not used[b]:
            assign[a], done[a], used[b] = b, True, True
    return assign


def score_association(assign, predicted_ids, true_ids) -> dict:
    """Score an association against the truth (simulator; notebook 04 experiments).

    assign (n,): :func:`associate`'s output; predicted_ids (m,): the true landmark id of
    each predicted landmark (column of d2); true_ids (n,): the true landmark of each
    measurement. A measurement of a landmark absent from ``predicted_ids`` *should* be
    NEW. Returns counts: correct; wrong (matched to the wrong landmark, including an
    unmapped landmark matched to a mapped one); missed (a mapped landmark rejected);
    false_new (a mapped landmark declared new: a future duplicate); new_ok (an unmapped
    landmark declared new); new_rejected (an unmapped landmark rejected).
    """
    assign = np.asarray(assign, dtype=np.int64)
    pred = np.asarray(predicted_ids, dtype=np.int64)
    true = np.asarray(true_ids, dtype=np.int64)
    if assign.shape != true.shape or assign.ndim != 1 or pred.ndim != 1:
        raise ValueError(f"assign and true_ids must be (n,), predicted_ids (m,), got "
                         f"{assign.shape}, {true.shape}, {pred.shape}")
    if np.any(assign >= pred.size) or np.any(assign < REJECTED):
        raise ValueError("assign holds an index outside the predicted landmarks")
    known = np.isin(true, pred)
    got = pred[np.clip(assign, 0, None)] if pred.size else np.full(assign.shape, -3)
    got = np.where(assign >= 0, got, -3)
    return {"correct": int(np.sum(known & (assign >= 0) & (got == true))),
            "wrong": int(np.sum(known & (assign >= 0) & (got != true))
                         + np.sum(~known & (assign >= 0))),
            "missed": int(np.sum(known & (assign == REJECTED))),
            "false_new": int(np.sum(known & (assign == NEW))),
            "new_ok": int(np.sum(~known & (assign == NEW))),
            "new_rejected": int(np.sum(~known & (assign == REJECTED)))}


def gate_experiment(dataset, mapped, P, R, probs, *, new_prob: float = NEW_LANDMARK_PROB,
                    S_scale: float = 1.0, seed: int = 0) -> list[dict]:
    """Association on a simulated run with a known pose error (notebook 04 "too small,
    too large").

    For every scan of ``dataset`` (simulated: ``info['scan_poses']`` and
    ``detections.landmark_id`` are the truth), the pose the filter believes is the true
    laser pose plus an error drawn from N(0, P) (P (3, 3), the same draw for every
    probability); the map holds the true positions of the beacons listed in ``mapped``.
    The filter predicts zhat = h(believed pose, landmark), S = S_scale * H P H^T + R
    (S_scale < 1: an over-confident filter), and associates with the gate
    chi2.ppf(prob, 2) and the new-landmark threshold max(chi2.ppf(new_prob, 2), gate).
    Returns, per probability, a dict with ``prob``, ``gate`` and the summed
    :func:`score_association` counts.
    """
    from ..models.observation import observe

    truth = dataset.info.get("scan_poses") if isinstance(dataset.info, dict) else None
    det = dataset.detections
    if truth is None or det is None or dataset.beacons is None:
        raise ValueError("gate_experiment needs a simulated dataset (true scan poses, "
                         "detections with landmark ids and the true beacons)")
    mapped = np.asarray(mapped, dtype=np.int64)
    if mapped.ndim != 1 or np.any(mapped < 0) or np.any(mapped >= len(dataset.beacons)):
        raise ValueError(f"mapped must list beacon indices 0..{len(dataset.beacons) - 1}")
    P = _checks.covariance("P", P, 3)
    R = _checks.covariance("R", R, 2)
    if not (np.isfinite(S_scale) and S_scale > 0):
        raise ValueError(f"S_scale must be a positive number, got {S_scale!r}")
    err = np.random.default_rng(seed).multivariate_normal(np.zeros(3), P, size=len(det))
    lms = dataset.beacons[mapped]
    rows = []
    for prob in probs:
        g = gate_threshold(prob)
        new = max(gate_threshold(new_prob), g)
        total = dict.fromkeys(("correct", "wrong", "missed", "false_new", "new_ok", "new_rejected"), 0)
        for k in np.flatnonzero(det.per_scan() > 0):
            z = det[k]
            zhat, Hp, _ = observe(truth[k] + err[k], lms)
            S = S_scale * (Hp @ P @ np.swapaxes(Hp, 1, 2)) + R
            a = associate(mahalanobis(z, zhat, S), gate=g, new_landmark=new)
            s = score_association(a, mapped, det.landmark_id[det.offsets[k]:det.offsets[k + 1]])
            for key in total:
                total[key] += s[key]
        rows.append({"prob": float(prob), "gate": g, **total})
    return rows


# ---------------------------------------------------------------- fast copies for the filter

def mahalanobis_fast(z, zhat, S) -> np.ndarray:
    """d2 (n, N) of observations z (n, 2) to predictions zhat (N, 2) with covariances S:
    Fast copy of :func:`mahalanobis` (same formula: explicit inverse of the symmetric 2x2 S,
    bearing difference wrapped) without its input checks, which cost more than the
    arithmetic when run every scan; tests/test_association.py checks the two agree. An S
    that is not positive definite still raises (the module's own error)."""
    a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
    det = a * c - b * b
    if det.min() <= 0.0 or a.min() <= 0.0:
        mahalanobis(z, zhat, S)                            # raises, naming the landmark
    nu_r = z[:, 0, None] - zhat[:, 0]
    nu_b = wrap_difference(z[:, 1, None] - zhat[:, 1])
    return (c * nu_r * nu_r - 2.0 * b * nu_r * nu_b + a * nu_b * nu_b) / det



def associate_fast(d2, gate: float, new_landmark: float) -> np.ndarray:
    """Fast copy of :func:`associate` (gated nearest neighbour with mutual exclusion), with a
    fast path for the common scan where no two observations compete: every observation
    has at most one landmark in its gate and every landmark at most one observation.
    Then the greedy assignment is simply those pairs, and the rest is new
    (d2 > new_landmark to every landmark) or rejected. Otherwise the general function."""
    i, j = np.nonzero(d2 <= gate)
    il, jl = i.tolist(), j.tolist()
    if len(set(il)) == len(il) and len(set(jl)) == len(jl):
        out = np.where(d2.min(axis=1) > new_landmark, NEW, REJECTED)
        out[i] = j
        return out.astype(np.int64)
    return np.asarray(associate(d2, gate=gate, new_landmark=new_landmark), dtype=np.int64)
