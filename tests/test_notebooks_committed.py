"""The committed instructor notebooks as a reader opens them (no kernel): every code cell
ran, in order, on one kernel; nothing failed, nothing warned; every autograded check
passed on the instructor's solution and says so; no output names a path of the machine
that ran it; every figure fits the text column. (nbval re-runs them and compares the outputs; it cannot see a check that
failed under a ``raises-exception`` tag, a warning on stderr it is told to ignore, or a
stale execution order.)"""
import base64
import re
import struct
from pathlib import Path

import nbformat
import pytest

NOTEBOOKS = sorted(p for p in (Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb")
                   if re.match(r"\d\d[a-z]?_", p.name))
MACHINE_PATH = re.compile(r"(/work/|/home/|/root/|/tmp/|/Users/|[A-Z]:\\\\)")


def _text(output) -> str:
    if output.output_type == "stream":
        return output.text
    if output.output_type == "error":
        return "\n".join(output.traceback)
    data = output.get("data", {})
    return "\n".join(str(data.get(k, "")) for k in ("text/plain", "text/markdown", "text/html"))


def test_the_course_has_its_chapters():
    """Chapters 00-11, each once, and the ones inserted between them (01a, 04a, 05a) lettered."""
    names = [p.name for p in NOTEBOOKS]
    assert all(re.fullmatch(r"\d\d[a-z]?_[a-z0-9_]+\.ipynb", n) for n in names), names
    assert sorted({n[:2] for n in names}) == [f"{i:02d}" for i in range(12)]
    assert [n.split("_")[0] for n in names if not n[2] == "_"] == ["01a", "04a", "05a"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_committed_notebook_ran_cleanly(path):
    nb = nbformat.read(path, as_version=4)
    code = [(i, c) for i, c in enumerate(nb.cells) if c.cell_type == "code"]
    counts = [c.execution_count for _, c in code]
    assert counts == list(range(1, len(code) + 1)), f"{path.name}: not one Run All in order"
    problems = []
    for i, c in code:
        for o in c.outputs:
            text = _text(o)
            if o.output_type == "error":
                problems.append(f"cell {i}: {o.ename}: {o.evalue[:120]}")
            elif o.output_type == "stream" and o.name == "stderr":
                problems.append(f"cell {i}: stderr: {text[:120]}")
            if MACHINE_PATH.search(text):
                problems.append(f"cell {i}: a machine path in the output: "
                                f"{MACHINE_PATH.search(text).group(0)}")
        meta = c.metadata.get("nbgrader", {})
        if meta.get("grade") and not meta.get("solution"):
            said = "".join(_text(o) for o in c.outputs)
            if "✓" not in said:
                problems.append(f"cell {i} ({meta.get('grade_id')}): the check did not report a pass")
    # widgets' Output areas (saved widget state): a callback that failed shows it there
    state = nb.metadata.get("widgets", {}).get("application/vnd.jupyter.widget-state+json", {})
    for wid, w in state.get("state", {}).items():
        for o in w.get("state", {}).get("outputs", []):
            if o.get("output_type") == "error" or (o.get("output_type") == "stream"
                                                   and o.get("name") == "stderr"):
                problems.append(f"widget {wid[:8]}: {o.get('ename', 'stderr')}: "
                                f"{str(o.get('evalue', o.get('text', '')))[:120]}")
    assert problems == [], f"{path.name}:\n" + "\n".join(problems)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_figures_fit_the_text_column(path):
    """Figures are drawn plots.style.FIG_WIDTH wide at its DPI (about 1000 px, JupyterLab's
    text column at 100 % zoom): none wider (labels or a title spilling past the figure grow
    the saved image), none so narrow that its fonts end up small next to the others."""
    from annslam_lib.plots.style import DPI, FIG_WIDTH

    full = FIG_WIDTH * DPI
    nb = nbformat.read(path, as_version=4)
    bad = []
    for i, c in enumerate(nb.cells):
        for o in c.get("outputs", []):
            png = o.get("data", {}).get("image/png")
            if png:
                raw = base64.b64decode(png)
                assert raw[:8] == b"\x89PNG\r\n\x1a\n"
                width, height = struct.unpack(">II", raw[16:24])
                if not (0.5 * full <= width <= 1.03 * full) or height > 1.2 * full:
                    bad.append(f"cell {i}: {width} x {height} px")
    assert bad == [], f"{path.name}: figures outside {0.5 * full:.0f}-{1.03 * full:.0f} px wide: {bad}"
