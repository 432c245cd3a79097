"""The map against the survey, and the split of the innovation covariance:
checked against a direct computation, against the chi-square distribution, and on the
simulator, where a consistent filter's innovations must have the variance it predicts."""
import types

import numpy as np
import pytest

from annslam_lib.data import simulate
from annslam_lib.evaluation import real_consistency
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig


def _fake(landmarks, P):
    return types.SimpleNamespace(landmarks=np.asarray(landmarks, float), covariance=np.asarray(P, float))


def _spd(n, rng):
    A = rng.standard_normal((n, n))
    return A @ A.T / n + 0.05 * np.eye(n)


def test_survey_nees_by_hand_uses_the_joint_covariance_and_the_survey():
    rng = np.random.default_rng(3)
    P = _spd(3 + 2 * 4, rng) * 0.01
    lms = rng.normal(size=(4, 2))
    survey = rng.normal(size=(5, 2))
    i, j = np.array([2, 0, 3]), np.array([4, 1, 0])
    got = real_consistency.survey_nees(_fake(lms, P), survey, i, j, sigma_survey=0.03)
    idx = [3 + 2 * 2, 4 + 2 * 2, 3, 4, 3 + 2 * 3, 4 + 2 * 3]
    e = (lms[i] - survey[j]).ravel()
    want = e @ np.linalg.inv(P[np.ix_(idx, idx)] + 0.03**2 * np.eye(6)) @ e
    assert got.dof == 6 and got.per_dof * 6 == pytest.approx(want, rel=1e-10)
    marg = sum((lms[a] - survey[b]) @ np.linalg.inv(P[3 + 2 * a:5 + 2 * a, 3 + 2 * a:5 + 2 * a]
                                                     + 0.03**2 * np.eye(2)) @ (lms[a] - survey[b])
               for a, b in zip(i, j))
    assert abs(marg - want) > 1e-3 * want                   # the cross terms count
    for bad in (([0, 0], [1, 2]), ([0, 1], [1, 1]), ([0, 9], [1, 2]), ([], [])):
        with pytest.raises(ValueError):
            real_consistency.survey_nees(_fake(lms, P), survey, *bad)
    with pytest.raises(ValueError):
        real_consistency.survey_nees(_fake(lms, P[:-1, :-1]), survey, i, j)


def test_survey_nees_is_chi_square_for_errors_drawn_from_the_claimed_covariance():
    rng = np.random.default_rng(4)
    P = _spd(3 + 2 * 6, rng) * 0.004
    survey = rng.normal(size=(6, 2)) * 10
    idx = np.arange(3, 15)
    C = P[np.ix_(idx, idx)] + 0.02**2 * np.eye(12)
    L = np.linalg.cholesky(C)
    out = [real_consistency.survey_nees(_fake(survey + (L @ rng.standard_normal(12)).reshape(6, 2), P),
                                        survey, np.arange(6), np.arange(6), sigma_survey=0.02)
           for _ in range(1500)]
    assert np.mean([o.per_dof for o in out]) == pytest.approx(1.0, abs=0.03)
    assert np.mean([o.inside for o in out]) == pytest.approx(0.95, abs=0.02)
    over = real_consistency.survey_nees(_fake(survey + 3 * (L @ rng.standard_normal(12)).reshape(6, 2), P),
                                        survey, np.arange(6), np.arange(6))
    assert over.per_dof > 3


@pytest.fixture(scope="module")
def simulated():
    ds = simulate.simulate(seed=11, raw_laser=False)
    cfg = SlamConfig.for_dataset("simulated")
    return ds, cfg, real_consistency.innovation_split(ds, cfg)


def test_recording_the_innovations_does_not_change_the_run(simulated):
    ds, cfg, split = simulated
    plain = runner.run(ds, cfg, progress=False)
    seen = []
    inspected = runner.run(ds, cfg, progress=False, inspect=seen.append)
    assert len(seen) == 1
    np.testing.assert_array_equal(plain.trajectory, inspected.trajectory)
    assert (split.sensor == "laser").sum() == plain.counts["associated"]
    batch = plain.nis["nis"][plain.nis["kind"] == 0].sum() / plain.nis["dof"][plain.nis["kind"] == 0].sum()
    assert split.nis.sum() / (2 * split.nis.size) == pytest.approx(batch, abs=0.05)


def test_a_consistent_filter_has_the_innovation_variance_it_predicts(simulated):
    """On the simulator (the filter's noise is the simulator's) E[nu^2] = H P H^T + R for
    each component; the 99 % gate trims the largest innovations, a few per cent."""
    ds, cfg, split = simulated
    laser = split.sensor == "laser"
    assert laser.sum() > 500 and set(split.sensor) == {"laser"}       # no GPS on the simulator
    predicted = (split.hph[laser] + split.r[laser]).mean(axis=0)
    measured = (split.nu[laser] ** 2).mean(axis=0)
    assert measured / predicted == pytest.approx([0.95, 0.95], abs=0.1)
    rows = {(s, c, w): row for s, c, w, *row in split.rows()}
    n_straight, n_turn = rows["laser", "range", "straight"][0], rows["laser", "range", "turning"][0]
    assert n_straight + n_turn == rows["laser", "range", "all"][0] == laser.sum()
    r_share = rows["laser", "range", "all"][-2]
    assert r_share == pytest.approx(split.r[laser, 0].mean() / (split.hph[laser, 0] + split.r[laser, 0]).mean())


def test_innovation_split_refuses_what_is_not_a_dataset():
    with pytest.raises(TypeError):
        real_consistency.innovation_split("car_park")


def test_a_laser_noisier_than_the_filter_thinks_shows_in_its_component():
    ds = simulate.simulate(seed=11, raw_laser=False, sigma_range=0.2)       # the filter says 0.1
    split = real_consistency.innovation_split(ds, SlamConfig.for_dataset("simulated"))
    ratio = (split.nu ** 2).mean(axis=0) / (split.hph + split.r).mean(axis=0)
    assert ratio[0] > 1.3 and ratio[1] == pytest.approx(0.95, abs=0.1)


def test_gps_rows_hold_the_covariance_before_the_update():
    """The filter updates P in place: the split must record the prior H P H^T of a fix."""
    ds = simulate.simulate(seed=11, raw_laser=False)
    cfg = SlamConfig.for_dataset("simulated", gps_mode="init", gps_init_seconds=10.0)
    split = real_consistency.innovation_split(ds, cfg)
    priors = []

    def snapshot(filt):
        gps_update = filt.gps_update

        def gps(xy, sigma, gate=float("inf")):
            filt.flush()
            before = np.diag(filt.state()[1][:2, :2]).copy()
            out = gps_update(xy, sigma, gate)
            if out[1]:
                priors.append(before)
            return out
        filt.gps_update = gps

    runner.run(ds, cfg, progress=False, inspect=snapshot)
    gps = split.sensor == "gps"
    assert gps.sum() == len(priors) > 20
    np.testing.assert_allclose(split.hph[gps], np.array(priors), rtol=1e-12)
    assert np.all(split.hph[gps] > 0)
