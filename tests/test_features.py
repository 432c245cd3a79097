"""Beacon extraction from raw laser (synthetic scans, noise-free simulator, the real Car Park
against the surveyed beacons) and the Victoria Park tree helpers."""
import dataclasses
import math

import numpy as np
import pytest


from annslam_lib.perception.beacons import BeaconConfig
from annslam_lib.perception.trees import TreeFilter
from annslam_lib.models.geometry import wrap_angle
from annslam_lib.models.geometry import interpolate_poses
from annslam_lib.models.observation import observe
from annslam_lib.data.records import LASER_ANGLES, Dataset, Detections, Laser
from annslam_lib.data import simulate
from annslam_lib.perception import beacons
from annslam_lib.perception import sources
from annslam_lib.perception import trees as tree_detections
from annslam_lib.slam import dead_reckoning

STEP = math.radians(0.5)
NO_RETURN = 81.91


def blank():
    return np.full(361, NO_RETURN), np.zeros(361, dtype=int)


# ----------------------------------------------------------------- synthetic scans

def test_contiguous_cluster_gives_its_midpoint_mean_range_and_chord():
    r, lv = blank()
    r[100:103] = [5.00, 4.98, 5.02]
    lv[100:103] = [1, 3, 2]
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES, BeaconConfig(pole_radius=0.03))
    assert s.z.shape == (1, 2)
    assert s.z[0, 0] == pytest.approx(5.00 + 0.03, abs=1e-12)      # mean of the three + radius
    assert s.z[0, 1] == pytest.approx(math.radians(50.5), abs=1e-12)  # beam 101 = 50.5 deg
    assert s.level[0] == 3 and s.n_beams[0] == 3 and tuple(s.beams[0]) == (100, 102)
    assert s.width[0] == pytest.approx(3 * STEP * 5.03, rel=1e-12)
    np.testing.assert_allclose(s.R[0], np.diag([0.1**2, math.radians(1) ** 2]))     # ACFR's


def test_single_beam_cluster_and_clusters_at_the_edges_of_the_scan():
    r, lv = blank()
    r[[0, 1, 200, 359, 360]] = [3.0, 3.0, 7.5, 4.0, 4.0]
    lv[[0, 1, 200, 359, 360]] = [2, 2, 1, 4, 4]
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES)
    # Edge clusters may be poles cut by the field of view: dropped by default.
    np.testing.assert_allclose(s.z, [[7.5, math.radians(100.0)]], atol=1e-12)
    assert s.n_beams.tolist() == [1] and s.width[0] == pytest.approx(STEP * 7.5)
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES, BeaconConfig(drop_edge=False))
    np.testing.assert_allclose(s.z[:, 1], np.radians([0.25, 100.0, 179.75]), atol=1e-12)
    assert s.beams.tolist() == [[0, 1], [200, 200], [359, 360]]


def test_range_window_and_min_level():
    r, lv = blank()
    r[[50, 120, 121, 250]] = [0.87, 31.0, 31.0, 12.0]
    lv[[50, 120, 121, 250]] = [3, 1, 1, 1]
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES)
    assert s.beams.tolist() == [[250, 250]]                   # 0.87 m and 31 m are outside 1..30 m
    assert beacons.beacons_from_scan(r, lv, LASER_ANGLES, BeaconConfig(min_level=2)).z.shape == (0, 2)
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES, BeaconConfig(min_range=0.5, max_range=40))
    assert s.beams.tolist() == [[50, 50], [120, 121], [250, 250]]


def test_gaps_inside_a_pole_are_bridged_only_up_to_max_gap_beams():
    r, lv = blank()
    r[150:154] = [2.0, 2.01, 2.02, 2.0]      # beam 152: an ordinary return of the same pole
    lv[[150, 151, 153]] = 4
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES)
    assert s.beams.tolist() == [[150, 153]] and s.n_beams.tolist() == [3]
    assert s.z[0, 0] == pytest.approx((2.0 + 2.01 + 2.0) / 3)      # bright beams only
    assert s.width[0] == pytest.approx(4 * STEP * s.z[0, 0])
    strict = beacons.beacons_from_scan(r, lv, LASER_ANGLES, BeaconConfig(max_gap_beams=0))
    assert strict.beams.tolist() == [[150, 151], [153, 153]]
    r[154:158], lv[154:158] = 2.0, [0, 0, 0, 4]                       # a 3-beam gap: two poles
    assert beacons.beacons_from_scan(r, lv, LASER_ANGLES).beams.tolist() == [[150, 153], [157, 157]]
    lv[156] = 4                                                        # a 2-beam gap: one pole
    assert beacons.beacons_from_scan(r, lv, LASER_ANGLES).beams.tolist() == [[150, 157]]


def test_range_jump_splits_clusters_and_the_partly_hidden_one_is_dropped():
    r, lv = blank()
    r[250:254] = [5.0, 5.0, 8.0, 8.0]        # a pole at 5 m in front of one at 8 m
    lv[250:254] = 2
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES)
    assert s.beams.tolist() == [[250, 251]]  # the far pole's neighbour (beam 251) is nearer
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES, BeaconConfig(drop_occluded=False))
    assert s.beams.tolist() == [[250, 251], [252, 253]]
    np.testing.assert_allclose(s.z[:, 0], [5.0, 8.0])
    r[249] = 3.0                             # an ordinary object in front of the near pole too
    assert beacons.beacons_from_scan(r, lv, LASER_ANGLES).z.shape == (0, 2)


def test_empty_scan_and_bad_input():
    r, lv = blank()
    s = beacons.beacons_from_scan(r, lv, LASER_ANGLES)
    assert s.z.shape == (0, 2) and s.R.shape == (0, 2, 2) and s.level.shape == (0,)
    with pytest.raises(ValueError, match="share the beam dimension"):
        beacons.beacons_from_scan(r[:-1], lv, LASER_ANGLES)
    with pytest.raises(ValueError, match="NaN"):
        beacons.beacons_from_scan(np.where(np.arange(361) == 3, np.nan, r), lv, LASER_ANGLES)
    with pytest.raises(ValueError, match="integer levels 0..255"):
        beacons.beacons_from_scan(r, lv + 0.5, LASER_ANGLES)
    with pytest.raises(ValueError, match="uniformly spaced"):
        beacons.beacons_from_scan(r, lv, LASER_ANGLES[::-1])
    with pytest.raises(ValueError, match="one scan"):
        beacons.beacons_from_scan(np.stack([r, r]), np.stack([lv, lv]), LASER_ANGLES)
    for bad in (dict(min_range=5, max_range=2), dict(max_gap_beams=-1), dict(min_level=0),
                dict(pole_radius=-0.1), dict(sigma_range=0.0), dict(max_range=math.inf)):
        with pytest.raises(ValueError, match="BeaconConfig"):
            BeaconConfig(**bad)
    with pytest.raises(TypeError, match="BeaconConfig.drop_edge"):
        BeaconConfig(drop_edge=1)


# ----------------------------------------------------------------- an independent reference

def _reference(ranges, levels, cfg):
    """A plain beam-by-beam loop of the documented rules (steps 1-4), for comparison."""
    out = []
    for k in range(ranges.shape[0]):
        r, lv = ranges[k], levels[k]
        bright = [i for i in range(361) if lv[i] >= cfg.min_level and cfg.min_range <= r[i] <= cfg.max_range]
        groups = []
        for i in bright:
            if groups and i - groups[-1][-1] - 1 <= cfg.max_gap_beams \
                    and abs(r[i] - r[groups[-1][-1]]) <= cfg.max_range_jump:
                groups[-1].append(i)
            else:
                groups.append([i])
        for g in groups:
            surface = sum(r[i] for i in g) / len(g)
            if cfg.drop_edge and (g[0] == 0 or g[-1] == 360):
                continue
            if cfg.drop_occluded and any(0 <= j <= 360 and r[j] < surface - cfg.max_range_jump
                                         for j in (g[0] - 1, g[-1] + 1)):
                continue
            out.append((k, surface + cfg.pole_radius, (LASER_ANGLES[g[0]] + LASER_ANGLES[g[-1]]) / 2,
                        max(lv[i] for i in g)))
    return np.array(out).reshape(-1, 4)


@pytest.mark.parametrize("cfg", [BeaconConfig(), BeaconConfig(max_gap_beams=0, drop_edge=False,
                                                                drop_occluded=False, pole_radius=0.03)])
def test_vectorised_extraction_equals_a_beam_by_beam_loop_on_the_car_park(car_park, cfg):
    ks = np.arange(0, len(car_park.laser), 3)          # a third of the scans keeps the loop quick
    laser = car_park.laser
    det = beacons.extract_beacons(laser, cfg)
    ref = _reference(laser.ranges[ks], laser.intensity[ks], cfg)
    scan = np.repeat(np.arange(len(det)), det.per_scan())
    sel = np.isin(scan, ks)
    got = np.column_stack([np.searchsorted(ks, scan[sel]), det.range[sel], det.bearing[sel],
                           det.intensity[sel]])
    assert got.shape == ref.shape and got.shape[0] > 250
    np.testing.assert_allclose(got, ref, atol=1e-12)


# ----------------------------------------------------------------- the noise-free simulator

def test_noise_free_simulator_centres_are_within_the_derived_bounds():
    """Ray-cast poles of radius rho: every beam hit lies between r - rho and r (triangle
    inequality; the near intersection is at r cos d - sqrt(...) <= r), so the mean hit + rho
    is within [r, r + rho]. The beams hitting a pole are those within asin(rho / r) of its
    bearing; the first and last are each less than one beam step s inside that interval,
    so their midpoint is within s/2 of the bearing (unless cut by the field of view, by
    another pole, or by the simulator's 30 m limit: poles under 29 m, edge and occluded
    clusters dropped)."""
    ds = simulate.simulate(seed=0, sigma_range=0.0, sigma_bearing=0.0, laps=1)
    rho = ds.info["config"].pole_radius
    det = sources.detections_for(ds, "laser")         # takes rho from the simulator
    scan = np.repeat(np.arange(len(det)), det.per_scan())
    z_true, _, _ = observe(ds.info["scan_poses"][scan][:, None, :], ds.beacons[None])

    def xy(z):
        return np.stack([z[..., 0] * np.sin(z[..., 1]), -z[..., 0] * np.cos(z[..., 1])], -1)

    z = np.column_stack([det.range, det.bearing])
    j = np.argmin(np.linalg.norm(xy(z_true) - xy(z)[:, None], axis=-1), axis=1)
    zt = z_true[np.arange(j.size), j]
    near = zt[:, 0] < 29.0
    dr, db = z[:, 0] - zt[:, 0], wrap_angle(z[:, 1] - zt[:, 1])
    assert det.count > 1000 and near.sum() > 0.95 * det.count
    assert np.all(dr[near] >= -1e-9) and np.all(dr[near] <= rho + 1e-9)
    assert np.all(np.abs(db[near]) < STEP / 2 + 1e-9)
    # Completeness: within rho / sin(s/2) = 22.9 m a pole is always hit by a beam. The
    # simulator's own detection list within 22 m is found but for edge / occluded poles.
    sim = ds.detections
    sim_scan = np.repeat(np.arange(len(sim)), sim.per_scan())
    close = sim.range <= 22.0
    found = set(zip(scan.tolist(), j.tolist()))
    hit = np.array([(k, m) in found for k, m in zip(sim_scan[close], sim.landmark_id[close])])
    assert hit.mean() > 0.97


# ----------------------------------------------------------------- the real Car Park run

def test_car_park_scans_with_a_beacon_are_the_bright_ones_less_window_and_edges(car_park):
    laser = car_park.laser
    det = beacons.extract_beacons(laser)
    with_beacon = set(np.flatnonzero(det.per_scan() > 0).tolist())
    bright = laser.intensity > 0
    bright_scans = set(np.flatnonzero(bright.any(axis=1)).tolist())
    assert len(bright_scans) == 506
    # Independently of the extractor: scans whose bright beams all lie below 1 m, or all
    # in one run ending at the scan's last beam (a pole cut by the field of view).
    below = {k for k in bright_scans if np.all(laser.ranges[k][bright[k]] < 1.0)}
    at_edge = {k for k in bright_scans
               if bright[k, -1] and np.all(np.diff(np.flatnonzero(bright[k])) == 1)}
    assert below and at_edge and not (below & at_edge)
    assert with_beacon == bright_scans - below - at_edge
    assert det.count > 850 and np.all(det.landmark_id == -1)
    assert set(np.unique(det.intensity)) <= {1, 2, 3, 4} and np.all(det.diameter > 0)


def test_extraction_is_deterministic(car_park):
    a, b = beacons.extract_beacons(car_park.laser), beacons.extract_beacons(car_park.laser)
    assert np.array_equal(a.range, b.range) and np.array_equal(a.bearing, b.bearing)
    assert np.array_equal(a.offsets, b.offsets) and a.count > 850


@pytest.fixture(scope="module")
def car_residuals(car_park):
    poses, valid = dead_reckoning.gps_scan_poses(car_park)
    det = beacons.extract_beacons(car_park.laser)
    return det, poses, valid, beacons.extraction_residuals(det, poses, valid, car_park.beacons)


def test_car_park_beacons_match_the_surveyed_ones_seen_from_gps(car_park, car_residuals):
    det, poses, valid, res = car_residuals
    scan = np.repeat(np.arange(len(det)), det.per_scan())
    seen = valid[scan]
    assert valid.sum() > 400 and seen.sum() > 550
    # Every beacon extracted while the GPS heading is known lies within 1 m of a surveyed one.
    assert np.array_equal(res.matched, seen)
    assert np.nanpercentile(res.distance, 90) < 0.3
    assert np.unique(res.landmark[res.matched]).size == 15   # all 15 beacons are seen
    s = res.stats()
    # Range: measured +1.0 cm mean, 3.8 cm std (GPS and survey errors included).
    assert 0.0 < s["range_mean"] < 0.02 and s["range_std"] < 0.05
    # Bearing against the GPS-derived heading: 0.7 deg mean, 1.2 deg std.
    assert abs(math.degrees(s["bearing_mean"])) < 1.0 and math.degrees(s["bearing_std"]) < 1.5


def test_car_park_bearing_noise_without_the_heading(car_residuals):
    """Two beacons of one scan share the heading error: the difference of their bearing
    residuals has variance 2 sigma_b^2 whatever the heading is."""
    det, _, _, res = car_residuals
    scan = np.repeat(np.arange(len(det)), det.per_scan())
    i, j = np.nonzero((scan[:, None] == scan[None, :]) & np.triu(np.ones((scan.size,) * 2, bool), 1))
    ok = res.matched[i] & res.matched[j] & (res.landmark[i] != res.landmark[j])
    diff = wrap_angle(res.bearing[i[ok]] - res.bearing[j[ok]])
    assert ok.sum() > 250
    sigma_b = math.degrees(np.std(diff) / math.sqrt(2))
    assert 0.3 < sigma_b < 0.7                          # measured 0.5 deg
    assert sigma_b < math.degrees(BeaconConfig().sigma_bearing)


def test_adding_the_nominal_pole_radius_makes_the_car_park_ranges_long(car_park, car_residuals):
    det, poses, valid, res = car_residuals
    with_radius = beacons.extract_beacons(car_park.laser, BeaconConfig(pole_radius=0.03))
    r3 = beacons.extraction_residuals(with_radius, poses, valid, car_park.beacons).stats()
    assert r3["range_mean"] == pytest.approx(res.stats()["range_mean"] + 0.03, abs=1e-9)
    assert abs(res.stats()["range_mean"]) < abs(r3["range_mean"]) / 2


def test_clusters_below_one_metre_are_not_beacons(car_park):
    poses, valid = dead_reckoning.gps_scan_poses(car_park)
    det = beacons.extract_beacons(car_park.laser, BeaconConfig(min_range=0.0))
    res = beacons.extraction_residuals(det, poses, valid, car_park.beacons)
    close = det.range < 1.0
    assert close.sum() >= 3
    assert np.all(res.distance[close & ~np.isnan(res.distance)] > 1.5)
    assert not res.matched[close].any()


def test_gps_scan_poses_on_a_noise_free_simulator():
    ds = simulate.simulate(seed=0, sigma_gps=0.0, sigma_steer=0.0, sigma_speed=0.0, laps=1)
    poses, valid = dead_reckoning.gps_scan_poses(ds)
    true = ds.info["scan_poses"]
    assert valid.mean() > 0.95 and not valid[0] and not valid[-1]   # standing at start and end
    assert np.max(np.hypot(*(poses[valid, :2] - true[valid, :2]).T)) < 0.01
    assert np.max(np.abs(wrap_angle(poses[valid, 2] - true[valid, 2]))) < math.radians(1.0)


# ----------------------------------------------------------------- choosing the source

def test_detections_for_picks_the_source(car_park, victoria_park):
    sim = simulate.simulate(seed=2, laps=1)
    assert sources.detections_for(sim) is sim.detections
    assert sources.detections_for(victoria_park) is victoria_park.detections
    ext = sources.detections_for(car_park)
    ref = beacons.extract_beacons(car_park.laser)
    np.testing.assert_array_equal(ext.range, ref.range)
    from_laser = sources.detections_for(sim, "laser")
    from_laser_0 = sources.detections_for(sim, "laser", config=BeaconConfig())
    np.testing.assert_allclose(from_laser.range - from_laser_0.range, sim.info["config"].pole_radius)
    with pytest.raises(ValueError, match="no raw laser"):
        sources.detections_for(victoria_park, "laser")
    with pytest.raises(ValueError, match="no provided detections"):
        sources.detections_for(car_park, "detections")
    with pytest.raises(ValueError, match="unknown source"):
        sources.detections_for(car_park, "gps")
    bare = dataclasses.replace(sim, laser=None, detections=None)
    with pytest.raises(ValueError, match="neither detections nor raw laser"):
        sources.detections_for(bare)
    with pytest.raises(TypeError, match="Dataset"):
        sources.detections_for(car_park.laser)


def test_measurement_sigmas_follow_the_source(car_park, victoria_park):
    sim = simulate.simulate(seed=2, laps=1, sigma_range=0.2)
    assert sources.measurement_sigmas(sim) == (0.2, sim.info["config"].sigma_bearing)
    cfg = BeaconConfig()
    assert sources.measurement_sigmas(sim, "laser") == (cfg.sigma_range, cfg.sigma_bearing)
    assert sources.measurement_sigmas(car_park) == (cfg.sigma_range, cfg.sigma_bearing)
    t = TreeFilter()
    assert sources.measurement_sigmas(victoria_park) == (t.sigma_range, t.sigma_bearing)


# ----------------------------------------------------------------- Victoria Park trees

def test_trees_filter_keeps_exactly_the_windowed_detections(victoria_park):
    trees = victoria_park.trees
    kept = tree_detections.trees_filter(trees)
    mask = (trees.range <= 40.0) & (trees.range >= 1.0) & (trees.diameter >= 0.05)
    assert len(kept) == len(trees) and kept.count == mask.sum()
    np.testing.assert_array_equal(kept.range, trees.range[mask])
    scan = np.repeat(np.arange(len(trees)), trees.per_scan())
    np.testing.assert_array_equal(kept.per_scan(), np.bincount(scan[mask], minlength=len(trees)))
    assert tree_detections.trees_filter(trees, max_range=20.0).range.max() <= 20.0
    assert sources.detections_for(victoria_park, tree_filter=TreeFilter()).count == kept.count
    with pytest.raises(ValueError, match="unknown TreeFilter field"):
        tree_detections.trees_filter(trees, max_rang=3)
    with pytest.raises(ValueError, match="TreeFilter"):
        TreeFilter(min_diameter=1.0, max_diameter=0.5)


def test_next_scan_distance_on_a_crafted_pair_of_scans():
    # The car moves 1 m forward (East) between scans; a tree 10 m ahead is 9 m ahead then.
    det = Detections(t=np.array([0.0, 0.2]), offsets=np.array([0, 2, 3]),
                     range=np.array([10.0, 5.0, 9.0]), bearing=np.array([np.pi / 2, 0.3, np.pi / 2]),
                     diameter=np.full(3, 0.3))
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    d, j = tree_detections.next_scan_match(det, poses)
    assert d[0] == pytest.approx(0.0, abs=1e-12) and d[1] > 4.0 and d[2] == np.inf
    assert j.tolist() == [2, 2, -1]
    rows, res = tree_detections.repeatability(det, poses)
    assert rows.tolist() == [0]                          # the 5 m detection found no partner
    np.testing.assert_allclose(res, [[0.0, 0.0]], atol=1e-12)
    rows, _ = tree_detections.repeatability(det, poses, lag=2)
    assert rows.size == 0
    with pytest.raises(ValueError, match="one per scan"):
        tree_detections.next_scan_match(det, poses[:1])


def test_victoria_park_far_trees_are_rarely_seen_again(victoria_park):
    """The basis of TreeFilter's 40 m: with dead-reckoned poses (accurate over one scan
    interval), most trees at 5-40 m reappear within 1 m in the next scan, under half beyond."""
    trees = victoria_park.trees
    path = dead_reckoning.dead_reckon(victoria_park.odometry, np.zeros(3), victoria_park.vehicle)
    poses = interpolate_poses(path, np.clip(trees.t, path[0, 0], path[-1, 0]))
    again = tree_detections.next_scan_match(trees, poses).distance < 1.0
    mid = (trees.range >= 5) & (trees.range < 40)
    assert again[mid].mean() > 0.75
    assert again[(trees.range >= 40) & (trees.range < 50)].mean() < 0.5
    assert again[trees.range >= 50].mean() < 0.45
    # Repeatability one scan apart, per view: a few cm and about 0.2 deg, under the
    # suggested sigmas; ten scans apart still within them.
    for lag, frac in ((1, 0.5), (10, 1.0)):
        rows, res = tree_detections.repeatability(trees, poses, lag=lag)
        mid = (trees.range[rows] >= 5) & (trees.range[rows] < 40)
        sd = np.std(res[mid], axis=0) / math.sqrt(2)
        assert rows.size > 20000 and sd[0] < frac * TreeFilter().sigma_range
        assert sd[1] < frac * TreeFilter().sigma_bearing


def test_laser_records_helpers_reject_bad_types(car_park):
    with pytest.raises(TypeError, match="Laser"):
        beacons.extract_beacons(car_park)
    with pytest.raises(TypeError, match="BeaconConfig"):
        beacons.extract_beacons(car_park.laser, config={"pole_radius": 0.03})
    laser = Laser(t=np.array([0.0]), ranges=np.full((1, 361), NO_RETURN), intensity=np.zeros((1, 361)))
    det = beacons.extract_beacons(laser)
    assert det.count == 0 and det.per_scan().tolist() == [0]
    bare = Dataset(name="x", odometry=car_park.odometry, gps=car_park.gps, vehicle=car_park.vehicle)
    with pytest.raises(ValueError, match="neither"):
        sources.measurement_sigmas(bare)
