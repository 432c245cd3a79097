"""The class's gradebook as CSV files a learning-management system imports
(``./course.sh class export``).

The scores are those ``class grade`` wrote (``course/grades/CHAPTER.json``), times the share a
late policy keeps (``course/grades/CHAPTER-collected.json``, written by ``class collect``:
:mod:`.deadlines`). A student with no submission that counts gets 0 points; one whose
submission could not be graded gets 0 and is named in the report. Students are the class's
accounts (the hub's user names); an optional roster, ``course/roster.csv`` with a header
``username,name,lms_id,sis_id,email,section`` (any of the last five may be empty), adds what
the LMS matches students by.

Two layouts (``LAYOUTS``):

- ``canvas``: ``Student, ID, SIS User ID, SIS Login ID, Section``, then one column per
  assignment named as in the course, and a first row ``Points Possible``: the layout of
  Canvas's gradebook export, which its import reads; Canvas matches a row by ID, SIS User ID
  or SIS Login ID (the hub's user name is put there) and creates an assignment for a column
  it does not know. No total column: Canvas computes its own.
- ``moodle``: ``Username, Email address, ID number``, one column per assignment, then
  ``Total``: Moodle's "Import grades from CSV" maps a column to identify users (username,
  email or ID number) and each other column to a grade item or to "ignore" (the total).
"""
from __future__ import annotations

import csv
import dataclasses
import io
import json
from pathlib import Path

__all__ = ["Row", "gradebook", "write", "read_roster", "LAYOUTS", "ROSTER_FIELDS"]

LAYOUTS = ("canvas", "moodle")
ROSTER_FIELDS = ("username", "name", "lms_id", "sis_id", "email", "section")


class GradebookError(ValueError):
    """Grades or a roster that cannot be exported, saying why."""


@dataclasses.dataclass(frozen=True)
class Row:
    """One student: their points per assignment (after any late penalty) and the reasons
    for every 0 that is not a graded 0."""
    student: str
    points: dict
    notes: tuple = ()

    @property
    def total(self) -> float:
        return round(sum(self.points.values()), 6)


def read_roster(path) -> dict[str, dict]:
    """The roster CSV (module docstring) by user name; {} when there is none."""
    path = Path(path)
    if not path.exists():
        return {}
    with path.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or "username" not in reader.fieldnames:
            raise GradebookError(f"{path}: the first line must name the columns, "
                                 f"'username' among them ({', '.join(ROSTER_FIELDS)})")
        extra = set(reader.fieldnames) - set(ROSTER_FIELDS)
        if extra:
            raise GradebookError(f"{path}: unknown column(s) {sorted(extra)}")
        roster = {}
        for n, r in enumerate(reader, start=2):
            name = (r.get("username") or "").strip()
            if not name or name in roster:
                raise GradebookError(f"{path} line {n}: an empty or repeated username")
            roster[name] = {k: (r.get(k) or "").strip() for k in ROSTER_FIELDS}
    return roster


def _load(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise GradebookError(f"cannot read {path}: {e}") from None


def gradebook(grades_dir, students, chapters) -> tuple[list[Row], dict[str, float]]:
    """The rows of ``students`` (in that order) over ``chapters`` (the assignments, in
    order) from the files of ``grades_dir``, and each assignment's points possible."""
    grades_dir = Path(grades_dir)
    points, possible = {s: {} for s in students}, {}
    notes = {s: [] for s in students}
    for ch in chapters:
        path = grades_dir / f"{ch}.json"
        graded = {g["student"]: g for g in _load(path)} if path.exists() else {}
        collected_path = grades_dir / f"{ch}-collected.json"
        taken = ({c["student"]: c for c in _load(collected_path)} if collected_path.exists()
                 else None)
        maxima = {g["max_score"] for g in graded.values() if g.get("graded")}
        if len(maxima) > 1:
            raise GradebookError(f"{path}: submissions graded out of different totals {maxima}")
        possible[ch] = maxima.pop() if maxima else None
        for s in students:
            g, c = graded.get(s), (taken or {}).get(s)
            factor = 1.0 if taken is None or c is None else float(c["factor"])
            if taken is not None and (c is None or c.get("submission") is None):
                points[s][ch] = 0.0
                notes[s].append(f"{ch}: no submission that counts"
                                + (f" ({c['why']})" if c else ""))
            elif g is None:
                points[s][ch] = 0.0
                notes[s].append(f"{ch}: not submitted")
            elif not g.get("graded"):
                points[s][ch] = 0.0
                notes[s].append(f"{ch}: not graded ({g.get('reason', '')})")
            else:
                points[s][ch] = round(float(g["score"]) * factor, 6)
                if factor < 1.0:
                    notes[s].append(f"{ch}: {c['why']}")
    if any(v is None for v in possible.values()):
        missing = [ch for ch, v in possible.items() if v is None]
        raise GradebookError(f"no graded submission of {', '.join(missing)}: its points "
                             "possible are unknown (grade it first, or leave it out)")
    return [Row(s, points[s], tuple(notes[s])) for s in students], possible


def write(rows: list[Row], possible: dict, layout: str, roster=None) -> str:
    """The CSV text of ``rows`` in ``layout`` (module docstring)."""
    if layout not in LAYOUTS:
        raise GradebookError(f"layout {layout!r}: one of {', '.join(LAYOUTS)}")
    roster = roster or {}
    chapters = list(possible)
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\r\n")
    if layout == "canvas":
        w.writerow(["Student", "ID", "SIS User ID", "SIS Login ID", "Section", *chapters])
        w.writerow(["Points Possible", "", "", "", "", *(f"{possible[c]:g}" for c in chapters)])
        for r in rows:
            who = roster.get(r.student, {})
            w.writerow([who.get("name") or r.student, who.get("lms_id", ""), who.get("sis_id", ""),
                        r.student, who.get("section", ""),
                        *(f"{r.points[c]:g}" for c in chapters)])
    else:
        w.writerow(["Username", "Email address", "ID number", *chapters, "Total"])
        for r in rows:
            who = roster.get(r.student, {})
            w.writerow([r.student, who.get("email", ""), who.get("sis_id", ""),
                        *(f"{r.points[c]:g}" for c in chapters), f"{r.total:g}"])
    return out.getvalue()
