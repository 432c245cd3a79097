"""Checks of the capstone (chapter 09): a student's whole EKF-SLAM loop, scored on what it
does on simulated runs it has not seen, with feedback that names the piece at fault.

Three checks, one per graded cell: :func:`check_runs` (the loop runs to the end and returns
a well-formed track), :func:`check_consistency` (its covariance is a correct EKF's: the
probes find no defect in its pieces, and its pose NEES and final map NEES are within a
factor :data:`NEES_RATIO` of the reference loop's on the same runs, both ways) and
:func:`check_map` (every true landmark mapped once, within 0.15 m RMS, at most one
spurious landmark per run). The probes (:func:`diagnose`) try the student's pieces on
crafted states and name the first defect they find: a cross covariance not propagated,
not updated or not created, a wrong sign in F, an unwrapped bearing innovation.
"""
from __future__ import annotations

import math

import numpy as np

from ..chapters import ch09_capstone as cap
from ..models.vehicle import ACFR_UTE
from ..slam import dense
from ._tracks import ratio_message, reference_scores, result_of
from ._tracks import try_run as tracks_try_run
from .core import NOT_WRITTEN, fail, forbids, passed

__all__ = ["RUNS", "check_runs", "check_consistency", "check_map", "check_car_park", "diagnose",
           "score", "try_run"]

#: The runs the notebook's visible checks use (the hidden ones use others).
RUNS = ("sim:3001:1",)
#: A consistent filter's NEES against a correct EKF's on the same runs: within this factor,
#: both ways. Over the four hidden runs a covariance reported twice or half as large is 2
#: away, an update in the (I - K H) P form 1.00, an Euler prediction 1.14 (the probes,
#: not this ratio, then ask for the chapter's midpoint step).
NEES_RATIO = 1.3
MAP_RMSE_LIMIT = 0.15
#: On the Car Park, the path's distance to GPS may be at most this factor of a correct EKF's.
GPS_RATIO = 1.3



def _result(fn, run: str, name: str, pieces=None) -> dict:
    """``fn(run)``, checked for its form, with the probes' diagnosis added to a failure
    (cached for a local function: the three checks of one notebook run the loop once per
    run)."""
    from .core import GradingError
    try:
        return result_of(fn, run, name)
    except GradingError as e:
        raise GradingError(f"{e}{_cause(pieces)}") from None


def _pieces(pieces) -> dict:
    return dict(pieces or {})


def try_run(my_slam, run: str):
    """``my_slam(run)`` for a notebook's demonstration cell: None, with a line that says so,
    while the loop is not written yet (so that Run All goes on)."""
    return tracks_try_run(my_slam, run, "my_slam")


# ------------------------------------------------------------------------- the probes

def _probe_state(seed: int = 0):
    """A pose with two landmarks and a correlated P (pose-map cross terms non-zero)."""
    rng = np.random.default_rng(seed)
    x = np.array([2.0, -1.0, 0.6, 9.0, 4.0, -3.0, 8.0])
    A = rng.normal(size=(7, 7)) * np.array([0.2, 0.2, 0.05, 0.3, 0.3, 0.3, 0.3])
    return x, A @ A.T + 1e-3 * np.eye(7)


def diagnose(pieces) -> str | None:
    """The first defect the probes find in ``pieces`` {'predict', 'update', 'augment'}
    (any may be missing), as a sentence; None if they agree with the reference."""
    p = _pieces(pieces)
    x, P = _probe_state()
    R = np.diag([0.1**2, math.radians(1.0) ** 2])
    if "predict" in p:
        u, dt, Q = np.array([3.0, 0.2]), 0.1, np.diag([0.04, 0.01])
        try:
            xr, Pr = cap.reference_predict(x, P, u, dt, Q, ACFR_UTE)
            xs, Ps = (np.asarray(a, float) for a in p["predict"](x.copy(), P.copy(), u, dt, Q, ACFR_UTE))
        except NotImplementedError:
            return f"my_predict {NOT_WRITTEN}"
        except Exception as e:             # noqa: BLE001 (the student's code)
            return f"my_predict raised {type(e).__name__}: {e}"
        if Ps.shape == Pr.shape and not np.allclose(Ps, Pr, atol=1e-9):
            if np.allclose(Ps[:3, 3:], P[:3, 3:]) and not np.allclose(Pr[:3, 3:], P[:3, 3:]):
                return ("my_predict does not propagate the cross covariances between the pose and "
                        "the map: after a prediction P_vm must become F P_vm (and P_mv its "
                        "transpose); left unchanged, the map keeps correlations with a pose the car "
                        "has left")
            _, F, _ = cap.midpoint_step(x[:3], u, dt, ACFR_UTE)
            Fw = F.copy()
            Fw[:2, 2] *= -1
            Pw = P.copy()
            Pw[:3, :] = Fw @ Pw[:3, :]
            Pw[:, :3] = Pw[:, :3] @ Fw.T
            if np.allclose(Ps[:3, :3] - Pw[:3, :3], Pr[:3, :3] - (F @ P[:3, :3] @ F.T), atol=1e-9):
                return ("the heading column of my_predict's F has the wrong sign: d x_k / d phi and "
                        "d y_k / d phi (entries [0, 2] and [1, 2]) must rotate the position with the "
                        "heading (chapter 01, exercise 1.3)")
            return "my_predict's covariance differs from F P F^T + G Q G^T on a state with landmarks"
    if "update" in p:
        # a landmark straight behind-left, its bearing predicted just below +pi, seen just above -pi
        pose = np.array([0.0, 0.0, 0.0])
        a = math.pi / 2 - 0.002
        xl = np.r_[pose, 10 * math.cos(a), 10 * math.sin(a), 5.0, 5.0]
        Pl = P.copy()
        z = np.array([[10.05, -math.pi + 0.004]])
        try:
            xr, Pr = cap.reference_update(xl, Pl, z, [0], R)
            xs, Ps = (np.asarray(v, float) for v in p["update"](xl.copy(), Pl.copy(), z, np.array([0]), R))
        except NotImplementedError:
            return f"my_update {NOT_WRITTEN}"
        except Exception as e:             # noqa: BLE001 (the student's code)
            return f"my_update raised {type(e).__name__}: {e}"
        if xs.shape == xr.shape and np.max(np.abs(xs[:2] - xr[:2])) > 0.05:
            return ("my_update does not wrap the bearing innovation: a landmark predicted just "
                    "below +pi and seen just above -pi is a few mrad off, not almost 2 pi; wrap "
                    "z_bearing - zhat_bearing into (-pi, pi]")
        if Ps.shape == Pr.shape and not np.allclose(Ps, Pr, atol=1e-9):
            if np.allclose(Ps[:3, 5:], Pl[:3, 5:]) or np.allclose(Ps[3:5, 5:], Pl[3:5, 5:]):
                return ("my_update does not update the cross covariances: every block of P changes "
                        "in an update, P+ = (I - K H) P (I - K H)^T + K R K^T over the WHOLE state, "
                        "including the landmarks not seen")
            return "my_update's covariance differs from the Joseph form over the whole state"
    if "augment" in p:
        zn = np.array([6.0, 1.2])
        try:
            xr, Pr = cap.reference_augment(x, P, zn, R)
            xs, Ps = (np.asarray(v, float) for v in p["augment"](x.copy(), P.copy(), zn, R))
        except NotImplementedError:
            return f"my_augment {NOT_WRITTEN}"
        except Exception as e:             # noqa: BLE001 (the student's code)
            return f"my_augment raised {type(e).__name__}: {e}"
        if Ps.shape == Pr.shape and not np.allclose(Ps, Pr, atol=1e-9):
            if np.allclose(Ps[7:, :7], 0.0):
                return ("my_augment leaves the new landmark uncorrelated with the state: its rows "
                        "must be G_v P_{v,:} (chapter 05, exercise 5.1)")
            return "my_augment's covariance differs from chapter 05's block formula"
    return None


def _cause(pieces) -> str:
    d = diagnose(pieces)
    return f" Probing your pieces: {d}." if d else ""


# ------------------------------------------------------------------------- the checks

def _library_filters():
    from ..perception import association
    from ..slam import efficient, runner
    return (cap.reference_slam, cap.reference_predict, cap.reference_update,
            cap.reference_augment, cap.reference_associate, dense.range_bearing_update,
            dense.joseph_update, dense.augment_landmark, dense.DenseEkfSlam.predict,
            dense.DenseEkfSlam.update, efficient.EkfSlam.update, runner.run,
            dense.kalman_gain, dense.joseph_covariance, association.mahalanobis,
            association.associate, association.mahalanobis_fast, association.associate_fast)


#: The capstone is the student's own filter from their own pieces: the course's filters,
#: their steps and the course's versions of what earlier chapters had them write (the gain
#: of 1a.3, the d^2 and association of 4.1 and 4.3, the Joseph form of 5.2) are off limits;
#: the geometry, the models and the midpoint step stay allowed.
_FORBIDS = forbids(*_library_filters())


@_FORBIDS
def check_runs(my_slam, pieces=None, *, runs=RUNS, name: str = "my_slam",
               quiet: bool = False) -> str:
    """The loop runs on each of ``runs`` and returns a well-formed track (one finite pose
    and symmetric positive semi-definite pose covariance per scan, a map with its joint
    covariance)."""
    for run in runs:
        _result(my_slam, run, name, pieces)
    return passed(f"✓ {name} ran on {len(runs)} simulated run(s) and returned a well-formed "
                  f"track.", quiet)


def _reference_scores(runs) -> list[dict]:
    """The scores of a correct EKF (the reference loop) on ``runs``, once per process."""
    return reference_scores("reference", runs, cap.reference_slam, cap.score_run)


@_FORBIDS
def check_consistency(my_slam, pieces=None, *, runs=RUNS, name: str = "my_slam",
                      quiet: bool = False) -> str:
    """The filter's covariance is the one a correct EKF keeps: the probes find no defect in
    ``pieces`` {'predict', 'update', 'augment'} (a cross covariance not propagated, not
    updated or not created, a wrong sign in F, an unwrapped bearing), and on the same runs
    its pose NEES (averaged over the runs' scans) and its final map's NEES per dof are
    within a factor :data:`NEES_RATIO` of the reference loop's, both ways: a filter that
    reports twice its covariance, or half of it, fails. Judged against the reference on
    the same runs because an EKF-SLAM's own NEES varies from run to run by more than a
    factor of two (1.1 to 9.0 on 200 one-lap runs), while two correct implementations on
    one run agree to a few per cent."""
    scores = [cap.score_run(_result(my_slam, run, name, pieces), run) for run in runs]
    defect = diagnose(pieces)
    if defect and NOT_WRITTEN in defect:
        fail(f"{defect}: write it in the cell of the pieces, run that cell, then this one.")
    if defect:
        fail(f"{name}'s pieces keep the covariance wrong, whatever NEES a run shows: {defect}.")
    refs = _reference_scores(runs)
    nees = float(np.mean([s["nees_mean"] for s in scores]))
    ref_nees = float(np.mean([s["nees_mean"] for s in refs]))
    maps = float(np.mean([s["map_nees_per_dof"] for s in scores]))
    ref_map = float(np.mean([s["map_nees_per_dof"] for s in refs]))
    n = f"{len(runs)} run(s)"
    pose_ratio, map_ratio = nees / ref_nees, maps / ref_map
    if not 1 / NEES_RATIO <= pose_ratio <= NEES_RATIO:        # NaN fails too
        worst = max(scores, key=lambda s: s["nees_mean"])
        fail(f"{ratio_message(f'{name} pose NEES on {n}', pose_ratio, nees, ref_nees)}; "
             f"accepted {1 / NEES_RATIO:.2f} to {NEES_RATIO:.2f} times. Largest NEES "
             f"{float(np.max(worst['nees'])):.3g} at scan {worst['worst_scan']} "
             f"(t = {worst['worst_t']:.1f} s).{_cause(pieces)}")
    if not 1 / NEES_RATIO <= map_ratio <= NEES_RATIO:
        fail(f"{ratio_message(f'{name} final map NEES per dof on {n}', map_ratio, maps, ref_map)}"
             f"; accepted {1 / NEES_RATIO:.2f} to {NEES_RATIO:.2f} times.{_cause(pieces)}")
    return passed(f"✓ {name}'s covariance is a correct EKF's on {n}: pose NEES {nees:.2f} "
                  f"({pose_ratio:.2f} of the reference's), map NEES per dof {maps:.2f} "
                  f"({map_ratio:.2f}).", quiet)


@_FORBIDS
def check_map(my_slam, pieces=None, *, runs=RUNS, name: str = "my_slam",
              quiet: bool = False) -> str:
    """Every true landmark mapped (within 1 m) and none twice, at most one spurious landmark
    per run, the matched landmarks within 0.15 m RMS of the truth."""
    for run in runs:
        s = cap.score_run(_result(my_slam, run, name, pieces), run)
        msg = None
        if s["duplicates"]:
            msg = (f"{s['duplicates']} landmark(s) mapped twice (two map entries within 1 m of one "
                   f"true landmark): a detection that should have been associated started a new "
                   f"landmark")
        elif s["matched"] < s["true"]:
            msg = f"only {s['matched']} of the {s['true']} true landmarks are on the map"
        elif s["spurious"] > 1:
            msg = f"{s['spurious']} landmarks are more than 1 m from every true one"
        elif not s["map_rmse"] <= MAP_RMSE_LIMIT:
            msg = (f"the mapped landmarks are {s['map_rmse']:.3f} m RMS from the truth (accepted "
                   f"up to {MAP_RMSE_LIMIT:g} m)")
        if msg:
            fail(f"{name} on {run!r}: {msg}.{_cause(pieces)}")
    return passed(f"✓ {name} mapped every landmark once on {len(runs)} run(s).", quiet)


@_FORBIDS
def check_car_park(my_slam, pieces=None, *, name: str = "my_slam", quiet: bool = False) -> str:
    """The real run: on the Car Park every surveyed beacon is mapped (within 1 m), the map's
    joint NEES per dof against the survey (chapter 05's, with the survey's own
    uncertainty) is within a factor :data:`NEES_RATIO` of a correct EKF's on the same run,
    both ways, and the path's RMS distance to GPS after alignment is at most
    :data:`GPS_RATIO` times a correct EKF's."""
    s = cap.car_park_scores(_result(my_slam, "car_park", name, pieces))
    ref = reference_scores("reference", ("car_park",), cap.reference_slam,
                           lambda r, run: cap.car_park_scores(r))[0]
    where = f"{name} on the Car Park"
    if s["matched"] < s["beacons"]:
        fail(f"{where}: {s['matched']} of the {s['beacons']} surveyed beacons have a landmark "
             f"within 1 m ({s['landmarks']} landmarks mapped).{_cause(pieces)}")
    ratio = s["map_nees_per_dof"] / ref["map_nees_per_dof"]
    if not 1 / NEES_RATIO <= ratio <= NEES_RATIO:
        fail(f"{ratio_message(f'{where}: the map NEES per dof against the survey', ratio, s['map_nees_per_dof'], ref['map_nees_per_dof']).replace('same runs', 'same run')}"
             f"; accepted {1 / NEES_RATIO:.2f} to {NEES_RATIO:.2f} times.{_cause(pieces)}")
    gps = s["gps_rmse_aligned"] / ref["gps_rmse_aligned"]
    if not gps <= GPS_RATIO:
        fail(f"{where}: the path is {s['gps_rmse_aligned']:.3f} m RMS from GPS after alignment, "
             f"{gps:.2f} times a correct EKF's {ref['gps_rmse_aligned']:.3f} m (accepted up to "
             f"{GPS_RATIO:.2f} times).{_cause(pieces)}")
    return passed(f"✓ {where}: all {s['beacons']} beacons mapped; map NEES per dof against the "
                  f"survey {s['map_nees_per_dof']:.2f} ({ratio:.2f} of a correct EKF's); path "
                  f"{s['gps_rmse_aligned']:.3f} m RMS from GPS ({gps:.2f} of a correct EKF's).",
                  quiet)


def score(my_slam, pieces=None, *, runs=RUNS, points=(1, 5, 2)) -> tuple[float, list[str]]:
    """The points the three graded cells would give (runs, consistency, map) and the
    messages of the failed ones: for the course's tests of broken loops."""
    total, messages = 0.0, []
    from .core import GradingError
    for check, pts in zip((check_runs, check_consistency, check_map), points):
        try:
            check(my_slam, pieces, runs=runs, quiet=True)
            total += pts
        except GradingError as e:
            messages.append(str(e))
    return total, messages
