"""The verdict's statistics (notebook 08): paired differences over the seeds with a
t-interval, checked against scipy's paired t-test; the decision rule; and the held-out map
error with the frame removed."""
import math

import numpy as np
import pytest
from scipy import linalg, stats

from annslam_lib.evaluation import summary
from annslam_lib.paper import study


def _study(**per_config):
    """A Study holding only per-seed values of 'map_rmse_heldout' per configuration."""
    n = len(next(iter(per_config.values())))
    runs = {k: [{"map_rmse_heldout": v} for v in vals] for k, vals in per_config.items()}
    return study.Study(dataset=None, seeds=tuple(range(n)), runs=runs, t_heldout=0.0,
                       results={}, models={}, training_set=None, split=None, folds=[],
                       natural_dataset=None)


def test_paired_interval_is_scipys_paired_t_interval():
    rng = np.random.default_rng(4)
    a, b = rng.normal(0.08, 0.01, 5), rng.normal(0.09, 0.01, 5)
    p = study.paired(_study(ann=a, beacons=b), "ann", "beacons", "map_rmse_heldout")
    ci = stats.ttest_rel(a, b).confidence_interval(0.95)
    assert p.mean == pytest.approx(np.mean(a - b), abs=1e-15)
    assert (p.lo, p.hi) == (pytest.approx(ci.low, rel=1e-12), pytest.approx(ci.high, rel=1e-12))
    # pairing matters: the unpaired interval of the same numbers is another one
    welch = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    assert abs(welch.low - p.lo) > 1e-4


@pytest.mark.parametrize("diff,decision", [
    ([-0.03, -0.02, -0.025, -0.028, -0.022], "better"),
    ([0.03, 0.02, 0.025, 0.028, 0.022], "worse"),
    ([-0.03, 0.02, -0.01, 0.015, 0.0], "no detectable difference"),
])
def test_decision_rule(diff, decision):
    base = np.full(5, 0.1)
    p = study.paired(_study(ann=base + diff, beacons=base), "ann", "beacons", "map_rmse_heldout")
    assert p.decision == decision
    assert p.decision in study.DECISION_RULE or decision == "no detectable difference"


def test_one_seed_decides_nothing_and_nan_is_refused():
    p = study.paired(_study(ann=[0.05], beacons=[0.09]), "ann", "beacons", "map_rmse_heldout")
    assert (p.lo, p.hi) == (-math.inf, math.inf) and p.decision == "no detectable difference"
    with pytest.raises(ValueError, match="non-finite"):
        study.paired(_study(ann=[0.05, np.nan], beacons=[0.09, 0.1]), "ann", "beacons",
                     "map_rmse_heldout")
    with pytest.raises(ValueError, match="unknown"):
        study.paired(_study(ann=[0.05], beacons=[0.09]), "ann", "nope", "map_rmse_heldout")


class _Run:
    def __init__(self, landmarks):
        self.landmarks = np.asarray(landmarks, dtype=float)


def test_heldout_map_error_aligned_removes_the_frame_only():
    rng = np.random.default_rng(1)
    beacons = rng.uniform(-20, 20, (15, 2))
    noisy = beacons + rng.normal(0, 0.03, beacons.shape)
    th = math.radians(0.5)
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    moved = noisy @ R.T + [0.2, -0.1]               # the same map in a frame 0.5 deg, 22 cm off
    held = [2, 7, 11]
    shape = summary.heldout_map_rmse(_Run(noisy), beacons, held, aligned=True)
    assert summary.heldout_map_rmse(_Run(moved), beacons, held, aligned=True) == \
        pytest.approx(shape, abs=1e-9)
    absolute = summary.heldout_map_rmse(_Run(moved), beacons, held)
    assert absolute > 0.15 > 0.06 > shape
    # by hand: align everything (Kabsch via scipy's orthogonal Procrustes), score the three
    a, b = noisy - noisy.mean(0), beacons - beacons.mean(0)
    Rp, _ = linalg.orthogonal_procrustes(a, b)
    fit = a @ Rp + beacons.mean(0)
    assert shape == pytest.approx(np.sqrt(np.mean(np.sum((fit - beacons)[held] ** 2, 1))), rel=1e-9)
