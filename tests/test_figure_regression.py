"""The figure comparison added to nbval (the repository's conftest.py), end to end: a small
notebook executed once, then checked by a real ``pytest --nbval`` run after its stored figure
was left alone, redrawn with another curve, touched in a few pixels, or duplicated."""
import base64
import io
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


def _executed(power: float) -> nbformat.NotebookNode:
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(CELL.format(power=power))],
                                  metadata={"kernelspec": {"name": "python3", "language": "python",
                                                           "display_name": "Python 3"}})
    NotebookClient(nb, timeout=120, kernel_name="python3").execute()
    return nb


@pytest.fixture(scope="module")
def stored():
    return _executed(2), _executed(3)


def _png_index(nb):
    return next(i for i, o in enumerate(nb.cells[0].outputs) if "image/png" in o.get("data", {}))


def _nbval(tmp_path, nb) -> subprocess.CompletedProcess:
    shutil.copy(ROOT / "conftest.py", tmp_path / "conftest.py")
    nbformat.write(nb, tmp_path / "fig.ipynb")
    return subprocess.run([sys.executable, "-m", "pytest", "--nbval", "--nbval-current-env",
                           "-p", "no:cacheprovider", "-p", "no:xdist", "-o", "addopts=",
                           "fig.ipynb"], cwd=tmp_path, capture_output=True, text=True, timeout=300)


def test_an_unchanged_figure_passes(stored, tmp_path):
    run = _nbval(tmp_path, stored[0])
    assert run.returncode == 0, run.stdout[-2000:]
    assert "1 passed" in run.stdout


def test_a_redrawn_curve_fails_with_the_difference(stored, tmp_path):
    nb, other = nbformat.from_dict(stored[0]), stored[1]
    i = _png_index(nb)
    nb.cells[0].outputs[i]["data"]["image/png"] = other.cells[0].outputs[_png_index(other)]["data"]["image/png"]
    run = _nbval(tmp_path, nb)
    assert run.returncode == 1, run.stdout[-2000:]
    assert "figure 1 of the cell changed" in run.stdout and "of the pixels differ" in run.stdout


def test_a_few_changed_pixels_pass_and_a_patch_fails(stored, tmp_path):
    nb = nbformat.from_dict(stored[0])
    i = _png_index(nb)
    raw = matplotlib.image.imread(io.BytesIO(base64.b64decode(nb.cells[0].outputs[i]["data"]["image/png"])))
    for patch, expect in ((3, 0), (40, 1)):          # 3 x 3 px (0.01 %) passes, 40 x 40 fails
        img = raw.copy()
        img[100:100 + patch, 100:100 + patch, :3] = 1.0 - img[100:100 + patch, 100:100 + patch, :3]
        buf = io.BytesIO()
        matplotlib.image.imsave(buf, np.clip(img, 0, 1), format="png")
        nb.cells[0].outputs[i]["data"]["image/png"] = base64.b64encode(buf.getvalue()).decode()
        run = _nbval(tmp_path, nb)
        assert run.returncode == expect, (patch, run.stdout[-2000:])


def test_a_missing_figure_fails(stored, tmp_path):
    nb = nbformat.from_dict(stored[0])
    i = _png_index(nb)
    nb.cells[0].outputs.insert(i, nbformat.from_dict(dict(nb.cells[0].outputs[i])))
    run = _nbval(tmp_path, nb)
    assert run.returncode == 1 and ("figure(s)" in run.stdout or "dissimilar number" in run.stdout), \
        run.stdout[-2000:]
