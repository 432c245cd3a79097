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


# ----------------------------------------------------------------- the grader's sandbox
def _sandbox_problem() -> str:
    from annslam_lib.course import sandbox

    return sandbox.bwrap_problem()


def pytest_report_header(config):
    why = _sandbox_problem()
    if why:
        return [f"grading sandbox: not available ({why}); the grading machinery's tests run "
                "with isolation 'none', the sandbox's own tests are skipped"]
    return ["grading sandbox: bubblewrap"]


@pytest.fixture(autouse=True)
def _unsandboxed_where_no_sandbox(request, monkeypatch):
    """Where bubblewrap cannot make the grader's sandbox (a laptop without it), the tests of
    the grading machinery (plans, checks, scores, reports) still run, explicitly without a
    sandbox; the tests of the sandbox itself skip, saying why (``needs_sandbox``)."""
    why = _sandbox_problem()
    if not why:
        yield
        return
    if request.node.get_closest_marker("needs_sandbox"):
        pytest.skip(f"the grader's sandbox cannot be made here: {why}")
    from annslam_lib.course import sandbox

    init = sandbox.Sandbox.__init__

    def unsandboxed(self, limits=sandbox.Limits(), *, isolation="auto", hide=()):
        init(self, limits, isolation="none" if isolation == "auto" else isolation, hide=hide)
    monkeypatch.setattr(sandbox.Sandbox, "__init__", unsandboxed)
    yield


def pytest_configure(config):
    config.addinivalue_line("markers", "needs_sandbox: the test runs the grader's real "
                            "sandbox (bubblewrap), in this process or a subprocess")
