"""Fill the study cache for a class: one Run All of every notebook, so that the heavy studies
(``annslam_lib._cache``) are computed once, here, instead of at each student's first Run All.

``python -m annslam_lib cache warm [--notebooks DIR]`` runs each notebook of DIR (default: the
course's ``notebooks/``) on a fresh kernel of this interpreter, with this process's
environment (its ``ANNSLAM_CACHE`` is the folder filled; its BLAS thread settings are part of
every key, so warm with the settings the class's kernels have). Student versions raise at
their exercises: execution goes on past them, and the cells that raised are counted, not
hidden. The hub's set-up runs it with the students' own environment into the class's
read-only folder (``ANNSLAM_CLASS_CACHE`` of every server).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

__all__ = ["warm_studies"]


def warm_studies(notebooks, *, timeout: float = 600, log=print) -> dict:
    """Run All of each notebook in ``notebooks`` (paths); returns ``{"notebooks": n,
    "entries": entries in the cache folder after, "new": entries added, "raised": cells that
    raised, by notebook name, "seconds": wall seconds by notebook name}``."""
    import nbformat

    from .. import _cache
    from . import kernels

    folder = _cache.cache_dir()
    if folder is None:
        raise ValueError("the study cache is off (ANNSLAM_CACHE=off): nothing to warm")
    paths = [Path(p) for p in notebooks]
    if not paths:
        raise ValueError("no notebooks to run")
    before = {p.name for p in folder.glob("*.pkl")} if folder.is_dir() else set()
    raised, seconds = {}, {}
    for path in paths:
        nb = nbformat.read(path, as_version=4)
        with tempfile.TemporaryDirectory() as work:     # what a notebook writes goes nowhere
            seconds[path.name] = kernels.run_notebook(nb, work, timeout=timeout,
                                                      allow_errors=True)
        raised[path.name] = sum(1 for c in nb.cells if c.cell_type == "code"
                                for o in c.get("outputs", []) if o.get("output_type") == "error")
        log(f"{path.name}: {seconds[path.name]:.1f} s"
            + (f", {raised[path.name]} cell(s) raised" if raised[path.name] else ""))
    after = {p.name for p in folder.glob("*.pkl")} if folder.is_dir() else set()
    return {"notebooks": len(paths), "entries": len(after), "new": len(after - before),
            "raised": raised, "seconds": seconds}
