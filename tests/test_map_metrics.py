"""Map accuracy (annslam_lib.map_metrics) on cases with known answers."""
import math

import numpy as np
import pytest
from annslam_lib.evaluation import map as map_eval


def rot(a):
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


@pytest.fixture
def beacons():
    return np.random.default_rng(0).uniform(-20, 20, size=(15, 2))


@pytest.mark.parametrize("angle, shift", [(0.0, (0.0, 0.0)), (0.3, (2.0, -1.0)),
                                          (-2.5, (-7.0, 4.0)), (math.pi, (0.5, 0.5))])
def test_rigid_align_recovers_known_motion(beacons, angle, shift):
    moved = beacons @ rot(angle).T + shift
    R, t = map_eval.rigid_align(beacons, moved)
    np.testing.assert_allclose(R, rot(angle), atol=1e-12)
    np.testing.assert_allclose(t, shift, atol=1e-12)


def test_rigid_align_is_least_squares_and_not_a_reflection(beacons):
    mirrored = beacons * [1.0, -1.0]
    R, _ = map_eval.rigid_align(beacons, mirrored)
    assert np.linalg.det(R) == pytest.approx(1.0)
    # small perturbations of the optimum never lower the cost
    noisy = beacons @ rot(0.2).T + [1, 2] + np.random.default_rng(1).normal(0, 0.1, beacons.shape)
    R, t = map_eval.rigid_align(beacons, noisy)
    cost = lambda R_, t_: np.sum((beacons @ R_.T + t_ - noisy) ** 2)  # noqa: E731
    best = cost(R, t)
    a = math.atan2(R[1, 0], R[0, 0])
    for da, dt in [(1e-3, (0, 0)), (-1e-3, (0, 0)), (0, (1e-3, 0)), (0, (0, -1e-3))]:
        assert cost(rot(a + da), t + dt) > best


def test_map_errors_absolute_and_aligned(beacons):
    """A map rotated by 1 degree about the origin and shifted 0.1 m, listed in another
    order, with a duplicate and a far spurious landmark."""
    true_shift = np.array([0.1, 0.0])
    mapped = beacons @ rot(math.radians(1.0)).T + true_shift
    order = np.random.default_rng(2).permutation(15)
    mapped = np.vstack([mapped[order], beacons[4] + [0.3, 0.0], [100.0, 100.0]])
    e = map_eval.map_errors(mapped, beacons, max_distance=1.0)
    assert e.i_mapped.size == 15 and e.missed == 0
    assert e.spurious == 2 and e.duplicates == 1
    np.testing.assert_array_equal(e.j_true, order[e.i_mapped])
    expected = np.hypot(*(beacons @ rot(math.radians(1.0)).T + true_shift - beacons).T)
    assert e.rmse == pytest.approx(np.sqrt(np.mean(expected**2)), rel=1e-12)
    assert e.rmse_aligned < 1e-12 and e.max_aligned < 1e-12
    assert e.rotation == pytest.approx(-math.radians(1.0), abs=1e-12)


def test_map_errors_missed_and_bad_input(beacons):
    e = map_eval.map_errors(beacons[:10] + 0.05, beacons)
    assert e.missed == 5 and e.spurious == 0
    assert e.rmse == pytest.approx(0.05 * math.sqrt(2), rel=1e-12)
    with pytest.raises(ValueError, match="need 2 to align"):
        map_eval.map_errors(beacons[:1], beacons)
    with pytest.raises(ValueError, match="mapped"):
        map_eval.map_errors(np.array([[np.nan, 0.0], [1.0, 1.0]]), beacons)
    with pytest.raises(ValueError, match="max_distance"):
        map_eval.match_landmarks(beacons, beacons, max_distance=-1)


def test_point_rmse_against_an_independent_sum():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(7, 2)), rng.normal(size=(7, 2))
    by_hand = math.sqrt(sum(math.hypot(*(a[i] - b[i])) ** 2 for i in range(7)) / 7)
    assert map_eval.point_rmse(a, b) == pytest.approx(by_hand, rel=1e-12)
    assert map_eval.point_rmse(a - b) == pytest.approx(by_hand, rel=1e-12)
    assert map_eval.point_rmse([[3.0, 4.0]]) == 5.0      # a distance, not a per-coordinate RMS
    for bad in (np.empty((0, 2)), np.ones((3, 3)), np.ones(2)):
        with pytest.raises(ValueError, match="non-empty"):
            map_eval.point_rmse(bad)
    with pytest.raises(ValueError, match="NaN"):
        map_eval.point_rmse([[np.nan, 0.0]])
