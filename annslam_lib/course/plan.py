"""The grading plan: the instructor's notebook read as the skeleton of a grade (rule 1 of
:mod:`~annslam_lib.course.grader`), and the static reading of a solution's source (the names
it defines and uses, the library functions it must not call)."""
from __future__ import annotations

import ast
import builtins
import importlib
import sys
from dataclasses import dataclass
from pathlib import Path

import nbformat

__all__ = ["PlannedCell", "GradePlan", "plan", "free_names", "static_forbidden",
           "static_evasions", "CODE_STUB", "SKIP_TAG"]

CODE_STUB = "# YOUR CODE HERE\nraise NotImplementedError()"
#: A course cell of the INSTRUCTOR's notebook with this tag is not run when grading: a study
#: of hundreds of simulated runs that no graded cell reads would cost every submission minutes
#: (the sandbox reads no study cache). Only the instructor's tags count; a submission's are
#: never read. That the honest solutions still earn full marks is what shows no graded cell
#: needs a skipped one (the grading tests of each chapter).
SKIP_TAG = "grading-skip"
_BUILTINS = set(dir(builtins))


def cell_meta(cell) -> dict:
    return cell.get("metadata", {}).get("nbgrader", {}) or {}


def defined_names(source: str) -> set[str]:
    """Top-level names a cell binds (def, class, assignment, import)."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return set()
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                names |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return names


def free_names(source: str) -> set[str]:
    """Names a cell reads that it does not bind itself (builtins excluded)."""
    tree = ast.parse(source)
    bound, read = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            (bound if isinstance(node.ctx, (ast.Store, ast.Del)) else read).add(node.id)
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, ast.arg):
            bound.add(node.arg)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return read - bound - _BUILTINS


def _trees(sources):
    """The syntax tree of each source that parses (a cell with a syntax error is read as
    empty: running it fails and says so)."""
    for src in sources:
        try:
            yield ast.parse(src)
        except SyntaxError:
            continue


def _grading_imports(sources: list[str]) -> list[str]:
    """The import statements of the notebook that bring in ``annslam_lib.grading``."""
    out = []
    for tree in _trees(sources):
        for node in tree.body:
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
                    "annslam_lib.grading"):
                out.append(ast.unparse(node))
            elif isinstance(node, ast.Import) and all(a.name.startswith("annslam_lib.grading")
                                                      for a in node.names):
                out.append(ast.unparse(node))
    return out


def _aliases(sources: list[str]) -> dict[str, str]:
    """{local name: dotted path} of every import in ``sources`` (for reading solutions)."""
    out = {}
    for tree in _trees(sources):
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    out[a.asname or a.name.split(".")[0]] = a.name if a.asname else \
                        a.name.split(".")[0]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                for a in node.names:
                    out[a.asname or a.name] = f"{node.module}.{a.name}"
    return out


def _resolve_dotted(path: str):
    """The object a dotted path names. Only the course's library is imported for it; any
    other module is looked up among those already imported (a submission's source names
    the path, and importing an arbitrary module runs its code in the grader)."""
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        name = ".".join(parts[:i])
        if name in sys.modules:
            obj = sys.modules[name]
        elif parts[0] == "annslam_lib":
            try:
                obj = importlib.import_module(name)
            except Exception:
                continue
        else:
            continue
        try:
            for p in parts[i:]:
                obj = getattr(obj, p)
        except AttributeError:
            return None
        return obj
    return None


def _definitions(sources) -> dict[str, list[ast.AST]]:
    """{name: the top-level statements of ``sources`` that define it} (functions, classes,
    assignments)."""
    out: dict[str, list[ast.AST]] = {}
    for tree in _trees(sources):
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                out.setdefault(node.name, []).append(node)
            elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                for t in targets:
                    for n in ast.walk(t):
                        if isinstance(n, ast.Name):
                            out.setdefault(n.id, []).append(node)
    return out


def _reachable(solution: str, helpers) -> list[ast.AST]:
    """The solution's syntax tree and the definitions in ``helpers`` (the student's other
    cells) of every name it uses, and of every name those use, in turn ([] if it does not
    parse)."""
    try:
        trees: list[ast.AST] = [ast.parse(solution)]
    except SyntaxError:
        return []
    defined = _definitions(helpers)
    seen: set[str] = set()
    k = 0
    while k < len(trees):
        for n in ast.walk(trees[k]):
            if isinstance(n, ast.Name) and n.id in defined and n.id not in seen:
                seen.add(n.id)
                trees += defined[n.id]
        k += 1
    return trees


def _paths(trees, aliases: dict):
    """(node, dotted path) of every name and attribute chain that starts at an imported
    name."""
    for node in (n for t in trees for n in ast.walk(t)):
        chain = []
        cur = node
        while isinstance(cur, ast.Attribute):
            chain.append(cur.attr)
            cur = cur.value
        if isinstance(cur, ast.Name) and cur.id in aliases:
            yield node, ".".join([aliases[cur.id], *reversed(chain)])


def static_forbidden(solution: str, context: list[str], forbidden_paths,
                     helpers: list[str] = ()) -> list[str]:
    """Forbidden library functions the solution's source refers to: every name and
    attribute chain in it, resolved through the notebook's imports to an object, compared
    with the forbidden functions (so re-exports and aliases are caught). ``helpers``: the
    sources of the student's other cells: a function, class or name the solution uses that
    one of them defines is read too, and what that one uses, in turn."""
    if not forbidden_paths:
        return []
    targets = {}
    for p in forbidden_paths:
        mod, _, qual = p.partition(":")
        obj = _resolve_dotted(f"{mod}.{qual}")
        if obj is not None:
            targets[id(getattr(obj, "__wrapped__", obj))] = p
    aliases = _aliases(context + [solution, *helpers])
    found = []
    for _, path in _paths(_reachable(solution, helpers), aliases):
        obj = _resolve_dotted(path)
        if obj is not None and id(getattr(obj, "__wrapped__", obj)) in targets:
            found.append(targets[id(getattr(obj, "__wrapped__", obj))])
    return sorted(set(found))


# What makes a call invisible to the source reading, and what reaches into the interpreter
# to switch off or bypass the call monitor in the kernel.
_HIDING_CALLS = {"__import__", "exec", "eval", "compile", "globals", "vars", "breakpoint"}
_NAMED_BY_VALUE = {"getattr", "setattr", "delattr"}
_HIDING_ATTRS = {"__code__", "__globals__", "__builtins__", "__closure__", "__dict__",
                 "__wrapped__", "__subclasses__", "f_globals", "f_locals", "f_code", "f_back",
                 "gi_frame", "cr_frame"}
_HIDING_MODULES = ("importlib", "ctypes", "gc", "inspect", "marshal", "pickle", "types",
                   "runpy", "builtins", "_thread", "annslam_lib.course")
_HIDING_MEMBERS = {"sys": {"modules", "setprofile", "settrace", "_getframe", "meta_path",
                           "path_hooks", "path_importer_cache"},
                   "threading": {"setprofile", "settrace", "setprofile_all_threads",
                                 "settrace_all_threads"}}


def static_evasions(solution: str, context: list[str], helpers: list[str] = ()) -> list[str]:
    """What, in the solution and the helpers it reaches, would hide a call from the source
    reading or switch off the call monitor: dynamic imports and evaluation, attributes
    looked up by a computed name, function internals (``__code__``, ``__dict__``, frames),
    and the modules and members that reach into the interpreter (``importlib``,
    ``ctypes``, ``types``, ``sys.modules``, ``sys.setprofile``, the grader's own modules).
    Sorted, each named once."""
    trees = _reachable(solution, helpers)
    aliases = _aliases(context + [solution, *helpers])
    found = set()

    def module_of(name: str) -> str | None:
        return next((m for m in _HIDING_MODULES if name == m or name.startswith(m + ".")),
                    None)

    for t in trees:
        for n in ast.walk(t):
            if isinstance(n, ast.Import):
                found |= {m for a in n.names if (m := module_of(a.name))}
            elif isinstance(n, ast.ImportFrom) and n.module and module_of(n.module):
                found.add(module_of(n.module))
            elif isinstance(n, ast.Call) and isinstance(n.func, ast.Name):
                if n.func.id in _HIDING_CALLS and n.func.id not in aliases:
                    found.add(f"{n.func.id}()")
                elif n.func.id in _NAMED_BY_VALUE and (len(n.args) < 2 or not isinstance(
                        n.args[1], ast.Constant)):
                    found.add(f"{n.func.id}() with a computed name")
            elif isinstance(n, ast.Attribute) and n.attr in _HIDING_ATTRS:
                found.add(n.attr)
    for _, path in _paths(trees, aliases):
        head, _, rest = path.partition(".")
        member = rest.split(".")[0]
        if module_of(path):
            found.add(module_of(path))
        elif member in _HIDING_MEMBERS.get(head, ()):
            found.add(f"{head}.{member}")
    return sorted(found)


@dataclass
class PlannedCell:
    """A cell of the graded notebook: role 'course' (the instructor's), 'solution' (the
    student's source for the instructor's solution cell ``grade_id``) or 'test'."""
    index: int
    role: str
    source: str
    grade_id: str = ""
    points: float = 0.0


@dataclass
class GradePlan:
    cells: list[PlannedCell]
    notes: list[str]
    grading_imports: list[str]
    context: list[str]                    # the course cells' sources (imports, for reading)


def read_graded_notebook(path: Path, what: str):
    """A notebook to grade read from ``path``: ValueError or TypeError naming ``what`` for
    unreadable bytes, text that is not UTF-8 or not nbformat JSON, or no list of cells."""
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ValueError(f"the {what} cannot be read: {e}") from None
    try:
        nb = nbformat.reads(raw.decode("utf-8"), as_version=4)
    except UnicodeDecodeError:
        raise ValueError(f"the {what} is not a notebook (not UTF-8 text)") from None
    except Exception as e:
        first = str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__
        raise ValueError(f"the {what} is not a valid notebook (not nbformat JSON: {first})"
                         ) from None
    if not isinstance(nb.get("cells"), list):
        raise TypeError(f"the {what} has no list of cells")
    return nb


def plan(instructor, submission) -> GradePlan:
    """The graded notebook: the instructor's cells with the submission's solution sources
    (rule 1 of the module docstring), and notes on everything ignored or restored."""
    notes = []
    inst_solutions, inst_tests = {}, {}
    for c in instructor.cells:
        m = cell_meta(c)
        if m.get("solution") and c.cell_type == "code":
            inst_solutions[m["grade_id"]] = c
        elif m.get("grade") and not m.get("solution"):
            inst_tests[m["grade_id"]] = c
    known = set(inst_solutions) | set(inst_tests) | {
        cell_meta(c).get("grade_id") for c in instructor.cells if cell_meta(c)}
    sub_by_id, by_defined = {}, {}
    for i, c in enumerate(submission.cells):
        m = cell_meta(c) if isinstance(c, dict) else {}
        gid = m.get("grade_id") if isinstance(m, dict) else None
        src = c.get("source", "") if isinstance(c, dict) else ""
        if not isinstance(src, str):
            src = "".join(src) if isinstance(src, list) else ""
        if c.get("cell_type") == "code":
            for name in defined_names(src):
                by_defined.setdefault(name, (i, src))
        if not gid:
            continue
        if gid not in known:
            notes.append(f"cell {i} has grade id {gid!r}, which the instructor's notebook does "
                         "not have: ignored (no points)")
            continue
        if gid in inst_tests:
            if c.get("cell_type") != "code":
                notes.append(f"test cell {gid!r} was turned into a {c.get('cell_type')} cell: "
                             "the instructor's test cell is used")
            elif src not in (inst_tests[gid].source, _visible(inst_tests[gid].source)):
                notes.append(f"test cell {gid!r} was edited: the instructor's test cell is used")
            pts = m.get("points")
            want = cell_meta(inst_tests[gid]).get("points")
            if pts != want:
                notes.append(f"points of {gid!r} changed to {pts!r}: the instructor's {want} count")
            continue
        if gid in inst_solutions:
            if c.get("cell_type") != "code":
                notes.append(f"solution cell {gid!r} was turned into a {c.get('cell_type')} "
                             "cell: its text is not code, scored as unanswered")
                continue
            sub_by_id.setdefault(gid, src)
    for gid in inst_tests:
        if not any(cell_meta(c).get("grade_id") == gid for c in submission.cells
                   if isinstance(c, dict)):
            notes.append(f"test cell {gid!r} is missing from the submission: restored")
    cells = []
    for i, c in enumerate(instructor.cells):
        if c.cell_type != "code":
            continue
        m = cell_meta(c)
        gid = m.get("grade_id", "")
        if m.get("solution"):
            src = sub_by_id.get(gid)
            if src is None:
                wanted = defined_names(c.source) - {"np", "math"}
                match = next((by_defined[n] for n in sorted(wanted) if n in by_defined), None)
                if match is not None:
                    notes.append(f"solution cell {gid!r} not found by its grade id: used cell "
                                 f"{match[0]}, which defines {', '.join(sorted(wanted))}")
                    src = match[1]
                else:
                    notes.append(f"solution cell {gid!r} is missing: scored as unanswered")
                    src = _stub_of(c.source)
            cells.append(PlannedCell(i, "solution", src, gid))
        elif m.get("grade"):
            cells.append(PlannedCell(i, "test", c.source, gid, float(m.get("points", 0))))
        elif SKIP_TAG in (c.get("metadata", {}).get("tags") or []):
            continue                      # a study no graded cell reads (SKIP_TAG)
        else:
            cells.append(PlannedCell(i, "course", c.source))
    course = [c.source for c in cells if c.role == "course"]
    return GradePlan(cells, notes, _grading_imports(course), course)


def _visible(source: str) -> str:
    """A test cell as the student version shows it (hidden tests removed)."""
    from .release import marked_regions, replace_regions

    return replace_regions(source, marked_regions(source, "BEGIN HIDDEN TESTS", "END HIDDEN TESTS", "cell"),
                    None)


def _stub_of(source: str) -> str:
    """The instructor's solution cell with its solution replaced by the stub (what an
    untouched student version holds)."""
    from .release import marked_regions, replace_regions

    return replace_regions(source, marked_regions(source, "BEGIN SOLUTION", "END SOLUTION", "cell"),
                    CODE_STUB)
