"""Copied-code flags in the course's grader: `grade_batch` compares each
solution with the library's implementation of the function its exercise asks for and with
the other submissions of the batch, reports near-identical pairs in the text report and the
JSON, and changes no score. Run on the two-exercise notebook of tests/grading_support.py:
an honest student, one who pasted the library's `axle_speed` (renamed), and two who share a
solution of `observe` written differently from everyone else's."""
from __future__ import annotations

import inspect
import json
import os
import re

import pytest

from annslam_lib.course.grader import grade_batch
from annslam_lib.course.sandbox import Limits, bwrap_available
from annslam_lib.models import motion

import grading_support as gs

LIMITS = Limits(cell_timeout=20.0, call_timeout=10.0, deadline=90.0)
ISOLATION = os.environ.get("ANNSLAM_TEST_ISOLATION",
                           "auto" if bwrap_available() is not None else "none")

SHARED = '''def my_observe(pose, landmark):
    """Range and bearing by complex numbers."""
    d = complex(landmark[0] - pose[0], landmark[1] - pose[1])
    b = np.angle(d * np.exp(-1j * pose[2]) * 1j)
    return abs(d), b'''

SHARED_RENAMED = '''def my_observe(pose, landmark):
    # we worked on this together, honest
    delta = complex(landmark[0] - pose[0],
                    landmark[1] - pose[1])
    beta = np.angle(delta * np.exp(-1j * pose[2]) * 1j)   # laser bearing
    return abs(delta), beta'''


def _library_copy() -> str:
    src = inspect.getsource(motion.axle_speed)
    src = src.replace("def axle_speed(encoder_speed, steering, vehicle: Vehicle):",
                      "def my_axle_speed(speed, steer, vehicle):")
    src = src.replace("encoder_speed", "speed").replace("steering", "steer")
    return "from annslam_lib import _checks\n" + src.replace("v_c", "vc")


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    root = tmp_path_factory.mktemp("flags")
    inst = root / "source" / "chapter.ipynb"
    gs.write(gs.instructor(), inst)
    # (each exercise's solutions differ from student to student but for the pairs tested)
    subs = {"honest": gs.honest(), "paster": gs.submission(None, _library_copy()),
            "ann": gs.submission(SHARED), "bob": gs.submission(SHARED_RENAMED)}
    for who, nb in subs.items():
        gs.write(nb, root / "submitted" / who / "chapter" / "chapter.ipynb")
    lines: list[str] = []
    results = grade_batch([root / "submitted"], instructor_dir=inst.parent,
                          json_path=root / "grades.json", limits=LIMITS, isolation=ISOLATION,
                          log=lines.append)
    return ({r.student: r for r in results}, lines, json.loads((root / "grades.json").read_text()),
            root)


def test_the_library_copy_and_the_shared_pair_are_flagged_and_nobody_else(batch):
    by, *_ = batch
    flagged = {(who, f["exercise"], f["other"]) for who, g in by.items() for f in g.flags}
    assert flagged == {
        ("paster", "ex-speed-tests", "library: annslam_lib.models.motion.axle_speed"),
        ("ann", "ex-observe-tests", "bob"), ("bob", "ex-observe-tests", "ann")}, flagged
    assert all(f["similarity"] >= 0.9 for g in by.values() for f in g.flags)


def test_flags_change_no_score(batch):
    by, *_ = batch
    full = sum(gs.POINTS.values())
    assert by["honest"].score == full
    assert by["ann"].score == by["bob"].score == gs.POINTS["ex-observe-tests"]   # shared, scored
    assert by["paster"].score == 0                    # the pasted library code does not even fit


def test_flags_are_in_the_text_report_and_the_json(batch):
    by, lines, js, _ = batch
    text = "\n".join(lines)
    assert "copied-code flags (2 pair(s); for the instructor to read, no score changed):" in text
    assert "FLAG ex-speed-tests" in by["paster"].report()
    assert "library: annslam_lib.models.motion.axle_speed" in by["paster"].report()
    rows = {r["student"]: r for r in js}
    assert [f["other"] for f in rows["ann"]["flags"]] == ["bob"]
    assert rows["honest"]["flags"] == [] and "solution_sources" not in rows["honest"]


def test_the_grade_command_prints_and_writes_the_flags(batch):
    """`python -m annslam_lib grade` (the instructors' entry) on the same folder: the flags
    in its text and its JSON."""
    import subprocess
    import sys

    *_, root = batch
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "grade", str(root / "submitted"),
                          "--instructor", str(root / "source"), "--json", str(root / "cli.json"),
                          "--isolation", ISOLATION], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "copied-code flags (2 pair(s)" in out.stdout
    assert re.search(r"paster ex-speed-tests: 0\.9\d similar to library: annslam_lib\.models\.motion"
                     r"\.axle_speed", out.stdout), out.stdout[-1500:]
    rows = {r["student"]: r for r in json.loads((root / "cli.json").read_text())}
    assert {f["other"] for f in rows["bob"]["flags"]} == {"ann"}


def test_only_the_instructor_s_skip_tag_leaves_a_course_cell_out_of_the_grade():
    """A course cell the instructor tagged ``grading-skip`` is not planned; the same tag in a
    submission changes nothing (a student cannot drop the instructor's cells, nor a test)."""
    import nbformat
    from annslam_lib.course import plan as gp

    def nb(tag_study, tag_test=False):
        v4 = nbformat.v4
        cells = [v4.new_code_cell("import math"),
                 v4.new_code_cell("study = sum(range(10))"),
                 v4.new_code_cell("def f(x):\n    return x", metadata={"nbgrader": {
                     "grade_id": "ex-f", "solution": True, "grade": False, "locked": False,
                     "schema_version": 3}}),
                 v4.new_code_cell("assert f(1) == 1", metadata={"nbgrader": {
                     "grade_id": "ex-f-tests", "solution": False, "grade": True, "locked": True,
                     "points": 1, "schema_version": 3}})]
        if tag_study:
            cells[1].metadata["tags"] = [gp.SKIP_TAG]
        if tag_test:
            cells[0].metadata["tags"] = [gp.SKIP_TAG]
            cells[3].metadata["tags"] = [gp.SKIP_TAG]
        return v4.new_notebook(cells=cells)

    planned = gp.plan(nb(tag_study=True), nb(tag_study=False))
    assert [c.index for c in planned.cells] == [0, 2, 3]
    assert [c.role for c in planned.cells] == ["course", "solution", "test"]
    kept = gp.plan(nb(tag_study=False), nb(tag_study=True, tag_test=True))
    assert [c.index for c in kept.cells] == [0, 1, 2, 3]
    assert kept.cells[3].role == "test"
