"""Stored figures are part of nbval's comparison.

nbval compares text outputs and skips ``image/png`` (without nbdime), so a figure could
change silently while every printed number stays the same. This hook extends its comparison
of each cell (not the ones marked ``# NBVAL_IGNORE_OUTPUT``, which nbval does not compare at
all): the cell must produce as many PNG figures as are stored, each of the same size, and
differing in at most FIGURE_PIXEL_TOLERANCE of its pixels by more than FIGURE_LEVEL_TOLERANCE
in any channel (anti-aliasing noise passes; a moved curve, a changed label or colour fails),
and carrying the same alt text (``annslam_lib.plots.alt``) as stored.
``tests/test_figure_regression.py`` runs it end to end on a small notebook.
"""
from __future__ import annotations

import base64
import io
import os
import shutil
import tempfile

import pytest

FIGURE_PIXEL_TOLERANCE = 5e-4        # fraction of the pixels
FIGURE_LEVEL_TOLERANCE = 0.1         # of the 0..1 channel range


def png_difference(stored_b64: str, new_b64: str) -> str | None:
    """None if the two base64 PNGs agree within the tolerances, else what differs."""
    import matplotlib.image
    import numpy as np

    a = matplotlib.image.imread(io.BytesIO(base64.b64decode(stored_b64)))[..., :3]
    b = matplotlib.image.imread(io.BytesIO(base64.b64decode(new_b64)))[..., :3]
    if a.shape != b.shape:
        return f"size {b.shape[1]} x {b.shape[0]} px, stored {a.shape[1]} x {a.shape[0]} px"
    off = np.abs(a - b).max(axis=2) > FIGURE_LEVEL_TOLERANCE
    frac = float(off.mean())
    if frac > FIGURE_PIXEL_TOLERANCE:
        rows, cols = np.nonzero(off)
        return (f"{100 * frac:.2f} % of the pixels differ (tolerance "
                f"{100 * FIGURE_PIXEL_TOLERANCE:.2f} %), within x {cols.min()}-{cols.max()}, "
                f"y {rows.min()}-{rows.max()} px")
    return None


def _pngs(outputs) -> list[str]:
    found = []
    for o in outputs:
        data = o.get("data", {}) if hasattr(o, "get") else {}
        png = data.get("image/png")
        if png:
            found.append(png if isinstance(png, str) else "".join(png))
    return found


def _alts(outputs) -> list[str]:
    """The alt text of each PNG output ('' where there is none)."""
    return [(o.get("metadata") or {}).get("image/png", {}).get("alt", "")
            for o in outputs if hasattr(o, "get") and "image/png" in o.get("data", {})]


def pytest_configure(config):
    _own_study_cache(config)
    _compile_library(config)
    try:
        from nbval.plugin import IPyNbCell
    except ImportError:            # nbval not installed: nothing to extend
        return
    if getattr(IPyNbCell, "_annslam_figures", False):
        return
    compare_text = IPyNbCell.compare_outputs

    def compare_outputs(self, test, ref, skip_compare=None):
        if not compare_text(self, test, ref, skip_compare):
            return False
        new, stored = _pngs(test), _pngs(ref)
        if len(new) != len(stored):
            self.comparison_traceback.append(
                f"the cell drew {len(new)} figure(s), {len(stored)} stored")
            return False
        for k, (s, n) in enumerate(zip(stored, new)):
            problem = png_difference(s, n)
            if problem:
                self.comparison_traceback.append(
                    f"figure {k + 1} of the cell changed: {problem}. If the change is meant, "
                    "refresh the notebook (./course.sh refresh) and look at the new figure.")
                return False
        for k, (s, n) in enumerate(zip(_alts(ref), _alts(test))):
            if s != n:
                self.comparison_traceback.append(
                    f"the alt text of figure {k + 1} of the cell changed: stored {s!r}, now "
                    f"{n!r}. Refresh the notebook (./course.sh refresh).")
                return False
        return True

    IPyNbCell.compare_outputs = compare_outputs
    IPyNbCell._annslam_figures = True


# ------------------------------------------------------------------ scheduling on workers
# `./course.sh test` runs on two pytest-xdist workers. A test module (and a notebook's cells)
# runs on one worker, so that its module fixtures are built once and a notebook's cells run
# in order in one kernel, as `--dist loadfile` does; except the modules in SPLIT, whose tests
# are independent Run Alls of one chapter each (the student versions, with nbclient), which
# go to whichever worker is free (a browser test module stays whole: one JupyterLab and one
# Chromium for its chapters). Work is
# handed out longest first (HEAVY_FIRST, then the rest in collection order; inside a SPLIT
# module the later, longer chapters first; every notebook before the short test modules),
# so that no worker is left with a long test at
# the end while the other idles (`--no-loadscope-reorder` keeps this order). xdist's own
# `--dist loadgroup` cannot do this with pytest 9.2: it renames node ids, which pytest 9.2
# no longer lets it do, and silently falls back to sending single tests.
SPLIT = ("tests/test_student_run.py",)
HEAVY_FIRST = ("tests/test_hub.py", "tests/test_install.py", "tests/test_grader_nbgrader.py",
               "tests/test_grader_attacks.py",
               "notebooks/08", "notebooks/10", "notebooks/05", "notebooks/07", "notebooks/06",
               "notebooks/",
               # after the instructor versions: the student versions' Run Alls and the
               # widget notebooks read the studies those computed (one cache per session)
               "tests/test_student_run.py", "tests/test_browser_widgets_0508.py",
               "tests/test_browser_widgets_0104.py",
               "tests/test_consistency.py", "tests/test_browser.py",
               "tests/test_figure_regression.py", "tests/test_workspace.py")


def _path(nodeid: str) -> str:
    return nodeid.split("::")[0]


def _rank(path: str) -> int:
    return next((k for k, p in enumerate(HEAVY_FIRST) if path.startswith(p)), len(HEAVY_FIRST))


def pytest_collection_modifyitems(config, items):
    order = {id(item): k for k, item in enumerate(items)}

    def key(item):
        path = _path(item.nodeid)
        return (_rank(path), -order[id(item)] if path in SPLIT else order[id(item)])

    items.sort(key=key)


@pytest.hookimpl(optionalhook=True)          # xdist's hook: absent under -p no:xdist
def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class CourseScheduling(LoadScopeScheduling):
        """One work unit per module (per notebook), one per test in SPLIT's modules."""

        def _split_scope(self, nodeid: str) -> str:
            path = _path(nodeid)
            return nodeid if path in SPLIT else path

    return CourseScheduling(config, log)


def _compile_library(config) -> None:
    """The library's bytecode, written once before the workers start: the grader watches
    every file of the library, ``__pycache__`` included, while it grades (a change stops
    it), so no test process may be the first to write one meanwhile."""
    if hasattr(config, "workerinput"):
        return
    import compileall
    import sys

    prefix, sys.pycache_prefix = sys.pycache_prefix, None
    try:
        compileall.compile_dir(os.path.join(os.path.dirname(__file__), "annslam_lib"), quiet=2)
    finally:
        sys.pycache_prefix = prefix


def _own_study_cache(config) -> None:
    """One study cache for this test session (annslam_lib._cache), made here in the main
    process and inherited by the workers and every kernel they start: each cached study is
    computed at least once per test session (never read from an earlier test session's
    code), and the second notebook run that needs it (nbval's, the browser's) reads it back."""
    if hasattr(config, "workerinput") or os.environ.get("ANNSLAM_CACHE"):
        return
    folder = tempfile.mkdtemp(prefix="annslam-study-cache-")
    os.environ["ANNSLAM_CACHE"] = folder
    config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
