"""The instructor notebooks' own solutions, as functions, for the tests of the checks.

The tests of a check must show that the chapter's solution, as the notebook has it, passes:
so the solution is read from the notebook (its solution cell, markers included), never
pasted into a test file. Each chapter's solution cells run in a namespace holding only the
notebook's import statements (running the whole notebook takes seconds).
"""
from __future__ import annotations

import ast
import functools
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]


def _chapter_path(chapter: str) -> Path:
    # '01' is 01_kinematics, not also 01a_kalman_filter: the number alone first
    found = (sorted((ROOT / "notebooks").glob(f"{chapter}_*.ipynb"))
             or sorted((ROOT / "notebooks").glob(f"{chapter}*.ipynb")))
    if len(found) != 1:
        raise LookupError(f"no single notebook matches {chapter!r}: {found}")
    return found[0]


@functools.lru_cache(maxsize=None)
def chapter(name: str) -> dict:
    """{function name: function} of every solution cell of notebook ``name`` (a prefix of
    its file name, e.g. '03' or '03_observation')."""
    nb = nbformat.read(_chapter_path(name), as_version=4)
    ns: dict = {"__name__": f"solutions_{name}"}
    code = [c for c in nb.cells if c.cell_type == "code"]
    for c in code:
        try:
            tree = ast.parse(c.source)
        except SyntaxError:                     # a cell with IPython magics
            continue
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                exec(compile(ast.unparse(node), "<imports>", "exec"), ns)
    out = {}
    for c in code:
        meta = c.metadata.get("nbgrader", {})
        if meta.get("solution"):
            # Only the functions: an ungraded exercise's solution cell is top-level code
            # that needs the notebook's earlier state.
            tree = ast.parse(c.source)
            defs = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
            for node in defs:
                exec(compile(ast.Module([node], []), f"<{name} {meta['grade_id']}>", "exec"), ns)
                out[node.name] = ns[node.name]
    if not out:
        raise LookupError(f"notebook {name!r} has no solution cells")
    return out


def solution(name: str, function: str):
    """The solution function ``function`` of notebook ``name``."""
    return chapter(name)[function]
