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


def _by_hand(mapped, true):
    """Independent reference for a known correspondence: Procrustes (scipy) and its RMSE."""
    from scipy.linalg import orthogonal_procrustes
    a, b = mapped - mapped.mean(0), true - true.mean(0)
    Rp, _ = orthogonal_procrustes(a, b)
    if np.linalg.det(Rp) < 0:
        raise AssertionError("reference would reflect")
    return float(np.sqrt(np.mean(np.sum((a @ Rp - b) ** 2, axis=1))))


@pytest.mark.parametrize("angle_deg, shift", [(15.0, (0.0, 0.0)), (15.0, (6.0, -3.0)),
                                              (-40.0, (25.0, 10.0)), (127.0, (-20.0, 5.0))])
def test_map_errors_align_first_does_not_depend_on_the_frame(beacons, angle_deg, shift):
    """A map whose frame is rotated (15 deg is 5 m at 20 m) gives the
    same matches and the same aligned RMSE as the same map in the right frame, plus a
    spurious landmark and a missed beacon; the absolute error shows the frame."""
    rng = np.random.default_rng(5)
    good = beacons[:14] + rng.normal(0, 0.05, (14, 2))
    good = np.vstack([good, [[60.0, -60.0]]])                  # a spurious landmark
    ref = map_eval.map_errors(good, beacons)
    moved = good @ rot(math.radians(angle_deg)).T + shift
    e = map_eval.map_errors(moved, beacons)
    np.testing.assert_array_equal(e.i_mapped, ref.i_mapped)
    np.testing.assert_array_equal(e.j_true, ref.j_true)
    assert e.i_mapped.size == 14 and e.missed == 1 and e.spurious == 1 and e.duplicates == 0
    assert e.rmse_aligned == pytest.approx(ref.rmse_aligned, rel=1e-9)
    assert e.rmse_aligned == pytest.approx(_by_hand(good[:14], beacons[:14]), rel=1e-9)
    assert e.rmse > 1.0 > 0.1 > e.rmse_aligned
    assert math.degrees(e.rotation) == pytest.approx(-angle_deg, abs=0.5)


def test_map_errors_align_first_covers_landmarks_far_as_mapped(beacons):
    """Rotated 1.5 degrees about one corner: the far landmarks are more than 1 m off as
    mapped (matching before aligning would leave them out), all 15 after the loop."""
    corner = beacons[np.argmin(beacons[:, 0] + beacons[:, 1])]
    mapped = (beacons - corner) @ rot(math.radians(1.5)).T + corner
    far = np.hypot(*(mapped - beacons).T) > 1.0
    assert 3 <= far.sum() <= 12
    i, _ = map_eval.match_landmarks(mapped, beacons, 1.0)
    assert i.size == 15 - far.sum()                            # the old, frame-bound count
    e = map_eval.map_errors(mapped, beacons)
    assert e.i_mapped.size == 15 and e.rmse_aligned < 1e-9


def test_map_errors_refuses_when_nothing_fits(beacons):
    # two landmarks 0.5 m apart, far from everything: no pair of beacons is that close
    with pytest.raises(ValueError, match="any rigid frame"):
        map_eval.map_errors(np.array([[300.0, 300.0], [300.5, 300.0]]), beacons)
