"""Run All in every student version reaches the last cell (the README's promise).

Where JupyterLab and Chromium run, tests/test_browser_widgets_*.py check it on the notebook
JupyterLab itself executed and saved (what a student sees), so the course is not executed a
third time here; without a browser, this test checks the same with nbclient (the course's
client, :mod:`annslam_lib.course.kernels`: a stalled client fails loudly). What is checked:
tests/student_run_checks.py.
"""
from pathlib import Path

import nbformat
import pytest
from browser_support import why_no_browser
from browser_widgets import notebooks
from student_run_checks import check_student_run

from annslam_lib.course import kernels, release

ROOT = Path(__file__).resolve().parents[1]
GRADED = [p for p in sorted((ROOT / "notebooks").glob("*.ipynb")) if release.exercises(p)]


IN_BROWSER = set(notebooks(1, 8)) if why_no_browser() is None else set()


@pytest.fixture(scope="module")
def student(tmp_path_factory):
    out = tmp_path_factory.mktemp("student")
    return {p.name: p for p in release.release(GRADED, out)}


@pytest.mark.parametrize("path", GRADED, ids=lambda p: p.stem)
def test_run_all_reaches_the_end_and_only_the_exercises_say_not_written(path, request):
    if path.stem in IN_BROWSER:
        pytest.skip("checked in JupyterLab on the student version by "
                    "tests/test_browser_widgets_*.py (this machine has a browser)")
    student = request.getfixturevalue("student")
    nb = nbformat.read(student[path.name], as_version=4)
    kernels.run_notebook(nb, student[path.name].parent, timeout=300)
    check_student_run(nb)
