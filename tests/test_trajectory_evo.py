"""Trajectory metrics against evo (github.com/MichaelGrupp/evo, the standard SLAM evaluation
tool; environment-instructor.txt): the course's absolute and SE(2)-aligned RMSE against GPS
must equal evo's APE on the translation part, without and with Umeyama alignment, on the
same positions. Real runs (the Car Park and Victoria Park filters) and a synthetic track in
a rotated frame."""
import math

import numpy as np
import pytest

from annslam_lib.data.records import Gps
from annslam_lib.evaluation.trajectory import trajectory_errors
from annslam_lib.models.geometry import interpolate_poses
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig

evo_metrics = pytest.importorskip("evo.core.metrics", reason="evo is not installed: pip install "
                                  "-r environment-instructor.txt (./course.sh test does)")
from evo.core.trajectory import PoseTrajectory3D  # noqa: E402


def _evo_ape(est_xy, ref_xy, t, align: bool) -> float:
    z = np.zeros((t.size, 1))
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1))
    est = PoseTrajectory3D(np.hstack([est_xy, z]), quat, t)
    ref = PoseTrajectory3D(np.hstack([ref_xy, z]), quat, t)
    if align:
        est.align(ref, correct_scale=False)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    return float(ape.get_statistic(evo_metrics.StatisticsType.rmse))


def _check(traj, gps):
    e = trajectory_errors(traj, gps)
    inside = (gps.t >= traj[0, 0]) & (gps.t <= traj[-1, 0])
    est = interpolate_poses(traj, gps.t[inside])[:, :2]
    ref = gps.xy[inside]
    assert e.rmse == pytest.approx(_evo_ape(est, ref, gps.t[inside], False), rel=1e-9)
    assert e.rmse_aligned == pytest.approx(_evo_ape(est, ref, gps.t[inside], True), rel=1e-6)
    return e


def test_synthetic_track_in_a_rotated_frame():
    t = np.linspace(0.0, 60.0, 601)
    xy = np.column_stack([10 * np.cos(t / 10), 6 * np.sin(t / 5)])
    phi = np.arctan2(np.gradient(xy[:, 1]), np.gradient(xy[:, 0]))
    th = math.radians(12.0)
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    noisy = xy + np.random.default_rng(3).normal(0, 0.05, xy.shape)
    est = noisy @ R.T + [3.0, -2.0]
    traj = np.column_stack([t, est, phi + th])
    gps = Gps(t=t[::5].copy(), east=xy[::5, 0].copy(), north=xy[::5, 1].copy())
    e = _check(traj, gps)
    assert e.rmse > 2.0 and e.rmse_aligned < 0.08              # the frame, then the shape
    assert math.degrees(e.rotation) == pytest.approx(-12.0, abs=0.2)


def test_car_park_filter_against_evo(car_park):
    r = runner.run(car_park, SlamConfig.for_dataset("car_park"), progress=False)
    e = _check(r.odometry_trajectory, car_park.gps)
    assert e.rmse_aligned < e.rmse


def test_victoria_park_filter_against_evo(victoria_park):
    r = runner.run(victoria_park, SlamConfig.for_dataset("victoria_park"), progress=False)
    e = _check(r.odometry_trajectory, victoria_park.gps)
    assert e.rmse_aligned < e.rmse
