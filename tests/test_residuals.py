"""Residuals that should be zero are shown as bounds, never as CPU-dependent digits."""
import math

import pytest

from annslam_lib import paper
from annslam_lib.evaluation.residuals import (DIFFERENCES, ROUNDING, bound_text, residual,
                                              residuals)


@pytest.mark.parametrize("x, bound, unit, text", [
    (3.3e-16, ROUNDING, "", "below 1e-12"),
    (0.0, ROUNDING, "m", "below 1e-12 m"),
    (-2.2e-16, ROUNDING, "rad", "below 1e-12 rad"),
    (9.9e-9, DIFFERENCES, "", "below 1e-7"),
    (2.5e-12, ROUNDING, "", "2.5e-12 (NOT below 1e-12)"),      # a broken comparison shows
    (1.0e-7, DIFFERENCES, "m", "1e-07 m (NOT below 1e-7)"),
    (math.nan, ROUNDING, "", "NaN (not computed)"),
])
def test_residual_reads_as_its_bound_or_shows_the_value(x, bound, unit, text):
    assert residual(x, bound, unit) == text


def test_the_phrase_does_not_depend_on_the_last_digits():
    # what two CPUs printed for the same quantity: the same words
    assert residual(3.3e-16) == residual(2.2e-16) == residual(0.0)
    assert residual(6.8e-15) == residual(9.3e-15)


def test_several_residuals_in_one_phrase():
    assert residuals([1e-16, 3e-15, 0.0]) == "all below 1e-12"
    assert residuals([1e-9], 1e-8, "m") == "below 1e-8 m"
    assert residuals([1e-16, 0.5]) == "below 1e-12, 0.5 (NOT below 1e-12)"


@pytest.mark.parametrize("bound, text", [(1e-12, "1e-12"), (1e-7, "1e-7"), (5e-8, "5e-8"),
                                         (1e3, "1e3")])
def test_bounds_are_written_without_padded_exponents(bound, text):
    assert bound_text(bound) == text


def test_the_errata_table_shows_rounding_as_the_checks_resolution():
    rows = {r["key"]: r for r in paper.errata_table()}
    table = paper.errata_markdown()
    assert 0 < rows["3.3-transform"]["corrected_error"] < DIFFERENCES       # rounding level
    line = next(x for x in table.splitlines() if "translation column of ijT_r" in x)
    assert line.endswith("| wrong equation | 25 | below 1e-7 |"), line
    assert rows["3.3-theta-case3"]["corrected_error"] == 0.0               # exactly 0 is too
    line = next(x for x in table.splitlines() if "third case of theta" in x)
    assert line.endswith("| 3.1 | below 1e-7 |"), line
