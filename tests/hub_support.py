"""The class hub for the tests: the folder ``./course.sh test`` prepared (a skip that says
why where there is none), started with :func:`annslam_lib.course.hub.client.launch`."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from annslam_lib.course import hub
from annslam_lib.course.hub import setup as hub_setup

HUB_DIR = Path(os.environ.get("ANNSLAM_HUB_TEST_DIR") or "/tmp/annslam-hub-test")


def prepared_layout() -> hub.HubLayout:
    """The hub folder ``./course.sh test`` prepared (skip, saying why, where it cannot be)."""
    if os.geteuid() != 0:
        pytest.skip("the class hub gives students Unix accounts: needs root")
    from annslam_lib.course import sandbox

    if sandbox.bwrap_problem():          # the hub refuses to start where grading would
        pytest.skip(f"the grader's sandbox cannot be made here: {sandbox.bwrap_problem()}")
    layout = hub.HubLayout(HUB_DIR)
    if not (layout.root / hub_setup.PREPARED).exists():
        pytest.skip(f"the class hub's folder {layout.root} is not prepared (./course.sh test "
                    "prepares it as root; its set-up output says why it could not)")
    return layout
