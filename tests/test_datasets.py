"""Loaders of the real runs: counts, units and the time base against PROVENANCE.md,
the event order against the Car Park file's own event list, and damaged files."""
from collections import Counter

import numpy as np
import pytest
import scipy.io


from annslam_lib.data.loaders import _parse_car_park, _parse_victoria_park
from annslam_lib.data.fetch import DataError
from annslam_lib.data.records import SENSOR_NAMES
from annslam_lib.models.vehicle import ACFR_UTE
from annslam_lib.data import fetch
from annslam_lib.data import loaders

# ---------------------------------------------------------------- Car Park


def test_car_park_counts_and_units(car_park):
    ds = car_park
    assert (len(ds.odometry), len(ds.laser), len(ds.gps)) == (5001, 586, 626)
    assert ds.beacons.shape == (15, 2)
    assert ds.vehicle == ACFR_UTE and ds.landmark_kind == "beacons" and ds.detections is None
    # ranges in metres: no-return marker about 81.9 m, every real return well below it
    r = ds.laser.ranges
    assert r.shape == (586, 361) and r.min() > 0.5 and 81.8 < r.max() <= 81.92
    assert r[ds.laser.valid].max() < 80
    # intensity: raw 8192*level -> level 0..4; beacon tape in 506 scans at 0.87..15.9 m
    assert set(np.unique(ds.laser.intensity)) == {0, 1, 2, 3, 4}
    tape = ds.laser.intensity > 0
    assert tape.any(axis=1).sum() == 506
    assert r[tape].min() == pytest.approx(0.87, abs=0.01) and r[tape].max() == pytest.approx(15.9, abs=0.05)
    # speed m/s, steering rad (PROVENANCE ranges)
    assert ds.odometry.speed.min() == pytest.approx(-0.02, abs=0.01)
    assert ds.odometry.speed.max() == pytest.approx(3.12, abs=0.01)
    assert ds.odometry.steering.min() == pytest.approx(-0.62, abs=0.01)
    assert ds.odometry.steering.max() == pytest.approx(0.60, abs=0.01)


def test_car_park_gps_and_beacons_share_the_frame(car_park):
    east, north = car_park.gps.east, car_park.gps.north
    assert (east.min(), east.max()) == pytest.approx((-3.5, 14.9), abs=0.06)
    assert (north.min(), north.max()) == pytest.approx((-21.5, 12.5), abs=0.06)
    b = car_park.beacons
    assert (b[:, 0].min(), b[:, 0].max()) == pytest.approx((-5.4, 14.6), abs=0.06)
    assert (b[:, 1].min(), b[:, 1].max()) == pytest.approx((-23.4, 16.4), abs=0.06)
    assert np.diff(car_park.gps.t) == pytest.approx(0.2, abs=1.5e-3)  # 5 Hz, 1 ms jitter, no gaps


def _file_events(ds):
    """The file's own event list (Time, Sensor 1/2/3 = GPS/odometry/laser, 1-based Index)."""
    m = scipy.io.loadmat(fetch.dataset_dir("car_park") / "data_set.mat")
    names = {1: "gps", 2: "odometry", 3: "laser"}
    t = m["Time"].ravel() - ds.info["time_offset_s"]
    return [(ti, names[int(s)], int(i) - 1) for ti, s, i in zip(t, m["Sensor"].ravel(), m["Index"].ravel())]


def _table_events(ds):
    return [(t, SENSOR_NAMES[c], int(i)) for t, c, i in zip(*ds.event_table())]


def test_car_park_event_table_matches_the_file_up_to_ties(car_park):
    table, expected = _table_events(car_park), _file_events(car_park)
    assert len(table) == len(expected) == 6213
    assert Counter(e[1] for e in table) == {"odometry": 5001, "laser": 586, "gps": 626}
    assert np.array_equal([e[0] for e in table], [e[0] for e in expected])  # same time sequence
    assert sorted(table) == sorted(expected)  # same (t, sensor, index) events


def test_car_park_events_agree_with_event_table(car_park):
    assert [tuple(e) for e in car_park.events()] == _table_events(car_park)


def test_car_park_events_match_the_file_order_exactly(car_park):
    assert _table_events(car_park) == _file_events(car_park)
    assert [tuple(e) for e in car_park.events()] == _file_events(car_park)


# ---------------------------------------------------------------- Victoria Park


def test_victoria_park_counts_and_trees(victoria_park):
    ds = victoria_park
    assert (len(ds.odometry), len(ds.gps)) == (61945, 4466)
    assert ds.laser is None and ds.beacons is None and ds.landmark_kind == "trees"
    assert ds.trees is ds.detections and ds.vehicle.a == pytest.approx(0.95 + ds.vehicle.L)
    trees = ds.trees
    assert (len(trees), trees.count) == (7249, 52974)
    assert (trees.per_scan() > 0).sum() == 7230 and trees.per_scan()[0] == 8
    first = (trees.range[0], trees.bearing[0], trees.diameter[0])
    assert first == pytest.approx((20.462, 0.8858, 0.354), abs=1e-3)
    assert np.array_equal(trees[0][0], [trees.range[0], trees.bearing[0]])
    assert (trees.range.min(), trees.range.max()) == pytest.approx((1.48, 75.3), abs=0.01)
    assert (trees.bearing.min(), trees.bearing.max()) == pytest.approx((0.11, 3.09), abs=0.01)
    assert (trees.diameter.min(), trees.diameter.max()) == pytest.approx((0.017, 1.48), abs=0.005)


def test_victoria_park_gps_keeps_its_gaps(victoria_park):
    gps = victoria_park.gps
    assert (gps.east[0], gps.north[0]) == pytest.approx((-67.65, -41.71), abs=0.01)
    gaps = gps.gaps(2.0)
    length = gaps[:, 1] - gaps[:, 0]
    assert len(gaps) == 67
    assert length.max() == pytest.approx(58.26, abs=0.05)
    assert length.sum() == pytest.approx(650, abs=1)


# ---------------------------------------------------------------- one time base


@pytest.mark.parametrize("name, offset, first", [
    # first sample of (odometry, gps, scans) in PROVENANCE, minus the offset
    ("car_park", 45.024, (45.024, 45.047, 45.103)),
    ("victoria_park", 20.967, (21.940, 20.967, 21.819)),
])
def test_one_time_base_in_seconds_from_zero(request, name, offset, first):
    ds = request.getfixturevalue(name)
    streams = (ds.odometry.t, ds.gps.t, ds.scan_times)
    assert ds.info["time_offset_s"] == pytest.approx(offset, abs=1e-9)
    assert [s[0] for s in streams] == pytest.approx(np.subtract(first, offset), abs=1e-9)
    assert min(s[0] for s in streams) == 0.0 and ds.t0 == 0.0
    assert all(np.all(np.diff(s) >= 0) for s in streams)
    assert np.diff(ds.odometry.t) == pytest.approx(0.025, abs=1e-9)
    assert ds.info["citation"] and ds.info["licence"] and ds.info["source"]


def test_durations(car_park, victoria_park):
    t, _, _ = car_park.event_table()
    assert t[-1] == pytest.approx(170.178 - 45.024, abs=1e-6)  # ~125.15 s
    odo = victoria_park.odometry.t
    assert odo[-1] - odo[0] == pytest.approx(1548.6, abs=1e-6)


def test_loading_is_cached_and_read_only(car_park, victoria_park):
    assert loaders.load("car_park") is car_park and loaders.load_victoria_park() is victoria_park
    with pytest.raises(ValueError, match="read-only"):
        car_park.odometry.speed[0] = 1.0
    for parse, ds in ((_parse_car_park, car_park), (_parse_victoria_park, victoria_park)):
        again = parse(fetch.dataset_dir(ds.name))
        assert np.array_equal(again.odometry.t, ds.odometry.t)


# ---------------------------------------------------------------- errors


def test_unknown_dataset_lists_the_known_names():
    with pytest.raises(ValueError, match="car_park, victoria_park"):
        loaders.load("car-park")


def test_corrupt_file_fails_the_hash_before_parsing(tmp_path, monkeypatch):
    folder = tmp_path / "acfr_car_park"
    folder.mkdir()
    for n in ("data_set.mat", "beac_juan3.mat"):
        scipy.io.savemat(folder / n, {"estbeac": np.zeros((15, 2))})  # a valid MAT file, wrong bytes
    monkeypatch.setenv("ANNSLAM_DATA", str(tmp_path))
    with pytest.raises(DataError, match="f44c8adfa7e8e38ea6c40da3cd5d52bd8e029fc2d5ea27a9d7df24ad4ec98be7"):
        loaders.load_car_park()


def _car_park_files(folder, **override):
    """A tiny but well-formed Car Park pair: 11 odometry samples from t = 10 s,
    3 GPS fixes, 2 laser scans whose intensity holds levels 0 and 2."""
    t = 10.0 + 0.025 * np.arange(11)
    intensity = np.zeros((2, 361), np.uint16)
    intensity[1, 100:103] = 2 * 8192
    m = {"Time_VS": t[None], "Velocity": np.ones((1, 11)), "Steering": np.zeros((1, 11)),
         "TimeGPS": 10.01 + 0.2 * np.arange(3)[None], "GPSLon": np.ones((1, 3)), "GPSLat": np.ones((1, 3)),
         "TimeLaser": np.array([[10.05, 10.26]]), "Laser": np.full((2, 361), 81.91),
         "Intensity": intensity}
    m.update(override)
    scipy.io.savemat(folder / "data_set.mat", {k: v for k, v in m.items() if v is not None})
    scipy.io.savemat(folder / "beac_juan3.mat", {"estbeac": np.zeros((3, 2))})
    return folder


def test_parse_car_park_small_file(tmp_path):
    ds = _parse_car_park(_car_park_files(tmp_path))
    assert ds.info["time_offset_s"] == 10.0 and ds.odometry.t[0] == 0.0
    assert ds.gps.t[0] == pytest.approx(0.01) and ds.laser.t[1] == pytest.approx(0.26)
    assert ds.laser.intensity[1, 100:103].tolist() == [2, 2, 2] and ds.laser.intensity.sum() == 6


@pytest.mark.parametrize("override, message", [
    ({"Velocity": np.ones((1, 8))}, r"data_set\.mat: variable 'Velocity' has shape \(8,\)"),
    ({"GPSLat": None}, r"data_set\.mat: variable 'GPSLat' is missing"),
    ({"Laser": np.ones((2, 360))}, r"variable 'Laser' has shape \(2, 360\), expected 2 x 361"),
    ({"Intensity": np.full((2, 361), 100, np.uint16)}, r"variable 'Intensity' must hold levels"),
    ({"Steering": np.full((1, 11), np.nan)}, r"odometry\.steering contains NaN"),
])
def test_parse_car_park_damaged(tmp_path, override, message):
    with pytest.raises(DataError, match=message):
        _parse_car_park(_car_park_files(tmp_path, **override))


def _victoria_park_files(folder, *, shift_s=0.0, bad_cell=False):
    """A tiny Victoria Park triple: ms clocks in aa3_*, seconds in the tree file;
    3 scans with 2, 0 and 1 trees; GPS starts first (t0 = 20.967 s)."""
    t_ms = (21940 + 25 * np.arange(5)).astype(np.int32)[:, None]
    scipy.io.savemat(folder / "aa3_dr.mat", {"time": t_ms, "speed": np.ones((5, 1)),
                                             "steering": np.zeros((5, 1))})
    scipy.io.savemat(folder / "aa3_gpsx.mat", {"timeGps": np.array([[20967], [21167]], np.int32),
                                               "Lo_m": np.ones((2, 1)), "La_m": np.ones((2, 1))})
    zt = np.empty((1, 3), dtype=object)
    zt[0, 0] = np.array([[20.0, 30.0], [0.9, 1.2], [0.35, 0.2]])
    zt[0, 1] = np.zeros((0, 0))
    zt[0, 2] = np.array([[5.0], [2.0], [0.1]]) if not bad_cell else np.array([[5.0], [2.0]])
    scipy.io.savemat(folder / "VictoriaParkSinSincronizar.mat", {
        "time": t_ms.T / 1000 + shift_s, "TLsr": np.array([[21.819, 22.033, 22.247]]), "zt": zt})
    return folder


def test_parse_victoria_park_small_files(tmp_path):
    ds = _parse_victoria_park(_victoria_park_files(tmp_path))
    assert ds.info["time_offset_s"] == pytest.approx(20.967, abs=1e-12) and ds.gps.t[0] == 0.0
    assert ds.odometry.t[0] == pytest.approx(0.973, abs=1e-9)
    assert ds.trees.per_scan().tolist() == [2, 0, 1]
    assert ds.trees.range.tolist() == [20.0, 30.0, 5.0] and ds.trees.diameter[2] == 0.1


@pytest.mark.parametrize("kwargs, message", [
    ({"shift_s": 1.0}, r"variable 'time' differs from aa3_dr\.mat"),
    ({"bad_cell": True}, r"variable 'zt' scan 2 has shape \(2, 1\)"),
])
def test_parse_victoria_park_damaged(tmp_path, kwargs, message):
    with pytest.raises(DataError, match=message):
        _parse_victoria_park(_victoria_park_files(tmp_path, **kwargs))
