"""Is the default filter consistent? Judged with the statistics of issue 13, on seeds the
course's notebooks never use: per scan, the average pose NEES of 20 runs against the band
of an average of 20 chi2(3) values; at the end, the map NEES of all landmarks together (joint
covariance, 2 N dof per run) summed over the runs against chi2(total dof). Two routes, one
of them long (8 laps). The Euler model fails the same statistics, so they can fail."""
import numpy as np
import pytest
from scipy.stats import chi2

from annslam_lib.data import simulate
from annslam_lib.evaluation import consistency
from annslam_lib.slam import runner
from annslam_lib.slam.config import SlamConfig

N_RUNS = 20


def _monte_carlo(route: str, laps: int, motion_model: str | None, seed0: int):
    cfg = SlamConfig.for_dataset("simulated")
    if motion_model is not None:
        cfg = cfg.replace(motion_model=motion_model)
    nees, maps, dofs = [], [], []
    for s in range(N_RUNS):
        ds = simulate.simulate(seed=seed0 + s, route=route, laps=laps, raw_laser=False)
        r = runner.run(ds, cfg, progress=False)
        assert r.counts["landmarks"] == ds.beacons.shape[0]
        nees.append(consistency.pose_nees(r, ds))
        m, d = consistency.map_nees(r, ds)
        maps.append(m)
        dofs.append(d)
    K = min(map(len, nees))
    return (consistency.nees_consistency([x[:K] for x in nees]),
            consistency.map_consistency(maps, dofs))


@pytest.mark.parametrize("route,laps,seed0", [("hairpin", 2, 7000), ("loop", 8, 7100)])
def test_default_filter_is_consistent(route, laps, seed0):
    assert SlamConfig().motion_model == "midpoint"
    pose, mapc = _monte_carlo(route, laps, None, seed0)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * N_RUNS) / N_RUNS
    assert pose.lo[0] == pytest.approx(lo) and pose.hi[0] == pytest.approx(hi)
    # 95 % expected; at least 90 % (the scans are correlated, so the fraction varies)
    assert pose.inside >= 0.90, pose.summary()
    assert mapc.inside, mapc.summary()


def test_euler_fails_the_same_statistics_on_the_long_route():
    pose, mapc = _monte_carlo("loop", 8, "euler", 7100)
    assert pose.inside < 0.85, pose.summary()
    assert mapc.per_dof > mapc.hi, mapc.summary()
    # ... while its time average alone, the old test, would not have caught it
    assert pose.lo[0] <= pose.mean <= pose.hi[0] * 1.1, pose.summary()


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
