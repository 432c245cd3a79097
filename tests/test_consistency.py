"""Is the default filter consistent, and can the tests tell?

Judged on seeds the course's notebooks never use (except where a test reads notebook 05's
own experiment), 50 runs each: per scan, the average pose NEES against the band of an
average of 50 chi2(3) values, with the pass threshold of the share of scans inside it and
the band of the time average (ANEES) derived under the null for correlated scans
(``evaluation.scan_null``); at the end, the map NEES of all landmarks together (joint
covariance, 2 N dof per run) summed over the runs against chi2(total dof). The rules were
fixed before these results: share >= its 5 % null quantile, ANEES within its 95 % band (a
t-test over the independent runs), map NEES inside its 95 % band. A filter reporting P / 1.1
(10 % over-confident) must fail them.
"""
import numpy as np
import pytest
from scipy.stats import binom, chi2

from annslam_lib.evaluation import consistency, scan_null
from annslam_lib.slam.config import SlamConfig

N_RUNS = 50
NOTEBOOK_05 = range(100, 100 + N_RUNS)          # notebook 05's seeds: read from its cache


def test_independent_scans_give_the_textbook_null():
    """With no correlation between scans the simulated null must be the textbook one: the
    share of K scans inside a 95 % band is Binomial(K, 0.95) / K, the ANEES band that of
    chi2(3 N K) / (N K). Checked against scipy, not against the module."""
    rng = np.random.default_rng(5)
    runs, K = 50, 200
    nt = scan_null.null_test(rng.chisquare(3, (runs, K)), n_sim=1000, seed=1)
    assert nt.acf.size - 1 == K // 4
    expected = binom.ppf(0.05, K, 0.95) / K
    assert abs(nt.share_threshold - expected) <= 2 / K
    assert abs(np.mean(nt.shares) - 0.95) < 0.003
    assert nt.anees_model_sd == pytest.approx(np.sqrt(6 / (runs * K)), rel=0.01)
    assert np.std(nt.anees) == pytest.approx(np.sqrt(6 / (runs * K)), rel=0.1)
    assert nt.anees_sd == pytest.approx(np.sqrt(6 / (runs * K)), rel=0.3)    # estimated from 50 runs


def test_correlated_paths_have_the_asked_correlation():
    rho = 0.9 ** np.arange(40)
    x = scan_null.correlated_paths(rho, 400, 4000, np.random.default_rng(2))
    assert x.shape == (4000, 400)
    assert np.mean(x) == pytest.approx(0, abs=0.01) and np.var(x) == pytest.approx(1, rel=0.02)
    measured = [np.mean(x[:, :400 - h] * x[:, h:]) for h in (1, 5, 20)]
    assert measured == pytest.approx(rho[[1, 5, 20]], abs=0.02)
    with pytest.raises(ValueError):
        scan_null.scan_autocorrelation(np.ones((3, 10)), 2)          # nothing varies


@pytest.fixture(scope="module")
def loop_4():
    """The default filter, 50 runs of 4 laps of the loop (1121 scans each)."""
    mc = consistency.monte_carlo(range(7100, 7100 + N_RUNS), "midpoint", "loop", 4)
    return mc, scan_null.null_test(mc.nees_runs)


def test_the_null_model_reproduces_the_runs_correlation():
    """The simulated null must be correlated like the real runs (notebook 05's experiment),
    and its ANEES spread must equal the closed form."""
    mc = consistency.monte_carlo(NOTEBOOK_05, "midpoint")
    nt = scan_null.null_test(mc.nees_runs)
    assert nt.acf[10] > 0.4                                   # scans are far from independent
    assert nt.acf_simulated[1:21] == pytest.approx(nt.acf[1:21], abs=0.06)
    assert np.std(nt.anees) == pytest.approx(nt.anees_model_sd, rel=0.1)
    # the model keeps K // 4 lags and is less correlated than the runs: its ANEES spread is
    # below the runs' own (model-free, the runs are independent), which the band therefore uses
    means = mc.nees_runs.mean(axis=1)
    assert nt.anees_sd == pytest.approx(means.std(ddof=1) / np.sqrt(means.size), rel=1e-12)
    assert 0.5 < nt.anees_model_sd / nt.anees_sd < 0.9
    assert nt.share_threshold < binom.ppf(0.05, nt.scans, 0.95) / nt.scans - 0.03


def test_the_default_filter_passes_and_a_10_percent_overconfident_one_fails(loop_4):
    mc, nt = loop_4
    assert SlamConfig().motion_model == "midpoint"
    assert set(mc.mapped) == {15}
    lo, hi = chi2.ppf([0.025, 0.975], 3 * N_RUNS) / N_RUNS
    assert nt.band == pytest.approx((lo, hi))
    honest = nt.judge(mc.nees_runs)
    assert honest.passes, (honest.summary(), nt.summary())
    assert mc.map.inside, mc.map.summary()
    # the same runs, the filter reporting P / 1.1: every NEES 1.1 times larger
    over = nt.judge(mc.nees_runs, scale=1.1)
    assert not over.anees_passes and not over.passes, over.summary()
    per_run = np.full(N_RUNS, mc.map.dof / N_RUNS)
    assert consistency.map_consistency(mc.map.runs * per_run, per_run).per_dof == pytest.approx(mc.map.per_dof)
    over_map = consistency.map_consistency(1.1 * mc.map.runs * per_run, per_run)
    assert not over_map.inside, over_map.summary()
    # on notebook 05's shorter runs the per-scan rules alone miss it; the map NEES catches it
    short = consistency.monte_carlo(NOTEBOOK_05, "midpoint")
    assert scan_null.null_test(short.nees_runs).judge(short.nees_runs, scale=1.1).passes
    per_run = np.full(N_RUNS, short.map.dof / N_RUNS)
    assert not consistency.map_consistency(1.1 * short.map.runs * per_run, per_run).inside


@pytest.mark.xfail(strict=True, reason="measured: on the hairpin the default filter's map is about "
                   "9 % over-confident (map NEES/dof 1.088 above 1.073; its ANEES, 3.315, is high but "
                   "within the band of the runs' spread); the cause is not found")
def test_the_default_filter_on_the_hairpin():
    mc = consistency.monte_carlo(range(7000, 7000 + N_RUNS), "midpoint", "hairpin", 2)
    verdict = scan_null.null_test(mc.nees_runs).judge(mc.nees_runs)
    assert verdict.passes and mc.map.inside, (verdict.summary(), mc.map.summary())


class _Result:
    def __init__(self, landmarks, cov, ids):
        self.landmarks, self.landmark_true_id = np.asarray(landmarks), np.asarray(ids)
        self.covariance = cov


class _Sim:
    truth = object()

    def __init__(self, beacons):
        self.beacons = np.asarray(beacons, dtype=float)


def test_map_nees_by_hand_uses_the_joint_covariance():
    beacons = [[0.0, 0.0], [5.0, 1.0]]
    lms = [[5.2, 0.9], [0.1, -0.1]]                  # landmark 0 is beacon 1, landmark 1 beacon 0
    P = np.eye(7)
    P[3:, 3:] = [[0.04, 0, 0.03, 0], [0, 0.01, 0, 0], [0.03, 0, 0.04, 0], [0, 0, 0, 0.01]]
    e = np.array([0.2, -0.1, 0.1, -0.1])
    value, dof = consistency.map_nees(_Result(lms, P, [1, 0]), _Sim(beacons))
    assert dof == 4
    assert value == pytest.approx(e @ np.linalg.inv(P[3:, 3:]) @ e, rel=1e-12)
    diag = e @ (e / np.diag(P[3:, 3:]))
    assert abs(value - diag) > 0.1                   # the cross term matters
    with pytest.raises(ValueError, match="match no true beacon"):
        consistency.map_nees(_Result(lms, P, [1, -1]), _Sim(beacons))
    with pytest.raises(ValueError, match="simulated dataset"):
        consistency.map_nees(_Result(lms, P, [1, 0]), type("D", (), {"truth": None})())


def test_map_consistency_band_covers_chi_square_draws_95_percent():
    rng = np.random.default_rng(0)
    dofs = np.full(N_RUNS, 30)
    inside = [consistency.map_consistency(rng.chisquare(30, N_RUNS), dofs).inside
              for _ in range(2000)]
    assert 0.935 <= np.mean(inside) <= 0.965          # 95 % +- 3 binomial sd
    scaled = [consistency.map_consistency(1.3 * rng.chisquare(30, N_RUNS), dofs).inside
              for _ in range(200)]
    assert np.mean(scaled) < 0.05                     # 30 % over-confident: caught
    with pytest.raises(ValueError):
        consistency.map_consistency([1.0, np.nan], [2, 2])
    with pytest.raises(ValueError):
        consistency.map_consistency([], [])


# ------------------------------------------------ effects over runs (consistency.EFFECT_RULE)

def test_ratio_effect_matches_scipy_t_interval_and_its_words():
    """Interval from scipy.stats.t.interval, not from the module; each word planted."""
    from scipy.stats import t as student_t
    rng = np.random.default_rng(11)
    for true, word in ((1.06, "over-confident"), (0.93, "under-confident"), (1.0, None)):
        v = true + 0.1 * rng.standard_normal(400)
        e = consistency.ratio_effect(v)
        lo, hi = student_t.interval(0.95, v.size - 1, loc=v.mean(), scale=v.std(ddof=1) / np.sqrt(v.size))
        assert e.lo == pytest.approx(lo, rel=1e-12) and e.hi == pytest.approx(hi, rel=1e-12)
        expected = word or ("no detectable difference" if lo <= 1 <= hi else None)
        assert e.word == expected
    tight = consistency.ratio_effect(1.02 + 0.01 * rng.standard_normal(400))
    assert tight.word == "over-confident" and tight.within_margin
    wide = consistency.ratio_effect(1.0 + 0.5 * rng.standard_normal(20))
    assert wide.word == "no detectable difference" and not wide.within_margin
    assert "not within the 5 % margin" in wide.summary()


def test_ratio_effect_power_matches_a_simulation_of_the_rule():
    """The stated power against 1.05 is the share of simulated studies (true ratio 1.05,
    the same n and spread) whose rule says 'over-confident'."""
    rng = np.random.default_rng(3)
    n, sd = 60, 0.17
    stated = consistency.ratio_effect(1.0 + sd * rng.standard_normal(n)).power
    sims = [consistency.ratio_effect(1.05 + sd * rng.standard_normal(n)).word == "over-confident"
            for _ in range(2000)]
    # the stated power uses the study's own sd, so allow its sampling error as well
    assert abs(np.mean(sims) - stated) < 0.12
    assert 0.3 < np.mean(sims) < 0.8          # a design that is neither trivially weak nor strong


def test_paired_effect_resolves_what_two_intervals_cannot():
    rng = np.random.default_rng(8)
    scene = 1.0 + 0.17 * rng.standard_normal(300)           # scene-to-scene variation
    a, b = scene + 0.03 + 0.005 * rng.standard_normal(300), scene + 0.005 * rng.standard_normal(300)
    ea, eb = consistency.ratio_effect(a), consistency.ratio_effect(b)
    assert ea.lo < eb.hi                                      # separate intervals overlap
    d = consistency.paired_effect(a, b)
    assert d.word == "higher" and d.lo > 0.02 and d.within_margin is None
    assert consistency.paired_effect(b, a).word == "lower"


@pytest.mark.parametrize("values, match", [
    ([1.0, 1.1], "at least 3"), ([[1.0, 1.1, 1.2]], "one value per run"),
    ([1.0, np.nan, 1.2], "non-finite"), ([1.0, -0.1, 1.2], "negative")])
def test_ratio_effect_refuses_bad_input(values, match):
    with pytest.raises(ValueError, match=match):
        consistency.ratio_effect(values)
    with pytest.raises(ValueError, match="margin"):
        consistency.ratio_effect([1.0, 1.1, 1.2], margin=0.0)
    with pytest.raises(ValueError, match="same runs"):
        consistency.paired_effect([1.0, 1.1, 1.2], [1.0, 1.1, 1.2, 1.3])
