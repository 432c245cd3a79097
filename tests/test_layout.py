"""The library's shape: folders are layers, no import cycles, no module over
800 lines, every subpackage names what it holds, and the light import paths stay light.
The cycle check reads the import statements (ast), not a list kept by hand."""
import ast
import pathlib
import subprocess
import sys

import pytest

import annslam_lib

ROOT = pathlib.Path(annslam_lib.__file__).parent
LAYERS = ["data", "models", "perception", "slam", "evaluation", "ann", "paper", "plots",
          "chapters", "grading", "course"]


def _modules():
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


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
                base = n.module or ""
                if n.level:
                    up = pkg.split(".")[: len(pkg.split(".")) - (n.level - 1)]
                    base = ".".join(up + ([base] if base else []))
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


def test_no_module_over_800_lines_and_layers_are_folders():
    sizes = {m: len(p.read_text().splitlines()) for m, p in _modules().items()}
    assert max(sizes.values()) <= 800, max(sizes.items(), key=lambda kv: kv[1])
    for layer in LAYERS:
        assert (ROOT / layer / "__init__.py").is_file(), layer
    loose = sorted(p.name for p in ROOT.glob("*.py"))
    assert loose == ["__init__.py", "__main__.py", "_cache.py", "_checks.py", "_lazy.py"]


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
