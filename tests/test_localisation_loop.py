"""Exercise 4a.2: a student's whole EKF-localisation filter. The harness with the map given,
the reference loop against the course's own localisation on the Car Park, and the grading
of whole loops: the notebook's loop and the reference get full marks on the hidden runs; each
planted defect (the process noise left out or added in the pose's frame, a wrong sign in F,
Euler for the midpoint step, a gate without the pose's uncertainty or without mutual
exclusion or adding landmarks, an unwrapped bearing, a covariance reported twice or half as
large) loses points with a message that names it; a correct variant (a batch update of
the gated sightings) passes; and the sandboxed grader does the same."""

import numpy as np
import pytest

from annslam_lib.chapters import ch04a_localisation as loc
from annslam_lib.grading import localisation_loop as gloop
from annslam_lib.grading.core import allowing_library_calls
from annslam_lib.models.geometry import wrap_angle
from annslam_lib.models.motion import predict as euler_step
from annslam_lib.models.observation import observe
from annslam_lib.perception.association import mahalanobis
from annslam_lib.slam import config, localisation
from annslam_lib.slam.dense import joseph_covariance, kalman_gain
from solutions import solution

HIDDEN = ("sim:4201:1", "sim:4202:1", "sim:4203:1", "sim:4204:1")    # the notebook's hidden runs
FULL = 5.0
REF = {"predict": loc.reference_loc_predict, "gate": loc.reference_gate,
       "update": loc.reference_update}


def test_the_reference_loop_is_the_course_localisation_on_the_car_park(car_park):
    """Within 2 cm: the course's run updates with all of a scan's sightings at once and
    splits a prediction at every GPS fix it skips; the loop updates one sighting at a time."""
    mine = loc.reference_localise("car_park")
    cfg = config.SlamConfig.for_dataset("car_park", gps_mode="none", motion_model="midpoint")
    r = localisation.localise(car_park, cfg)
    np.testing.assert_allclose(mine["t"], r.trajectory[:, 0])
    err = np.hypot(*(mine["pose"][:, :2] - r.trajectory[:, 1:3]).T)
    assert err.max() < 0.02, err.max()
    assert mine["landmarks"].shape == (0, 2) and mine["landmark_cov"].shape == (0, 0)


def test_the_steps_give_the_map_only_when_asked():
    start = next(loc.steps("sim:3001:1"))
    ds = loc.dataset_of("sim:3001:1")
    np.testing.assert_array_equal(start.beacons, ds.beacons)
    from annslam_lib.chapters import ch09_capstone as cap
    assert next(cap.steps("sim:3001:1")).beacons is None


def _loop(**pieces):
    def my_localise(run):
        return loc.reference_localise(run, **pieces)
    return my_localise


def test_the_notebook_loop_gets_full_marks_on_the_hidden_runs():
    nb = {"predict": solution("04a", "my_loc_predict"), "gate": solution("04a", "my_gate"),
          "update": solution("04a", "my_beacon_update")}
    assert gloop.score(solution("04a", "my_localise"), nb, runs=HIDDEN) == (FULL, [])
    with allowing_library_calls():
        assert gloop.score(_loop(), REF, runs=HIDDEN) == (FULL, [])


def _no_q(pose, P, u, dt, Q, vehicle):
    new, F, _ = loc.midpoint_step(pose, u, dt, vehicle)
    return new, F @ P @ F.T


def _q_on_xy(pose, P, u, dt, Q, vehicle):
    new, F, _ = loc.midpoint_step(pose, u, dt, vehicle)
    P = F @ P @ F.T
    P[:2, :2] += Q
    return new, P


def _sign(pose, P, u, dt, Q, vehicle):
    new, F, G = loc.midpoint_step(pose, u, dt, vehicle)
    F = F.copy()
    F[:2, 2] *= -1
    return new, F @ P @ F.T + G @ Q @ G.T


def _euler(pose, P, u, dt, Q, vehicle):
    new, F, G = euler_step(np.asarray(pose, float), np.asarray(u, float), dt, vehicle)
    return new, F @ P @ F.T + G @ Q @ G.T


def _gate_r_only(pose, P, z, beacons, R, gate):
    return loc.reference_gate(pose, np.zeros((3, 3)), z, beacons, R, gate)


def _gate_no_exclusion(pose, P, z, beacons, R, gate):
    z = np.asarray(z, float).reshape(-1, 2)
    if not len(z):
        return np.zeros(0, int)
    zhat, Hp, _ = observe(pose, beacons)
    d2 = mahalanobis(z, zhat, np.einsum("nij,jk,nlk->nil", Hp, P, Hp) + R)
    a = d2.argmin(axis=1)
    a[d2.min(axis=1) > gate] = -2
    return a


def _gate_new(pose, P, z, beacons, R, gate):
    a = loc.reference_gate(pose, P, z, beacons, R, gate)
    a[a == -2] = -1
    return a


def _no_wrap(pose, P, z, beacon, R):
    zhat, H, _ = observe(np.asarray(pose, float), np.asarray(beacon, float))
    K, _ = kalman_gain(P, H, R)
    new = pose + K @ (np.asarray(z, float) - zhat)
    new[2] = wrap_angle(new[2])
    return new, joseph_covariance(P, H, R, K)


@pytest.mark.parametrize("broken, pieces, names, at_most", [
    ("no process noise", {"predict": _no_q}, "leaves out the process noise", 1),
    ("Q in the pose's frame", {"predict": _q_on_xy}, "adds Q to the position block", 2),
    ("wrong Jacobian sign", {"predict": _sign}, "F has the wrong sign", 2),
    ("Euler step", {"predict": _euler}, "chapter 01's Euler step", 2),
    ("S without P", {"gate": _gate_r_only}, "S must be H P H^T + R", 2),
    ("no mutual exclusion", {"gate": _gate_no_exclusion}, "mutual exclusion", 2),
    ("new landmarks", {"gate": _gate_new}, "returned -1 (a new landmark)", 2),
    ("no angle wrap", {"update": _no_wrap}, "does not wrap the bearing innovation", 1),
])
def test_a_broken_loop_loses_points_and_the_message_names_the_defect(broken, pieces, names,
                                                                     at_most):
    with allowing_library_calls():
        points, messages = gloop.score(_loop(**pieces), {**REF, **pieces}, runs=HIDDEN)
    assert points <= at_most, (broken, points, messages)
    assert messages and all(names in m for m in messages), messages


def _reports(k):
    """A correct loop that reports k times its covariance."""
    def my_localise(run):
        r = loc.reference_localise(run)
        return {**r, "pose_cov": r["pose_cov"] * k}
    return my_localise


@pytest.mark.parametrize("k, says", [(2.0, "under-confident"), (0.5, "over-confident"),
                                     (1.5, "under-confident"), (1 / 1.5, "over-confident")])
def test_a_covariance_reported_too_large_or_too_small_fails_consistency(k, says):
    with allowing_library_calls():
        points, messages = gloop.score(_reports(k), REF, runs=HIDDEN)
    assert points == FULL - 3, (k, points, messages)               # runs and path still pass
    assert len(messages) == 1 and says in messages[0], messages
    assert f"{1 / k:.2f} " in messages[0] or f"{1 / k:.2f} of" in messages[0], messages


def _batch_loop(run):
    """Every gated sighting of a scan in one stacked update: a correct variant."""
    track = loc.Track()
    it = loc.steps(run)
    start = next(it)
    pose, P = start.x0.copy(), start.P0.copy()
    for step in it:
        if isinstance(step, loc.Predict):
            pose, P = loc.reference_loc_predict(pose, P, step.control, step.dt, step.Q,
                                                start.vehicle)
            continue
        a = loc.reference_gate(pose, P, step.z, start.beacons, start.R, start.gate)
        ok = np.flatnonzero(a >= 0)
        if ok.size:
            zhat, Hp, _ = observe(pose, start.beacons[a[ok]])
            H, nu = Hp.reshape(-1, 3), step.z[ok] - zhat
            nu[:, 1] = wrap_angle(nu[:, 1])
            Rm = np.kron(np.eye(ok.size), start.R)
            K, _ = kalman_gain(P, H, Rm)
            pose = pose + K @ nu.ravel()
            pose[2] = wrap_angle(pose[2])
            P = joseph_covariance(P, H, Rm, K)
        track.record(step.t, pose, P)
    return track.result()


def test_a_batch_update_passes_and_the_library_filter_is_refused():
    with allowing_library_calls():
        assert gloop.score(_batch_loop, REF, runs=HIDDEN) == (FULL, [])

    def shortcut(run):
        return loc.reference_localise(run)
    shortcut.__name__ = "my_localise"
    with pytest.raises(AssertionError, match="reference_localise"):
        gloop.check_runs(shortcut, quiet=True)
    # chapter 04's association is the student's own to bring (exercises 4.1 and 4.3)
    with pytest.raises(AssertionError, match="associate"):
        gloop.check_runs(_batch_loop, quiet=True)


def test_a_loop_not_written_yet_is_named_and_the_demonstration_goes_on(capsys):
    def my_localise(run):
        raise NotImplementedError()
    assert gloop.try_run(my_localise, "sim:3001:1") is None
    assert "my_localise is not written yet" in capsys.readouterr().out

    def my_gate(pose, P, z, beacons, R, gate):
        raise NotImplementedError()
    with allowing_library_calls():
        points, messages = gloop.score(_loop(), {**REF, "gate": my_gate}, runs=HIDDEN[:1])
    assert points == 2 and "my_gate is not written yet" in messages[0], messages


def test_the_sandboxed_grader_names_a_gate_without_the_pose_uncertainty(tmp_path):
    import grading_support as gs
    from annslam_lib.course.sandbox import Limits
    from solutions import ROOT

    notebook = ROOT / "notebooks" / "04a_ekf_localisation.ipynb"
    bodies = gs.solution_bodies(notebook)
    assert bodies["ex04a-filter"].count("S = H @ P @ H.T + R") == 1
    bodies["ex04a-filter"] = bodies["ex04a-filter"].replace("S = H @ P @ H.T + R", "S = R")
    g = gs.grade_chapter(notebook, bodies, tmp_path,
                         Limits(cell_timeout=240.0, call_timeout=120.0, deadline=600.0))
    r = {e.grade_id: e for e in g.exercises}
    assert r["ex04a-filter-runs-tests"].points == 1
    assert r["ex04a-filter-consistency-tests"].points == 0
    assert "S must be H P H^T + R" in r["ex04a-filter-consistency-tests"].message
    assert g.score == 3 + 1 + 1 + 2, g.report()
