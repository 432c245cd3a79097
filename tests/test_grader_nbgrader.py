"""The course's grader agrees with nbgrader's own autograde on the same submissions.

nbgrader 0.9.6 (environment-instructor.txt) is run for real: a course directory with a
gradebook, ``generate_assignment``, the submissions under ``submitted/<student>/<assignment>/``,
``autograde``, and the scores read back from its gradebook. The submissions are honest, partly
done and the metadata attacks (points edited, an edited test cell), where both graders must
give the same score. A submission with an added bonus cell (unknown grade id) makes nbgrader
0.9.6 stop grading it ("the nbgrader metadata may be corrupted"; it stays at 0 in the
gradebook); the course's grader ignores that cell, says so, and grades the rest. The attacks that disarm checks from inside the kernel are
not compared: nbgrader runs the checks in the student's kernel and gives them full marks
(tests/test_grader_attacks.py shows the course's grader gives 0).
"""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from annslam_lib.course.grader import grade_batch
from annslam_lib.course.sandbox import Limits

import grading_support as gs

FULL = sum(gs.POINTS.values())


def _bonus(nb):
    c = nbformat.v4.new_code_cell("pass")
    c.metadata["nbgrader"] = {"grade": True, "grade_id": "bonus", "points": 100,
                              "solution": False, "locked": True, "schema_version": 3}
    nb.cells.append(c)


def _points(nb):
    nb.cells[gs.solution_index(nb, "ex-observe-tests")].metadata["nbgrader"]["points"] = 1000


def _edited(nb):
    nb.cells[gs.solution_index(nb, "ex-speed-tests")].source = "pass  # edited"


SUBMISSIONS = {
    "honest": lambda: gs.honest(),
    "empty": lambda: gs.submission(),
    "partial": lambda: gs.submission(gs.OBSERVE_BODY),
    "wrong": lambda: gs.submission(gs.OBSERVE_BODY.replace("+ np.pi / 2", ""), gs.SPEED_BODY),
    "points1000": lambda: gs.submission(gs.OBSERVE_BODY, edit=_points),
    "bonus": lambda: gs.submission(edit=_bonus),
    "editedtest": lambda: gs.submission(None, gs.SPEED_BODY, edit=_edited),
}
EXPECTED = {"honest": FULL, "empty": 0, "partial": 2, "wrong": 3, "points1000": 2, "bonus": 0,
            "editedtest": 3}


def _nbgrader(course: Path, *args, env, check=True):
    out = subprocess.run([sys.executable, "-m", "nbgrader", *args,
                          f"--CourseDirectory.root={course}"], capture_output=True, text=True,
                         timeout=600, env=env, cwd=course)
    if check:
        assert out.returncode == 0, f"nbgrader {' '.join(args)} failed:\n{out.stderr[-3000:]}"
    return out


def test_nbgrader_autograde_and_the_course_grader_agree(tmp_path):
    if importlib.util.find_spec("nbgrader") is None:
        pytest.skip("nbgrader is not installed: pip install -r environment-instructor.txt "
                    "(./course.sh test does)")
    course = tmp_path / "course"
    gs.write(gs.instructor(), course / "source" / "chapter" / "chapter.ipynb")
    for student, make in SUBMISSIONS.items():
        gs.write(make(), course / "submitted" / student / "chapter" / "chapter.ipynb")
    # nbgrader runs helper executables (alembic) from PATH: this venv's bin first
    mark = tmp_path / "clients.txt"
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "PYTHONPATH": str(Path(__file__).parent), "ANNSLAM_CLIENT_MARK": str(mark)}
    # INSTRUCTOR.md's one line that gives nbgrader's autograde the course's stall-proof client
    (course / "nbgrader_config.py").write_text(
        'c = get_config()  # noqa: F821\n'
        'c.AsyncKernelManager.client_class = "grading_support.MarkedKernelClient"\n')
    # the class list in one import (each nbgrader command costs about 3 s of start-up);
    # generate_assignment adds the assignment to the gradebook
    (tmp_path / "students.csv").write_text("id\n" + "".join(f"{s}\n" for s in SUBMISSIONS))
    _nbgrader(course, "db", "student", "import", str(tmp_path / "students.csv"), env=env)
    _nbgrader(course, "generate_assignment", "chapter", "--force", env=env)
    out = _nbgrader(course, "autograde", "chapter", "--force", env=env, check=False)
    assert "error processing assignment 'chapter' for student 'bonus'" in out.stderr
    made = mark.read_text().split()                  # one client per graded submission
    assert len(made) >= len(SUBMISSIONS) - 1 and set(made) == {"CourseKernelClient"}, made
    from nbgrader.api import Gradebook, MissingEntry

    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gb:
        theirs = {}
        for s in SUBMISSIONS:
            try:
                theirs[s] = gb.find_submission("chapter", s).score
            except MissingEntry:
                theirs[s] = None                       # refused
        their_max = gb.find_assignment("chapter").max_score
    results = grade_batch([course / "submitted"], instructor_dir=course / "source" / "chapter",
                          limits=Limits(cell_timeout=30, deadline=120), log=lambda s: None)
    ours = {r.student: r.score for r in results}
    assert {r.max_score for r in results} == {their_max} == {FULL}
    bonus = next(r for r in results if r.student == "bonus")
    assert any("'bonus'" in n and "ignored" in n for n in bonus.notes)
    assert ours == theirs == EXPECTED, f"course {ours}\nnbgrader {theirs}"
