"""Grading that a submission cannot game.

Design, in three rules:

1. **The instructor's notebook is the skeleton.** Its cells, in its order, with its grade
   ids, points and test cells (hidden tests included), are what is graded. A submission
   contributes only the source of its *solution* cells, matched by grade id (or, if the
   student re-created a cell, by the function it defines). Everything else in it is ignored
   and reported: edited, deleted or retyped test cells, changed points, unknown grade ids,
   cells added with grading metadata.
2. **Student code runs in a sandbox, and only there.** One kernel per submission
   (:class:`~annslam_lib.course.sandbox.Sandbox`: bubblewrap where available, else an
   unprivileged user, a scratch folder, resource limits, time-outs, a deadline) runs the
   instructor's course cells and the student's solution cells, in order. Test cells are
   *not* run there.
3. **Scores are decided outside the student's process.** Each test cell is executed by the
   grader, in its own process, with the genuine check modules; the names the test cell
   takes from the student (``my_observe``) are :class:`RemoteFunction` proxies that send
   the check's inputs to the kernel and bring back only data (:mod:`~annslam_lib.course.
   codec`: no pickles, no code). Nothing the student's code does in its kernel, rebinding
   the check module, patching check functions, IPython input transformers, editing files,
   can reach the checker's state; at most it changes what the student's own function
   returns, which is then compared with the grader's reference.

An error or a time-out in a solution cell scores 0 for the exercises whose test cells use
the names it defines, with the reason; a kernel that dies is restarted and the notebook's
good cells replayed, so one broken exercise does not take the others with it. A check may
declare library functions a solution must not call (``grading.core.forbids``); a solution
that calls one scores 0 ("my_observe calls annslam_lib.models.observation.observe: write it
yourself"), found both in its source and by a call monitor in the kernel. What the monitor
cannot stop: a student who copies the library's code into the answer, or hides a call from
both the source reading and the monitor; the README says so.

Batch grading (:func:`grade_batch`) grades every submission it can, gives each one it
cannot a reason, and writes one JSON file after every submission.
"""
from __future__ import annotations

import ast
import builtins
import contextlib
import hashlib
import importlib
import io
import json
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import nbformat

from ..grading.core import GradingError, forbidden, forbidden_message
from . import codec
from .sandbox import ExecResult, Limits, Sandbox

__all__ = ["ExerciseResult", "SubmissionGrade", "GradePlan", "plan", "grade_submission",
           "grade_batch", "RemoteFunction", "student_of", "CODE_STUB"]

CODE_STUB = "# YOUR CODE HERE\nraise NotImplementedError()"
ROOT = Path(__file__).resolve().parents[2]
MAX_RESTARTS = 4
_BUILTINS = set(dir(builtins))


# ------------------------------------------------------------------------------ results

@dataclass
class ExerciseResult:
    """One autograded exercise: 'passed', 'failed' (the check's message), 'not written',
    'forbidden' (a library call the exercise forbids), 'solution error' (its cell raised
    or timed out), 'kernel died', or 'check error'."""
    grade_id: str
    points: float
    max_points: float
    status: str
    message: str = ""
    seconds: float = 0.0


@dataclass
class SubmissionGrade:
    """A graded (or ungradable) submission."""
    submission: str                      # its full path
    notebook: str                        # the instructor notebook's file name
    student: str | None = None           # from an nbgrader-style submitted/<student>/<assignment>/
    assignment: str | None = None
    score: float = 0.0
    max_score: float = 0.0
    exercises: list[ExerciseResult] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)       # what was restored or ignored
    errors: list[str] = field(default_factory=list)      # cells outside exercises that failed
    graded: bool = True
    reason: str = ""                     # why it could not be graded
    isolation: str = ""
    seconds: float = 0.0

    def report(self) -> str:
        who = f" ({self.student})" if self.student else ""
        if not self.graded:
            return f"{self.submission}{who}: NOT GRADED: {self.reason}"
        lines = [f"{self.submission}{who}: {self.score:g} / {self.max_score:g} points "
                 f"({self.seconds:.1f} s, sandbox: {self.isolation})"]
        for r in self.exercises:
            mark = "ok  " if r.status == "passed" else "FAIL"
            lines.append(f"  {mark} {r.grade_id} ({r.points:g}/{r.max_points:g})"
                         + ("" if r.status == "passed" else f" [{r.status}]"))
            if r.status != "passed" and r.message:
                lines += ["       " + s for s in r.message.splitlines()[:6]]
        lines += [f"  note: {n}" for n in self.notes]
        lines += [f"  error outside the exercises: {e}" for e in self.errors]
        return "\n".join(lines)

    def as_json(self) -> dict:
        d = asdict(self)
        d["exercises"] = [asdict(r) for r in self.exercises]
        return d


# ------------------------------------------------------------------------------ the plan

def _meta(cell) -> dict:
    return cell.get("metadata", {}).get("nbgrader", {}) or {}


def _defined_names(source: str) -> set[str]:
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


def _grading_imports(sources: list[str]) -> list[str]:
    """The import statements of the notebook that bring in ``annslam_lib.grading``."""
    out = []
    for src in sources:
        try:
            tree = ast.parse(src)
        except SyntaxError:
            continue
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
    for src in sources:
        try:
            tree = ast.parse(src)
        except SyntaxError:
            continue
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
    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except Exception:
            continue
        try:
            for p in parts[i:]:
                obj = getattr(obj, p)
        except AttributeError:
            return None
        return obj
    return None


def static_forbidden(solution: str, context: list[str], forbidden_paths) -> list[str]:
    """Forbidden library functions the solution's source refers to: every name and
    attribute chain in it, resolved through the notebook's imports to an object, compared
    with the forbidden functions (so re-exports and aliases are caught)."""
    if not forbidden_paths:
        return []
    targets = {}
    for p in forbidden_paths:
        mod, _, qual = p.partition(":")
        obj = _resolve_dotted(f"{mod}.{qual}")
        if obj is not None:
            targets[id(getattr(obj, "__wrapped__", obj))] = p
    aliases = _aliases(context + [solution])
    try:
        tree = ast.parse(solution)
    except SyntaxError:
        return []
    found = []
    for node in ast.walk(tree):
        chain = []
        cur = node
        while isinstance(cur, ast.Attribute):
            chain.append(cur.attr)
            cur = cur.value
        if not isinstance(cur, ast.Name) or cur.id not in aliases:
            continue
        path = ".".join([aliases[cur.id], *reversed(chain)])
        obj = _resolve_dotted(path)
        if obj is not None and id(getattr(obj, "__wrapped__", obj)) in targets:
            found.append(targets[id(getattr(obj, "__wrapped__", obj))])
    return sorted(set(found))


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


def _read_notebook(path: Path, what: str):
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
        m = _meta(c)
        if m.get("solution") and c.cell_type == "code":
            inst_solutions[m["grade_id"]] = c
        elif m.get("grade") and not m.get("solution"):
            inst_tests[m["grade_id"]] = c
    known = set(inst_solutions) | set(inst_tests) | {
        _meta(c).get("grade_id") for c in instructor.cells if _meta(c)}
    sub_by_id, by_defined = {}, {}
    for i, c in enumerate(submission.cells):
        m = _meta(c) if isinstance(c, dict) else {}
        gid = m.get("grade_id") if isinstance(m, dict) else None
        src = c.get("source", "") if isinstance(c, dict) else ""
        if not isinstance(src, str):
            src = "".join(src) if isinstance(src, list) else ""
        if c.get("cell_type") == "code":
            for name in _defined_names(src):
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
            want = _meta(inst_tests[gid]).get("points")
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
        if not any(_meta(c).get("grade_id") == gid for c in submission.cells
                   if isinstance(c, dict)):
            notes.append(f"test cell {gid!r} is missing from the submission: restored")
    cells = []
    for i, c in enumerate(instructor.cells):
        if c.cell_type != "code":
            continue
        m = _meta(c)
        gid = m.get("grade_id", "")
        if m.get("solution"):
            src = sub_by_id.get(gid)
            if src is None:
                wanted = _defined_names(c.source) - {"np", "math"}
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
        else:
            cells.append(PlannedCell(i, "course", c.source))
    course = [c.source for c in cells if c.role == "course"]
    return GradePlan(cells, notes, _grading_imports(course), course)


def _visible(source: str) -> str:
    """A test cell as the student version shows it (hidden tests removed)."""
    from .release import _regions, _replace

    return _replace(source, _regions(source, "BEGIN HIDDEN TESTS", "END HIDDEN TESTS", "cell"),
                    None)


def _stub_of(source: str) -> str:
    """The instructor's solution cell with its solution replaced by the stub (what an
    untouched student version holds)."""
    from .release import _regions, _replace

    return _replace(source, _regions(source, "BEGIN SOLUTION", "END SOLUTION", "cell"),
                    CODE_STUB)


# ------------------------------------------------------------------------------ the kernel

class _KernelGone(GradingError):
    """The kernel died or had to be killed during a call."""


class RemoteFunction:
    """Stands for the student's function ``name`` in the grader: calling it sends the
    arguments to the kernel (as data) and returns what the student's function returned
    there, or raises what it raised (as an exception of the same builtin class)."""

    __annslam_remote__ = True

    def __init__(self, session: _Session, name: str) -> None:
        self._session = session
        self.__name__ = self.__qualname__ = name
        self._batch: dict[str, dict] = {}

    def __repr__(self) -> str:
        return f"<the student's {self.__name__}>"

    def _round_trip(self, method: str, payload, timeout: float):
        s = self._session
        s.ensure_kernel()
        paths = json.dumps(list(forbidden()))
        code = (f"__annslam_reply__ = __annslam_kernel__.{method}({self.__name__!r}, "
                f"{payload!r}, {paths!r})")
        res = s.sandbox.execute(code, timeout, user_expressions={"r": "__annslam_reply__"})
        s.calls += 1
        if not res.alive:
            raise _KernelGone(f"{self.__name__}: {res.reason()}")
        if res.status == "timeout":
            raise GradingError(f"{self.__name__} did not return: {res.reason()}")
        if res.status != "ok":
            raise GradingError(f"{self.__name__} could not be called ({res.reason()})")
        return _read_reply(res, self.__name__)

    def __annslam_prefetch__(self, cases) -> None:
        """Evaluate a check's whole list of inputs in one round trip (``grading.core.
        prefetch``); arguments holding torch modules are left to the single calls."""
        payloads = []
        for args in cases:
            modules: list = []
            p = json.dumps(codec.encode(tuple(args), modules), allow_nan=False,
                           separators=(",", ":"))
            if modules:
                return
            payloads.append(p)
        todo = [p for p in dict.fromkeys(payloads) if p not in self._batch]
        if not todo:
            return
        timeout = self._session.sandbox.limits.call_timeout * 4
        replies = self._round_trip("call_many", todo, timeout)
        if isinstance(replies, list) and len(replies) == len(todo):
            key = json.dumps(list(forbidden()))
            self._batch.update({key + p: r for p, r in zip(todo, replies)})

    def __call__(self, *args):
        modules: list = []
        payload = json.dumps(codec.encode(args, modules), allow_nan=False,
                             separators=(",", ":"))
        reply = self._batch.pop(json.dumps(list(forbidden())) + payload, None)
        if reply is None:
            reply = self._round_trip("call", payload, self._session.sandbox.limits.call_timeout)
        if not isinstance(reply, dict):
            raise GradingError(f"{self.__name__}: malformed reply from the kernel")
        if reply.get("hits"):
            raise GradingError(forbidden_message(self.__name__, reply["hits"]))
        for module, state in zip(modules, reply.get("states") or []):
            codec.load_state(module, state)          # a training loop changes its net in place
        if "error" in reply:
            err = _exception(codec.decode(reply["error"]))
            err.__annslam_student__ = self.__name__      # raised by the student's code
            raise err
        return codec.decode(reply["value"])


def _read_reply(res: ExecResult, name: str) -> dict:
    try:
        expr = (res.user_expressions or {})["r"]
        if expr.get("status") != "ok":
            raise ValueError(expr.get("evalue", "no value"))
        text = expr["data"]["text/plain"]
        if not isinstance(text, str) or len(text) > codec.MAX_BYTES or text[:1] not in "'\"":
            raise ValueError("not a string")
        reply = json.loads(ast.literal_eval(text))
        if not isinstance(reply, (dict, list)):
            raise TypeError("not an object")
        return reply
    except (KeyError, ValueError, SyntaxError, TypeError, RecursionError, MemoryError) as e:
        raise GradingError(f"{name}: the grader could not read what came back from your "
                           f"kernel ({e}); did the notebook change IPython itself?") from None


_REMOTE_CLASSES: dict[str, type] = {}


def _exception(remote) -> BaseException:
    """The exception to raise in the grader for one raised in the kernel: the first builtin
    class (or numpy's LinAlgError) along its MRO, with its message; the remote class name
    stays visible in messages."""
    import numpy as np

    if not isinstance(remote, codec.RemoteException):
        return GradingError(f"unexpected reply {remote!r}")
    known = {"LinAlgError": np.linalg.LinAlgError}
    base = Exception
    for n in remote.names:
        cls = known.get(n) or getattr(builtins, n, None)
        if isinstance(cls, type) and issubclass(cls, Exception) and cls is not GradingError:
            base = cls
            break
    name = remote.names[0] if remote.names else "Exception"
    if base.__name__ == name:
        return base(remote.message)
    key = f"{name}<{base.__name__}>"
    if key not in _REMOTE_CLASSES:
        _REMOTE_CLASSES[key] = type(re.sub(r"\W", "_", name) or "Exception", (base,), {})
    return _REMOTE_CLASSES[key](remote.message)


class _Session:
    """One submission's kernel and what ran in it (cells, restarts, replays)."""

    def __init__(self, sandbox: Sandbox, gplan: GradePlan) -> None:
        self.sandbox = sandbox
        self.plan = gplan
        self.status: dict[int, ExecResult] = {}
        self.restarts = 0
        self.calls = 0
        self.helper_error = ""

    def _after_start(self) -> None:
        res = self.sandbox.execute("import annslam_lib.course.kernel_side as __annslam_kernel__",
                                   60)
        self.helper_error = "" if res.ok else res.reason()

    def run_all(self) -> None:
        """Run the course and solution cells in order (test cells run in the grader)."""
        for k, cell in enumerate(self.plan.cells):
            if cell.role == "test":
                continue
            if self.sandbox.remaining() <= 0:
                self.status[k] = ExecResult("timeout", evalue="the notebook's grading deadline "
                                            f"({self.sandbox.limits.deadline:g} s) had passed")
                continue
            self.ensure_kernel()
            self.status[k] = self.sandbox.execute(cell.source)
        self.ensure_kernel()

    def ensure_kernel(self) -> None:
        """A live kernel in which every cell that succeeded so far has run: after a death
        (or a kill), a new kernel replays them."""
        if self.sandbox.alive:
            return
        if self.sandbox.kernels_started:
            if self.restarts >= MAX_RESTARTS:
                raise _KernelGone(f"the kernel died {self.restarts + 1} times; the rest of the "
                                  "notebook cannot be graded")
            self.restarts += 1
        self.sandbox.start()
        self._after_start()
        for k in sorted(self.status):
            if self.status[k].ok:
                res = self.sandbox.execute(self.plan.cells[k].source)
                if not res.ok:
                    self.status[k] = res
                if not res.alive:
                    self.ensure_kernel()
                    return


def _exercise(session: _Session, cell: PlannedCell, solutions: dict[str, int]) -> ExerciseResult:
    """Score one test cell (rule 3 of the module docstring)."""
    t0 = time.monotonic()
    gid, pts = cell.grade_id, cell.points

    def result(status: str, message: str) -> ExerciseResult:
        return ExerciseResult(gid, pts if status == "passed" else 0.0, pts, status, message,
                              round(time.monotonic() - t0, 3))

    names = free_names(cell.source)
    aliases = set()
    ns: dict = {"__name__": "__annslam_test__"}
    for stmt in session.plan.grading_imports:
        exec(stmt, ns)                                   # the instructor's own imports
        aliases |= set(ns) - {"__name__", "__builtins__"}
    student_names = sorted(names - aliases)
    # 1. the solution cells these names come from must have run
    for name in student_names:
        if name not in solutions:
            return result("check error", f"the test cell uses {name!r}, which no solution cell "
                          "defines (an error in the instructor's notebook)")
        k = solutions[name]
        res = session.status.get(k)
        if res is None or not res.ok:
            why = res.reason() if res is not None else "it did not run"
            return result("solution error", f"the cell that defines {name} failed, so its "
                          f"exercise scores 0: {why}")
    # 2. forbidden library calls, read from the source
    checks = _checks_used(cell.source, ns)
    paths = tuple(p for c in checks for p in getattr(c, "__annslam_forbids__", ()))
    for name in student_names:
        k = solutions[name]
        hits = static_forbidden(session.plan.cells[k].source, session.plan.context, paths)
        if hits:
            return result("forbidden", forbidden_message(name, hits))
    if session.helper_error:
        return result("kernel died", "the grader's helper could not be loaded in the "
                      f"submission's kernel: {session.helper_error}")
    # 3. the check itself, here, with the student's functions behind proxies
    for name in student_names:
        ns[name] = RemoteFunction(session, name)
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            exec(compile(cell.source, f"<test cell {gid}>", "exec"), ns)
    except _KernelGone as e:
        return result("kernel died", str(e))
    except AssertionError as e:                        # GradingError, or a plain assert
        msg = str(e) or "an assertion of the test failed"
        status = "not written" if "is not written yet" in msg else "failed"
        return result(status, msg)
    except Exception as e:
        who = getattr(e, "__annslam_student__", None)
        if who is None:
            return result("check error", f"the check raised {type(e).__name__}: {e}")
        if isinstance(e, NotImplementedError):
            return result("not written", f"{who} is not written yet: it raised "
                          "NotImplementedError.")
        return result("failed", f"{who} raised {type(e).__name__}: {e}")
    return result("passed", out.getvalue().strip())


def _checks_used(source: str, ns: dict) -> list:
    """The check functions a test cell calls (``gk.check_x``), resolved in ``ns``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call):
            f = node.func
            chain = []
            while isinstance(f, ast.Attribute):
                chain.append(f.attr)
                f = f.value
            if isinstance(f, ast.Name) and f.id in ns:
                obj = ns[f.id]
                for part in reversed(chain):
                    obj = getattr(obj, part, None)
                if callable(obj):
                    found.append(obj)
    return found


# ------------------------------------------------------------------------------ integrity

def _fingerprint(folders) -> dict[str, str]:
    out = {}
    for folder in folders:
        folder = Path(folder)
        if not folder.exists():
            continue
        for p in sorted(folder.rglob("*")):
            if p.is_file() and "__pycache__" not in p.parts:
                with contextlib.suppress(OSError):
                    out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _snapshot(folders) -> dict[str, bytes]:
    out = {}
    for folder in folders:
        for p in sorted(Path(folder).rglob("*")):
            if p.is_file() and "__pycache__" not in p.parts:
                with contextlib.suppress(OSError):
                    out[str(p)] = p.read_bytes()
    return out


def _restore(backup: dict[str, bytes], folders) -> list[str]:
    """Put back every file of ``backup`` that changed or vanished, remove new ones."""
    changed = []
    now = _fingerprint(folders)
    for path, data in backup.items():
        if now.get(path) != hashlib.sha256(data).hexdigest():
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            Path(path).write_bytes(data)
            changed.append(path)
    for path in set(now) - set(backup):
        with contextlib.suppress(OSError):
            os.unlink(path)
        changed.append(path)
    return sorted(changed)


# ------------------------------------------------------------------------------ entry points

def student_of(path) -> tuple[str | None, str | None]:
    """(student, assignment) from an nbgrader-style ``.../submitted/<student>/<assignment>/
    <notebook>.ipynb`` path, else (None, None)."""
    parts = Path(path).resolve().parts
    if len(parts) >= 4 and parts[-4] == "submitted":
        return parts[-3], parts[-2]
    return None, None


def grade_submission(path, instructor, *, limits: Limits = Limits(), isolation: str = "auto",
                     hide=(), guard=None) -> SubmissionGrade:
    """Grade one submitted notebook against the instructor notebook ``instructor`` (a path).
    Never raises for a bad submission: an ungradable one comes back with ``graded=False``
    and its reason. ``guard``: folders whose files must not change (checked and restored
    when the sandbox cannot guarantee it)."""
    t0 = time.monotonic()
    path = Path(path).resolve()
    student, assignment = student_of(path)
    g = SubmissionGrade(str(path), Path(instructor).name, student, assignment)
    try:
        inst = _read_notebook(Path(instructor), "instructor notebook")
    except ValueError as e:
        g.graded, g.reason = False, str(e)
        return g
    try:
        sub = _read_notebook(path, "submission")
        gplan = plan(inst, sub)
    except ValueError as e:
        g.graded, g.reason = False, str(e)
        return g
    g.notes = gplan.notes
    solutions = {}
    for k, c in enumerate(gplan.cells):
        if c.role == "solution":
            inst_cell = next(x for x in inst.cells if _meta(x).get("grade_id") == c.grade_id)
            for name in _defined_names(inst_cell.source):
                solutions.setdefault(name, k)
    tests = [c for c in gplan.cells if c.role == "test"]
    g.max_score = sum(c.points for c in tests)
    guard = [Path(p) for p in (guard or [])]
    backup = _snapshot(guard) if guard else {}
    try:
        with Sandbox(limits, isolation=isolation, hide=hide) as sb:
            g.isolation = sb.isolation
            session = _Session(sb, gplan)
            try:
                session.run_all()
            except (_KernelGone, TimeoutError, RuntimeError) as e:
                g.notes.append(f"the notebook could not be run to its end: {e}")
            for k, c in enumerate(gplan.cells):
                res = session.status.get(k)
                if c.role == "course" and res is not None and not res.ok:
                    g.errors.append(f"cell {c.index}: {res.reason()}")
            for cell in tests:
                try:
                    g.exercises.append(_exercise(session, cell, solutions))
                except _KernelGone as e:
                    g.exercises.append(ExerciseResult(cell.grade_id, 0.0, cell.points,
                                                      "kernel died", str(e)))
            if session.restarts:
                g.notes.append(f"the kernel was restarted {session.restarts} time(s) and the "
                               "notebook's good cells replayed")
    except Exception as e:               # the grader's own trouble: say so, never a score
        g.graded, g.reason = False, f"grading failed: {type(e).__name__}: {e}"
    finally:
        if guard:
            changed = _restore(backup, guard)
            if changed:
                g.notes.append(f"the submission changed {len(changed)} course file(s) outside "
                               f"its scratch folder (e.g. {changed[0]}); they were restored "
                               "and the submission scores 0")
                for r in g.exercises:
                    r.points, r.status = 0.0, "tampered"
                    r.message = "the submission changed the course's files"
    g.score = sum(r.points for r in g.exercises)
    g.seconds = round(time.monotonic() - t0, 2)
    return g


def _submissions(args) -> list[Path]:
    """Notebook files named, or found below named folders (sorted)."""
    out = []
    for a in args:
        p = Path(a)
        if p.is_dir():
            out += sorted(q for q in p.rglob("*.ipynb") if ".ipynb_checkpoints" not in q.parts)
        else:
            out.append(p)
    return out


def grade_batch(paths, *, instructor_dir=None, json_path=None, limits: Limits = Limits(),
                isolation: str = "auto", log=print) -> list[SubmissionGrade]:
    """Grade every submission in ``paths`` (files, or folders searched for notebooks) against
    the instructor notebook of the same file name in ``instructor_dir`` (default the
    course's ``notebooks/``). A submission that cannot be graded gets its reason and the
    others go on; ``json_path`` is rewritten after every submission."""
    inst_dir = Path(instructor_dir or ROOT / "notebooks").resolve()
    subs = _submissions(paths)
    hide = {inst_dir} | {p.resolve().parent for p in subs}
    guard = [ROOT / "annslam_lib", inst_dir]
    from ..data import fetch
    if fetch.data_dir().exists():
        guard.append(fetch.data_dir())
    results = []
    for p in subs:
        inst = inst_dir / p.name
        if not p.exists():
            g = SubmissionGrade(str(p.resolve()), p.name, *student_of(p), graded=False,
                                reason="no such file")
        elif not inst.exists():
            g = SubmissionGrade(str(p.resolve()), p.name, *student_of(p), graded=False,
                                reason=f"no instructor notebook {p.name} in {inst_dir}")
        else:
            g = grade_submission(p, inst, limits=limits, isolation=isolation, hide=hide,
                                 guard=guard)
        results.append(g)
        log(g.report())
        if json_path:
            _write_json(json_path, results)
    return results


def _write_json(path, results) -> None:
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps([r.as_json() for r in results], indent=1))
    os.replace(tmp, path)
