"""Chapter 04a explorer, headless: what it shows for a (beacon, shift) against a run made
here with the map edited by hand, and its cache."""
import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from annslam_lib.chapters import ch04a_localisation as ch  # noqa: E402
from annslam_lib.evaluation.trajectory import trajectory_errors  # noqa: E402
from annslam_lib.slam import localisation  # noqa: E402
from layout_support import assert_kept_layouts_clear  # noqa: E402
from widget_support import close_figures, move  # noqa: F401


def test_the_explorer_shows_the_run_on_the_edited_map(car_park):
    w = ch.map_error_explorer(car_park, beacon=12, shift=0.0)
    s = move(w, **{"shift [m]": 0.5, "beacon": 8})
    b = car_park.beacons.copy()
    b[8, 0] += 0.5
    r = localisation.localise(localisation.with_beacons(car_park, b), gps_mode="none")
    e = trajectory_errors(r.odometry_trajectory, car_park.gps)
    assert (s["beacon"], s["shift"]) == (8, 0.5)
    assert s["traj_rmse"] == pytest.approx(e.rmse, rel=1e-12)
    assert s["accepted"] + s["rejected"] <= s["sightings"]
    np.testing.assert_allclose(s["errors"].error, e.error)


def test_a_setting_seen_before_is_not_run_again(car_park):
    cache = {}
    a = ch.map_error_summary(car_park, 3, 0.3, cache=cache)
    b = ch.map_error_summary(car_park, 3, 0.30000000001, cache=cache)
    assert a is b


def test_bad_beacon_index_is_refused(car_park):
    with pytest.raises(ValueError, match="beacon"):
        ch.map_error_summary(car_park, 15, 0.1)


def test_kept_layout_stays_clear_at_the_controls_ends(car_park):
    # plots.style.render_png draws later steps at the first step's layout (tests/layout_support.py)
    assert_kept_layouts_clear(lambda: ch.map_error_explorer(car_park, beacon=12, shift=0.0))
