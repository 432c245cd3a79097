"""Re-execute course notebooks in place, top to bottom, on a fresh kernel each.

    python scripts/refresh_notebooks.py               # every notebooks/*.ipynb
    python scripts/refresh_notebooks.py notebooks/01_kinematics.ipynb

Use ./course.sh refresh, which fixes the BLAS thread count first: stored outputs
are compared digit for digit by strict nbval.
"""
import json
import sys
from pathlib import Path

import nbformat

from annslam_lib.course import kernels
from annslam_lib.plots import frames

ROOT = Path(__file__).resolve().parents[1]


def refresh(path: Path) -> float:
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:  # a clean slate: no stale outputs or timing metadata
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
            cell.metadata.pop("execution", None)
    # the widgets marked for the website's animations: their frames are captured in the
    # notebook's own kernel after Run All, by cells added at the end and removed again
    marked = [c for c in nb.cells if c.cell_type == "code"
              and "animate" in c.metadata.get("annslam", {})]
    for cell in marked:
        cell.metadata["annslam"].pop("frames", None)
        control = cell.metadata["annslam"]["animate"]["control"]
        nb.cells.append(nbformat.v4.new_code_cell(
            "from annslam_lib.plots import frames as _frames\n"
            f"_frames.emit(In, Out, {cell.source!r}, {control!r})"))
    seconds = kernels.run_notebook(nb, path.parent, timeout=900)
    added = nb.cells[len(nb.cells) - len(marked):]
    del nb.cells[len(nb.cells) - len(marked):]
    for cell, extra in zip(marked, added):
        text = "".join(o.get("text", "") for o in extra.outputs if o.output_type == "stream")
        line = next(x for x in text.splitlines() if x.startswith(frames.MARKER))
        cell.metadata["annslam"]["frames"] = json.loads(line[len(frames.MARKER):])["frames"]
    nbformat.write(nb, path)
    return seconds


def main(argv: list[str]) -> int:
    paths = [Path(p).resolve() for p in argv] or sorted((ROOT / "notebooks").glob("*.ipynb"))
    for p in paths:
        print(f"executing {p.relative_to(ROOT)} ...", flush=True)
        print(f"  done in {refresh(p):.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
