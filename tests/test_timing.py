"""annslam_lib.timing: the per-step cost harness (notebook 06). Timings themselves are not
asserted (machine-dependent); what is asserted is that the harness does what it says."""
import math

import numpy as np
import pytest


from annslam_lib.slam.dense import DenseEkfSlam
from annslam_lib.slam.efficient import EkfSlam
from annslam_lib.models.observation import inverse_observe
from annslam_lib.evaluation import timing


def test_random_filter_holds_the_drawn_landmarks_in_both_classes():
    eff = timing.random_filter(EkfSlam, 7, seed=3)
    dense = timing.random_filter(DenseEkfSlam, 7, seed=3)
    rng = np.random.default_rng(3)
    z = np.column_stack([rng.uniform(3.0, 40.0, 7), rng.uniform(0.05, 3.1, 7)])
    lm, _, _ = inverse_observe(np.array([0.0, 0.0, 0.3]), z)
    for f in (eff, dense):
        assert f.n_landmarks == 7
        np.testing.assert_allclose(f.landmarks(), lm, atol=1e-12)
        assert np.all(np.hypot(*(f.landmarks() - f.pose[:2]).T) <= 40.0 + 1e-9)
    x_e, P_e = eff.state()
    np.testing.assert_allclose(P_e, dense.P, rtol=1e-12, atol=1e-15)


def test_both_filters_do_the_same_work_when_timed():
    # Same start, controls and measurements: the timed steps must leave both filters in
    # the same state (otherwise the comparison would time different computations).
    controls = timing.step_controls(50)
    eff = timing.random_filter(EkfSlam, 12, seed=1)
    dense = timing.random_filter(DenseEkfSlam, 12, seed=1)
    x0 = eff.state()[0].copy()
    te = timing.time_steps(eff, 40, controls, seed=5)
    td = timing.time_steps(dense, 40, controls, seed=5)
    x_e, P_e = eff.state()
    np.testing.assert_allclose(x_e, dense.x, atol=1e-9)
    np.testing.assert_allclose(P_e, dense.P, atol=1e-10)
    assert np.max(np.abs(x_e[:2] - x0[:2])) > 1.0           # 40 steps of 25 ms at 2 m/s: ~2 m
    for t in (te, td):
        assert t.steps == 40 and t.predict > 0 and t.update > 0
        assert t.step == pytest.approx(t.predict + t.update)


def test_step_controls_drive_at_two_metres_per_second():
    c = timing.step_controls(100)
    assert len(c) == 100
    alpha = np.array([row[1] for row in c])
    np.testing.assert_allclose(alpha, 0.2 * np.sin(np.arange(100) / 20), atol=1e-15)
    # v_c is the encoder speed moved to the axle centre: 2 m/s when driving straight.
    assert c[0][0] == pytest.approx(2.0) and c[0][8] == pytest.approx(timing.DT)


def test_step_costs_rows_and_dense_step_budget():
    rows = timing.step_costs((5, 10), dense_sizes=(10,), efficient_steps=7, dense_budget=2.0)
    assert [r.N for r in rows] == [5, 10] and [r.n for r in rows] == [13, 23]
    assert rows[0].dense is None and rows[0].ratio is None
    assert rows[0].efficient.steps == rows[1].efficient.steps == 7
    assert rows[1].dense.steps == int(2.0 * (50 / 10) ** 2) == 50
    assert rows[1].ratio == pytest.approx(rows[1].dense.step / rows[1].efficient.step)


def test_loglog_slope_recovers_power_laws():
    x = np.array([50.0, 150.0, 300.0, 1200.0])
    for p in (1.0, 2.0, 3.0, 0.5):
        assert timing.loglog_slope(x, 7e-6 * x**p) == pytest.approx(p, abs=1e-12)
    noisy = 1e-3 * x**2 * np.array([1.1, 0.9, 1.05, 0.95])
    assert timing.loglog_slope(x, noisy) == pytest.approx(2.0, abs=0.1)


@pytest.mark.parametrize("call, match", [
    (lambda: timing.random_filter(object, 5), "cls must be"),
    (lambda: timing.random_filter(EkfSlam, 0), "n_landmarks must be an integer >= 1"),
    (lambda: timing.random_filter(EkfSlam, 2.5), "n_landmarks"),
    (lambda: timing.step_controls(1), "n must be an integer >= 2"),
    (lambda: timing.time_steps(timing.random_filter(EkfSlam, 3), 0, timing.step_controls()), "steps"),
    (lambda: timing.time_steps(timing.random_filter(EkfSlam, 3), 2, []), "controls"),
    (lambda: timing.time_steps(EkfSlam(np.zeros(3), np.eye(3) * 0.01, timing.ACFR_UTE), 2,
                               timing.step_controls()), "no landmark"),
    (lambda: timing.step_costs(()), "at least one"),
    (lambda: timing.step_costs((10,), efficient_steps=0), "efficient_steps"),
    (lambda: timing.step_costs((10,), dense_budget=math.nan), "dense_budget"),
    (lambda: timing.loglog_slope([1, 2], [1, 0]), "positive"),
    (lambda: timing.loglog_slope([1, 2, 3], [1, 2]), "same length"),
    (lambda: timing.loglog_slope([2, 2], [1, 3]), "all equal"),
])
def test_bad_input_is_a_clear_error(call, match):
    # wrong types (a class that is no filter, a float count) raise TypeError
    kind = TypeError if match in ("cls must be", "n_landmarks") else ValueError
    with pytest.raises(kind, match=match):
        call()
