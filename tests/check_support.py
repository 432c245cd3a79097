"""Helpers the tests of the grading checks share (tests/test_grading_*.py): a student function
not written yet, the angle wrap the tests compute their own answers with, and a check that
must fail with a given message."""
import numpy as np
import pytest

from annslam_lib.grading import GradingError


def stub(*args):
    raise NotImplementedError()


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def fails(check, fn, match):
    with pytest.raises(GradingError, match=match):
        check(fn, quiet=True)
