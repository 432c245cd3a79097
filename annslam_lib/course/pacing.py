"""How long a chapter takes a student, estimated from the notebooks (INSTRUCTOR.md's pacing
table; ``python -m annslam_lib pacing`` prints it).

Not measured with students: an estimate from what can be counted. Reading: the words of a
chapter's text cells at :data:`WORDS_PER_MINUTE` (derivations read with their code and
output, slower than prose). Exercises: :data:`MINUTES_PER_POINT` per autograded point
(:data:`MINUTES_PER_POINT_OF` for the capstone, whose points grade a whole filter) and
:data:`MINUTES_PER_UNGRADED` per ungraded exercise (a solution cell without a test cell).
The machine's own time (Run All) is in INSTRUCTOR.md's table 'What the machine takes' and adds under a
minute per chapter.
"""
from __future__ import annotations

import re
from pathlib import Path

from .release import exercises, read_notebook

__all__ = ["WORDS_PER_MINUTE", "MINUTES_PER_POINT", "MINUTES_PER_UNGRADED", "MINUTES_PER_POINT_OF",
           "OPTIONAL_MODULES", "module_of", "chapter_rows", "pacing_table"]

#: Reading pace of the chapters' text (words per minute): an assumption, stated.
WORDS_PER_MINUTE = 50
#: Working time per autograded point and per ungraded exercise (minutes): assumptions.
MINUTES_PER_POINT = 10
MINUTES_PER_UNGRADED = 20
#: Chapters whose points stand for more work than one function each: the capstone's eight
#: points grade a whole filter (minutes per point there).
MINUTES_PER_POINT_OF = {"09_capstone": 20}
#: The optional modules a class may leave out (INSTRUCTOR.md's plans, the course map); every
#: other chapter is the core.
OPTIONAL_MODULES = {"paper": ("07_ann_training", "08_ann_slam_verdict"),
                    "beyond": ("10_beyond_the_ekf", "11_graph_slam")}


def module_of(notebook: str) -> str:
    """'core', or the name of the optional module (:data:`OPTIONAL_MODULES`) holding it."""
    return next((m for m, names in OPTIONAL_MODULES.items() if notebook in names), "core")


def _words(nb) -> int:
    return sum(len(re.findall(r"\w+", c.source)) for c in nb.cells if c.cell_type == "markdown")


def _ungraded(nb) -> list[str]:
    """Grade ids of the solution cells no test cell uses (an exercise without a check)."""
    from .plan import defined_names, free_names

    meta = [c.metadata.get("nbgrader", {}) for c in nb.cells]
    used = set()
    for c, m in zip(nb.cells, meta):
        if m.get("grade") and not m.get("solution"):
            used |= free_names(c.source)
    return [m["grade_id"] for c, m in zip(nb.cells, meta)
            if m.get("solution") and c.cell_type == "code" and not (defined_names(c.source) & used)]


def chapter_rows(paths) -> list[dict]:
    """Per notebook: words of text, autograded points, ungraded exercises (grade ids), and
    the estimated minutes of reading, of exercises and in total (rounded to 5)."""
    rows = []
    for path in sorted(Path(p) for p in paths):
        nb = read_notebook(path)
        words = _words(nb)
        points = sum(e.points for e in exercises(path))
        ungraded = _ungraded(nb)
        reading = words / WORDS_PER_MINUTE
        per_point = MINUTES_PER_POINT_OF.get(path.stem, MINUTES_PER_POINT)
        work = points * per_point + len(ungraded) * MINUTES_PER_UNGRADED
        rows.append({"notebook": path.stem, "module": module_of(path.stem), "words": words,
                     "points": points,
                     "ungraded": ungraded, "reading_min": 5 * round(reading / 5),
                     "exercise_min": 5 * round(work / 5),
                     "total_min": 5 * round((reading + work) / 5)})
    return rows


def pacing_table(paths) -> str:
    """:func:`chapter_rows` as a Markdown table, with the totals of the core, of the core with
    each optional module, and of everything."""
    rows = chapter_rows(paths)
    out = ["| chapter | module | words | graded points | ungraded exercises | reading (min) "
           "| exercises (min) | total (h) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| `{r['notebook']}` | {r['module']} | {r['words']} | {r['points']:g} | "
                   f"{len(r['ungraded'])} | {r['reading_min']} | {r['exercise_min']} | "
                   f"{r['total_min'] / 60:.1f} |")

    def total(label, keep):
        sel = [r for r in rows if r["module"] in keep]
        out.append(f"| {label} | | {sum(r['words'] for r in sel)} | "
                   f"{sum(r['points'] for r in sel):g} | {sum(len(r['ungraded']) for r in sel)} "
                   f"| | | {sum(r['total_min'] for r in sel) / 60:.1f} |")

    total("core", {"core"})
    for name in OPTIONAL_MODULES:
        total(f"core + {name}", {"core", name})
    total("all", {"core", *OPTIONAL_MODULES})
    return "\n".join(out)
