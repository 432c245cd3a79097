"""Grading that a submission cannot game.

Design, in three rules:

1. **The instructor's notebook is the skeleton** (:mod:`~annslam_lib.course.plan`). Its cells, in its order, with its grade
   ids, points and test cells (hidden tests included), are what is graded. A submission
   contributes only the source of its *solution* cells, matched by grade id (or, if the
   student re-created a cell, by the function it defines). Everything else in it is ignored
   and reported: edited, deleted or retyped test cells, changed points, unknown grade ids,
   cells added with grading metadata.
2. **Student code runs in a sandbox, and only there.** One kernel per submission
   (:class:`~annslam_lib.course.sandbox.Sandbox`: bubblewrap, no privilege whoever starts
   the grader, nothing of the machine but the system, the Python environment and the data,
   resource limits, time-outs, a deadline) runs the instructor's course cells and the
   student's solution cells, in order. Test cells are *not* run there. Where the sandbox
   cannot be made, grading stops (isolation 'none', the grader's own rights, only when
   asked for, for a trusted notebook).
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
yourself"), found both in its source (and in the helpers it uses from the student's other
cells) and by a call monitor in the kernel (every thread); a solution that could hide what
it calls from both (dynamic imports, computed attribute names, function internals) scores 0
with the constructs named (:func:`~annslam_lib.course.plan.static_evasions`). What no
check stops: a student who copies the library's code into the answer; INSTRUCTOR.md says so.

Nothing the grader's own process loads can come from a submission: its bytecode lives in
a private folder (:func:`prepare_grader`), and every file of the course's folders,
``__pycache__`` and ``.git`` included, is watched while a batch is graded
(:class:`Guard`); a change stops the batch with a :class:`GradingEnvironmentError`. Every
text a submission can influence is made inert (:func:`inert`) before it is reported.

Batch grading (:func:`grade_batch`) grades every submission it can, gives each one it
cannot a reason, and writes one JSON file after every submission.
"""
from __future__ import annotations

import ast
import builtins
import contextlib
import io
import json
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from ..grading import forget_results
from ..grading.core import (GradingError, forbidden, forbidden_message, full_feedback,
                            grading_student)
from . import codec
from .integrity import Guard, course_folders, inert, prepare_grader
from .plan import (CODE_STUB, GradePlan, PlannedCell, defined_names, cell_meta, read_graded_notebook,
                   free_names, plan, static_evasions, static_forbidden)
from .sandbox import (NO_SANDBOX_WARNING, ExecResult, GradingEnvironmentError,
                      KernelStartError, Limits, Sandbox)

__all__ = ["ExerciseResult", "SubmissionGrade", "grade_submission", "grade_batch",
           "check_environment", "GradingEnvironmentError", "RemoteFunction", "student_of",
           "CODE_STUB"]

ROOT = Path(__file__).resolve().parents[2]
MAX_RESTARTS = 4


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
    # copied-code flags (grade_batch): {exercise, other, similarity}; never a score
    flags: list[dict] = field(default_factory=list)
    # what the flags compare, per test cell: {functions, source, references}; not reported
    solution_sources: dict = field(default_factory=dict, repr=False)

    def report(self) -> str:
        """The text report: one line per submission and per exercise; every line a
        submission's text continues is indented under its own (texts are inert)."""
        def more(text: str, indent: str) -> str:
            return text.replace("\n", "\n" + indent)

        who = f" ({self.student})" if self.student else ""
        if not self.graded:
            return f"{self.submission}{who}: NOT GRADED: {more(self.reason, '    | ')}"
        lines = [f"{self.submission}{who}: {self.score:g} / {self.max_score:g} points "
                 f"({self.seconds:.1f} s, sandbox: {self.isolation})"]
        if self.isolation == "none":
            lines.append(f"  WARNING: {NO_SANDBOX_WARNING}")
        for r in self.exercises:
            mark = "ok  " if r.status == "passed" else "FAIL"
            lines.append(f"  {mark} {r.grade_id} ({r.points:g}/{r.max_points:g})"
                         + ("" if r.status == "passed" else f" [{r.status}]"))
            if r.status != "passed" and r.message:
                lines += ["       | " + x for x in r.message.splitlines()[:6]]
        lines += [f"  note: {more(n, '    | ')}" for n in self.notes]
        lines += [f"  error outside the exercises: {more(e, '    | ')}" for e in self.errors]
        lines += [f"  FLAG {f['exercise']}: {f['similarity']:.2f} similar to {f['other']} "
                  f"(copied code? not scored: the instructor decides)" for f in self.flags]
        return "\n".join(lines)

    def make_inert(self) -> SubmissionGrade:
        """Escape, in every text a submission can influence, the characters a terminal or
        a page would act on (:func:`~annslam_lib.course.integrity.inert`); names and paths
        on one line, messages cut to a few thousand characters."""
        def one(x):
            return None if x is None else inert(x, lines=False)

        self.submission, self.notebook = one(self.submission), one(self.notebook)
        self.student, self.assignment = one(self.student), one(self.assignment)
        self.reason = inert(self.reason)
        self.notes = [inert(n) for n in self.notes]
        self.errors = [inert(e) for e in self.errors]
        for r in self.exercises:
            r.message = inert(r.message)
            r.grade_id = one(r.grade_id)
        for f in self.flags:
            f["other"] = one(str(f["other"]))
        return self

    def as_json(self) -> dict:
        d = asdict(self)
        d.pop("solution_sources")
        d["exercises"] = [asdict(r) for r in self.exercises]
        return d


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
        key = json.dumps(list(forbidden()))      # a reply holds for these paths only
        todo = [p for p in dict.fromkeys(payloads) if key + p not in self._batch]
        if not todo:
            return
        timeout = self._session.sandbox.limits.call_timeout * 4
        replies = self._round_trip("call_many", todo, timeout)
        if isinstance(replies, list) and len(replies) == len(todo):
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
        self._proxies: dict[str, tuple[int, RemoteFunction]] = {}

    def proxy(self, name: str) -> RemoteFunction:
        """The proxy of the student's ``name``: one per kernel, so that checks which keep a
        function's results by the function (``grading.forget_results``: a whole filter run per
        hidden run) run it once for all the test cells, as they do in the notebook; no
        student code runs between the test cells, and after a restart a new proxy is made."""
        made = self._proxies.get(name)
        if made is None or made[0] != self.restarts:
            made = self._proxies[name] = (self.restarts, RemoteFunction(self, name))
        return made[1]

    def _after_start(self, first: bool) -> None:
        res = self.sandbox.execute("import annslam_lib.course.kernel_side as __annslam_kernel__",
                                   60)
        self.helper_error = "" if res.ok else res.reason()
        if first and not res.ok:          # no student code has run yet: not the student's fault
            said = self.sandbox.kernel_log(0)
            raise GradingEnvironmentError(
                "the course's library cannot be imported in the grading kernel (before any "
                f"student code ran): {res.reason()}" + (f"; the kernel said: {said}" if said
                                                         else ""))

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
        first = not self.sandbox.kernels_started
        try:
            self.sandbox.start()
        except KernelStartError as e:
            if first:                     # nothing of the student's has run: the machine's fault
                raise GradingEnvironmentError(str(e)) from None
            raise _KernelGone(str(e)) from None
        self._after_start(first)
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
    mine = [c.source for c in session.plan.cells if c.role == "solution"]
    for name in student_names:
        k = solutions[name]
        source = session.plan.cells[k].source
        hits = static_forbidden(source, session.plan.context, paths, helpers=mine)
        if hits:
            return result("forbidden", forbidden_message(name, hits))
        hiding = static_evasions(source, session.plan.context, helpers=mine) if paths else []
        if hiding:
            return result("forbidden", f"{name} uses {', '.join(hiding)}: code that can hide "
                          "what it calls cannot be checked against the rule of this exercise "
                          "(write the library's function yourself); write it without these.")
    if session.helper_error:
        return result("kernel died", "the grader's helper could not be loaded in the "
                      f"submission's kernel: {session.helper_error}")
    # 3. the check itself, here, with the student's functions behind proxies
    for name in student_names:
        ns[name] = session.proxy(name)
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


# ------------------------------------------------------------------------------ copied code

def _solution_sources(gplan: GradePlan, tests, solutions: dict[str, int]) -> dict:
    """Per test cell: the student's functions it checks, the source of their solution
    cell, and the library functions its checks forbid (the references a copy would come
    from). Read from the plan, in the grader: no student code runs here."""
    ns: dict = {"__name__": "__annslam_sources__"}
    for stmt in gplan.grading_imports:
        exec(stmt, ns)                                   # the instructor's own imports
    aliases = set(ns)
    out = {}
    for cell in tests:
        names = sorted(n for n in free_names(cell.source) - aliases if n in solutions)
        if not names:
            continue
        paths = [p for c in _checks_used(cell.source, ns)
                 for p in getattr(c, "__annslam_forbids__", ())]
        out[cell.grade_id] = {"functions": names,
                              "source": "\n".join(dict.fromkeys(
                                  gplan.cells[solutions[n]].source for n in names)),
                              "references": list(dict.fromkeys(paths))}
    return out


def _reference_source(path: str) -> str | None:
    """The source of the library function 'module:qualname', or None."""
    import importlib
    import inspect

    mod, _, qual = path.partition(":")
    try:
        obj = importlib.import_module(mod)
        for part in qual.split("."):
            obj = getattr(obj, part)
        return inspect.getsource(inspect.unwrap(obj))
    except (ImportError, AttributeError, OSError, TypeError):
        return None


def flag_copied_code(results: list[SubmissionGrade], *, threshold: float | None = None) -> int:
    """Compare, exercise by exercise, every graded submission's solution with the library's
    implementation of the function it asks for and with the other submissions of the same
    notebook (:func:`similarity.flag_copies`); add each flag to the submissions involved
    (``SubmissionGrade.flags``). Scores are not touched. Returns the number of flags."""
    from .similarity import THRESHOLD, flag_copies

    by_notebook: dict[str, list[SubmissionGrade]] = {}
    for g in results:
        if g.graded:
            by_notebook.setdefault(g.notebook, []).append(g)
    labels = {id(g): labels_of(g) for g in results}
    n = 0
    for subs in by_notebook.values():
        exercises = sorted({gid for g in subs for gid in g.solution_sources})
        for gid in exercises:
            # a solution still the released stub is no solution: nothing to compare
            have = [g for g in subs if gid in g.solution_sources and not any(
                r.grade_id == gid and r.status == "not written" for r in g.exercises)]
            if not have:
                continue
            sols = {labels[id(g)]: g.solution_sources[gid]["source"] for g in have}
            refs = {}
            for p in have[0].solution_sources[gid]["references"]:
                src = _reference_source(p)
                if src is not None:
                    refs[p.replace(":", ".")] = src
            fn = have[0].solution_sources[gid]["functions"][0]
            who = {labels[id(g)]: g for g in have}
            for f in flag_copies(sols, refs, function=None,
                                 threshold=THRESHOLD if threshold is None else threshold):
                entry = {"exercise": gid, "function": fn, "similarity": round(f.similarity, 3)}
                who[f.student].flags.append({**entry, "other": f.other})
                if f.other in who:
                    who[f.other].flags.append({**entry, "other": f.student})
                n += 1
    return n


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
    and its reason. Raises :class:`GradingEnvironmentError` when the grading machine is at
    fault (no sandbox, a kernel that cannot start or import the library before any student
    code ran, a course file changed while this submission was graded): that is never a
    student's score; the exception's ``grade`` holds this submission's result when there is
    one. ``guard``: a :class:`Guard`, or folders to make one of, checked after the
    submission."""
    if guard is not None and not isinstance(guard, Guard):
        guard = Guard(guard, restorable=guard)
    t0 = time.monotonic()
    path = Path(path).resolve()
    student, assignment = student_of(path)
    g = SubmissionGrade(str(path), Path(instructor).name, student, assignment)
    try:
        inst = read_graded_notebook(Path(instructor), "instructor notebook")
        sub = read_graded_notebook(path, "submission")
        gplan = plan(inst, sub)
    except ValueError as e:
        g.graded, g.reason = False, str(e)
        return g.make_inert()
    g.notes = gplan.notes
    solutions = {}
    for k, c in enumerate(gplan.cells):
        if c.role == "solution":
            inst_cell = next(x for x in inst.cells if cell_meta(x).get("grade_id") == c.grade_id)
            for name in defined_names(inst_cell.source):
                solutions.setdefault(name, k)
    tests = [c for c in gplan.cells if c.role == "test"]
    g.max_score = sum(c.points for c in tests)
    g.solution_sources = _solution_sources(gplan, tests, solutions)
    tampered: list[str] = []
    try:
        with Sandbox(limits, isolation=isolation, hide=hide, user=student) as sb:
            g.isolation = sb.isolation
            session = _Session(sb, gplan)
            try:
                session.run_all()
            except GradingEnvironmentError:
                raise
            except (_KernelGone, TimeoutError, RuntimeError) as e:
                g.notes.append(f"the notebook could not be run to its end: {e}")
            for k, c in enumerate(gplan.cells):
                res = session.status.get(k)
                if c.role == "course" and res is not None and not res.ok:
                    g.errors.append(f"cell {c.index}: {res.reason()}")
            for cell in tests:
                try:
                    # the instructor's returned feedback, in full; a draw per student is
                    # the submission's student's (the demo draw outside nbgrader's layout)
                    with full_feedback(), grading_student(student or "demo"):
                        g.exercises.append(_exercise(session, cell, solutions))
                except _KernelGone as e:
                    g.exercises.append(ExerciseResult(cell.grade_id, 0.0, cell.points,
                                                      "kernel died", str(e)))
            if session.restarts:
                g.notes.append(f"the kernel was restarted {session.restarts} time(s) and the "
                               "notebook's good cells replayed")
    except GradingEnvironmentError:      # the machine's fault: the caller stops, no score
        raise
    except Exception as e:               # the grader's own trouble: say so, never a score
        g.graded, g.reason = False, f"grading failed: {type(e).__name__}: {e}"
    finally:
        forget_results()                 # the results of this submission's functions
        if guard is not None:
            tampered = guard.changes()
    if tampered:
        lost = guard.restore(tampered)
        by = ("by this submission, which ran unsandboxed" if g.isolation == "none" else
              "while this submission was graded (not by it: the sandbox cannot write there)")
        g.notes.append(f"{len(tampered)} course file(s) changed {by}: "
                       + ", ".join(tampered[:5]) + ("; restored" if not lost else
                                                    f"; NOT restorable: {', '.join(lost[:5])}"))
        if g.isolation == "none":
            for r in g.exercises:
                r.points, r.status = 0.0, "tampered"
                r.message = "the submission changed the course's files"
    g.score = sum(r.points for r in g.exercises)
    g.seconds = round(time.monotonic() - t0, 2)
    g.make_inert()
    if tampered:
        err = GradingEnvironmentError(
            f"course files changed while {g.submission} was graded ({g.notes[-1]}); grading "
            "stops here: check the machine (and restore anything not restorable from a clean "
            "copy of the course) before grading again")
        err.grade = g
        raise err
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


def check_environment(*, limits: Limits = Limits(), isolation: str = "auto",
                      hide=()) -> str:
    """Start a grading kernel with no student code, import the course's library and NumPy in
    it, and return the isolation used; raise :class:`GradingEnvironmentError` naming the
    cause if any of it fails (no bubblewrap or no rights to use it, an interpreter or
    library the sandbox cannot reach, a broken install)."""
    probe = ("import os, numpy, annslam_lib, annslam_lib.course.kernel_side\n"
             "assert annslam_lib.__file__.startswith(os.environ['PYTHONPATH']), "
             "f'the kernel imported {annslam_lib.__file__}, not the snapshot'")
    with Sandbox(limits, isolation=isolation, hide=hide) as sb:
        try:
            sb.start()
        except KernelStartError as e:
            raise GradingEnvironmentError(str(e)) from None
        res = sb.execute(probe, 120)
        if not res.ok:
            said = sb.kernel_log(0)
            raise GradingEnvironmentError(
                "the course's library cannot be imported in the grading kernel: "
                f"{res.reason()}" + (f"; the kernel said: {said}" if said else ""))
        return sb.isolation


def grade_batch(paths, *, instructor_dir=None, json_path=None, limits: Limits = Limits(),
                isolation: str = "auto", log=print, hide=()) -> list[SubmissionGrade]:
    """Grade every submission in ``paths`` (files, or folders searched for notebooks) against
    the instructor notebook of the same file name in ``instructor_dir`` (default the
    course's ``notebooks/``). A submission that cannot be graded gets its reason and the
    others go on; ``json_path`` is rewritten after every submission. The student's code
    never sees the course's checkout, the instructor notebooks, the other submissions, the
    JSON's folder or ``hide`` (more folders). Raises :class:`GradingEnvironmentError` (the
    JSON keeping what was graded before) when the sandbox cannot be made or a course file
    changes (:class:`Guard`)."""
    inst_dir = Path(instructor_dir or ROOT / "notebooks").resolve()
    subs = _submissions(paths)
    hide = ({inst_dir} | {p.resolve().parent for p in subs} | {Path(h).resolve() for h in hide}
            | ({Path(json_path).resolve().parent} if json_path else set()))
    results: list[SubmissionGrade] = []
    if any(p.exists() for p in subs):
        prepare_grader(isolation)
        if check_environment(limits=limits, isolation=isolation, hide=hide) != "none":
            from .cgroup import unavailable
            if why := unavailable():
                log(f"note: memory and processes are bounded per process here, not for each "
                    f"submission as a whole ({why}); the grader bounds both when run as root")
    guarded, restorable = course_folders(inst_dir, isolation=isolation)
    guard = Guard(guarded, restorable=restorable)
    for p in subs:
        inst = inst_dir / p.name
        if not p.exists():
            g = SubmissionGrade(str(p.resolve()), p.name, *student_of(p), graded=False,
                                reason="no such file").make_inert()
        elif not inst.exists():
            g = SubmissionGrade(str(p.resolve()), p.name, *student_of(p), graded=False,
                                reason=f"no instructor notebook {p.name} in {inst_dir}"
                                ).make_inert()
        else:
            try:
                g = grade_submission(p, inst, limits=limits, isolation=isolation, hide=hide,
                                     guard=guard)
            except GradingEnvironmentError as e:
                if getattr(e, "grade", None) is not None:
                    results.append(e.grade)
                    log(e.grade.report())
                    if json_path:
                        _write_json(json_path, results)
                raise
        results.append(g)
        log(g.report())
        if json_path:
            _write_json(json_path, results)
    n = flag_copied_code(results)
    if n:
        log(f"copied-code flags ({n} pair(s); for the instructor to read, no score changed):")
        for g in results:
            for f in g.flags:
                log(f"  {labels_of(g)} {f['exercise']}: {f['similarity']:.2f} similar to {f['other']}")
    if json_path:
        _write_json(json_path, results)
    return results


def labels_of(g: SubmissionGrade) -> str:
    """How a submission is named in the flags: its student, else its path."""
    return g.student or g.submission


def _write_json(path, results) -> None:
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps([r.as_json() for r in results], indent=1))
    os.replace(tmp, path)
