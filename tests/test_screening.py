"""Damaged sensor streams on the Car Park run: each fault injected, the
stated rule of annslam_lib.data.screening applied, counted in the result, and the run the
same as on the data repaired by hand (or, for a clock jump, kept and visible)."""
import dataclasses

import numpy as np
import pytest

from annslam_lib.data import screening
from annslam_lib.data.records import Gps, Odometry
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig

CFG = SlamConfig.for_dataset("car_park")


@pytest.fixture(scope="module")
def car(car_park):
    return car_park


@pytest.fixture(scope="module")
def clean_run(car):
    return runner.run(car, CFG, progress=False)


def _odo(car, keep=None, **arrays):
    o = car.odometry
    t, v, a = arrays.get("t", o.t), arrays.get("speed", o.speed), arrays.get("steering", o.steering)
    if keep is not None:
        t, v, a = t[keep], v[keep], a[keep]
    return dataclasses.replace(car, odometry=Odometry(t=t, speed=v, steering=a))


def test_clean_runs_are_untouched(car, clean_run):
    out, rep = screening.screen(car)
    assert out is car and rep.changed == 0 and rep.odometry_gaps == 0
    assert all(v == 0 for k, v in clean_run.counts.items() if k.startswith("screen_"))
    assert rep.summary() == "sensor streams: nothing to repair"


def test_an_impossible_speed_is_dropped_and_counted(car, clean_run):
    v = car.odometry.speed.copy()
    v[2000] = 1e4                                     # an encoder sample of 10 km/s
    hurt = runner.run(_odo(car, speed=v), CFG, progress=False)
    assert hurt.counts["screen_odometry_impossible"] == 1
    keep = np.ones(len(car.odometry), bool)
    keep[2000] = False
    by_hand = runner.run(_odo(car, keep=keep), CFG, progress=False)
    np.testing.assert_array_equal(hurt.trajectory, by_hand.trajectory)
    assert np.max(np.abs(hurt.trajectory[:, 1:3] - clean_run.trajectory[:, 1:3])) < 0.05
    a = car.odometry.steering.copy()
    a[100:103] = 3.0                                  # beyond any lock
    assert runner.run(_odo(car, steering=a), CFG, progress=False).counts["screen_odometry_impossible"] == 3


def test_repeated_odometry_times_keep_the_first_reading(car):
    o = car.odometry
    idx = np.sort(np.concatenate([np.arange(len(o)), [500, 1500, 1500]]))  # 3 extra rows
    v, a = o.speed[idx].copy(), o.steering[idx].copy()
    v[1502] += 5.0                                    # the second repeat of 1500 disagrees
    hurt = runner.run(_odo(car, t=o.t[idx], speed=v, steering=a), CFG, progress=False)
    assert hurt.counts["screen_odometry_duplicates"] == 2
    assert hurt.counts["screen_odometry_conflicts"] == 1
    clean = runner.run(car, CFG, progress=False)
    np.testing.assert_array_equal(hurt.trajectory, clean.trajectory)


def test_a_clock_jump_is_kept_counted_and_costs_certainty(car, clean_run):
    t = car.odometry.t.copy()
    t[2000:] += 2.0                                   # the odometry clock jumps 2 s
    hurt = runner.run(_odo(car, t=t), CFG, progress=False)
    assert hurt.counts["screen_odometry_gaps"] == 1
    _, rep = screening.screen(_odo(car, t=t))
    assert rep.longest_gap == pytest.approx(2.025) and "1 odometry gaps (kept; the longest 2.03 s)" in rep.summary()
    k = np.searchsorted(hurt.trajectory[:, 0], t[2000])          # the first scan after the jump
    trace = hurt.pose_cov[:, 0, 0] + hurt.pose_cov[:, 1, 1]
    ref = clean_run.pose_cov[:, 0, 0] + clean_run.pose_cov[:, 1, 1]
    assert trace[k] > 3 * np.median(ref)              # the filter knows it does not know


def test_duplicated_scans_and_fixes(car, clean_run):
    L = car.laser
    idx = np.sort(np.concatenate([np.arange(len(L)), [100, 300]]))
    ranges = L.ranges[idx].copy()
    ranges[302, 10] += 1.0                            # the repeat of 300 differs in one beam
    laser = dataclasses.replace(L, t=L.t[idx], ranges=ranges, intensity=L.intensity[idx])
    g = car.gps
    gi = np.sort(np.concatenate([np.arange(len(g)), [10]]))
    gps = Gps(t=g.t[gi], east=g.east[gi], north=g.north[gi])
    hurt = runner.run(dataclasses.replace(car, laser=laser, gps=gps), CFG, progress=False)
    c = hurt.counts
    assert (c["screen_laser_duplicates"], c["screen_laser_conflicts"], c["screen_gps_duplicates"]) == (1, 1, 1)
    np.testing.assert_array_equal(hurt.trajectory, clean_run.trajectory)


def test_nothing_possible_is_an_error(car):
    with pytest.raises(ValueError, match="no odometry sample is possible"):
        screening.screen(_odo(car, speed=np.full(len(car.odometry), 99.0)))
    with pytest.raises(ValueError, match="max_gap"):
        screening.screen(car, max_gap=0.0)
