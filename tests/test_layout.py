"""The library's shape: folders are layers imported only downward, no import cycles, no
module over 800 lines, every subpackage names what it holds, and the light import paths stay
light. The checks read the import statements (ast), not a list kept by hand."""
import ast
import pathlib
import subprocess
import sys

import pytest

import annslam_lib

ROOT = pathlib.Path(annslam_lib.__file__).parent
LAYERS = list(annslam_lib.LAYERS)
BASE = {"annslam_lib._checks", "annslam_lib._lazy", "annslam_lib._cache", "annslam_lib._settings"}


def _modules():
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _import_base(pkg: str, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` names, in package ``pkg``."""
    base = node.module or ""
    if node.level:
        up = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
        base = ".".join(up + ([base] if base else []))
    return base


def _imports(name: str, path: pathlib.Path, known) -> set[str]:
    """Library modules imported by ``name`` at module level or in functions (a lazy import
    is still a dependency, but function-level imports cannot form an import-time cycle, so
    they are returned separately by the caller's filter)."""
    tree = ast.parse(path.read_text())
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in tree.body:                                 # import time only
        nodes = [node]
        if isinstance(node, ast.If):                       # TYPE_CHECKING blocks do not run
            continue
        for n in nodes:
            if isinstance(n, ast.Import):
                found.update(a.name for a in n.names)
            elif isinstance(n, ast.ImportFrom):
                base = _import_base(pkg, n)
                found.add(base)
                found.update(f"{base}.{a.name}" for a in n.names)
    return {m for m in found if m in known and m != name}


def test_no_import_time_cycles():
    mods = _modules()
    graph = {m: _imports(m, p, mods) for m, p in mods.items()}
    # A package importing its own submodules in __init__ is not a cycle of layers; drop
    # the edge child -> parent package that Python resolves by importing the parent first.
    for m in graph:
        graph[m] = {d for d in graph[m] if not m.startswith(d + ".")}
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for d in sorted(graph[m]):
            if state.get(d) == 1:
                cycles.append(stack[stack.index(d):] + [d])
            elif d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert cycles == []
    assert len(mods) > 60


def test_the_cycle_check_finds_a_planted_cycle(tmp_path, monkeypatch):
    pkg = tmp_path / "annslam_lib"
    (pkg / "a").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a" / "__init__.py").write_text("")
    (pkg / "a" / "x.py").write_text("from . import y\n")
    (pkg / "a" / "y.py").write_text("from .x import thing\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", pkg)
    with pytest.raises(AssertionError):
        test_no_import_time_cycles()


def _all_imports(name: str, path: pathlib.Path) -> list[tuple[int, str]]:
    """Every ``annslam_lib`` import of a module, at any depth (a function-level import is a
    dependency too), as (line, imported module or name)."""
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = []
    for n in ast.walk(ast.parse(path.read_text())):
        if isinstance(n, ast.Import):
            out += [(n.lineno, a.name) for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            base = _import_base(pkg, n)
            out += [(n.lineno, base)] + [(n.lineno, f"{base}.{a.name}") for a in n.names]
    return [(line, m) for line, m in out if m.startswith("annslam_lib.")]


def _rank(module: str) -> int | None:
    """A module's height: -1 for the base modules every layer may use, the index in
    LAYERS for a layer's module, None for the package's own top (``__main__``)."""
    if module in BASE:
        return -1
    part = module.split(".")[1]
    return LAYERS.index(part) if part in LAYERS else None


def test_every_import_runs_down_the_layers():
    upward = []
    for name, path in _modules().items():
        if name.count(".") == 0:
            continue
        src = _rank(name)
        if src is None:
            continue
        for line, target in _all_imports(name, path):
            dst = _rank(target)
            if dst is not None and dst > src:
                upward.append(f"{name}:{line} -> {target}")
    assert upward == []


def test_the_direction_check_finds_a_planted_upward_import(tmp_path, monkeypatch):
    pkg = tmp_path / "annslam_lib"
    for layer in ("models", "slam"):
        (pkg / layer).mkdir(parents=True)
        (pkg / layer / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "slam" / "x.py").write_text("from ..models import y\n")            # down: allowed
    (pkg / "models" / "y.py").write_text("def f():\n    from ..slam import x\n")  # up, lazily
    monkeypatch.setattr(sys.modules[__name__], "ROOT", pkg)
    with pytest.raises(AssertionError, match="annslam_lib.models.y:2 -> annslam_lib.slam"):
        test_every_import_runs_down_the_layers()


def _private_uses(name: str, path: pathlib.Path, modules) -> list[str]:
    """Another library module's private names used by ``name``: imported (``from .x import
    _y``) or read off an imported module (``x._y``). The base modules ``_checks``, ``_settings``,
    ``_lazy`` and ``_cache`` are the package's own and may be imported whole."""
    tree = ast.parse(path.read_text())
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    aliases, found = {}, []
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom):
            base = _import_base(pkg, n)
            if not base.startswith("annslam_lib") or base == name:
                continue
            for a in n.names:
                full = f"{base}.{a.name}"
                if full in modules:
                    aliases[a.asname or a.name] = full
                elif a.name.startswith("_") and not a.name.startswith("__"):
                    found.append(f"{name}:{n.lineno} imports {full}")
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.name in modules and a.asname:
                    aliases[a.asname] = a.name
    for n in ast.walk(tree):
        if (isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
                and n.value.id in aliases and aliases[n.value.id] != name
                and n.attr.startswith("_") and not n.attr.startswith("__")):
            found.append(f"{name}:{n.lineno} reads {aliases[n.value.id]}.{n.attr}")
    return found


def test_no_module_uses_another_modules_private_names():
    mods = _modules()
    found = [f for m, p in mods.items() for f in _private_uses(m, p, mods)]
    assert found == []


def test_the_private_name_check_finds_planted_uses(tmp_path):
    pkg = tmp_path / "annslam_lib"
    (pkg / "a").mkdir(parents=True)
    for f in ("__init__.py", "a/__init__.py"):
        (pkg / f).write_text("")
    (pkg / "a" / "x.py").write_text("_hidden = 1\n")
    (pkg / "a" / "y.py").write_text("from .x import _hidden\nfrom . import x\nv = x._hidden\n")
    mods = {"annslam_lib.a.x": pkg / "a" / "x.py", "annslam_lib.a.y": pkg / "a" / "y.py",
            "annslam_lib.a": pkg / "a" / "__init__.py"}
    assert _private_uses("annslam_lib.a.y", mods["annslam_lib.a.y"], mods) == [
        "annslam_lib.a.y:1 imports annslam_lib.a.x._hidden",
        "annslam_lib.a.y:3 reads annslam_lib.a.x._hidden"]


def test_the_order_is_written_once_and_repeated_where_readers_look():
    chain = " < ".join(LAYERS)
    for doc in ("README.md", "MAINTAINING.md"):
        assert chain in (ROOT.parent / doc).read_text(), doc
    listed = [line.split("``")[1] for line in annslam_lib.__doc__.splitlines()
              if line.startswith("- ``")]
    assert listed == LAYERS
    table = [line.split("`")[1] for line in (ROOT.parent / "MAINTAINING.md").read_text().splitlines()
             if line.startswith("| `") and line.split("`")[1] in LAYERS]
    assert table == LAYERS
    assert sorted(LAYERS) == sorted(p.parent.name for p in ROOT.glob("*/__init__.py"))


def test_no_module_over_800_lines_and_layers_are_folders():
    sizes = {m: len(p.read_text().splitlines()) for m, p in _modules().items()}
    assert max(sizes.values()) <= 800, max(sizes.items(), key=lambda kv: kv[1])
    for layer in LAYERS:
        assert (ROOT / layer / "__init__.py").is_file(), layer
    loose = sorted(p.name for p in ROOT.glob("*.py"))
    assert loose == ["__init__.py", "__main__.py", "_cache.py", "_checks.py", "_lazy.py",
                     "_settings.py"]


@pytest.mark.parametrize("layer", LAYERS)
def test_every_layer_says_what_it_holds(layer):
    text = (ROOT / layer / "__init__.py").read_text()
    tree = ast.parse(text)
    assert ast.get_docstring(tree) and len(ast.get_docstring(tree)) > 40
    assert "__all__" in text


def _fresh(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()


HEAVY = ["scipy.stats", "scipy.linalg", "torch", "matplotlib", "ipywidgets"]


def test_importing_the_run_loop_loads_nothing_heavy_until_a_filter_is_made():
    code = ("import sys\nimport annslam_lib.slam.runner\n"
            f"print(*[m in sys.modules for m in {HEAVY!r}])\n"
            "from annslam_lib.slam.efficient import EkfSlam\nimport numpy as np\n"
            "from annslam_lib.models.vehicle import ACFR_UTE\n"
            "EkfSlam(np.zeros(3), np.eye(3), ACFR_UTE)\n"
            "print('scipy.linalg' in sys.modules, 'scipy.stats' in sys.modules)")
    assert _fresh(code) == ["False"] * len(HEAVY) + ["True", "False"]


BEFORE_THE_ANN = ["ch00_course_map", "ch01_kinematics", "ch02_laser_offset", "ch03_observation",
                  "ch04_landmarks", "ch05_ekf_slam", "ch06_victoria_park"]


def test_chapters_before_the_ann_do_not_import_torch():
    # one interpreter, the chapters imported in turn: torch would appear in sys.modules at the
    # first chapter that imports it, directly or through anything it imports
    code = ("import importlib, sys\n"
            f"for c in {BEFORE_THE_ANN!r}:\n"
            "    importlib.import_module('annslam_lib.chapters.' + c)\n"
            "    print(c, 'torch' in sys.modules)")
    out = _fresh(code)
    assert out == [w for c in BEFORE_THE_ANN for w in (c, "False")], out


def test_every_subpackage_names_each_of_its_modules():
    # Each module and subpackage of a package (private ``_x`` ones aside) is named as
    # ``name`` in the package's docstring and listed in its ``__all__``.
    import importlib

    missing = []
    for init in sorted(ROOT.rglob("__init__.py")):
        folder = init.parent
        if folder == ROOT:
            continue
        package = ".".join(folder.relative_to(ROOT.parent).parts)
        members = sorted({p.stem for p in folder.glob("*.py")} - {"__init__"}
                         | {p.parent.name for p in folder.glob("*/__init__.py")})
        doc = ast.get_docstring(ast.parse(init.read_text())) or ""
        listed = set(getattr(importlib.import_module(package), "__all__", ()))
        for m in members:
            if m.startswith("_"):
                continue
            if f"``{m}``" not in doc:
                missing.append(f"{package}: {m} not in the docstring")
            if m not in listed:
                missing.append(f"{package}: {m} not in __all__")
    assert missing == []
