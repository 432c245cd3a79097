"""Checks of the diagnose-the-broken-filter lab (chapter 05a).

A student names, for each filter drawn for them (:func:`..chapters.ch05a_diagnose.draw`),
its defect and the evidence that shows it, as ``my_diagnosis()`` returning
``{letter: {"defect": key, "evidence": key}}``. :func:`check_form` (the notebook's own
check) reads the answer's form only: whether it is right is never shown to the student
while they can still change it. :func:`check_filter` (the grader's, one per filter) scores
one letter: the defect and its telltale. The student is the grader's
(:func:`.core.graded_student`), never what the submission's kernel says it is.
"""
from __future__ import annotations

from ..chapters import ch05a_diagnose as lab
from .core import NOT_WRITTEN, call, fail, forbids, graded_student, passed

__all__ = ["check_form", "check_filter"]


def _student() -> str:
    return graded_student() or lab.student()


def _answers(fn, name: str = "my_diagnosis") -> dict:
    """``fn()`` read as {letter: (defect, evidence)}; a GradingError names what is wrong
    with its form."""
    got = call(fn, (), name=name)
    letters = sorted(lab.draw(_student()))
    if not isinstance(got, dict):
        fail(f"{name}() returned a {type(got).__name__}; return a dict with one entry per "
             f"filter ({', '.join(letters)}).")
    missing = [k for k in letters if k not in got]
    extra = [repr(k) for k in got if k not in letters]
    if extra:
        fail(f"{name}() answers for filter(s) {', '.join(extra)}, which are not yours: your "
             f"filters are {', '.join(letters)}.")
    if missing:
        fail(f"{name}() has no answer for filter(s) {', '.join(missing)}.")
    out = {}
    for k in letters:
        a = got[k]
        if not isinstance(a, dict) or set(a) != {"defect", "evidence"}:
            fail(f"{name}()[{k!r}] must be a dict with the keys 'defect' and 'evidence', "
                 f"got {a!r}.")
        d, e = a["defect"], a["evidence"]
        if d is None or e is None:
            fail(f"{name}()[{k!r}] " + NOT_WRITTEN + ": choose its defect and its evidence.")
        if d not in lab.DEFECTS:
            fail(f"{name}()[{k!r}]['defect'] = {d!r} is not one of the defects: "
                 f"{', '.join(repr(x) for x in lab.DEFECTS)}.")
        if e not in lab.EVIDENCE:
            fail(f"{name}()[{k!r}]['evidence'] = {e!r} is not one of the kinds of evidence: "
                 f"{', '.join(repr(x) for x in lab.EVIDENCE)}.")
        out[k] = (d, e)
    return out


#: The answer key's functions: the draw read directly, or the evidence turned into a defect
#: by the course's own rule, is not a diagnosis.
_FORBIDS = forbids(lab.draw, lab.reference_diagnosis)


@_FORBIDS
def check_form(my_diagnosis, letter: str | None = None, quiet: bool = False):
    """The answer has the form the grader reads: every filter drawn for this student, each
    with one of the defects and one of the kinds of evidence (``letter``: say so of that
    filter). Says nothing of whether an answer is right."""
    got = _answers(my_diagnosis)
    which = f"filter {letter}" if letter in got else f"filters {', '.join(got)}"
    return passed(f"✓ my_diagnosis answers for {which} in the form the grader reads (whether "
                  "it is right is graded after the deadline).", quiet)


@_FORBIDS
def check_filter(my_diagnosis, letter: str, quiet: bool = False):
    """Filter ``letter``: the defect named is the one drawn, and the evidence cited is its
    telltale (the evidence that sets it apart from every other defect)."""
    drawn = lab.draw(_student())
    if letter not in drawn:
        fail(f"there is no filter {letter!r} in this lab (filters {', '.join(sorted(drawn))}).")
    d, e = _answers(my_diagnosis)[letter]
    truth = lab.DEFECTS[drawn[letter]]
    if d != drawn[letter]:
        fail(f"filter {letter}: its defect is not {d!r} ({lab.DEFECTS[d].text}). That defect "
             f"would show '{lab.EVIDENCE[lab.DEFECTS[d].telltale]}': compare that with what "
             f"filter {letter}'s runs show against the control's."
             + (f" [instructor: the defect is {drawn[letter]!r}, its telltale "
                f"{truth.telltale!r}.]" if _full() else ""))
    if e != truth.telltale:
        fail(f"filter {letter}: the defect is right, but the evidence cited ('{lab.EVIDENCE[e]}') "
             "is not what sets this defect apart: which figure of its runs differs from the "
             "control's, and only for this defect?"
             + (f" [instructor: its telltale is {truth.telltale!r}.]" if _full() else ""))
    return passed(f"✓ filter {letter}: {truth.text}, shown by: {lab.EVIDENCE[e]}.", quiet)


def _full() -> bool:
    from .core import is_full_feedback
    return is_full_feedback()
