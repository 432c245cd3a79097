"""Run All in every student version reaches the last cell (the README's promise), run with
nbclient (the course's client, :mod:`annslam_lib.course.kernels`: a stalled client fails
loudly). JupyterLab's Run All executes the same cells in the same kernel; the browser tests
(tests/test_browser_widgets_*.py) drive the widgets in JupyterLab on small notebooks, so
that a whole chapter is not rendered in Chromium on top of its kernel's work. What is
checked: tests/student_run_checks.py.
"""
from pathlib import Path

import nbformat
import pytest
from student_run_checks import check_student_run

from annslam_lib.course import kernels, release

ROOT = Path(__file__).resolve().parents[1]
GRADED = [p for p in sorted((ROOT / "notebooks").glob("*.ipynb")) if release.exercises(p)]


@pytest.fixture(scope="module")
def student(tmp_path_factory):
    out = tmp_path_factory.mktemp("student")
    return {p.name: p for p in release.release(GRADED, out)}


@pytest.mark.parametrize("path", GRADED, ids=lambda p: p.stem)
def test_run_all_reaches_the_end_and_only_the_exercises_say_not_written(path, request):
    student = request.getfixturevalue("student")
    nb = nbformat.read(student[path.name], as_version=4)
    kernels.run_notebook(nb, student[path.name].parent, timeout=300)
    check_student_run(nb)
