"""Systematic errors modelled instead of absorbed (notebook 05): a laser
calibration read off a survey and applied to every detection, and a steering noise that
grows in turns. Checked on the simulator, where the injected errors are known, and
against a hand-made equivalent."""
import math

import numpy as np
import pytest

from annslam_lib.data import simulate
from annslam_lib.evaluation import calibration
from annslam_lib.models import motion
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.perception import sources
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig


def test_steering_noise_grows_with_the_steering_angle():
    ds = simulate.simulate(seed=1, raw_laser=False)
    odo = ds.odometry
    plain = np.array(motion.control_table(odo, ACFR_UTE, 0.1, 0.03))
    grown = np.array(motion.control_table(odo, ACFR_UTE, 0.1, 0.03, steer_gain=0.5))
    sa = 0.03 + 0.5 * np.abs(odo.steering)
    np.testing.assert_allclose(grown[:, 7], sa**2, rtol=1e-12)          # q11
    np.testing.assert_allclose(plain[:, 7], 0.03**2, rtol=1e-12)
    np.testing.assert_array_equal(grown[:, :5], plain[:, :5])            # the control itself
    v_c, J = motion.axle_speed(odo.speed, odo.steering, ACFR_UTE)
    np.testing.assert_allclose(grown[:, 5], J[:, 0] ** 2 * 0.01 + J[:, 1] ** 2 * sa**2, rtol=1e-12)
    assert np.array_equal(np.array(motion.control_table(odo, ACFR_UTE, 0.1, 0.03, 0.0)), plain)


@pytest.mark.parametrize("field,value", [("steer_noise_gain", -0.1), ("range_bias", math.nan),
                                         ("bearing_offset", math.radians(20)), ("range_bias", 2.0),
                                         ("bearing_offset", "1")])
def test_bad_systematic_error_settings_are_refused(field, value):
    with pytest.raises((ValueError, TypeError)):
        SlamConfig(**{field: value})


def test_the_calibration_is_subtracted_from_every_detection():
    ds = simulate.simulate(seed=2, raw_laser=False)
    det = ds.detections
    by_hand = sources.with_detections(
        ds, type(det)(t=det.t, offsets=det.offsets, range=det.range - 0.03, bearing=det.bearing - 0.01,
                      diameter=det.diameter, landmark_id=det.landmark_id), kind=ds.landmark_kind)
    cfg = SlamConfig.for_dataset("simulated", feature_source="detections")
    a = runner.run(ds, cfg.replace(range_bias=0.03, bearing_offset=0.01), progress=False)
    b = runner.run(by_hand, cfg, progress=False)
    np.testing.assert_array_equal(a.trajectory, b.trajectory)
    np.testing.assert_array_equal(a.landmarks, b.landmarks)
    c = runner.run(ds, cfg, progress=False)
    assert np.max(np.abs(c.trajectory[:, 1:3] - a.trajectory[:, 1:3])) > 1e-3


@pytest.mark.parametrize("seed", [3, 4])
def test_laser_calibration_recovers_errors_injected_in_the_simulator(seed):
    """The simulator's raw laser with a known range bias and a turned mounting, seen from
    a GPS of 1 cm (the Car Park receiver's scatter): the calibration moves by the injected
    range bias within 3 standard errors, and by most of the injected bearing offset (the
    GPS heading's noise and the 1 m matching trim the residuals' tails: 75-90 % of it)."""
    base = calibration.laser_calibration(simulate.simulate(seed=seed, sigma_gps=0.01))
    for rb, bo in ((0.05, math.radians(1.0)), (-0.03, math.radians(-0.7))):
        c = calibration.laser_calibration(simulate.simulate(seed=seed, sigma_gps=0.01, range_bias=rb,
                                                            bearing_offset=bo))
        assert c.n > 1000
        assert abs((c.range_bias - base.range_bias) - rb) < 3 * math.hypot(c.range_se, base.range_se)
        assert 0.7 < (c.bearing_offset - base.bearing_offset) / bo < 1.0


def test_laser_calibration_needs_a_laser_and_a_survey():
    ds = simulate.simulate(seed=1, raw_laser=False)
    with pytest.raises(ValueError, match="raw laser"):
        calibration.laser_calibration(ds)
    with pytest.raises(TypeError):
        calibration.laser_calibration("car_park")
