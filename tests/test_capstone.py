"""The capstone (chapter 09): the harness and the reference loop against the course's own
filter, and the grading of whole loops: the notebook's loop and the reference get full
marks on the hidden runs, the three typical broken loops (cross covariances not
propagated, a wrong sign in F, an unwrapped bearing) score below half, each with a message
that names its defect."""
import math

import numpy as np
import pytest

from annslam_lib.chapters import ch09_capstone as cap
from annslam_lib.grading import capstone as gc
from annslam_lib.grading.core import GradingError, allowing_library_calls
from annslam_lib.models.observation import observe
from annslam_lib.slam import config, runner
from annslam_lib.slam.dense import joseph_covariance, kalman_gain
from solutions import solution

HIDDEN = ("sim:4101:1", "sim:4102:1", "sim:4103:1", "sim:4104:1")    # the notebook's hidden runs
FULL = 8.0                      # the three simulated cells (gc.score)
GRADED = FULL + 2               # and the Car Park cell, in the grader (the analysis is read)


def test_the_reference_loop_is_the_course_filter_on_the_car_park(car_park):
    """Equal to a millimetre: the course's run also splits a prediction at every GPS fix
    it skips, which moves the discretisation by a few tenths of a millimetre."""
    mine = cap.reference_slam("car_park")
    cfg = config.SlamConfig.for_dataset("car_park", gps_mode="none", motion_model="midpoint")
    r = runner.run(car_park, cfg, progress=False, backend="dense")
    np.testing.assert_allclose(mine["t"], r.trajectory[:, 0])
    np.testing.assert_allclose(mine["pose"][:, :2], r.trajectory[:, 1:3], rtol=0, atol=1e-3)
    np.testing.assert_allclose(mine["landmarks"], r.landmarks, rtol=0, atol=1e-3)


def test_steps_hold_the_control_and_cover_the_run():
    it = cap.steps("sim:3001:1")
    start = next(it)
    steps = list(it)
    dts = [s.dt for s in steps if isinstance(s, cap.Predict)]
    scans = [s for s in steps if isinstance(s, cap.Scan)]
    ds = cap.dataset_of("sim:3001:1")
    assert len(scans) == len(ds.detections)
    end = max(ds.detections.t[-1], ds.odometry.t[-1])
    assert sum(dts) == pytest.approx(end - ds.odometry.t[0], abs=1e-9)
    assert start.P0.shape == (3, 3) and start.gate == pytest.approx(9.2103, abs=1e-4)


def _no_cross_predict(x, P, u, dt, Q, vehicle):
    x, P = np.array(x, float), np.array(P, float)
    pose, F, G = cap.midpoint_step(x[:3], u, dt, vehicle)
    x[:3] = pose
    P[:3, :3] = F @ P[:3, :3] @ F.T + G @ Q @ G.T
    return x, P


def _sign_predict(x, P, u, dt, Q, vehicle):
    x, P = np.array(x, float), np.array(P, float)
    pose, F, G = cap.midpoint_step(x[:3], u, dt, vehicle)
    F = F.copy()
    F[:2, 2] *= -1
    x[:3] = pose
    P[:3, :] = F @ P[:3, :]
    P[:, :3] = P[:, :3] @ F.T
    P[:3, :3] += G @ Q @ G.T
    return x, 0.5 * (P + P.T)


def _stacked(x, z, idx, R):
    """z (m, 2), the predicted zhat (m, 2), the stacked H (2m, n) and R (2m, 2m)."""
    z, idx = np.asarray(z, float).reshape(-1, 2), np.asarray(idx, int)
    zhat, Hp, Hm = observe(x[:3], np.reshape(x[3:], (-1, 2))[idx])
    H = np.zeros((2 * idx.size, len(x)))
    for i, j in enumerate(idx):
        H[2 * i:2 * i + 2, :3], H[2 * i:2 * i + 2, 3 + 2 * j:5 + 2 * j] = Hp[i], Hm[i]
    return z, zhat, H, np.kron(np.eye(idx.size), R)


def _no_wrap_update(x, P, z, idx, R):
    z, zhat, H, Rm = _stacked(x, z, idx, R)
    K, _ = kalman_gain(P, H, Rm)
    x = x + K @ (z - zhat).ravel()
    x[2] = (x[2] + math.pi) % (2 * math.pi) - math.pi
    return x, joseph_covariance(P, H, Rm, K)


REF = {"predict": cap.reference_predict, "update": cap.reference_update,
       "augment": cap.reference_augment}


def _loop(**pieces):
    def my_slam(run):
        return cap.reference_slam(run, **pieces)
    return my_slam


def test_the_notebook_loop_gets_full_marks_on_the_hidden_runs():
    nb = {k: solution("09", f"my_{k}") for k in ("predict", "update", "augment")}
    assert gc.score(solution("09", "my_slam"), nb, runs=HIDDEN) == (FULL, [])
    with allowing_library_calls():
        assert gc.score(_loop(), REF, runs=HIDDEN) == (FULL, [])


@pytest.mark.parametrize("broken, pieces, names", [
    ("no cross covariance", {"predict": _no_cross_predict},
     "does not propagate the cross covariances between the pose and the map"),
    ("wrong Jacobian sign", {"predict": _sign_predict},
     "heading column of my_predict's F has the wrong sign"),
    ("no angle wrap", {"update": _no_wrap_update},
     "does not wrap the bearing innovation"),
])
def test_a_broken_loop_scores_below_half_and_the_message_names_the_defect(broken, pieces, names):
    with allowing_library_calls():
        points, messages = gc.score(_loop(**pieces), {**REF, **pieces}, runs=HIDDEN)
    assert points < FULL / 2, (broken, points)
    assert messages and all(names in m for m in messages), messages


def test_a_malformed_track_is_refused_with_what_is_wrong():
    with pytest.raises(gc.GradingError if hasattr(gc, "GradingError") else AssertionError,
                       match="must return track.result"):
        gc.check_runs(lambda run: [1, 2, 3], quiet=True)
    nan = {"t": [0.0], "pose": [[0.0, 0.0, np.nan]], "pose_cov": np.eye(3)[None],
           "landmarks": np.zeros((0, 2)), "landmark_cov": np.zeros((0, 0))}
    with pytest.raises(AssertionError, match="NaN or infinite"):
        gc.check_runs(lambda run: nan, quiet=True)


def test_the_library_filter_is_refused_in_a_student_loop():
    def shortcut(run):
        return cap.reference_slam(run)
    shortcut.__name__ = "my_slam"
    with pytest.raises(AssertionError, match="calls annslam_lib.chapters.ch09_capstone.reference_slam"):
        gc.check_runs(shortcut, quiet=True)


def test_the_course_grader_gives_an_honest_capstone_full_marks(tmp_path):
    """Through the sandboxed grader: the student's loop runs in the kernel, the checks in
    the grader, the hidden runs included."""
    import grading_support as gs
    from annslam_lib.course.sandbox import Limits
    from solutions import ROOT

    notebook = ROOT / "notebooks" / "09_capstone.ipynb"
    g = gs.grade_chapter(notebook, gs.solution_bodies(notebook), tmp_path,
                         Limits(cell_timeout=240.0, call_timeout=120.0, deadline=600.0))
    assert (g.score, g.max_score) == (GRADED, GRADED), g.report()
    assert g.errors == [], g.report()


def _reports(k):
    """A correct loop that reports k times its covariance."""
    def my_slam(run):
        r = cap.reference_slam(run)
        return {**r, "pose_cov": r["pose_cov"] * k, "landmark_cov": r["landmark_cov"] * k}
    return my_slam


def _no_cross_augment(x, P, z, R):
    x2, P2 = cap.reference_augment(x, P, z, R)
    n = len(x)
    P2 = P2.copy()
    P2[n:, :n] = 0.0
    P2[:n, n:] = 0.0
    return x2, P2


def _simple_update(x, P, z, idx, R):
    """The update with (I - K H) P instead of the Joseph form: the same for the optimal gain."""
    z, zhat, H, Rm = _stacked(x, z, idx, R)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + Rm)
    nu = z - zhat
    nu[:, 1] = (nu[:, 1] + math.pi) % (2 * math.pi) - math.pi
    x = x + K @ nu.ravel()
    x[2] = (x[2] + math.pi) % (2 * math.pi) - math.pi
    P = (np.eye(len(x)) - K @ H) @ P
    return x, 0.5 * (P + P.T)


@pytest.mark.parametrize("k, says", [(2.0, "under-confident"), (0.5, "over-confident")])
def test_a_covariance_reported_twice_or_half_as_large_fails_consistency(k, says):
    with allowing_library_calls():
        points, messages = gc.score(_reports(k), REF, runs=HIDDEN)
    assert points == FULL - 5, (k, points, messages)               # runs and map still pass
    assert len(messages) == 1 and says in messages[0], messages
    ratio = f"{k ** -1:.2f}"
    assert ratio in messages[0], messages


def test_a_correct_variant_passes_and_a_missing_cross_covariance_in_augment_fails():
    with allowing_library_calls():
        simple = {**REF, "update": _simple_update}
        assert gc.score(_loop(update=_simple_update), simple, runs=HIDDEN) == (FULL, [])
        broken = {**REF, "augment": _no_cross_augment}
        points, messages = gc.score(_loop(augment=_no_cross_augment), broken, runs=HIDDEN)
    assert points == FULL - 5, (points, messages)
    assert "my_augment leaves the new landmark uncorrelated with the state" in messages[0]


def test_the_sandboxed_grader_names_a_broken_augmentation(tmp_path):
    """Through the grader: the probes reach the student's pieces in the kernel (the car is
    sent as data, not as an opaque object) and the message names the broken one."""
    import grading_support as gs
    from annslam_lib.course.sandbox import Limits
    from solutions import ROOT

    notebook = ROOT / "notebooks" / "09_capstone.ipynb"
    bodies = gs.solution_bodies(notebook)
    bodies["ex09-pieces"] = bodies["ex09-pieces"].replace(
        "def my_augment(x, P, z, R):",
        "def my_augment(x, P, z, R):\n    return _augment_without_cross(x, P, z, R)\n\n\n"
        "def _augment_without_cross(x, P, z, R):\n    n = len(x)\n"
        "    x2, P2 = _augment(x, P, z, R)\n    P2 = P2.copy()\n    P2[n:, :n] = 0.0\n"
        "    P2[:n, n:] = 0.0\n    return x2, P2\n\n\ndef _augment(x, P, z, R):", 1)
    g = gs.grade_chapter(notebook, bodies, tmp_path,
                         Limits(cell_timeout=240.0, call_timeout=120.0, deadline=600.0))
    r = {e.grade_id: e for e in g.exercises}
    assert g.score == GRADED - 7, g.report()        # consistency and the Car Park fail
    assert "my_augment leaves the new landmark uncorrelated" in r["ex09-consistency-tests"].message
    assert "Opaque" not in g.report()


def _update_with_the_course_gain(x, P, z, idx, R):
    z, zhat, H, Rm = _stacked(x, z, idx, R)
    K, _ = kalman_gain(P, H, Rm)
    nu = z - zhat
    nu[:, 1] = (nu[:, 1] + math.pi) % (2 * math.pi) - math.pi
    x = x + K @ nu.ravel()
    x[2] = (x[2] + math.pi) % (2 * math.pi) - math.pi
    return x, joseph_covariance(P, H, Rm, K)


def test_the_course_versions_of_the_students_own_pieces_are_refused():
    """The capstone is built from the student's pieces of 1a.3, 4.1, 4.3 and 5.2: a loop
    that calls the course's kalman_gain instead is refused, naming it."""
    predict, associate_ = solution("09", "my_predict"), solution("09", "my_data_association")
    augment = solution("09", "my_augment")

    def my_slam(run):
        track = cap.Track()
        it = cap.steps(run)
        start = next(it)
        x, P = start.x0.copy(), start.P0.copy()
        for step in it:
            if isinstance(step, cap.Predict):
                x, P = predict(x, P, step.control, step.dt, step.Q, start.vehicle)
                continue
            a = np.asarray(associate_(x, P, step.z, start.R, start.gate, start.new_landmark))
            old = np.flatnonzero(a >= 0)
            if old.size:
                x, P = _update_with_the_course_gain(x, P, step.z[old], a[old], start.R)
            for i in np.flatnonzero(a == -1):
                x, P = augment(x, P, step.z[i], start.R)
            track.record(step.t, x, P)
        return track.result()
    with pytest.raises(AssertionError, match="kalman_gain"):
        gc.check_runs(my_slam, quiet=True)


@pytest.mark.parametrize("k, says", [(2.0, "under-confident"), (0.5, "over-confident")])
def test_on_the_car_park_a_covariance_twice_or_half_as_large_fails(k, says):
    """The real-data cell: the map's joint NEES against the survey (with the survey's 2 cm)
    compared with a correct EKF's on the same run, both ways; GPS named as GPS."""
    with allowing_library_calls():
        ok = gc.check_car_park(cap.reference_slam, quiet=True)
        assert "all 15 beacons mapped" in ok and "1.00 of a correct EKF's" in ok and "GPS" in ok
        with pytest.raises(GradingError, match=says):
            gc.check_car_park(_reports(k), quiet=True)


def test_the_car_park_map_nees_is_chapter_05s_survey_nees():
    """car_park_scores against real_consistency.survey_nees of chapter 05 on the same map."""
    from types import SimpleNamespace

    from annslam_lib.data import loaders
    from annslam_lib.evaluation.map import match_landmarks
    from annslam_lib.evaluation.real_consistency import survey_nees

    r = cap.reference_slam("car_park")
    car = loaders.load_car_park()
    i, j = match_landmarks(r["landmarks"], car.beacons, 1.0)
    n = len(r["landmarks"])
    P = np.zeros((3 + 2 * n,) * 2)
    P[3:, 3:] = r["landmark_cov"]
    ref = survey_nees(SimpleNamespace(landmarks=r["landmarks"], covariance=P), car.beacons, i, j,
                      sigma_survey=cap.SIGMA_SURVEY)
    got = cap.car_park_scores(r)
    assert got["matched"] == 15
    assert math.isclose(got["map_nees_per_dof"], ref.per_dof, rel_tol=1e-9), (got, ref)


def test_the_track_records_each_scans_nis_and_the_lines_give_their_verdicts():
    r = cap.reference_slam("sim:3001:1")
    assert r["nis"].shape == r["t"].shape and np.all(r["nis_dof"] % 2 == 0)
    assert np.all(np.isnan(r["nis"][r["nis_dof"] == 0]))
    lines = cap.consistency_lines(r, "sim:3001:1").splitlines()
    assert lines[0].startswith("mean pose NEES per dof") and "band" in lines[0]
    used = r["nis_dof"] > 0
    assert f"{np.sum(r['nis'][used]) / r['nis_dof'].sum():.2f}" in lines[1]
    stripped = {**r, "nis": np.full_like(r["nis"], np.nan), "nis_dof": np.zeros_like(r["nis_dof"])}
    assert "no NIS recorded" in cap.consistency_lines(stripped, "sim:3001:1")
