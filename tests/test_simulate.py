"""Tests of annslam_lib.simulate: determinism, geometry of the truth, sensor rates,
noise statistics, and consistency with the kinematics and observation models."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from annslam_lib.models.motion import axle_pose, axle_speed, laser_velocity, predict, predict_exact
from annslam_lib.models.observation import observe
from annslam_lib.data.records import LASER_ANGLES
from annslam_lib.data.simulate import GPS_DT, LASER_DT, MAX_STEER, NO_RETURN, ODOMETRY_DT, ROUTES, SimConfig, make_route, simulate

NOISELESS = dict(sigma_speed=0.0, sigma_steer=0.0, sigma_range=0.0, sigma_bearing=0.0,
                 sigma_gps=0.0)


def _arrays(ds):
    """Every array of a dataset, by name."""
    out = {"odo." + k: getattr(ds.odometry, k) for k in ("t", "speed", "steering")}
    out.update({"gps." + k: getattr(ds.gps, k) for k in ("t", "east", "north")})
    out.update({"laser." + k: getattr(ds.laser, k) for k in ("t", "ranges", "intensity")})
    out.update({"det." + k: getattr(ds.detections, k)
                for k in ("t", "offsets", "range", "bearing", "diameter", "landmark_id")})
    out.update({"beacons": ds.beacons, "truth.poses": ds.truth.poses,
                "truth.landmarks": ds.truth.landmarks})
    out.update({"info." + k: v for k, v in ds.info.items() if isinstance(v, np.ndarray)})
    return out


def _same(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def _true_z(ds):
    """True (range, bearing) of every detection, and the scan index of each."""
    d = ds.detections
    k = np.repeat(np.arange(len(d)), d.per_scan())
    z, _, _ = observe(ds.info["scan_poses"][k], ds.beacons[d.landmark_id])
    return z, k


@pytest.fixture(scope="module")
def default():
    return simulate()


@pytest.fixture(scope="module")
def noiseless():
    return simulate(**NOISELESS)


@pytest.fixture(scope="module")
def long_biased():
    """Four laps with systematic errors: enough samples for 10 % checks of the noise std."""
    return simulate(seed=11, laps=4, sigma_gps=0.2, range_bias=0.3, range_scale=1.02,
                    bearing_offset=0.02, speed_scale=0.97, steering_offset=0.01,
                    raw_laser=False)


# --------------------------------------------------------------------------- determinism

def test_same_seed_is_bitwise_identical_and_other_seed_differs(default):
    again, other = _arrays(simulate(seed=0)), _arrays(simulate(seed=1))
    for name, value in _arrays(default).items():
        assert _same(value, again[name]), name
    for name in ("odo.speed", "odo.steering", "gps.east", "laser.ranges", "beacons"):
        assert not np.array_equal(_arrays(default)[name], other[name]), name


def test_a_noise_level_changes_only_its_own_sensor(default):
    ref = _arrays(default)
    gps = _arrays(simulate(sigma_gps=0.3))
    for name in ref:
        if name in ("gps.east", "gps.north"):
            assert not _same(ref[name], gps[name]), name
        else:
            assert _same(ref[name], gps[name]), name
    no_raw = simulate(raw_laser=False, sigma_speed=0.2)
    assert no_raw.laser is None
    for name in ("det.range", "det.bearing", "det.landmark_id", "gps.east", "odo.steering"):
        assert _same(ref[name], _arrays_no_laser(no_raw)[name]), name
    assert not _same(ref["odo.speed"], no_raw.odometry.speed)


def _arrays_no_laser(ds):
    return {"det.range": ds.detections.range, "det.bearing": ds.detections.bearing,
            "det.landmark_id": ds.detections.landmark_id, "gps.east": ds.gps.east,
            "odo.steering": ds.odometry.steering}


def test_beacon_layout_has_its_own_seed_and_can_be_given(default):
    a = simulate(seed=3, beacon_seed=42, raw_laser=False)
    b = simulate(seed=4, beacon_seed=42, raw_laser=False)
    c = simulate(seed=3, beacon_seed=43, raw_laser=False)
    assert np.array_equal(a.beacons, b.beacons)
    assert not np.array_equal(a.beacons, c.beacons)
    assert not np.array_equal(a.odometry.speed, b.odometry.speed)
    given = np.array([[0.0, 0.0], [5.0, 20.0]])
    d = simulate(beacons=given, raw_laser=False)
    assert np.array_equal(d.beacons, given) and np.array_equal(d.truth.landmarks, given)
    assert set(np.unique(d.detections.landmark_id)) <= {0, 1}


@pytest.mark.parametrize("route", ROUTES)
def test_beacons_are_placed_beside_the_route(route):
    cfg = SimConfig(route=route, n_beacons=20, seed=5)
    ds = simulate(cfg, raw_laser=False)
    b = ds.beacons
    assert b.shape == (20, 2)
    path = make_route(route).path(0.02)
    laser = ds.truth.poses[:, 1:]
    d_axle = np.min(np.linalg.norm(b[:, None] - path[None, :, :2], axis=-1), axis=1)
    d_laser = np.min(np.linalg.norm(b[:, None] - laser[None, :, :2], axis=-1), axis=1)
    assert np.all(d_axle >= cfg.beacon_min_dist - 0.01)
    assert np.all(d_axle <= cfg.beacon_max_dist + 0.01)
    assert np.all(d_laser >= cfg.beacon_min_dist - 0.05)      # truth sampled every ~5 cm
    sep = np.linalg.norm(b[:, None] - b[None], axis=-1) + np.eye(20) * 1e9
    assert sep.min() >= cfg.beacon_min_sep


# --------------------------------------------------------------------------- truth

@pytest.mark.parametrize("route", ROUTES)
def test_truth_drives_whole_closed_laps_within_steering_limits(route):
    ds = simulate(route=route, laps=2, raw_laser=False)
    veh, rt = ds.vehicle, make_route(route)
    poses, controls = ds.truth.poses, ds.info["controls"]
    # Whole laps: back at the start, same heading, having driven exactly 2 laps.
    assert np.hypot(*(poses[-1, 1:3] - poses[0, 1:3])) < 0.01
    assert abs(math.remainder(poses[-1, 3] - poses[0, 3], 2 * math.pi)) < 1e-3
    assert np.sum(controls[:, 0]) * ODOMETRY_DT == pytest.approx(2 * rt.length, rel=1e-9)
    # Steering within the car's limits and smooth (rate well below 1 rad/s).
    assert np.max(np.abs(controls[:, 1])) <= MAX_STEER
    assert np.max(np.abs(np.diff(controls[:, 1]))) / ODOMETRY_DT < 1.0
    assert controls[0, 0] < 0.1 and controls[-1, 0] == 0.0
    # The rear axle stays on the designed path (feedforward with midpoint rule).
    axle, _ = axle_pose(poses[:, 1:], veh)
    path = rt.path(0.002)[:, :2]
    off = [np.min(np.hypot(*(path - p).T)) for p in axle[::50, :2]]
    assert max(off) < 0.005
    # Truth heading is the steering-driven heading: laps of 2 pi (or 0 for the figure-8).
    turning = np.sum(controls[:, 0] * np.tan(controls[:, 1]) / veh.L) * ODOMETRY_DT
    assert abs(turning) == pytest.approx(0 if route == "figure8" else 4 * math.pi, abs=1e-3)


@pytest.mark.parametrize("route", ROUTES)
def test_every_truth_step_is_the_exact_arc_of_its_control(route):
    ds = simulate(route=route, raw_laser=False, laps=3)
    poses, u = ds.truth.poses[:, 1:], ds.info["controls"]
    nxt = predict_exact(poses[:-1], u[:-1], ODOMETRY_DT, ds.vehicle)
    assert np.max(np.abs(nxt[:, :2] - poses[1:, :2])) < 1e-9
    assert np.max(np.abs(np.remainder(nxt[:, 2] - poses[1:, 2] + np.pi, 2 * np.pi) - np.pi)) < 1e-12


def test_sensor_rates_and_counts(default):
    odo, gps, laser, det = default.odometry, default.gps, default.laser, default.detections
    t_end = odo.t[-1]
    assert np.allclose(np.diff(odo.t), ODOMETRY_DT, rtol=0, atol=1e-9)
    assert np.allclose(np.diff(laser.t), LASER_DT, rtol=0, atol=1e-9)
    assert np.allclose(np.diff(gps.t), GPS_DT, rtol=0, atol=1e-9)
    assert len(odo) == round(t_end / ODOMETRY_DT) + 1
    assert abs(len(laser) - t_end / LASER_DT) <= 1 and abs(len(gps) - t_end / GPS_DT) <= 1
    assert laser.t[0] >= 0 and laser.t[-1] <= t_end and gps.t[-1] <= t_end
    assert np.array_equal(det.t, laser.t)
    assert np.array_equal(default.truth.poses[:, 0], odo.t)
    assert 100 < t_end < 140                      # like the 125 s Car Park run
    shifted = simulate(t0=45.0, raw_laser=False)
    assert np.allclose(shifted.odometry.t, odo.t + 45.0) and shifted.t0 == pytest.approx(45.0)


def test_gps_dropouts_remove_fixes():
    ds = simulate(gps_dropouts=((20.0, 30.0),), raw_laser=False)
    assert not np.any((ds.gps.t >= 20.0) & (ds.gps.t < 30.0))
    gaps = ds.gps.gaps(2.0)
    assert gaps.shape == (1, 2) and gaps[0, 1] - gaps[0, 0] == pytest.approx(10.0, abs=0.21)


# --------------------------------------------------------------------------- noise

def _ratio_ok(est, true, tol=0.10):
    return abs(est / true - 1) < tol


def test_gps_noise_statistics(long_biased):
    ds = long_biased
    res = ds.gps.xy - ds.info["gps_truth"]
    assert res.size > 2000
    assert _ratio_ok(res.std(), 0.2)
    assert np.all(np.abs(res.mean(0)) < 5 * 0.2 / math.sqrt(res.shape[0]))


def test_laser_noise_and_systematic_error(long_biased):
    ds, cfg = long_biased, long_biased.info["config"]
    det = ds.detections
    z, _ = _true_z(ds)
    n = det.count
    assert n > 3000
    r_res = det.range - (cfg.range_scale * z[:, 0] + cfg.range_bias)
    b_res = det.bearing - z[:, 1] - cfg.bearing_offset
    assert abs(r_res.mean()) < 5 * cfg.sigma_range / math.sqrt(n)
    assert _ratio_ok(r_res.std(), cfg.sigma_range)
    assert abs(b_res.mean()) < 5 * cfg.sigma_bearing / math.sqrt(n)
    assert _ratio_ok(b_res.std(), cfg.sigma_bearing)
    # Regression of the measured on the true range recovers scale and bias.
    slope, icpt = np.polyfit(z[:, 0], det.range, 1)
    assert _ratio_ok(slope, 1.02, 0.01) and abs(icpt - 0.3) < 0.05
    # Field of view and range limits.
    assert np.all((det.bearing >= 0) & (det.bearing <= np.pi))
    assert np.all((z[:, 0] >= cfg.min_range) & (z[:, 0] <= cfg.max_range))


def test_odometry_noise_and_systematic_error(long_biased):
    ds, cfg = long_biased, long_biased.info["config"]
    v_c, alpha = ds.info["controls"].T
    v_e = v_c / axle_speed(1.0, alpha, ds.vehicle)[0]      # encoder speed of the true motion
    s_res = ds.odometry.speed - cfg.speed_scale * v_e
    a_res = ds.odometry.steering - alpha - cfg.steering_offset
    n = s_res.size
    assert n > 9000
    assert abs(s_res.mean()) < 5 * cfg.sigma_speed / math.sqrt(n)
    assert _ratio_ok(s_res.std(), cfg.sigma_speed)
    assert abs(a_res.mean()) < 5 * cfg.sigma_steer / math.sqrt(n)
    assert _ratio_ok(a_res.std(), cfg.sigma_steer)
    slope = np.polyfit(v_e, ds.odometry.speed, 1)[0]
    assert _ratio_ok(slope, cfg.speed_scale, 0.01)


# --------------------------------------------------------------------------- model consistency

def test_noiseless_detections_equal_observe_of_truth(noiseless):
    ds, cfg = noiseless, noiseless.info["config"]
    det, poses = ds.detections, ds.info["scan_poses"]
    for k in range(len(det)):
        s = slice(det.offsets[k], det.offsets[k + 1])
        z, _, _ = observe(poses[k], ds.beacons)
        seen = ((z[:, 0] >= cfg.min_range) & (z[:, 0] <= cfg.max_range)
                & (z[:, 1] >= 0) & (z[:, 1] <= np.pi))
        assert np.array_equal(det.landmark_id[s], np.flatnonzero(seen))
        assert np.array_equal(det[k], z[seen])
    assert np.array_equal(ds.gps.xy, ds.info["gps_truth"])
    # The scan poses lie on the truth between the bracketing odometry samples.
    t, p = ds.truth.poses[:, 0], ds.truth.poses[:, 1:3]
    interp = np.column_stack([np.interp(ds.laser.t, t, p[:, i]) for i in range(2)])
    assert np.max(np.hypot(*(interp - poses[:, :2]).T)) < 1e-3


def test_noiseless_odometry_dead_reckons_the_truth_with_euler():
    """Euler keeps the heading exact, so its position error is the sum of the
    one-step chord errors, each at most u |w| dt^2 / 2 (u, w: laser speed and yaw rate)."""
    ds = simulate(laps=1, raw_laser=False, **NOISELESS)
    veh, dt = ds.vehicle, ODOMETRY_DT
    v_c, _ = axle_speed(ds.odometry.speed, ds.odometry.steering, veh)
    assert np.allclose(v_c, ds.info["controls"][:, 0], rtol=0, atol=1e-12)
    u = np.column_stack([v_c, ds.odometry.steering])
    truth = ds.truth.poses[:, 1:]
    pose, err = truth[0].copy(), np.zeros(len(truth))
    for k in range(1, len(truth)):
        pose = predict(pose, u[k - 1], dt, veh)[0]
        err[k] = np.hypot(*(pose[:2] - truth[k, :2]))
    assert abs(math.remainder(pose[2] - truth[-1, 2], 2 * math.pi)) < 1e-9
    rate = laser_velocity(truth[:-1], u[:-1], veh)
    bound = 0.5 * dt * np.sum(np.hypot(rate[:, 0], rate[:, 1]) * np.abs(rate[:, 2]) * dt)
    assert 0.05 < bound < 0.5          # the principled bound is itself small
    assert err.max() <= bound


def test_raw_laser_sees_the_poles(noiseless, default):
    step = LASER_ANGLES[1] - LASER_ANGLES[0]
    for ds in (noiseless, default):
        cfg, laser = ds.info["config"], ds.laser
        rho, tol = cfg.pole_radius, cfg.sigma_range
        z, k = _true_z(ds)
        # Isolated poles only (another pole within 0.25 rad may occlude it or add
        # beams), within 20 m (beyond, the 0.2 m pole may fall between two beams).
        zk = [observe(ds.info["scan_poses"][j], ds.beacons)[0] for j in range(len(laser))]
        checked, counts_ok, misses = 0, 0, 0
        for (r, b), j in zip(z, k):
            near = np.sum(np.abs(zk[j][:, 1] - b) < 0.25)
            edge = math.asin(rho / r) + 2 * step                # whole pole inside 0..pi
            if near > 1 or r > 20.0 or not (edge < b < np.pi - edge):
                continue
            i = int(np.argmin(np.abs(LASER_ANGLES - b)))
            checked += 1
            if tol == 0:
                assert r - rho - 1e-9 <= laser.ranges[j, i] <= r + 1e-9
            else:
                assert abs(laser.ranges[j, i] - r) <= rho + 5 * tol
                misses += abs(laser.ranges[j, i] - r) > rho + 3 * tol
            assert laser.intensity[j, i] == 3
            # The pole spans 2 asin(rho / r) of bearing: that many beams, +-1, return.
            w = np.abs(LASER_ANGLES - b) < math.asin(rho / r) + 2 * step
            n_hit = int(np.sum(laser.intensity[j, w] > 0))
            counts_ok += abs(n_hit - 2 * math.asin(rho / r) / step) <= 1
        assert checked > 400 and counts_ok == checked
        assert misses <= 0.01 * checked
    # Beams without a pole report no return; only beacon hits carry intensity.
    assert np.all((laser.intensity > 0) == (laser.ranges < laser.max_range))
    assert np.all(laser.ranges[laser.intensity == 0] == NO_RETURN)


def test_raw_laser_applies_systematic_range_error():
    base = simulate(raw_laser=True, **NOISELESS)
    biased = simulate(raw_laser=True, range_bias=0.3, range_scale=1.02, **NOISELESS)
    hit = base.laser.intensity > 0
    assert np.array_equal(hit, biased.laser.intensity > 0)
    assert np.allclose(biased.laser.ranges[hit], 1.02 * base.laser.ranges[hit] + 0.3,
                       rtol=0, atol=1e-9)


# --------------------------------------------------------------------------- api

@pytest.mark.parametrize("bad, name", [
    (dict(sigma_gps=-0.1), "sigma_gps"),
    (dict(sigma_range=float("nan")), "sigma_range"),
    (dict(speed=float("inf")), "speed"),
    (dict(route="oval"), "route"),
    (dict(laps=0), "laps"),
    (dict(seed=-1), "seed"),
    (dict(seed=1.5), "seed"),
    (dict(range_scale=0.0), "range_scale"),
    (dict(max_range=0.5), "max_range"),
    (dict(gps_dropouts=((5.0, 1.0),)), "gps_dropouts"),
    (dict(sigma_fancy=1.0), "sigma_fancy"),
    (dict(route="hairpin", route_scale=0.5), "route_scale"),
    (dict(n_beacons=60, beacon_min_sep=10.0), "n_beacons"),
])
def test_bad_config_raises_value_error_naming_it(bad, name):
    kind = TypeError if bad == dict(seed=1.5) else ValueError      # a float seed: wrong type
    with pytest.raises(kind, match=name):
        simulate(raw_laser=False, **bad)


def test_bad_beacons_and_config_type():
    with pytest.raises(ValueError, match="beacons"):
        simulate(beacons=np.zeros((3, 3)))
    with pytest.raises(TypeError, match="config"):
        simulate({"seed": 1})


def test_dataset_shape():
    ds = simulate()
    assert ds.name == "simulated" and ds.landmark_kind == "beacons"
    assert ds.truth.poses.shape == (len(ds.odometry), 4)
    assert np.array_equal(ds.truth.landmarks, ds.beacons) and ds.beacons.shape == (15, 2)
    assert ds.laser.ranges.shape == (len(ds.laser), 361)


def test_clutter_adds_spurious_detections_and_leaves_the_rest_alone(default):
    """clutter_rate: Poisson spurious detections after each scan's true ones, uniform over
    the range window and the field of view, landmark_id -1; every other stream unchanged."""
    from scipy.stats import kstest
    cfg = default.info["config"]
    c = simulate(dataclasses.replace(cfg, clutter_rate=2.0))
    da, dc = default.detections, c.detections
    real = dc.landmark_id >= 0
    np.testing.assert_array_equal(c.odometry.speed, default.odometry.speed)
    per_scan = np.diff(dc.offsets) - np.diff(da.offsets)
    n = per_scan.size
    # Poisson(2): mean 2 within 4 standard errors, variance equal to the mean within 20 %
    assert abs(per_scan.mean() - 2.0) < 4 * math.sqrt(2.0 / n)
    assert per_scan.var() == pytest.approx(2.0, rel=0.2)
    for k in range(n):         # the scan's own detections, unchanged, among its clutter by bearing
        sa, sc = slice(da.offsets[k], da.offsets[k + 1]), slice(dc.offsets[k], dc.offsets[k + 1])
        mine = real[sc]
        assert np.all(np.diff(dc.bearing[sc]) >= 0) and int((~mine).sum()) == per_scan[k]
        got = sorted(zip(dc.landmark_id[sc][mine], dc.range[sc][mine], dc.bearing[sc][mine]))
        assert got == sorted(zip(da.landmark_id[sa], da.range[sa], da.bearing[sa]))
    r, b = dc.range[~real], dc.bearing[~real]
    assert kstest(r, "uniform", args=(cfg.min_range, cfg.max_range - cfg.min_range)).pvalue > 1e-3
    assert kstest(b, "uniform", args=(0.0, math.pi)).pvalue > 1e-3
    with pytest.raises(ValueError, match="clutter_rate"):
        SimConfig(clutter_rate=-1.0)
