"""Notebook 06's graded exercises (annslam_lib.grading.metrics): the references and the
notebook's solutions pass (also on the real Victoria Park GPS), the typical mistakes fail
with their specific messages, a stub is 'not written yet'. (The paper prints nothing about
Victoria Park, so there is no printed form to fail here.)"""
import numpy as np
import pytest


from annslam_lib.grading import NOT_WRITTEN, GradingError
from annslam_lib.grading.core import full_feedback
from annslam_lib.grading import metrics as gm
from annslam_lib.data.records import Gps
from annslam_lib.evaluation.trajectory import gps_outliers
from annslam_lib.evaluation import trajectory
from solutions import solution
from check_support import stub


# ---------------------------------------------------------------- the notebook's solutions
# (the same code as the solution cells of notebooks/06_victoria_park.ipynb)

my_track_rmse = solution("06", "my_track_rmse")
my_gps_outliers = solution("06", "my_gps_outliers")


def _reference_rmse(traj, gps_t, gps_xy):
    return trajectory.trajectory_errors(traj, Gps(t=gps_t, east=gps_xy[:, 0],
                                               north=gps_xy[:, 1])).rmse


# ---------------------------------------------------------------- (a) right answers pass

def test_track_rmse_reference_and_solution_pass(capsys):
    assert gm.check_track_rmse(_reference_rmse).startswith("✓")
    msg = gm.check_track_rmse(my_track_rmse, seed=7, n=6)
    assert "on 10 drives" in msg and capsys.readouterr().out.strip().endswith(msg)


def test_gps_outliers_reference_and_solution_pass():
    def ref(t, xy, max_speed=10.0, tolerance=3.0):
        return gps_outliers(Gps(t=t, east=xy[:, 0], north=xy[:, 1]), max_speed, tolerance)
    assert gm.check_gps_outliers(ref).startswith("✓")
    assert "on 8 GPS records" in gm.check_gps_outliers(my_gps_outliers, seed=7, n=4)
    gm.check_gps_outliers(my_gps_outliers, max_speed=5.0, tolerance=1.0)


def test_with_the_real_run(victoria_park):
    vp = victoria_park
    track = np.c_[vp.odometry.t, np.interp(vp.odometry.t, vp.gps.t, vp.gps.east) + 1.0,
                  np.interp(vp.odometry.t, vp.gps.t, vp.gps.north), np.zeros(len(vp.odometry))]
    assert "on 5 drives" in gm.check_track_rmse(my_track_rmse, n=0, real=(track, vp.gps))
    msg = gm.check_gps_outliers(my_gps_outliers, n=0, gps=vp.gps)
    assert "the chapter" not in msg and "on 5 GPS records" in msg
    with pytest.raises(TypeError, match="records.Gps"):
        gm.check_track_rmse(my_track_rmse, real=(track, vp.gps.xy))


def test_cases_hold_what_victoria_park_does():
    drives = gm._rmse_cases(0, 4)
    outside = [np.count_nonzero(~gm._inside(tr, t)) for tr, t, _ in drives.values()]
    assert min(outside) == 0 and max(outside) > 0
    assert all(np.max(np.diff(t)) > 2.0 for _, t, _ in drives.values())      # gaps
    for traj, t, _ in drives.values():
        assert np.allclose(np.diff(traj[:, 0]), 0.025)                       # 40 Hz
        assert np.min(np.abs((t[:, None] - traj[None, :, 0]))) > 1e-3         # off the grid
    records = gm._outlier_cases(0, 3)
    flags = {lab: gm._outliers_ref(*a) for lab, a in records.items()}
    spike, legit, jitter, two = list(flags.values())[:4]
    assert spike.sum() == 2 and legit.sum() == 0 and jitter.sum() == 0 and two.sum() == 2


# ---------------------------------------------------------------- (c) typical mistakes

def _rmse_variant(kind):
    def f(traj, gps_t, gps_xy):
        inside = (gps_t >= traj[0, 0]) & (gps_t <= traj[-1, 0])
        if kind == "clamped":
            inside[:] = True
        t, g = gps_t[inside], gps_xy[inside]
        if kind == "nearest":
            k = np.abs(t[:, None] - traj[None, :, 0]).argmin(axis=1)
            est = traj[k, 1:3]
        elif kind == "previous":
            est = traj[np.searchsorted(traj[:, 0], t, side="right") - 1, 1:3]
        else:
            est = np.c_[np.interp(t, traj[:, 0], traj[:, 1]), np.interp(t, traj[:, 0], traj[:, 2])]
        d = est - g
        e = np.sqrt(np.sum(d**2, axis=1))
        if kind == "gps-interp":
            s = (traj[:, 0] >= gps_t[0]) & (traj[:, 0] <= gps_t[-1])
            gi = np.c_[np.interp(traj[s, 0], gps_t, gps_xy[:, 0]),
                       np.interp(traj[s, 0], gps_t, gps_xy[:, 1])]
            e = np.linalg.norm(traj[s, 1:3] - gi, axis=1)
        return {"mean": np.mean(e), "mse": np.mean(e**2), "per-axis": np.sqrt(np.mean(d**2)),
                "median": np.median(e)}.get(kind, np.sqrt(np.mean(e**2)))
    return f


@pytest.mark.parametrize("kind, phrase", [
    ("mean", r"MEAN error, not the root-mean-square"),
    ("mse", r"mean SQUARED error"),
    ("per-axis", r"2N coordinates.*sqrt\(2\)"),
    ("median", r"median error, not the RMSE"),
    ("nearest", r"NEAREST sample instead of being interpolated"),
    ("previous", r"last sample BEFORE each fix"),
    ("clamped", r"fixes before the first or after the last track sample are included"),
    ("gps-interp", r"GPS is interpolated to the track's times.*gap"),
])
def test_track_rmse_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gm.check_track_rmse(_rmse_variant(kind))


def test_track_rmse_must_reject_no_overlap():
    def silent(traj, gps_t, gps_xy):
        inside = (gps_t >= traj[0, 0]) & (gps_t <= traj[-1, 0])
        return my_track_rmse(traj, gps_t, gps_xy) if inside.any() else 0.0
    with pytest.raises(GradingError, match=r"no GPS fix inside.*returned 0; it should raise "
                                           r"ValueError"):
        gm.check_track_rmse(silent)


def test_track_rmse_generic_failure_names_the_drive():
    def off(traj, gps_t, gps_xy):
        return my_track_rmse(traj, gps_t, gps_xy) + (0.5 if gps_t.size > 300 else 0.0)
    with pytest.raises(GradingError, match=r"disagrees with the reference at \d of 8 inputs\. "
                                           r"First: case=\"#4: 78 s drive"):
        gm.check_track_rmse(off)


def _outlier_variant(kind):
    def f(t, xy, max_speed=10.0, tolerance=3.0):
        step = np.hypot(*np.diff(xy, axis=0).T)
        allowed = max_speed * (0.2 if kind == "fixed-dt" else np.diff(t)) + \
            (0.0 if kind == "no-tolerance" else tolerance)
        fast = step > allowed
        flag = np.zeros(len(t), dtype=bool)
        if kind == "every-fast":
            flag[1:] = fast
            return flag
        if kind == "one-early":
            for i in range(len(t) - 1):
                flag[i] = fast[i] and not (i > 0 and flag[i - 1])
            return flag
        if kind == "next":                    # compared with the next fix only
            flag[:-1] = fast
            return flag
        if kind == "ints":
            return my_gps_outliers(t, xy, max_speed, tolerance).astype(int)
        if kind == "floats":
            return np.hypot(*xy.T)
        if kind == "short":
            return fast
        if kind == "in-place":
            xy[:] = 0.0
            return flag
        for i in range(1, len(t)):
            flag[i] = fast[i - 1] and not flag[i - 1]
        return flag
    return f


@pytest.mark.parametrize("kind, phrase", [
    ("every-fast", r"fix AFTER a one-fix spike is flagged too"),
    ("fixed-dt", r"fixed 0\.2 s between fixes"),
    ("no-tolerance", r"tolerance is missing"),
    ("one-early", r"one fix early"),
    ("next", r"(?s)disagrees with the reference on \d+ of 7 GPS records.*flagged but not "
             r"outliers: fixes \[29, 59\]; e\.g\. fix 29: .* m from fix 28, 0\.20 s earlier, "
             r"allowed 5\.00 m.*outliers not flagged"),
    ("floats", r"must return booleans"),
    ("short", r"expected one flag per fix"),
])
def test_gps_outlier_mistakes(kind, phrase):
    with pytest.raises(GradingError, match=phrase):
        gm.check_gps_outliers(_outlier_variant(kind))


def test_gps_outliers_accept_0_1_and_refuse_changed_inputs():
    gm.check_gps_outliers(_outlier_variant("ints"))

    def in_place(t, xy, max_speed=10.0, tolerance=3.0):
        flag = my_gps_outliers(t, xy, max_speed, tolerance)
        xy -= xy[0]
        return flag
    with pytest.raises(GradingError, match="changed its input arrays"):
        gm.check_gps_outliers(in_place)


# ---------------------------------------------------------------- (d) the stub

@pytest.mark.parametrize("check", [gm.check_track_rmse, gm.check_gps_outliers])
def test_stub_is_not_written_yet(check):
    with pytest.raises(GradingError, match=NOT_WRITTEN):
        check(stub)


def test_the_remedy_is_in_the_instructors_feedback_only():
    """A student's check names the kind of mistake; the instructor's feedback adds the fix."""
    fix = "traj[0, 0] <= t <= traj[-1, 0]"
    with pytest.raises(GradingError) as plain:
        gm.check_track_rmse(_rmse_variant("clamped"))
    assert fix not in str(plain.value)
    with full_feedback(), pytest.raises(GradingError) as full:
        gm.check_track_rmse(_rmse_variant("clamped"))
    assert fix in str(full.value)
