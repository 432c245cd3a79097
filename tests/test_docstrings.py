"""The library functions students call from the notebooks carry numpydoc docstrings: a
``Parameters`` section naming every parameter of the signature, a ``Returns`` (or
``Yields``) section unless the function returns None, and a ``Raises`` section when its own
body raises (errors raised by the functions it calls are documented where they matter, not
checked here).

The list is read from the notebooks, not kept by hand: every code cell of
``notebooks/*.ipynb`` is parsed (ast; IPython magics and shell lines, ``%`` and ``!``, are
blanked first; a cell that still does not parse is read with regular expressions), the names
imported from ``annslam_lib.models``, ``annslam_lib.slam`` and ``annslam_lib.evaluation``
(``from annslam_lib.slam import runner``, ``from annslam_lib.models.observation import
observe as h``) are followed through every use in the notebook's code (``runner.run(...)``,
``h(...)``, ``SlamConfig.for_dataset(...)``, a class passed as a value), and what they
resolve to is kept when it is a function or class defined in one of those three layers. A
class documents its constructor's parameters in the class docstring. Methods called on
instances are not followed.
"""
from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import json
import re
import textwrap
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
LAYERS = ("models", "slam", "evaluation")
#: The modules whose names a notebook may import: a layer or one of its modules.
_SOURCE = re.compile(r"^annslam_lib\.(?:%s)(?:\.\w+)?$" % "|".join(LAYERS))
_FROM = re.compile(r"^\s*from\s+(annslam_lib\.[\w.]+)\s+import\s+(?:\(([^)]*)\)|([^\n#]*))",
                   re.M)
_DOTTED = re.compile(r"(?<![\w.])([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*)")
#: Fewer names than this means the notebook reader broke (about 65 are found).
AT_LEAST = 55


# ------------------------------------------------------------------ the notebooks' names

def _code_cells(path: Path) -> list[str]:
    """The sources of a notebook's code cells, magics and shell lines blanked."""
    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    out = []
    for cell in cells:
        if cell["cell_type"] != "code":
            continue
        src = cell["source"] if isinstance(cell["source"], str) else "".join(cell["source"])
        out.append("\n".join("" if line.lstrip().startswith(("%", "!")) else line
                             for line in src.splitlines()))
    return out


def _imports(src: str, tree: ast.Module | None) -> dict[str, tuple[str, str]]:
    """alias -> (module, name) of the layer imports of one cell."""
    found = {}
    if tree is not None:
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and _SOURCE.match(node.module):
                for a in node.names:
                    found[a.asname or a.name] = (node.module, a.name)
        return found
    for module, bracketed, names in _FROM.findall(src):
        names = bracketed or names
        if _SOURCE.match(module):
            for item in names.split(","):
                words = item.split()
                if words:
                    found[words[-1]] = (module, words[0])
    return found


def _chain(node: ast.AST) -> list[str] | None:
    """``a.b.c`` as ['a', 'b', 'c'], or None if it does not start with a name."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return [node.id] + parts[::-1] if isinstance(node, ast.Name) else None


def _uses(src: str, tree: ast.Module | None) -> list[list[str]]:
    """Every dotted name used in one cell (the longest chain: ``runner.run``, not also
    ``runner``)."""
    if tree is None:
        return [m.split(".") for m in _DOTTED.findall(src)]
    inner = {id(n.value) for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
    return [c for n in ast.walk(tree)
            if isinstance(n, (ast.Name, ast.Attribute)) and id(n) not in inner
            and (c := _chain(n))]


def _attribute(obj, name: str):
    """``obj.name``, importing a package's submodule when it is one."""
    if isinstance(obj, ModuleType) and hasattr(obj, "__path__"):
        full = f"{obj.__name__}.{name}"
        if importlib.util.find_spec(full) is not None:
            return importlib.import_module(full)
    return getattr(obj, name, None)


def _resolve(aliases: dict, parts: list[str]):
    if parts[0] not in aliases:
        return None
    module, name = aliases[parts[0]]
    obj = _attribute(importlib.import_module(module), name)
    for p in parts[1:]:
        if obj is None:
            return None
        obj = _attribute(obj, p)
    return obj


def _in_layers(obj) -> bool:
    """A function, method or class defined in one of the three layers."""
    if not (inspect.isroutine(obj) or inspect.isclass(obj)):
        return False
    parts = (getattr(obj, "__module__", None) or "").split(".")
    return len(parts) > 2 and parts[0] == "annslam_lib" and parts[1] in LAYERS


def student_facing(paths=NOTEBOOKS) -> dict:
    """{function or class: sorted notebook uses ('05_ekf_slam: runner.run', ...)} of every
    function and class of the three layers that the notebooks' code uses."""
    found: dict = {}
    for path in paths:
        cells = []
        for src in _code_cells(path):
            try:
                cells.append((src, ast.parse(src)))
            except SyntaxError:
                cells.append((src, None))
        aliases = {}
        for src, tree in cells:
            aliases.update(_imports(src, tree))
        for src, tree in cells:
            for parts in _uses(src, tree):
                obj = _resolve(aliases, parts)
                if _in_layers(obj):
                    found.setdefault(obj, set()).add(f"{path.stem}: {'.'.join(parts)}")
    return {obj: sorted(uses) for obj, uses in found.items()}


# ------------------------------------------------------------------ the numpydoc check

def sections(doc: str | None) -> dict[str, list[str]]:
    """numpydoc sections of a docstring: {header: its lines}, a header being a line
    followed by a line of dashes."""
    lines = inspect.cleandoc(doc or "").splitlines()
    out: dict[str, list[str]] = {}
    current = None
    k = 0
    while k < len(lines):
        line = lines[k]
        under = lines[k + 1].strip() if k + 1 < len(lines) else ""
        if line.strip() and len(under) >= 3 and set(under) == {"-"}:
            current = line.strip()
            out[current] = []
            k += 2
            continue
        if current is not None:
            out[current].append(line)
        k += 1
    return out


def documented_names(lines: list[str]) -> list[str]:
    """The names a Parameters section gives: its unindented lines, ``x : type`` or
    ``x, y : type`` or ``x``."""
    names = []
    for line in lines:
        if line.strip() and not line[0].isspace():
            names += [n.strip() for n in line.split(" : ")[0].split(",")]
    return names


def _body(fn) -> list[ast.AST] | None:
    """The nodes of a function's own body (not of functions or classes defined in it), read
    from its source; None when the source is unknown."""
    fn = inspect.unwrap(getattr(fn, "__func__", fn))
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(fn)))
    except (OSError, TypeError, SyntaxError):
        return None
    out, stack = [], list(ast.iter_child_nodes(tree.body[0]))
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        out.append(node)
        stack.extend(ast.iter_child_nodes(node))
    return out


def _returns_value(fn) -> bool:
    """Whether a function may return something other than None (a ``return value`` or a
    ``yield`` in its own body); True when the source is unknown."""
    body = _body(fn)
    return body is None or any(
        isinstance(n, (ast.Yield, ast.YieldFrom)) or (
            isinstance(n, ast.Return) and n.value is not None
            and not (isinstance(n.value, ast.Constant) and n.value.value is None))
        for n in body)


def _raises(fn) -> bool:
    """Whether a function's own body holds a ``raise`` statement."""
    return any(isinstance(n, ast.Raise) for n in _body(fn) or ())


def problems(obj) -> list[str]:
    """What the docstring of ``obj`` (a function, or a class for its constructor) lacks."""
    found = sections(obj.__doc__)
    params = list(inspect.signature(obj).parameters.values())
    if (params and params[0].name in ("self", "cls") and not inspect.isclass(obj)
            and "." in getattr(obj, "__qualname__", "")):   # a method read off its class
        params = params[1:]
    out = []
    if params or "Parameters" in found:
        if "Parameters" not in found:
            out.append("no Parameters section")
        else:
            named = set(documented_names(found["Parameters"]))
            missing = []
            for p in params:                   # *args, **kwargs: named or skipped
                if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD) and p.name not in named:
                    missing.append(p.name)
            if missing:
                out.append("parameters not documented: " + ", ".join(missing))
            known = {p.name for p in params} | {f"*{p.name}" for p in params} | {
                f"**{p.name}" for p in params}
            extra = sorted(named - known)
            if extra:
                out.append("documented but not in the signature: " + ", ".join(extra))
    if not inspect.isclass(obj) and _returns_value(obj) and not (
            {"Returns", "Yields"} & set(found)):
        out.append("no Returns section")
    if _raises(obj.__init__ if inspect.isclass(obj) else obj) and "Raises" not in found:
        out.append("raises, but no Raises section")
    return out


def _label(obj) -> str:
    return f"{obj.__module__}.{obj.__qualname__}"


STUDENT_FACING = student_facing()


def test_the_notebooks_name_enough_functions():
    assert len(STUDENT_FACING) >= AT_LEAST, sorted(_label(o) for o in STUDENT_FACING)
    assert all(m in {_label(o) for o in STUDENT_FACING} for m in (
        "annslam_lib.models.motion.predict", "annslam_lib.models.observation.observe",
        "annslam_lib.slam.runner.run", "annslam_lib.evaluation.consistency.chi2_band"))


def test_student_facing_functions_have_numpydoc_parameters_and_returns():
    offenders = []
    for obj in sorted(STUDENT_FACING, key=_label):
        found = problems(obj)
        if found:
            offenders.append(f"{_label(obj)} (used in {STUDENT_FACING[obj][0]}): "
                             + "; ".join(found))
    assert not offenders, (f"{len(offenders)} of {len(STUDENT_FACING)} student-facing "
                           "functions lack numpydoc sections:\n" + "\n".join(offenders))


# ------------------------------------------------------------------ the checks' own checks

def _planted(x, y, *, scale=1.0):
    """Scale a point.

    Parameters
    ----------
    x : float
        Abscissa, m.
    scale : float, optional

    Returns
    -------
    float
    """
    return scale * x


def _planted_silent(x, *args, **kwargs):
    """Print a point.

    Parameters
    ----------
    x : float
    """
    print(x)


def _planted_no_returns(x):
    """Double it.

    Parameters
    ----------
    x, unknown : float
    """
    return 2 * x


def _planted_raises(cls):
    """Make one.

    Parameters
    ----------
    cls : type

    Returns
    -------
    object
    """
    if not isinstance(cls, type):
        raise TypeError("not a class")
    return cls()


class _PlantedClass:
    """A thing.

    Parameters
    ----------
    a : int
    """

    def __init__(self, a, b):
        self.a, self.b = a, b

    def scaled(self, k):
        """Scaled.

        Parameters
        ----------
        k : float

        Returns
        -------
        float
        """
        return k * self.a


def test_the_check_finds_planted_defects():
    assert problems(_planted) == ["parameters not documented: y"]
    assert problems(_planted_silent) == []            # returns None; *args, **kwargs skipped
    assert problems(_planted_no_returns) == [
        "documented but not in the signature: unknown", "no Returns section"]
    assert problems(_planted_raises) == ["raises, but no Raises section"]   # cls: a parameter
    assert problems(_PlantedClass) == ["parameters not documented: b"]
    assert problems(_PlantedClass.scaled) == []       # self is not a parameter to document
    assert problems(_PlantedClass(1, 2).scaled) == []


def test_the_notebook_reader_follows_imports_aliases_and_unparsable_cells(tmp_path):
    cells = [
        "%matplotlib inline\nfrom annslam_lib.models import motion\n"
        "from annslam_lib.slam.config import SlamConfig\n"
        "from annslam_lib.evaluation.map import point_rmse as rmse\n"
        "from annslam_lib.data import loaders\n",
        "x = motion.predict(p, u, 0.1, V)\ncfg = SlamConfig.for_dataset('car_park')\n"
        "loaders.load('car_park')\n",
        "from annslam_lib.slam import (runner,\n    dead_reckoning as dr)  # two\n"
        "r = rmse(a, b) ??\ndr.dead_reckon(odo, p0, V)\n",       # does not parse
    ]
    nb = {"cells": [{"cell_type": "code", "source": s} for s in cells]
          + [{"cell_type": "markdown", "source": "`observation.observe(...)`"}]}
    path = tmp_path / "99_planted.ipynb"
    path.write_text(json.dumps(nb))
    found = {_label(o): uses for o, uses in student_facing([path]).items()}
    assert found == {
        "annslam_lib.models.motion.predict": ["99_planted: motion.predict"],
        "annslam_lib.slam.config.SlamConfig.for_dataset": ["99_planted: SlamConfig.for_dataset"],
        "annslam_lib.evaluation.map.point_rmse": ["99_planted: rmse"],
        "annslam_lib.slam.dead_reckoning.dead_reckon": ["99_planted: dr.dead_reckon"],
    }


@pytest.mark.parametrize("doc, names", [
    ("One.\n\nParameters\n----------\nx : ndarray, shape (3,)\n    Pose.\n"
     "y, z : float\n\nReturns\n-------\nfloat\n", ["x", "y", "z"]),
    ("One.\n\n    Parameters\n    ----------\n    *args\n    **kwargs : dict\n", ["*args", "**kwargs"]),
])
def test_the_section_reader(doc, names):
    assert documented_names(sections(doc)["Parameters"]) == names
