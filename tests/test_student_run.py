"""Run every student version top to bottom: it must fail exactly at the autograded cells,
each with the grading message, and nowhere else (no later cell may need a student's answer).

This executes each notebook a second time (the instructor copies run under nbval), so it is
the slowest test file; it has its own file so pytest-xdist can run it beside the others.
"""
from pathlib import Path

import pytest

from annslam_lib import release
from annslam_lib.grading import NOT_WRITTEN

ROOT = Path(__file__).resolve().parents[1]
GRADED = [p for p in sorted((ROOT / "notebooks").glob("*.ipynb")) if release.exercises(p)]


@pytest.fixture(scope="module")
def student(tmp_path_factory):
    out = tmp_path_factory.mktemp("student")
    return {p.name: p for p in release.release(GRADED, out)}


@pytest.mark.parametrize("path", GRADED, ids=lambda p: p.stem)
def test_student_version_fails_only_at_its_exercises_with_the_grading_message(path, student):
    g = release.grade(student[path.name], timeout=300)
    assert g.other_errors == [], f"cells that are not exercises failed: {g.other_errors}"
    assert len(g.results) >= 2 and g.score == 0
    for r in g.results:
        assert r.error.startswith("GradingError: "), f"{r.grade_id}: {r.error[:300]}"
        assert NOT_WRITTEN in r.error, f"{r.grade_id}: {r.error[:300]}"
