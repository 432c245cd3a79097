"""Checks that compare a student's function with the course's reference and say what is wrong.

A check evaluates both functions on the same inputs (seeded random cases plus the edge
cases a chapter chooses) and either returns a one-line success message or raises
:class:`GradingError` whose message names the input, the output component or Jacobian entry,
the expected and the received value, and, where the pattern is recognisable, the likely
mistake: a sign error, a transposed matrix, swapped outputs, degrees instead of radians, a
constant bearing offset (the laser's bearing convention), ``arctan`` instead of ``arctan2``,
an unwrapped angle, a constant factor, or one of the chapter's known mistakes
(:class:`Mistake`, e.g. the paper's printed equation).

nbgrader marks a test cell failed when it raises; ``GradingError`` is an ``AssertionError``
so the cell fails like any assertion, but with a message a student can act on.
"""
from __future__ import annotations

import contextlib
import contextvars
import functools
import sys
import threading
import types
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .. import _settings

__all__ = ["GradingError", "Mistake", "Passed", "passed", "call", "check_function", "check_jacobian", "check_raises",
           "describe", "fail", "fmt", "NOT_WRITTEN", "forbids", "forbidden", "watch_calls",
           "function_path", "prefetch", "labelled", "passing_prefetch", "copying", "wrap_pi",
           "allowing_library_calls", "full_feedback", "is_full_feedback",
           "graded_student", "grading_student"]

NOT_WRITTEN = "is not written yet"


class GradingError(AssertionError):
    """An exercise check failed; the message says what, where, expected vs got, and why.

    In a notebook the message is all a student sees: IPython shows what
    ``_render_traceback_`` returns instead of a traceback into the grading code."""

    def _render_traceback_(self) -> list[str]:
        lines = str(self).splitlines() or [""]
        return [f"\x1b[0;31mGradingError\x1b[0m: {lines[0]}", *lines[1:]]


# ----------------------------------------------------------------------- forbidden calls

_FORBIDDEN: contextvars.ContextVar[tuple[str, ...]] = contextvars.ContextVar(
    "annslam_forbidden", default=())


def function_path(fn) -> str:
    """'module:qualname' of a function, the name the call monitor watches."""
    fn = getattr(fn, "__wrapped__", fn)
    return f"{fn.__module__}:{fn.__qualname__}"


def forbids(*functions: Callable):
    """Decorator for a check: a solution must not call these library functions (it is the
    exercise to write them). While the check runs, a call to one of them from the student's
    function fails with "my_f calls module.function: write it yourself" (here by a call
    monitor; in the grader also by reading the solution's source)."""
    paths = tuple(function_path(f) for f in functions)

    def decorate(check):
        @functools.wraps(check)
        def wrapper(*args, **kwargs):
            token = _FORBIDDEN.set(_FORBIDDEN.get() + paths)
            try:
                return check(*args, **kwargs)
            finally:
                _FORBIDDEN.reset(token)
        wrapper.__annslam_forbids__ = paths
        return wrapper
    return decorate


_ALLOWED: contextvars.ContextVar[bool] = contextvars.ContextVar("annslam_allowed", default=False)


def forbidden() -> tuple[str, ...]:
    """The 'module:qualname' paths forbidden by the checks running now."""
    return () if _ALLOWED.get() else _FORBIDDEN.get()


@contextlib.contextmanager
def allowing_library_calls():
    """Checks inside this block accept answers built from the library (the course's own
    tests of the checks' messages build wrong answers that way; a grader never uses it)."""
    token = _ALLOWED.set(True)
    try:
        yield
    finally:
        _ALLOWED.reset(token)


def _function_of(path: str):
    """The library function 'module:qualname' (None if it is not a Python function)."""
    import importlib

    mod, _, qual = path.partition(":")
    try:
        obj = importlib.import_module(mod)
        for part in qual.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError):
        return None
    return obj if isinstance(getattr(obj, "__code__", None), types.CodeType) else None


class _Tripwire:
    """For the life of a block, a library function's code is replaced by one that records
    the call and then runs the original: every reference to the function object (an alias,
    a ``getattr``, a helper, another thread) goes through it."""

    def __init__(self, fn, path: str, record) -> None:
        self.fn, self.code = fn, fn.__code__
        if self.code.co_freevars:           # a closure's code cannot be swapped: profile only
            self.fn = None
            return
        original = types.FunctionType(self.code, fn.__globals__, fn.__name__, fn.__defaults__)
        original.__kwdefaults__ = fn.__kwdefaults__
        self.key = f"__annslam_tripwire_{id(fn):x}__"
        fn.__globals__[self.key] = (record, original, path)
        ns: dict = {}
        exec(compile(f"def {fn.__name__}(*args, **kwargs):\n"
                     f"    record, original, path = {self.key}\n"
                     "    record(path)\n"
                     "    return original(*args, **kwargs)\n", "<call monitor>", "exec"), ns)
        fn.__code__ = ns[fn.__name__].__code__

    def remove(self) -> None:
        if self.fn is not None:
            self.fn.__code__ = self.code
            self.fn.__globals__.pop(self.key, None)


@contextlib.contextmanager
def watch_calls(paths: Sequence[str]):
    """Record, in the yielded list, which of the functions ``paths`` ('module:qualname')
    are called inside the block, from any thread: a profile function on this thread and on
    every thread started in the block (``sys.setprofile``, ``threading.setprofile``), and a
    tripwire in each watched function itself (:class:`_Tripwire`), which also sees calls
    from threads started before the block. A monitor removed by the code inside is recorded
    too."""
    functions = {p: f for p in paths if (f := _function_of(p)) is not None}
    hits: list[str] = []
    if not functions:
        yield hits
        return
    watched = {f.__code__: p for p, f in functions.items()}

    def monitor(frame, event, arg):
        if event == "call" and frame.f_code in watched:
            hits.append(watched[frame.f_code])

    previous, previous_threads = sys.getprofile(), threading.getprofile()
    wires = []
    try:
        for p, f in functions.items():
            wires.append(_Tripwire(f, p, hits.append))
        sys.setprofile(monitor)
        threading.setprofile(monitor)
        yield hits
    finally:
        if sys.getprofile() is not monitor:
            hits.append("<the call monitor was removed>")
        sys.setprofile(previous)
        threading.setprofile(previous_threads)
        for w in wires:
            w.remove()


def forbidden_message(name: str, hits: Sequence[str]) -> str:
    shown = [h.replace(":", ".") for h in dict.fromkeys(hits)]
    if any(h.startswith("<") for h in shown):
        return (f"{name} removed the grader's call monitor (sys.setprofile): a solution must "
                "not interfere with the checks.")
    return f"{name} calls {' and '.join(shown)}: write it yourself."


class Passed(str):
    """The success message of a check. It is printed when the check runs; as the value of a
    notebook cell's last line it displays nothing, so the message is not shown twice."""

    def _ipython_display_(self) -> None:
        pass


def passed(message: str, quiet: bool = False) -> Passed:
    """A check's success: ``message`` printed (unless ``quiet``) and returned as :class:`Passed`."""
    ok = Passed(message)
    if not quiet:
        print(ok)
    return ok


@dataclass(frozen=True)
class Mistake:
    """A known wrong answer: if the student's output equals ``wrong(*args)`` on every case
    (within tolerance), the check fails with ``message`` instead of a generic diff.
    ``wrong`` returns the COMPARED part (what a check's ``output=`` extracts), not the whole
    return value.

    ``message`` names the KIND of mistake and where to look; it never states the answer.
    ``answer`` (optional) is what would hand the exercise over (the correct formula): it is
    added only in the instructor's returned feedback (:func:`full_feedback`), so a student
    cannot guess-and-check their way to a pass from the messages of their own checks."""
    message: str
    wrong: Callable[..., Any]
    answer: str = ""

    @property
    def text(self) -> str:
        """The message as this audience sees it (with ``answer`` in full feedback)."""
        if self.answer and _FULL_FEEDBACK.get():
            return f"{self.message} {self.answer}"
        return self.message

    def renamed(self, old: str, new: str) -> "Mistake":
        """The same mistake with ``old`` replaced by ``new`` in its texts (a function's name)."""
        return Mistake(self.message.replace(old, new), self.wrong, self.answer.replace(old, new))


_FULL_FEEDBACK: contextvars.ContextVar[bool] = contextvars.ContextVar(
    "annslam_full_feedback", default=_settings.full_feedback())


_STUDENT: contextvars.ContextVar[str | None] = contextvars.ContextVar("annslam_student",
                                                                   default=None)


def is_full_feedback() -> bool:
    """True inside :func:`full_feedback` (or with ``ANNSLAM_FEEDBACK=full``): messages may
    carry their answer."""
    return _FULL_FEEDBACK.get()


def graded_student() -> str | None:
    """The student the course's grader is grading (its nbgrader id), None in a notebook."""
    return _STUDENT.get()


@contextlib.contextmanager
def grading_student(name: str | None):
    """Grade as student ``name`` (a check drawn per student reads it, never the kernel's)."""
    token = _STUDENT.set(name)
    try:
        yield
    finally:
        _STUDENT.reset(token)


@contextlib.contextmanager
def full_feedback():
    """Messages with their ``answer`` part: the feedback an instructor returns after grading
    (the course's grader grades inside this; ``ANNSLAM_FEEDBACK=full`` sets it for a kernel)."""
    token = _FULL_FEEDBACK.set(True)
    try:
        yield
    finally:
        _FULL_FEEDBACK.reset(token)


def fail(message: str) -> None:
    """Raise :class:`GradingError` with ``message`` (for chapter-specific checks)."""
    raise GradingError(message)


# ----------------------------------------------------------------------------- formatting

def fmt(x) -> str:
    """Compact, deterministic text for a number, vector or matrix (4 significant digits)."""
    if x is None:
        return "None"
    try:
        a = np.asarray(x)
    except ValueError:  # ragged, e.g. a tuple (vector, matrix)
        return "(" + ", ".join(fmt(v) for v in x) + ")" if isinstance(x, (tuple, list)) else repr(x)
    if a.dtype == bool:
        return str(a.tolist())
    if not np.issubdtype(a.dtype, np.number):
        return repr(x)
    a = a.astype(float)
    if a.size > 12:  # a whole covariance matrix would drown the message
        return f"<{'x'.join(map(str, a.shape))} array, max |entry| {np.nanmax(np.abs(a)):.4g}>"
    if a.ndim == 0:
        v = float(a)
        return "0" if v == 0 else f"{v:.4g}"
    if a.ndim == 1:
        return "(" + ", ".join(fmt(v) for v in a) + ")"
    return "[" + ", ".join(fmt(r) for r in a) + "]"


def describe(args: Sequence, names: Sequence[str] | None = None) -> str:
    """'v_e=2, alpha=0.3' for the inputs of one case."""
    names = list(names or [f"arg{i}" for i in range(len(args))])
    return ", ".join(f"{n}={fmt(a)}" for n, a in zip(names, args))


def prefetch(fn: Callable, cases: Sequence[Sequence]) -> None:
    """Tell ``fn`` the inputs it is about to be called with, one by one. A plain function
    ignores this; the grader's proxy for a student's function (which runs in another
    process) evaluates them all in one round trip, so the calls that follow are answered
    from that batch."""
    hook = getattr(fn, "__annslam_prefetch__", None)
    if hook is not None:
        hook([tuple(c) for c in cases])


def labelled(fn: Callable, table: dict) -> Callable:
    """``fn`` called with the arguments stored under a case label (checks whose inputs are
    big arrays name the case by its label in messages); prefetching passes through."""
    def by_label(label):
        return fn(*table[label])
    by_label.__annslam_prefetch__ = lambda cases: prefetch(fn, [table[c[0]] for c in cases])
    return by_label


def passing_prefetch(wrapper: Callable, fn: Callable) -> Callable:
    """Mark ``wrapper`` (called with the same arguments as ``fn``) as prefetching for it."""
    wrapper.__annslam_prefetch__ = lambda cases: prefetch(fn, cases)
    return wrapper


def copying(fn: Callable) -> Callable:
    """Call ``fn`` on copies, so a student function that edits its input in place cannot
    change the cases the check compares afterwards."""
    def run(*args):
        return fn(*(a.copy() if isinstance(a, np.ndarray) else a for a in args))
    return run


def call(fn: Callable, args: Sequence, *, name: str, arg_names: Sequence[str] | None = None):
    """Call the student's ``fn(*args)`` and turn what it raises into a :class:`GradingError`
    that names the function and the input (NotImplementedError: not written yet)."""
    paths = forbidden()
    try:
        if paths and not getattr(fn, "__annslam_remote__", False):
            with watch_calls(paths) as hits:
                out = fn(*args)
            if hits:
                raise GradingError(forbidden_message(name, hits))
            return out
        return fn(*args)
    except NotImplementedError:
        raise GradingError(
            f"{name} {NOT_WRITTEN}: it raised NotImplementedError. Replace the line "
            f"`raise NotImplementedError()` in its cell with your code, run that cell, "
            f"then run this check again.") from None
    except GradingError:
        raise
    except Exception as e:  # the student's bug: report it with the input that caused it
        raise GradingError(f"{name}({describe(args, arg_names)}) raised "
                           f"{type(e).__name__}: {e}") from None


def _as_numbers(name: str, out, shape: tuple, where: str) -> np.ndarray:
    if out is None:
        raise GradingError(f"{name} returned None at {where}: did you forget `return`?")
    try:
        a = np.asarray(out, dtype=float)
    except (TypeError, ValueError):
        raise GradingError(f"{name} returned {type(out).__name__} {out!r:.80} at {where}; "
                           f"expected numbers of shape {shape}") from None
    if a.shape != shape:
        if a.size == int(np.prod(shape)) and np.squeeze(a).shape == tuple(d for d in shape if d != 1):
            return a.reshape(shape)
        raise GradingError(f"{name} returned shape {a.shape} at {where}; expected shape {shape}")
    return a


def wrap_pi(a):
    """Angles wrapped to [-pi, pi) by the modulo, NaN passed through (a student's NaN must
    reach the comparison)."""
    # not models.geometry.wrap_angle: that one maps to (-pi, pi] and rejects NaN
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


# ----------------------------------------------------------------------------- checks

@dataclass
class _Run:
    got: np.ndarray       # (n, *shape)
    exp: np.ndarray
    err: np.ndarray       # got - exp, angle entries wrapped
    tol: np.ndarray
    bad: np.ndarray       # (n, *shape) bool
    where: list[str]


def _evaluate(fn, reference, cases, *, name, arg_names, output, angle_mask, atol, rtol,
              wrap_mask=None) -> _Run:
    prefetch(fn, cases)
    got, exp, where = [], [], []
    for args in cases:
        args = tuple(args)
        w = describe(args, arg_names)
        e = np.asarray(output(reference(*args)), dtype=float)
        raw = call(fn, args, name=name, arg_names=arg_names)
        try:
            part = output(raw)
        except GradingError:
            raise
        except Exception:  # e.g. None or a 2-tuple where the check takes out[2]
            raise GradingError(f"{name} returned {type(raw).__name__} {fmt(raw)} at {w}, which is "
                               f"not what the exercise asks for (check the number and order of "
                               f"the values you return)") from None
        g = _as_numbers(name, part, e.shape, w)
        got.append(g)
        exp.append(e)
        where.append(w)
    got, exp = np.array(got), np.array(exp)
    with np.errstate(invalid="ignore"):
        err = got - exp
        err = np.where(angle_mask, wrap_pi(err), err)
        tol = atol + rtol * np.abs(exp)
        bad = ~(np.abs(err) <= tol)  # NaN counts as bad
        if wrap_mask is not None and wrap_mask.any():  # must lie in (-pi, pi]
            bad |= wrap_mask & ~((got > -np.pi - tol) & (got <= np.pi + tol))
    return _Run(got, exp, err, tol, bad, where)


def _label(labels, idx: tuple) -> str:
    """'bearing' / 'd bearing / d phi, entry [1, 2]' / 'entry [1, 2]'."""
    if not idx:
        return "the output"
    if labels is None:
        return f"entry {list(idx)}" if len(idx) > 1 else f"component {idx[0]}"
    if len(idx) == 1:
        return f"'{labels[idx[0]]}'"
    rows, cols = labels
    return f"d {rows[idx[0]]} / d {cols[idx[1]]} (entry [{idx[0]}, {idx[1]}])"


def _close(a, b, tol) -> bool:
    with np.errstate(invalid="ignore"):
        return bool(np.all(np.abs(a - b) <= tol))


def _diagnose(run: _Run, *, name, labels, angle_mask, wrap_mask, mistakes, cases,
              angle_hint: str, matrix: bool, output: Callable = lambda out: out) -> str | None:
    """A message for a recognisable pattern of failure, or None."""
    got, exp, tol = run.got, run.exp, run.tol
    # 1. NaN or inf where the reference is finite
    nonfinite = ~np.isfinite(got) & np.isfinite(exp)
    if nonfinite.any():
        k, *idx = (int(i) for i in np.argwhere(nonfinite)[0])
        msg = (f"{name} returned {fmt(got[(k, *idx)])} for {_label(labels, tuple(idx))} at "
               f"{run.where[k]}; expected {fmt(exp[(k, *idx)])}.")
        if angle_mask[tuple(idx)]:
            msg += " np.arctan(dy / dx) fails when dx = 0: use np.arctan2(dy, dx)."
        else:
            msg += " Look for a division by zero."
        return msg
    # 2. a chapter's known mistakes (e.g. the paper's printed equation)
    for m in mistakes:
        try:
            wrong = np.array([np.asarray(m.wrong(*c), dtype=float) for c in cases])
        except Exception:  # the wrong form may be undefined on some case: then it is not this
            continue
        if wrong.shape == got.shape:
            d = np.where(angle_mask, wrap_pi(got - wrong), got - wrong)
            if _close(d, 0, tol) and not _close(wrong, exp, tol):
                return m.text
    # 3. patterns over all cases
    if _close(got, -exp, tol):
        return f"every output of {name} has the wrong sign (e.g. at {run.where[0]}: expected " \
               f"{fmt(exp[0])}, got {fmt(got[0])})."
    if matrix and got.shape[1] == got.shape[2] and _close(np.swapaxes(got, 1, 2), exp, tol):
        return f"{name} returns the transpose of the expected matrix: rows are the outputs, " \
               f"columns the inputs you differentiate by."
    if not matrix and got.ndim == 2 and got.shape[1] == 2 and _close(got[:, ::-1], exp, tol):
        comp = " and ".join(labels) if labels else "the two outputs"
        return f"{name} returns {comp} swapped: return them in that order."
    # per entry (vector component or Jacobian entry): a specific message for each wrong entry
    # whose pattern is recognisable; if every wrong entry has one, they are the answer,
    # otherwise the generic report lists the entries (with these notes).
    notes = _entry_notes(run, labels=labels, angle_mask=angle_mask, wrap_mask=wrap_mask,
                         angle_hint=angle_hint)
    wrong = [tuple(int(i) for i in ix) for ix in np.argwhere(run.bad.any(axis=0))]
    if wrong and all(ix in notes for ix in wrong):
        return "\n".join(notes[ix] for ix in wrong)
    return None


def _entry_notes(run: _Run, *, labels, angle_mask, wrap_mask, angle_hint) -> dict:
    """{entry index: message} for wrong entries with a recognisable pattern over all cases."""
    n = len(run.got)
    flat_got = run.got.reshape(n, -1)
    flat_exp, flat_tol = run.exp.reshape(n, -1), run.tol.reshape(n, -1)
    flat_angle, flat_wrap = angle_mask.reshape(-1), wrap_mask.reshape(-1)
    shape = run.got.shape[1:]
    notes = {}
    for j in range(flat_got.shape[1]):
        g, e, t = flat_got[:, j], flat_exp[:, j], flat_tol[:, j]
        idx = tuple(int(i) for i in np.unravel_index(j, shape)) if shape else ()
        note = _entry_note(g, e, t, run.where, _label(labels, idx), bool(flat_angle[j]),
                           bool(flat_wrap[j]), angle_hint)
        if note:
            notes[idx] = note
    return notes


def _entry_note(g, e, t, where, lab, angle: bool, wrap: bool, angle_hint: str) -> str | None:
    if angle:
        d = wrap_pi(g - e)
        if _close(d, 0, t):
            if wrap and not _close(g, e, t):
                k = int(np.argmax(np.abs(g - e) > t))
                return (f"{lab} is right modulo 2π but not wrapped into (-π, π]: at "
                        f"{where[k]} expected {fmt(e[k])}, got {fmt(g[k])}. Wrap it, e.g. "
                        f"(a + np.pi) % (2 * np.pi) - np.pi.")
            return None
        if _close(g, np.degrees(e), np.degrees(t)):
            return f"{lab} is in degrees; the course works in radians."
        off = float(np.median(d))
        if _close(wrap_pi(d - off), 0, t) and abs(off) > 1e-6:
            deg = np.degrees(off)
            amount = "180°" if abs(abs(deg) - 180) < 1e-3 else f"{deg:+.1f}°"
            msg = (f"{lab} is off by a constant {amount} at every input (e.g. at {where[0]}: "
                   f"expected {fmt(e[0])}, got {fmt(g[0])}).")
            if abs(abs(deg) - 90) < 1e-3 and angle_hint:
                msg += " " + angle_hint
            elif abs(abs(deg) - 180) < 1e-3:
                msg += (" A 180° offset means the direction is reversed: sensor to landmark, "
                        "not landmark to sensor.")
            return msg
        with np.errstate(invalid="ignore"):
            half = (np.abs(np.abs(d) - np.pi) <= t) | (np.abs(d) <= t)
        if np.all(half):
            k = int(np.argmax(np.abs(d) > t))
            return (f"{lab} is off by 180° at some inputs (e.g. {where[k]}: expected "
                    f"{fmt(e[k])}, got {fmt(g[k])}) and right at others: np.arctan(dy / dx) "
                    f"loses the quadrant; use np.arctan2(dy, dx).")
        return None
    if _close(g, e, t):
        return None
    scale = np.abs(e) > 1e-6
    if scale.any() and _close(g, -e, t) and np.any(np.abs(e) > t):
        k = int(np.argmax(scale))
        return (f"{lab} has the wrong sign at every input (e.g. at {where[k]}: expected "
                f"{fmt(e[k])}, got {fmt(g[k])}).")
    if scale.sum() >= 2 and not np.any(~scale & (np.abs(g) > t)):
        ratio = g[scale] / e[scale]
        r0 = float(np.median(ratio))
        if np.all(np.abs(ratio - r0) <= 1e-6 * max(1.0, abs(r0))) and abs(r0 - 1) > 1e-6 \
                and abs(r0) > 1e-9:
            k = int(np.argmax(scale))
            return (f"{lab} is off by a constant factor {r0:.4g} at every input (e.g. at "
                    f"{where[k]}: expected {fmt(e[k])}, got {fmt(g[k])}).")
    return None


def _report(run: _Run, *, name, labels, notes: dict | None = None) -> str:
    """The generic message: how many inputs fail, and the first one in detail."""
    n = len(run.got)
    bad_case = run.bad.reshape(n, -1).any(axis=1)
    k = int(np.argmax(bad_case))
    entries = [tuple(int(i) for i in ix) for ix in np.argwhere(run.bad[k])]
    lines = [f"{name} disagrees with the reference at {int(bad_case.sum())} of {n} inputs. "
             f"First: {run.where[k]}"]
    for idx in entries[:4]:
        g, e = run.got[(k, *idx)], run.exp[(k, *idx)]
        note = ""
        if abs(e) > run.tol[(k, *idx)] and abs(g + e) <= run.tol[(k, *idx)]:
            note = "  <- sign error"
        elif g == 0 and e != 0:
            note = "  <- left at zero"
        elif e == 0 and g != 0:
            note = "  <- should be zero"
        lines.append(f"  {_label(labels, idx)}: expected {fmt(e)}, got {fmt(g)}{note}")
    if len(entries) > 4:
        lines.append(f"  ... and {len(entries) - 4} more entries")
    always = run.bad.all(axis=0)
    if run.got.ndim > 2 and always.any() and bad_case.sum() > 1:
        wrong = [_label(labels, tuple(int(i) for i in ix)) for ix in np.argwhere(always)]
        lines.append(f"  wrong at every failing input: {', '.join(wrong[:4])}")
    lines += [f"  {note}" for note in (notes or {}).values()]
    return "\n".join(lines)


def _masks(shape: tuple, angles: Sequence, wrap: bool | Sequence) -> tuple[np.ndarray, np.ndarray]:
    angle = np.zeros(shape, bool)
    for i in angles:
        angle[i] = True
    wrap_mask = angle.copy() if wrap is True else np.zeros(shape, bool)
    if wrap not in (True, False):
        for i in wrap:
            wrap_mask[i] = True
    return angle, wrap_mask


def check_function(fn: Callable, reference: Callable, cases: Sequence[Sequence], *, name: str,
                   arg_names: Sequence[str] | None = None, labels: Sequence[str] | None = None,
                   angles: Sequence[int] = (), wrap: bool | Sequence[int] = True,
                   atol: float = 1e-8, rtol: float = 1e-6, mistakes: Sequence[Mistake] = (),
                   angle_hint: str = "", output: Callable = lambda out: out,
                   what: str = "the reference", quiet: bool = False) -> str:
    """Compare ``fn(*case)`` with ``reference(*case)`` on every case.

    ``labels`` name the output components; ``angles`` are the indices of angle components
    (compared modulo 2π; with ``wrap`` they must also lie in (-π, π]). ``output`` extracts the
    compared part of both results (e.g. ``lambda out: out[0]``). ``mistakes`` are known wrong
    answers with their own messages; ``angle_hint`` explains a ±90° offset (the bearing
    convention). Returns (and prints, unless ``quiet``) a one-line success message; raises
    :class:`GradingError` otherwise.
    """
    cases = [tuple(c) for c in cases]
    if not cases:
        raise ValueError("check_function needs at least one case")
    shape = np.asarray(output(reference(*cases[0])), dtype=float).shape
    angle_mask, wrap_mask = _masks(shape, [(i,) if np.ndim(i) == 0 else tuple(i) for i in angles],
                                   wrap if isinstance(wrap, bool) else [(i,) for i in wrap])
    run = _evaluate(fn, reference, cases, name=name, arg_names=arg_names, output=output,
                    angle_mask=angle_mask, atol=atol, rtol=rtol, wrap_mask=wrap_mask)
    if run.bad.any():
        msg = _diagnose(run, name=name, labels=labels, angle_mask=angle_mask,
                        wrap_mask=wrap_mask, mistakes=mistakes, cases=cases,
                        angle_hint=angle_hint, matrix=False, output=output)
        raise GradingError(msg or _report(run, name=name, labels=labels, notes=_entry_notes(
            run, labels=labels, angle_mask=angle_mask, wrap_mask=wrap_mask, angle_hint=angle_hint)))
    return passed(f"✓ {name} agrees with {what} on {len(cases)} inputs.", quiet)


def check_jacobian(fn: Callable, reference: Callable, cases: Sequence[Sequence], *, name: str,
                   rows: Sequence[str], cols: Sequence[str],
                   arg_names: Sequence[str] | None = None, atol: float = 1e-7,
                   rtol: float = 1e-6, mistakes: Sequence[Mistake] = (),
                   output: Callable = lambda out: out, what: str = "the reference Jacobian",
                   quiet: bool = False) -> str:
    """Compare a Jacobian ``fn(*case)`` (len(rows) x len(cols)) with ``reference(*case)``.

    A failure names the entry as 'd bearing / d phi (entry [1, 2])', the input, expected vs
    got, and flags sign errors, entries left at zero, a transposed matrix and entries wrong at
    every failing input. Returns (and prints) a success message or raises GradingError.
    """
    cases = [tuple(c) for c in cases]
    shape = (len(rows), len(cols))
    ref_shape = np.asarray(output(reference(*cases[0])), dtype=float).shape
    if ref_shape != shape:
        raise ValueError(f"reference Jacobian has shape {ref_shape}, labels say {shape}")
    no_angles = np.zeros(shape, bool)
    run = _evaluate(fn, reference, cases, name=name, arg_names=arg_names, output=output,
                    angle_mask=no_angles, atol=atol, rtol=rtol)
    labels = (list(rows), list(cols))
    if run.bad.any():
        msg = _diagnose(run, name=name, labels=labels, angle_mask=no_angles, wrap_mask=no_angles,
                        mistakes=mistakes, cases=cases, angle_hint="", matrix=True,
                        output=output)
        raise GradingError(msg or _report(run, name=name, labels=labels, notes=_entry_notes(
            run, labels=labels, angle_mask=no_angles, wrap_mask=no_angles, angle_hint="")))
    return passed(f"✓ {name} agrees with {what} on {len(cases)} inputs.", quiet)


def check_raises(fn: Callable, args: Sequence, *, name: str, why: str,
                 exception: type[BaseException] = ValueError,
                 arg_names: Sequence[str] | None = None) -> None:
    """``fn(*args)`` must raise ``exception`` (bad input gets a clear error, never a
    silent wrong answer); ``why`` says what is wrong with the input."""
    try:
        out = fn(*args)
    except NotImplementedError:
        call(fn, args, name=name)  # re-raises the 'not written yet' message
    except exception:
        return
    except Exception as e:
        raise GradingError(f"{name}({describe(args, arg_names)}) raised {type(e).__name__}: {e}; "
                           f"expected {exception.__name__} because {why}") from None
    else:
        raise GradingError(f"{name}({describe(args, arg_names)}) returned {fmt(out)}; it should "
                           f"raise {exception.__name__} because {why}")
