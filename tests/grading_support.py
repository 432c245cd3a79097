"""A small instructor notebook with two real exercises, and submissions made from it.

Grading a real chapter runs the whole chapter (5-30 s); the attacks of
tests/test_grader_attacks.py only need the grading machinery, so they use this two-exercise
notebook, built like the course's chapters (nbgrader schema 3, the course's real checks,
hidden tests), which grades in a few seconds.
"""
from __future__ import annotations

import copy

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook
from annslam_lib.course import release


OBSERVE = '''def my_observe(pose, landmark):
    """Range and laser bearing of `landmark` from the laser `pose`."""
    ### BEGIN SOLUTION
    dx, dy = landmark[0] - pose[0], landmark[1] - pose[1]
    bearing = np.arctan2(dy, dx) - pose[2] + np.pi / 2
    return np.hypot(dx, dy), (bearing + np.pi) % (2 * np.pi) - np.pi
    ### END SOLUTION'''

SPEED = '''def my_axle_speed(v_e, alpha, H, L):
    """Rear-axle-centre speed from the encoder speed."""
    ### BEGIN SOLUTION
    return v_e / (1 - np.tan(alpha) * H / L)
    ### END SOLUTION'''

OBSERVE_BODY = OBSERVE.replace("    ### BEGIN SOLUTION\n", "").replace("\n    ### END SOLUTION", "")
SPEED_BODY = SPEED.replace("    ### BEGIN SOLUTION\n", "").replace("\n    ### END SOLUTION", "")
POINTS = {"ex-observe-tests": 2, "ex-speed-tests": 3}


def _meta(gid: str, *, grade: bool, solution: bool, points=None) -> dict:
    m = {"grade": grade, "grade_id": gid, "locked": not solution, "schema_version": 3,
         "solution": solution, "task": False}
    if points is not None:
        m["points"] = points
    return m


def _cell(src: str, **meta):
    c = new_code_cell(src)
    c.metadata["nbgrader"] = _meta(**meta)
    return c


def instructor():
    """The instructor notebook: imports, two solution cells, two test cells with hidden
    tests, a course cell between them and one at the end."""
    return new_notebook(cells=[
        new_markdown_cell("# A small chapter\nTwo exercises."),
        new_code_cell("import numpy as np\nfrom annslam_lib.models import motion, observation\n"
                      "from annslam_lib.grading import kinematics as gkin\n"
                      "from annslam_lib.grading import observation as gk"),
        new_markdown_cell("### Exercise 1 (2 points)"),
        _cell(OBSERVE, gid="ex-observe", grade=False, solution=True),
        _cell("# Autograded: exercise 1 (2 points)\ngk.check_observe(my_observe)\n"
              "### BEGIN HIDDEN TESTS\ngk.check_observe(my_observe, seed=7, n=40, quiet=True)\n"
              "### END HIDDEN TESTS", gid="ex-observe-tests", grade=True, solution=False,
              points=POINTS["ex-observe-tests"]),
        new_code_cell("z, _, _ = observation.observe(np.zeros(3), np.array([3.0, 4.0]))\n"
                      "print(round(float(z[0]), 3))"),
        new_markdown_cell("### Exercise 2 (3 points)"),
        _cell(SPEED, gid="ex-speed", grade=False, solution=True),
        _cell("# Autograded: exercise 2 (3 points)\ngkin.check_axle_speed(my_axle_speed)\n"
              "### BEGIN HIDDEN TESTS\ngkin.check_axle_speed(my_axle_speed, seed=8, n=30, "
              "quiet=True)\n### END HIDDEN TESTS", gid="ex-speed-tests", grade=True,
              solution=False, points=POINTS["ex-speed-tests"]),
        new_code_cell("print('the end')"),
    ], metadata={"kernelspec": {"name": "python3", "display_name": "Python 3",
                                "language": "python"}})


def student():
    """The student version (the course's own release)."""
    return release.student_version(instructor(), "chapter")


def solution_index(nb, gid: str) -> int:
    return next(i for i, c in enumerate(nb.cells)
                if c.metadata.get("nbgrader", {}).get("grade_id") == gid)


def submission(observe: str | None = None, speed: str | None = None, *, extra_cells=(),
               edit=None):
    """A student version whose two solution cells hold ``observe`` and ``speed`` (None: the
    stub left as released); ``extra_cells`` are appended; ``edit(nb)`` changes it further."""
    nb = student()
    if observe is not None:
        nb.cells[solution_index(nb, "ex-observe")].source = observe
    if speed is not None:
        nb.cells[solution_index(nb, "ex-speed")].source = speed
    for c in extra_cells:
        nb.cells.append(copy.deepcopy(c))
    if edit is not None:
        edit(nb)
    return nb


def honest():
    return submission(OBSERVE_BODY, SPEED_BODY)


def write(nb, path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, path)


def marked_kernel_client():
    """annslam_lib.course.kernels.CourseKernelClient that appends a line to the file named
    by $ANNSLAM_CLIENT_MARK whenever one is made: shows that a tool's configuration
    (``c.AsyncKernelManager.client_class``) reached the kernels it starts."""
    import os

    from annslam_lib.course.kernels import CourseKernelClient

    class MarkedKernelClient(CourseKernelClient):
        def __init__(self, **kw):
            super().__init__(**kw)
            with open(os.environ["ANNSLAM_CLIENT_MARK"], "a") as f:
                f.write(f"{type(self).__mro__[1].__name__}\n")

    return MarkedKernelClient


MarkedKernelClient = marked_kernel_client()


# ------------------------------------------------------------- a real chapter, graded

def solution_bodies(notebook) -> dict:
    """{grade id: source} of an instructor notebook's solution cells, markers removed: the
    honest submission of that chapter."""
    out = {}
    for c in nbformat.read(notebook, as_version=4).cells:
        m = c.metadata.get("nbgrader", {})
        if m.get("solution"):
            out[m["grade_id"]] = "\n".join(line for line in c.source.splitlines()
                                           if "### BEGIN SOLUTION" not in line
                                           and "### END SOLUTION" not in line)
    return out


def grade_chapter(notebook, bodies: dict, folder, limits):
    """The released version of ``notebook`` with the solution cells ``bodies`` {grade id:
    source} filled in (the others left as stubs), written under ``folder`` and graded by
    the course's grader against ``notebook``."""
    from annslam_lib.course.grader import grade_submission

    nb = release.student_version(nbformat.read(notebook, as_version=4), notebook.stem)
    for c in nb.cells:
        gid = c.metadata.get("nbgrader", {}).get("grade_id")
        if gid in bodies:
            c.source = bodies[gid]
    path = folder / notebook.name
    write(nb, path)
    return grade_submission(path, notebook, limits=limits)


def both_feedbacks(check, fn) -> tuple[str, str]:
    """(the message a student's own check gives, the instructor's full feedback) of a check
    that fails on ``fn``."""
    import pytest

    from annslam_lib.grading.core import GradingError, full_feedback

    with pytest.raises(GradingError) as plain:
        check(fn, quiet=True)
    with full_feedback(), pytest.raises(GradingError) as full:
        check(fn, quiet=True)
    return str(plain.value), str(full.value)
