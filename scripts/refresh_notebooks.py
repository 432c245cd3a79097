"""Re-execute course notebooks in place, top to bottom, on a fresh kernel each.

    python scripts/refresh_notebooks.py               # every notebooks/*.ipynb
    python scripts/refresh_notebooks.py notebooks/01_kinematics.ipynb

Use ./course.sh refresh, which fixes the BLAS thread count first: stored outputs
are compared digit for digit by strict nbval.
"""
import sys
from pathlib import Path

import nbformat

from annslam_lib.course import kernels

ROOT = Path(__file__).resolve().parents[1]


def refresh(path: Path) -> float:
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:  # a clean slate: no stale outputs or timing metadata
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
            cell.metadata.pop("execution", None)
    seconds = kernels.run_notebook(nb, path.parent, timeout=900)
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
