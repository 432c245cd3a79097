"""What the graded loops of chapters 04a and 09 share: a loop's result checked for its form
(and kept, so that a notebook's graded cells run a loop once per run), the sentence that
compares a NEES with a correct filter's, and the demonstration cells' call."""
from __future__ import annotations

import numpy as np

from .core import call, fail, forbidden

__all__ = ["CACHE", "KEYS", "forget_results", "result_of", "reference_scores", "ratio_message",
           "try_run"]

KEYS = ("t", "pose", "pose_cov", "landmarks", "landmark_cov")
#: Results by (id of the loop, run, forbidden paths), and the reference scores by
#: ("reference", run).
CACHE: dict = {}


def forget_results() -> None:
    """Drop the kept results of students' functions (a grader calls it after each
    submission); the reference filter's scores stay."""
    for key in [k for k, (fn, _) in CACHE.items() if fn is not None]:
        del CACHE[key]


def result_of(fn, run: str, name: str) -> dict:
    """``fn(run)``, checked for its form: one finite pose and symmetric positive
    semi-definite pose covariance per recorded scan, times that do not go backwards, a map
    with its joint covariance (empty for a localisation filter)."""
    key = (id(fn), run, forbidden())     # a result holds for the rule it was computed under
    if key in CACHE and CACHE[key][0] is fn:
        return CACHE[key][1]
    out = call(fn, (run,), name=name, arg_names=("run",))
    if not isinstance(out, dict) or any(k not in out for k in KEYS):
        fail(f"{name}({run!r}) returned {type(out).__name__}; it must return track.result(), a "
             f"dict with the keys {', '.join(KEYS)}.")
    r = {k: np.asarray(out[k], dtype=float) for k in KEYS}
    K = r["t"].size
    problems = []
    if K == 0:
        problems.append("no scan was recorded (call track.record(t, x, P) after every scan)")
    if r["pose"].shape != (K, 3) or r["pose_cov"].shape != (K, 3, 3):
        problems.append(f"pose {r['pose'].shape} and pose_cov {r['pose_cov'].shape} must be "
                        f"({K}, 3) and ({K}, 3, 3), one per recorded scan")
    N = r["landmarks"].size // 2
    if r["landmark_cov"].shape != (2 * N, 2 * N):
        problems.append(f"landmark_cov is {r['landmark_cov'].shape}, expected ({2 * N}, {2 * N}) "
                        f"for {N} landmarks")
    if not problems:
        bad = [k for k in KEYS if not np.all(np.isfinite(r[k]))]
        if bad:
            problems.append(f"{', '.join(bad)} hold NaN or infinite values")
        elif K and np.any(np.diff(r["t"]) < 0):
            problems.append("the scan times go backwards")
        else:
            C = r["pose_cov"]
            asym = float(np.max(np.abs(C - np.swapaxes(C, 1, 2)))) if K else 0.0
            low = float(np.min(np.linalg.eigvalsh(0.5 * (C + np.swapaxes(C, 1, 2))))) if K else 0.0
            if asym > 1e-9 or low < -1e-12:
                k = int(np.argmin(np.linalg.eigvalsh(0.5 * (C + np.swapaxes(C, 1, 2)))[:, 0]))
                problems.append(f"the pose covariance is not a covariance (asymmetry {asym:.2g}, "
                                f"smallest eigenvalue {low:.2g}, first at scan {k})")
    if problems:
        fail(f"{name}({run!r}): " + "; ".join(problems) + ".")
    CACHE[key] = (fn, r)
    return r


def ratio_message(what: str, ratio: float, mine: float, ref: float) -> str:
    if ratio > 1:
        return (f"{what} is {mine:.3g}, {ratio:.2f} times what a correct EKF reports on the same "
                f"runs ({ref:.3g}): its covariance is too small for its errors (over-confident)")
    return (f"{what} is {mine:.3g}, {ratio:.2f} of what a correct EKF reports on the same runs "
            f"({ref:.3g}): its covariance is too large for its errors (under-confident)")


def reference_scores(label: str, runs, loop, score) -> list[dict]:
    """``score(loop(run), run)`` of a correct filter on each of ``runs``, once per process
    (kept under ``(label, run)``)."""
    out = []
    for run in runs:
        if (label, run) not in CACHE:
            CACHE[(label, run)] = (None, score(loop(run), run))
        out.append(CACHE[(label, run)][1])
    return out


def try_run(loop, run: str, name: str):
    """``loop(run)`` for a notebook's demonstration cell: None, with a line that says so,
    while the loop is not written yet (so that Run All goes on)."""
    try:
        return loop(run)
    except NotImplementedError:
        print(f"{name} is not written yet: write it above, run its cell, then this one")
        return None
