"""The figure comparison added to nbval (the repository's conftest.py), end to end: a small
notebook executed once, then checked by a real ``pytest --nbval`` run after its stored figure
was left alone, redrawn with another curve, touched in a few pixels, or duplicated."""
import base64
import io
import os
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import nbformat
import numpy as np
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
CELL = """import matplotlib
matplotlib.use("module://matplotlib_inline.backend_inline")
import matplotlib.pyplot as plt
import numpy as np
fig, ax = plt.subplots(figsize=(4, 3), dpi=80)
ax.plot(np.linspace(0, 1, 50), np.linspace(0, 1, 50) ** {power})
ax.set_title("a curve")
plt.show()
print("drawn")"""


def _executed(power: float, cells: int = 1) -> nbformat.NotebookNode:
    nb = nbformat.v4.new_notebook(
        cells=[nbformat.v4.new_code_cell(CELL.format(power=power)) for _ in range(cells)],
        metadata={"kernelspec": {"name": "python3", "language": "python", "display_name": "Python 3"}})
    NotebookClient(nb, timeout=120, kernel_name="python3").execute()
    return nb


@pytest.fixture(scope="module")
def stored():
    return _executed(2, cells=3), _executed(3)


def _png(nb, cell=0):
    outs = nb.cells[cell].outputs
    i = next(i for i, o in enumerate(outs) if "image/png" in o.get("data", {}))
    return outs, i


def _nbval(tmp_path, nb) -> subprocess.CompletedProcess:
    shutil.copy(ROOT / "conftest.py", tmp_path / "conftest.py")
    nbformat.write(nb, tmp_path / "fig.ipynb")
    return subprocess.run([sys.executable, "-m", "pytest", "--nbval", "--nbval-current-env",
                           "-p", "no:cacheprovider", "-p", "no:xdist", "-o", "addopts=", "-rf",
                           "fig.ipynb"], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "COLUMNS": "80"})


def _patched(b64: str, size: int) -> str:
    """The PNG with a size x size square of its pixels inverted."""
    img = matplotlib.image.imread(io.BytesIO(base64.b64decode(b64))).copy()
    img[100:100 + size, 100:100 + size, :3] = 1.0 - img[100:100 + size, 100:100 + size, :3]
    buf = io.BytesIO()
    matplotlib.image.imsave(buf, np.clip(img, 0, 1), format="png")
    return base64.b64encode(buf.getvalue()).decode()


def test_unchanged_and_nearly_unchanged_figures_pass(stored, tmp_path):
    nb = nbformat.from_dict(stored[0])
    outs, i = _png(nb, 1)
    outs[i]["data"]["image/png"] = _patched(outs[i]["data"]["image/png"], 3)   # 9 px: 0.01 %
    run = _nbval(tmp_path, nb)
    assert run.returncode == 0, run.stdout[-2000:]
    assert "3 passed" in run.stdout


def test_a_redrawn_curve_a_patch_and_a_missing_figure_fail(stored, tmp_path):
    nb, other = nbformat.from_dict(stored[0]), stored[1]
    outs, i = _png(nb, 0)                                   # cell 1: another curve
    o_outs, j = _png(other, 0)
    outs[i]["data"]["image/png"] = o_outs[j]["data"]["image/png"]
    outs, i = _png(nb, 1)                                   # cell 2: a 40 x 40 px patch
    outs[i]["data"]["image/png"] = _patched(outs[i]["data"]["image/png"], 40)
    outs, i = _png(nb, 2)                                   # cell 3: two figures stored
    outs.insert(i, nbformat.from_dict(dict(outs[i])))
    run = _nbval(tmp_path, nb)
    assert run.returncode == 1, run.stdout[-2000:]
    assert "3 failed" in run.stdout, run.stdout[-2000:]
    # The failure reports only: the short summary repeats messages as far as the terminal is wide.
    report = run.stdout.split("short test summary info")[0]
    assert report.count("figure 1 of the cell changed") == 2, report[-3000:]
    assert "of the pixels differ" in run.stdout
    assert "figure(s)" in run.stdout or "dissimilar number" in run.stdout


def test_a_figure_whose_alt_text_changed_fails(stored, tmp_path):
    """The alt text is compared as the pixels are: a stored figure whose alt text the code
    no longer produces (here: the cell draws without one) fails, naming what changed."""
    nb = nbformat.from_dict(stored[0])
    outs, i = _png(nb, 1)
    outs[i].setdefault("metadata", {})["image/png"] = {"alt": "Figure: a curve that rises."}
    run = _nbval(tmp_path, nb)
    assert run.returncode == 1, run.stdout[-2000:]
    assert "1 failed, 2 passed" in run.stdout, run.stdout[-2000:]
    assert "the alt text of figure 1 of the cell changed" in run.stdout
