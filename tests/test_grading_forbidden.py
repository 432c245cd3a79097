"""Every check names the library functions its exercise asks the student to write: the
notebook's own solution passes with the rule on, and a "solution" that calls the library's
function instead fails with "my_f calls module.function: write it yourself"."""
import numpy as np
import pytest

from annslam_lib.ann import network
from annslam_lib.evaluation import map as map_eval
from annslam_lib.evaluation import trajectory
from annslam_lib.grading import GradingError
from annslam_lib.grading import ann as gann
from annslam_lib.grading import association as ga
from annslam_lib.grading import ekf as ge
from annslam_lib.grading import kalman as gkf
from annslam_lib.grading import kinematics as gkin
from annslam_lib.grading import localisation as gloc
from annslam_lib.grading import metrics as gm
from annslam_lib.grading import observation as gobs
from annslam_lib.grading import graph_slam as ggs
from annslam_lib.grading import smoothing as gsm
from annslam_lib.grading import verdict as gv
from annslam_lib.models import geometry, motion, observation
from annslam_lib.models.vehicle import Vehicle
from annslam_lib.perception import association
from annslam_lib.slam import dense, kalman, localisation
from annslam_lib.smoothing import factors, gauss_newton

from solutions import solution


def _car(L, a, b, H=0.76):
    return Vehicle(L=L, H=H, a=a, b=b)


# (check, notebook, function, a "solution" that calls the forbidden library function, its name)
CASES = [
    (gkin.check_axle_speed, "01", "my_axle_speed",
     lambda v, al, H, L: motion.axle_speed(v, al, _car(L, 3.78, 0.5, H))[0], "models.motion.axle_speed"),
    (gkin.check_euler_step, "01", "my_euler_step",
     lambda p, u, dt, L, a, b: motion.predict(p, u, dt, _car(L, a, b))[0], "models.motion.predict"),
    (gkf.check_update_1d, "01a", "my_update_1d",
     lambda m, v, z, r: kalman.update_1d(m, v, z, r)[:2], "slam.kalman.update_1d"),
    (gkf.check_steady_state, "01a", "my_steady_state",
     lambda q, r: kalman.steady_state_variance(q, r)[1], "slam.kalman.steady_state_variance"),
    (gkf.check_kalman_gain, "01a", "my_kalman_gain",
     lambda P, H, R: dense.kalman_gain(P, H, R)[0], "slam.kalman.kalman_gain"),
    (gkf.check_gate, "01a", "my_gate",
     lambda nu, S, p: kalman.innovation_gate(nu, S, p)[2], "slam.kalman.innovation_gate"),
    (gkin.check_axle_pose, "02", "my_axle_pose",
     lambda p, a, b: motion.axle_pose(p, _car(2.83, a, b))[0], "models.motion.axle_pose"),
    (gkin.check_laser_velocity, "02", "my_laser_velocity",
     lambda p, u, L, a, b: motion.laser_velocity(p, u, _car(L, a, b)), "models.motion.laser_velocity"),
    (gobs.check_observe, "03", "my_observe",
     lambda p, m: observation.observe(p, m)[0], "models.observation.observe"),
    (gobs.check_inverse_observe, "03", "my_inverse_observe",
     lambda p, z: observation.inverse_observe(p, z)[0], "models.observation.inverse_observe"),
    (gobs.check_two_point_frame, "03", "my_two_point_frame",
     lambda a, b: observation.landmark_from_two_points(a, b)[0],
     "models.observation.landmark_from_two_points"),
    (ga.check_associate, "04", "my_associate",
     lambda d2, g, n: association.associate(d2, g, n), "perception.association.associate"),
    (gloc.check_beacon_update, "04a", "my_beacon_update",
     lambda pose, P, z, b, R: localisation.beacon_update(pose, P, z, b, R)[:2],
     r"slam.localisation.beacon_update and annslam_lib\.slam\.dense\.innovation"),
    (gloc.check_nis_verdict, "04a", "my_nis_verdict",
     lambda nis, dof, p: localisation.nis_verdict(nis, dof, p)[0], "slam.localisation.nis_verdict"),
    (ge.check_joseph_covariance, "05", "my_joseph_covariance",
     lambda P, H, R, K: dense.joseph_covariance(P, H, R, K), "slam.kalman.joseph_covariance"),
    (gm.check_gps_outliers, "06", "my_gps_outliers",
     lambda t, xy, m=10.0, tol=3.0: trajectory.gps_outliers(
         trajectory.Gps(t=t, east=xy[:, 0], north=xy[:, 1]), m, tol),
     "evaluation.trajectory.gps_outliers"),
    (gann.check_forward, "07", "my_forward",
     lambda *a: network.forward(*a), "ann.network.forward"),
    (gann.check_train_loop, "07", "my_train_loop",
     lambda net, X, Y, opt, epochs: network.train_loop(net, X, Y, opt, epochs),
     "ann.network.train_loop"),
    (gv.check_rigid_align, "08", "my_rigid_align",
     lambda a, b: map_eval.rigid_align(a, b), "evaluation.map.rigid_align"),
    (gsm.check_between_error, "10", "my_between_error",
     lambda xi, xj, d: factors.between_error(xi, xj, d),
     r"smoothing.factors.between_error and annslam_lib\.smoothing\.factors\.se2_log"),
    (gsm.check_bearing_range_error, "10", "my_bearing_range_error",
     lambda p, m, z: factors.bearing_range_error(p, m, z), "smoothing.factors.bearing_range_error"),
    (gsm.check_tangent_to_world, "10", "my_tangent_to_world",
     lambda S, phi: factors.tangent_to_world(S, phi), "smoothing.factors.tangent_to_world"),
    (ggs.check_whitened_range_bearing, "11", "my_whitened_range_bearing",
     lambda p, m, z, sr, sb: ggs.whitened_range_bearing(p, m, z, sr, sb),
     "grading.graph_slam.whitened_range_bearing"),
    (ggs.check_gauss_newton_step, "11", "my_gauss_newton_step",
     lambda J, e: gauss_newton.step(J, e), "smoothing.gauss_newton.step"),
    (ggs.check_huber_weights, "11", "my_huber_weights",
     lambda r, k: gauss_newton.huber(r, k)[1], "smoothing.gauss_newton.huber"),
]


@pytest.mark.parametrize("check, chapter, name, shortcut, target", CASES,
                         ids=[c[2] for c in CASES])
def test_the_notebook_solution_passes_and_the_library_shortcut_does_not(check, chapter, name,
                                                                        shortcut, target):
    out = check(solution(chapter, name), quiet=True) if "quiet" in check.__code__.co_varnames \
        else check(solution(chapter, name))
    assert out.startswith("✓")
    shortcut.__name__ = name
    with pytest.raises(GradingError, match=rf"{name} calls annslam_lib\.{target}: write it yourself"):
        check(shortcut)


def test_every_check_of_the_course_declares_what_it_forbids():
    import annslam_lib.grading as grading
    import importlib
    import pkgutil

    checks = []
    for m in pkgutil.iter_modules(grading.__path__):
        mod = importlib.import_module(f"annslam_lib.grading.{m.name}")
        checks += [getattr(mod, n) for n in dir(mod) if n.startswith("check_") and m.name != "core"
                   and getattr(getattr(mod, n), "__module__", "") == mod.__name__]
    assert len(checks) >= 24
    missing = [c.__name__ for c in checks if not getattr(c, "__annslam_forbids__", ())]
    assert missing == [], f"checks without forbidden library functions: {missing}"


def test_the_rule_is_found_through_aliases_and_getattr():
    def sneaky(pose, landmark):
        mod = __import__("annslam_lib.models.observation", fromlist=["x"])
        return getattr(mod, "obs" + "erve")(pose, landmark)[0]
    sneaky.__name__ = "my_observe"
    with pytest.raises(GradingError, match="my_observe calls annslam_lib.models.observation.observe"):
        gobs.check_observe(sneaky)
    forward = network.forward
    with pytest.raises(GradingError, match="write it yourself"):
        from annslam_lib.grading import ann as gann
        gann.check_forward(lambda *a: forward(*a))
    assert np.isfinite(1.0)


def test_the_inverse_map_through_the_library_is_refused_too():
    """B S B^T is also world_to_tangent(S, -phi): that shortcut is forbidden as well."""
    from annslam_lib.smoothing.problem import world_to_tangent

    def my_tangent_to_world(S, phi):
        return world_to_tangent(S, -phi)
    with pytest.raises(GradingError, match="world_to_tangent: write it yourself"):
        gsm.check_tangent_to_world(my_tangent_to_world, quiet=True)


@pytest.mark.parametrize("shortcut, target", [
    (lambda p, a, b: motion.laser_pose(p, _car(2.83, -a, -b))[0], "models.motion.laser_pose"),
    (lambda p, a, b: np.r_[geometry.from_frame(p, [-a, -b])[0], p[2]], "models.geometry.from_frame"),
], ids=["laser_pose", "from_frame"])
def test_the_axle_pose_through_the_forward_transform_is_refused_too(shortcut, target):
    """P_l - R(phi)(a, b) is the forward transform with the lever arm negated: the library's
    forward transform (motion.laser_pose, or the frame change it is) is refused as well."""
    shortcut.__name__ = "my_axle_pose"
    with pytest.raises(GradingError, match=rf"my_axle_pose calls annslam_lib\.{target}: write it yourself"):
        gkin.check_axle_pose(shortcut, quiet=True)
