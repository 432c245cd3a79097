"""Student versions of the course notebooks, and a light autograder, in nbgrader's format.

The instructor notebooks in ``notebooks/`` hold the solutions. An exercise is two cells with
nbgrader metadata (schema 3): a *solution* cell whose answer sits between ``### BEGIN
SOLUTION`` and ``### END SOLUTION``, and an autograded *test* cell (``grade: true``, points)
that calls a check from :mod:`annslam_lib.grading` and may hold ``### BEGIN HIDDEN TESTS`` /
``### END HIDDEN TESTS``.

:func:`student_version` does what nbgrader's ``generate_assignment`` does to the cell
sources (same delimiters, matched anywhere in a line; same stub; hidden tests removed;
outputs cleared), so a course can use either tool; a test compares the two when nbgrader is
installed. Grading lives in :mod:`annslam_lib.course.grader`.

    python -m annslam_lib release [--out student] [NOTEBOOK ...]
"""
from __future__ import annotations

import copy
import re
from dataclasses import dataclass
from pathlib import Path

import nbformat

from .plan import cell_meta

__all__ = ["ReleaseError", "Exercise", "exercises", "validate", "student_version", "release",
           "leaks", "read_notebook", "exercise_table", "solution_lines", "hidden_test_lines",
           "CODE_STUB", "TEXT_STUB", "ANSWER_TAG", "ANSWER_STUB", "CELL_METADATA",
           "NOTEBOOK_METADATA"]

CODE_STUB = "# YOUR CODE HERE\nraise NotImplementedError()"  # nbgrader's Python stub
TEXT_STUB = "YOUR ANSWER HERE"
#: The tag of an ungraded exercise's written answer (an ordinary markdown cell: nbgrader
#: takes a markdown solution cell only as a manually graded one). The student version
#: replaces the cell by ANSWER_STUB; nbgrader's generate_assignment leaves such a cell as it is.
ANSWER_TAG = "answer"
ANSWER_STUB = "**Your answer.** " + TEXT_STUB
BEGIN_SOLUTION, END_SOLUTION = "BEGIN SOLUTION", "END SOLUTION"
BEGIN_HIDDEN, END_HIDDEN = "BEGIN HIDDEN TESTS", "END HIDDEN TESTS"
_GRADE_ID = re.compile(r"^[a-zA-Z0-9_\-]+$")  # what nbgrader accepts
# A marker in any other case: nbgrader matches the capitals only and would copy the
# solution verbatim, so the course refuses it.
_ANY_CASE_MARKER = re.compile(r"(begin|end)\s+(solution|hidden\s+tests)", re.I)
#: Cell and notebook metadata a student version keeps; anything else (a custom key can hold
#: an answer) is dropped.
CELL_METADATA = frozenset({"nbgrader", "tags", "deletable", "editable", "collapsed",
                           "jupyter", "scrolled", "slideshow"})
NOTEBOOK_METADATA = frozenset({"kernelspec", "language_info"})


class ReleaseError(ValueError):
    """A notebook's exercise markup is broken (names the notebook and the cell)."""


def _is_solution(cell) -> bool:
    return bool(cell_meta(cell).get("solution"))


def _is_grade(cell) -> bool:
    return bool(cell_meta(cell).get("grade"))


@dataclass(frozen=True)
class Exercise:
    """One autograded test cell: its grade id, points and cell index."""
    notebook: str
    grade_id: str
    points: float
    cell: int


def marked_regions(source: str, begin: str, end: str, where: str) -> list[tuple[int, int]]:
    """(first, last) line indices of each begin..end region (markers included)."""
    out, start = [], None
    for i, line in enumerate(source.split("\n")):
        if begin in line:
            if start is not None:
                raise ReleaseError(f"{where}: nested '{begin}' (line {i + 1})")
            start = i
        elif end in line:
            if start is None:
                raise ReleaseError(f"{where}: '{end}' without '{begin}' (line {i + 1})")
            out.append((start, i))
            start = None
    if start is not None:
        raise ReleaseError(f"{where}: '{begin}' (line {start + 1}) has no '{end}'")
    return out


def validate(nb, name: str = "notebook", *, instructor: bool = True) -> list[Exercise]:
    """Check the nbgrader markup of one notebook and return its autograded exercises.

    Raises :class:`ReleaseError` for: duplicate or invalid grade ids, a test cell without
    positive points or that is not code, unbalanced or nested markers, solution regions
    outside solution cells, hidden tests outside test cells, a markdown solution cell that
    is not a grade cell (as nbgrader), a code solution cell without a
    region (nbgrader would replace the whole cell; only checked for ``instructor`` copies:
    in a student version the regions are stubs).
    """
    seen: dict[str, int] = {}
    found = []
    for i, cell in enumerate(nb.cells):
        where = f"{name}, cell {i}"
        for n, line in enumerate(cell.source.split("\n"), 1):
            m = _ANY_CASE_MARKER.search(line)
            if m and m.group(0) not in (BEGIN_SOLUTION, END_SOLUTION, BEGIN_HIDDEN, END_HIDDEN):
                raise ReleaseError(f"{where}, line {n}: marker {m.group(0)!r} is not written "
                                   f"'{m.group(0).upper()}' (capitals, one space): nbgrader and "
                                   "this release would not see it and copy the answer")
        sol = marked_regions(cell.source, BEGIN_SOLUTION, END_SOLUTION, where)
        hid = marked_regions(cell.source, BEGIN_HIDDEN, END_HIDDEN, where)
        meta = cell_meta(cell)
        if sol and not _is_solution(cell):
            raise ReleaseError(f"{where}: a solution region in a cell not marked as a solution")
        if hid and not _is_grade(cell):
            raise ReleaseError(f"{where}: hidden tests in a cell not marked as autograded")
        if not meta:
            continue
        gid = meta.get("grade_id")
        if not gid or not _GRADE_ID.match(str(gid)):
            raise ReleaseError(f"{where}: grade id {gid!r} must be letters, digits, '-' or '_'")
        if gid in seen:
            raise ReleaseError(f"{where}: grade id {gid!r} already used in cell {seen[gid]}")
        seen[gid] = i
        if cell.cell_type == "markdown" and _is_solution(cell) and not _is_grade(cell):
            # nbgrader refuses it too (a written answer is a manually graded cell, which
            # every submission would then wait on): an ungraded exercise's written answer
            # goes in a <details> block of an ordinary cell instead.
            raise ReleaseError(f"{where}: markdown solution cell {gid!r} is not a grade cell "
                               "(nbgrader refuses it); put an ungraded answer in <details>")
        if instructor and _is_solution(cell) and cell.cell_type == "code" and not sol:
            raise ReleaseError(f"{where}: solution cell {gid!r} has no ### BEGIN/END SOLUTION")
        if _is_grade(cell):
            pts = meta.get("points")
            if not isinstance(pts, (int, float)) or pts <= 0:
                raise ReleaseError(f"{where}: autograded cell {gid!r} needs points > 0, got {pts!r}")
            if cell.cell_type != "code" and not _is_solution(cell):
                raise ReleaseError(f"{where}: autograded test cell {gid!r} must be a code cell")
            if not _is_solution(cell):
                found.append(Exercise(name, str(gid), float(pts), i))
    return found


def exercises(path, *, instructor: bool = True) -> list[Exercise]:
    """The autograded test cells of the notebook at ``path`` (markup validated)."""
    path = Path(path)
    return validate(read_notebook(path), path.name, instructor=instructor)


def exercise_table(paths) -> str:
    """Markdown table of the autograded exercises per notebook (INSTRUCTOR.md; ``python -m
    annslam_lib exercises``): notebook, number of exercises, their grade ids, points."""
    rows = ["| notebook | exercises | grade ids | points |", "|---|---|---|---|"]
    for path in sorted(Path(p) for p in paths):
        found = exercises(path)
        if not found:
            continue
        ids = ", ".join(f"`{e.grade_id.removesuffix('-tests')}`" for e in found)
        rows.append(f"| `{path.stem}` | {len(found)} | {ids} | {sum(e.points for e in found):g} |")
    return "\n".join(rows)


def replace_regions(source: str, regions, stub: str | None) -> str:
    lines = source.split("\n")
    out, k = [], 0
    for first, last in regions:
        out += lines[k:first]
        if stub is not None:
            indent = re.match(r"\s*", lines[first]).group(0)
            out += [indent + s for s in stub.split("\n")]
        k = last + 1
    return "\n".join(out + lines[k:])


def student_version(nb, name: str = "notebook"):
    """A copy of instructor notebook ``nb`` for students: every solution region replaced by
    nbgrader's stub (code: ``# YOUR CODE HERE`` / ``raise NotImplementedError()``, indented
    like the marker; text: ``YOUR ANSWER HERE``), hidden tests removed, outputs and
    execution counts cleared, nbgrader metadata kept. A markdown cell tagged
    :data:`ANSWER_TAG` (an ungraded exercise's written answer) becomes :data:`ANSWER_STUB`; a
    solution cell without a region becomes the stub as a whole, as in nbgrader; a code
    cell whose stub stands at the top level is tagged ``raises-exception`` like the test
    cells, so Run All goes on past an exercise not done yet."""
    validate(nb, name)
    nb = copy.deepcopy(nb)
    for i, cell in enumerate(nb.cells):
        where = f"{name}, cell {i}"
        stub = CODE_STUB if cell.cell_type == "code" else TEXT_STUB
        regions = marked_regions(cell.source, BEGIN_SOLUTION, END_SOLUTION, where)
        if cell.cell_type == "markdown" and ANSWER_TAG in cell.metadata.get("tags", []):
            cell.source = ANSWER_STUB          # an ungraded exercise's written answer
            cell.pop("attachments", None)
        elif _is_solution(cell) and not regions:
            cell.source = stub                 # nbgrader: a solution cell without a region
        else:
            cell.source = replace_regions(cell.source, regions, stub)
        cell.source = replace_regions(cell.source, marked_regions(cell.source, BEGIN_HIDDEN, END_HIDDEN,
                                                     where), None)
        for key in set(cell.metadata) - CELL_METADATA:
            del cell.metadata[key]             # a custom key may hold the answer
        if _is_solution(cell) or _is_grade(cell):
            cell.pop("attachments", None)      # an image of the answer, pasted into the cell
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
            if _is_grade(cell) and not _is_solution(cell):
                _tag_raises(cell)
            elif _is_solution(cell) and re.search(r"^raise NotImplementedError", cell.source,
                                                  re.M):
                _tag_raises(cell)              # an unindented stub raises when the cell runs
    for key in set(nb.metadata) - NOTEBOOK_METADATA:
        del nb.metadata[key]                   # widget state, custom keys: not the student's
    return nb


def leaks(instructor, student) -> list[str]:
    """What of the instructor notebook shows in its student version: solution or hidden-test
    code lines, a marker, an attachment of a solution cell, metadata beyond
    :data:`CELL_METADATA` / :data:`NOTEBOOK_METADATA`, outputs. Empty when clean.
    :func:`release` refuses to write a student version with any."""
    found = []
    text = "\n".join(c.source for c in student.cells)
    lines = {s.strip() for s in text.split("\n")}
    code = (solution_lines(instructor) | hidden_test_lines(instructor)) & lines
    found += [f"solution or hidden-test line {s!r}" for s in sorted(code)]
    found += [f"marker {m.group(0)!r}" for m in _ANY_CASE_MARKER.finditer(text)]
    for i, c in enumerate(instructor.cells):
        if ANSWER_TAG in c.metadata.get("tags", []) and c.source.strip() and \
                i < len(student.cells) and student.cells[i].source != ANSWER_STUB:
            found.append(f"cell {i}: the written answer (tagged {ANSWER_TAG!r})")
    for i, c in enumerate(student.cells):
        if c.get("attachments") and (_is_solution(c) or _is_grade(c)):
            found.append(f"cell {i}: attachments {sorted(c['attachments'])}")
        extra = set(c.metadata) - CELL_METADATA
        if extra:
            found.append(f"cell {i}: metadata {sorted(extra)}")
        if c.cell_type == "code" and c.get("outputs"):
            found.append(f"cell {i}: outputs")
    extra = set(student.metadata) - NOTEBOOK_METADATA
    if extra:
        found.append(f"notebook metadata {sorted(extra)}")
    return found


def read_notebook(path):
    """``nbformat.read`` with a :class:`ReleaseError` naming the file for one that is not a
    notebook (not JSON, not nbformat)."""
    path = Path(path)
    try:
        return nbformat.read(path, as_version=4)
    except (ValueError, KeyError, TypeError, AttributeError) as e:  # NotJSONError is a ValueError
        raise ReleaseError(f"{path}: not a readable notebook ({type(e).__name__}: "
                           f"{str(e)[:200]})") from e


def _tag_raises(cell) -> None:
    """Mark an autograded test cell ``raises-exception``: JupyterLab's Run All and nbclient
    then go on past it while its exercise is not written yet (its check raises)."""
    tags = cell.metadata.setdefault("tags", [])
    if "raises-exception" not in tags:
        tags.append("raises-exception")


def _region_lines(nb, begin: str, end: str) -> set[str]:
    lines = set()
    for cell in nb.cells:
        src = cell.source.split("\n")
        for first, last in marked_regions(cell.source, begin, end, "notebook"):
            lines |= {s.strip() for s in src[first + 1:last]}
    return {s for s in lines if s and not s.startswith("#")}


def _outside_lines(nb, begin: str, end: str) -> set[str]:
    lines = set()
    for cell in nb.cells:
        src = cell.source.split("\n")
        inside = set()
        for first, last in marked_regions(cell.source, begin, end, "notebook"):
            inside |= set(range(first, last + 1))
        lines |= {s.strip() for i, s in enumerate(src) if i not in inside}
    return lines


def solution_lines(nb) -> set[str]:
    """Code lines that occur ONLY inside solution regions of ``nb`` (stripped, no comments):
    none of them may appear anywhere in the student version."""
    return _region_lines(nb, BEGIN_SOLUTION, END_SOLUTION) - _outside_lines(nb, BEGIN_SOLUTION,
                                                                            END_SOLUTION)


def hidden_test_lines(nb) -> set[str]:
    """Lines that occur only inside hidden-test regions of ``nb``."""
    return _region_lines(nb, BEGIN_HIDDEN, END_HIDDEN) - _outside_lines(nb, BEGIN_HIDDEN,
                                                                      END_HIDDEN)


def release(paths, out) -> list[Path]:
    """Write the student version of each instructor notebook in ``paths`` into folder ``out``
    (created) and return the written paths. All notebooks are validated first (grade ids
    unique across them); ``out`` must not be a folder of a source notebook."""
    paths = [Path(p).resolve() for p in paths]
    out = Path(out).resolve()
    if not paths:
        raise ReleaseError("no notebooks to release")
    if any(p.parent == out for p in paths):
        raise ReleaseError(f"output folder {out} holds the instructor notebooks: choose another")
    books, owner, names = [], {}, {}
    for p in paths:
        if p.name in names:
            raise ReleaseError(f"two notebooks named {p.name}: {names[p.name]} and {p}; the "
                               "student versions would overwrite each other in one folder")
        names[p.name] = p
        nb = read_notebook(p)
        for ex in validate(nb, p.name):
            if ex.grade_id in owner:
                raise ReleaseError(f"grade id {ex.grade_id!r} is in both {owner[ex.grade_id]} "
                                   f"and {p.name}")
            owner[ex.grade_id] = p.name
        books.append((p, nb))
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for p, nb in books:
        dest = out / p.name
        st = student_version(nb, p.name)
        problems = leaks(nb, st)
        if problems:
            raise ReleaseError(f"{p.name}: the student version would show " + "; ".join(problems))
        nbformat.write(st, dest)
        written.append(dest)
    return written
