"""What a student's Run All must show (the README's promise), checked on an executed student
version by tests/test_student_run.py.

Run All reaches the last cell; only the autograded test cells (tagged ``raises-exception``,
which JupyterLab's Run All and nbclient honour) and the ungraded exercise stubs raise; a test
cell says "my_... is not written yet" as the message alone (GradingError's
``_render_traceback_``), not a traceback into the grading code.
"""
from annslam_lib.grading import NOT_WRITTEN

MAX_FEEDBACK_LINES = 6


def _is_stub(cell) -> bool:
    m = cell.metadata.get("nbgrader", {})
    return (bool(m.get("solution")) and not m.get("grade")
            and cell.source.strip().endswith("raise NotImplementedError()")
            and not cell.source.lstrip().startswith("def "))


def _is_test(cell) -> bool:
    m = cell.metadata.get("nbgrader", {})
    return bool(m.get("grade")) and not m.get("solution")


def check_student_run(nb) -> None:
    """Assert the above on ``nb``, an executed student version (nbformat)."""
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
