"""Run All in every student version reaches the last cell (the README's promise).

Each student version (the course's release) is executed top to bottom with nbclient (the
course's client, :mod:`annslam_lib.course.kernels`: a stalled client fails loudly),
``allow_errors=False``: only the autograded test cells may raise (they carry the
``raises-exception`` tag that JupyterLab's Run All and nbclient honour), each with the
grading message "my_... is not written yet", shown as the message alone (GradingError's
``_render_traceback_``), not a traceback into the grading code. Any other cell raising, or
a later cell needing a student's answer, fails the test.
"""
from pathlib import Path

import nbformat
import pytest

from annslam_lib.course import kernels, release
from annslam_lib.grading import NOT_WRITTEN

ROOT = Path(__file__).resolve().parents[1]
GRADED = [p for p in sorted((ROOT / "notebooks").glob("*.ipynb")) if release.exercises(p)]
MAX_FEEDBACK_LINES = 6


@pytest.fixture(scope="module")
def student(tmp_path_factory):
    out = tmp_path_factory.mktemp("student")
    return {p.name: p for p in release.release(GRADED, out)}


def _is_stub(cell) -> bool:
    m = cell.metadata.get("nbgrader", {})
    return (bool(m.get("solution")) and not m.get("grade")
            and cell.source.strip().endswith("raise NotImplementedError()")
            and not cell.source.lstrip().startswith("def "))


def _is_test(cell) -> bool:
    m = cell.metadata.get("nbgrader", {})
    return bool(m.get("grade")) and not m.get("solution")


@pytest.mark.parametrize("path", GRADED, ids=lambda p: p.stem)
def test_run_all_reaches_the_end_and_only_the_exercises_say_not_written(path, student):
    nb = nbformat.read(student[path.name], as_version=4)
    kernels.run_notebook(nb, student[path.name].parent, timeout=300)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code[-1].get("execution_count") is not None, "Run All did not reach the last cell"
    errors = {i: o for i, c in enumerate(nb.cells) if c.cell_type == "code"
              for o in c.get("outputs", []) if o.get("output_type") == "error"}
    tests = {i for i, c in enumerate(nb.cells) if c.cell_type == "code" and _is_test(c)}
    # an ungraded exercise's stub (top-level code, tagged raises-exception by the release)
    stubs = {i for i, c in enumerate(nb.cells) if c.cell_type == "code" and _is_stub(c)}
    assert set(errors) == tests | stubs, (f"cells that raised: {sorted(errors)}, test cells: "
                                          f"{sorted(tests)}, ungraded stubs: {sorted(stubs)}")
    for i in stubs:
        assert errors[i]["ename"] == "NotImplementedError", errors[i]
        assert "raises-exception" in nb.cells[i].metadata.get("tags", [])
    for i, out in ((i, o) for i, o in errors.items() if i in tests):
        assert out["ename"] == "GradingError" and NOT_WRITTEN in out["evalue"], out["evalue"]
        shown = "\n".join(out["traceback"])
        assert len(out["traceback"]) <= MAX_FEEDBACK_LINES, shown
        assert "File " not in shown and "Traceback" not in shown, shown   # no grading frames
        assert NOT_WRITTEN in shown
