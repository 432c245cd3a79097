"""Shared fixtures: the real ACFR runs.

They are skipped only when the data is simply not there and ``ANNSLAM_DATA`` is unset
(a student's machine before ``python -m annslam_lib data fetch``). With ``ANNSLAM_DATA``
set (CI), missing or corrupt data is an error, never a skip. Tests never download.
"""
import os

import pytest
from annslam_lib.data import fetch
from annslam_lib.data import loaders


def _real(name: str):
    try:
        fetch.verify(name)
    except fetch.DataError as e:
        if os.environ.get(fetch.ENV_DIR):
            raise
        pytest.skip(f"real {name!r} data not available ({str(e).splitlines()[0]}); "
                    f"set ANNSLAM_DATA or run: python -m annslam_lib data fetch {name}")
    return loaders.load(name)


@pytest.fixture(scope="session")
def car_park():
    """The real Car Park run (records.Dataset)."""
    return _real("car_park")


@pytest.fixture(scope="session")
def victoria_park():
    """The real Victoria Park run (records.Dataset)."""
    return _real("victoria_park")


@pytest.fixture(autouse=True)
def _library_answers_allowed(request):
    """The tests of the checks' messages (test_grading_*.py) build right and wrong answers
    from the library's own functions; the rule that a solution must not call them has its
    own tests (test_grading_forbidden.py), so it is off in the others."""
    from annslam_lib.grading.core import allowing_library_calls

    name = request.module.__name__
    if name.startswith("test_grading_") and name != "test_grading_forbidden":
        with allowing_library_calls():
            yield
    else:
        yield
