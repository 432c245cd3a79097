"""GPS noise from the receiver's own scatter (annslam_lib.evaluation.calibration): exact on
white noise, blind to a slow drift (a lower bound, as its docstring says), and refusing
data it cannot use."""
import numpy as np
import pytest

from annslam_lib.data.records import Gps
from annslam_lib.evaluation.calibration import gps_sigma_from_scatter


def _track(n=300, dt=0.2):
    t = np.arange(n) * dt
    return t, np.column_stack([2.0 * t, 5.0 * np.sin(t / 8.0)])     # a car at 2 m/s, curving


def test_white_noise_is_recovered():
    t, xy = _track()
    rng = np.random.default_rng(0)
    for sigma in (0.1, 0.3, 1.0):
        noisy = xy + rng.normal(0, sigma, xy.shape)
        est = gps_sigma_from_scatter(Gps(t=t, east=noisy[:, 0], north=noisy[:, 1]), floor=0.0)
        assert est == pytest.approx(sigma, rel=0.1)


def test_a_slow_drift_is_invisible_lower_bound():
    t, xy = _track()
    rng = np.random.default_rng(1)
    drift = np.column_stack([np.cumsum(rng.normal(0, 0.02, t.size))] * 2)   # a wandering bias
    noisy = xy + drift + rng.normal(0, 0.1, xy.shape)
    est = gps_sigma_from_scatter(Gps(t=t, east=noisy[:, 0], north=noisy[:, 1]), floor=0.0)
    actual = np.sqrt(np.mean((noisy - xy) ** 2))
    assert est == pytest.approx(0.1, rel=0.15) and actual > 2 * est


def test_floor_steady_rate_and_bad_input():
    t, xy = _track()
    assert gps_sigma_from_scatter(Gps(t=t, east=xy[:, 0], north=xy[:, 1])) == 0.05   # the floor
    gappy = np.cumsum(np.random.default_rng(2).uniform(0.05, 1.0, t.size))   # no steady rate
    with pytest.raises(ValueError, match="steady rate"):
        gps_sigma_from_scatter(Gps(t=gappy, east=xy[:, 0], north=xy[:, 1]))
    with pytest.raises(ValueError, match="at least 3"):
        gps_sigma_from_scatter(Gps(t=t[:2], east=xy[:2, 0], north=xy[:2, 1]))
    with pytest.raises(TypeError):
        gps_sigma_from_scatter(xy)
