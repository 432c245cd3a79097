"""geometry.wrap_angle: range, idempotence to the bit, and the +-pi convention."""
import numpy as np
import pytest

from annslam_lib.models.geometry import wrap_angle


def test_wrap_angle_range_and_equivalence():
    a = np.random.default_rng(0).uniform(-50, 50, 100_000)
    w = wrap_angle(a)
    assert np.all((w > -np.pi) & (w <= np.pi))
    # same direction: the difference is a whole number of turns
    turns = (a - w) / (2 * np.pi)
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-12)


def test_wrap_angle_is_idempotent_to_the_bit():
    a = np.random.default_rng(1).uniform(-np.pi, np.pi, 100_000)
    assert np.array_equal(wrap_angle(a), a)  # in-range angles pass through untouched
    w = wrap_angle(np.random.default_rng(2).uniform(-20, 20, 10_000))
    assert np.array_equal(wrap_angle(w), w)


def test_wrap_angle_pi_convention_and_bad_input():
    assert wrap_angle(np.pi) == np.pi and wrap_angle(-np.pi) == np.pi
    assert wrap_angle(3 * np.pi) == pytest.approx(np.pi)
    with pytest.raises(ValueError, match="angle"):
        wrap_angle([0.0, np.nan])
