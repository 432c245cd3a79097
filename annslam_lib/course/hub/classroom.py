"""The instructor's steps of a class on the hub, one command each, through nbgrader's exchange.

    ./course.sh class release CHAPTER    the chapter's student version, to every student's
                                         Assignments panel (nbgrader release_assignment)
    ./course.sh class collect CHAPTER    each student's latest submission, into
                                         course/submitted/ (nbgrader collect)
    ./course.sh class grade CHAPTER      the course's sandboxed grader on every collected
                                         submission: scores in course/grades/CHAPTER.json,
                                         one feedback page per student
    ./course.sh class feedback CHAPTER   the feedback pages back through the exchange
                                         (nbgrader release_feedback); each student fetches
                                         theirs in the Assignments panel

Run as root on the hub's machine, with ``ANNSLAM_HUB_DIR`` as for the hub. ``CHAPTER`` is a
notebook's name without ``.ipynb`` (``03_observation``); it is the nbgrader assignment's
name too. Grading is the course's grader, never ``nbgrader autograde``: there the checks run
in the student's own kernel, which the student's code can disarm.

A submission in the exchange whose folder belongs to another account than the student it
names (one student submitting as another) is not collected: it is moved to
``course/rejected/`` and named.
"""
from __future__ import annotations

import html
import os
import pwd
import shutil
import subprocess
from pathlib import Path

from . import COURSE_ID, HubError, HubLayout

__all__ = ["release", "collect", "grade", "feedback", "feedback_page", "ACTIONS"]

ROOT = Path(__file__).resolve().parents[3]


def _notebook(chapter: str) -> Path:
    path = ROOT / "notebooks" / f"{chapter}.ipynb"
    if "/" in chapter or not path.is_file():
        names = ", ".join(p.stem for p in sorted((ROOT / "notebooks").glob("*.ipynb")))
        raise HubError(f"no chapter {chapter!r}: one of {names}")
    return path


def _nbgrader(layout: HubLayout, *args: str) -> None:
    exe = layout.env / "bin" / "nbgrader"
    if not exe.exists():
        raise HubError(f"{exe} is missing: prepare the hub first (./course.sh hub "
                       "--prepare-only)")
    env = dict(os.environ, JUPYTER_CONFIG_DIR=str(layout.role_config("instructor")),
               PATH=f"{layout.env / 'bin'}:{os.environ.get('PATH', '/usr/bin:/bin')}")
    out = subprocess.run([str(exe), *args, f"--CourseDirectory.root={layout.course}",
                          f"--CourseDirectory.course_id={COURSE_ID}",
                          f"--Exchange.root={layout.exchange}"], cwd=layout.course, env=env)
    if out.returncode != 0:
        raise HubError(f"nbgrader {args[0]} failed (exit {out.returncode}, above)")


def release(layout: HubLayout, chapter: str) -> Path:
    """The chapter's student version into the exchange (replacing an earlier release)."""
    from ..release import release as write_release

    src = _notebook(chapter)
    folder = layout.course / "release" / chapter
    shutil.rmtree(folder, ignore_errors=True)
    write_release([src], folder)
    source = layout.course / "source" / chapter
    source.mkdir(parents=True, exist_ok=True)
    os.chmod(layout.course / "source", 0o700)            # solutions: the instructor's only
    shutil.copyfile(src, source / src.name)
    _nbgrader(layout, "release_assignment", chapter, "--force")
    return folder / src.name


def _forged(layout: HubLayout, chapter: str) -> list[str]:
    """Move aside every inbound submission of ``chapter`` not owned by the student it names."""
    inbound = layout.exchange / COURSE_ID / "inbound"
    said = []
    for entry in sorted(inbound.glob(f"*+{chapter}+*")) if inbound.is_dir() else []:
        student = entry.name.split("+", 1)[0]
        try:
            owner = pwd.getpwuid(entry.lstat().st_uid).pw_name
        except KeyError:
            owner = f"uid {entry.lstat().st_uid}"
        if owner != student or entry.is_symlink():
            dest = layout.course / "rejected" / entry.name
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(entry), dest)
            said.append(f"{entry.name}: names {student} but was submitted by {owner}; moved "
                        f"to {dest}, not collected")
    return said


def collect(layout: HubLayout, chapter: str) -> list[str]:
    """Each student's latest submission of ``chapter`` into ``course/submitted``."""
    _notebook(chapter)
    said = _forged(layout, chapter)
    for line in said:
        print(f"== {line}", flush=True)
    _nbgrader(layout, "collect", chapter, "--update")
    return said


def feedback_page(g) -> str:
    """One student's feedback (a :class:`~.grader.SubmissionGrade`) as a self-contained HTML
    page. Every text is escaped: messages can quote the student's own output."""
    e = html.escape
    rows = "".join(
        f"<tr><td>{e(r.grade_id)}</td><td>{r.points:g} / {r.max_points:g}</td>"
        f"<td>{e(r.status)}</td><td>{e(r.message)}</td></tr>" for r in g.exercises)
    notes = "".join(f"<li>{e(n)}</li>" for n in [*g.notes, *g.errors])
    head = (f"<p><b>Score: {g.score:g} / {g.max_score:g}</b></p>" if g.graded else
            f"<p><b>Not graded</b>: {e(g.reason)}</p>")
    return ("<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            "<meta name='viewport' content='width=device-width, initial-scale=1'><title>"
            f"{e(g.assignment or '')} feedback</title></head><body>\n"
            f"<h1>{e(g.assignment or '')}: feedback for {e(g.student or '')}</h1>\n{head}\n"
            "<table border='1'><caption>points per exercise</caption><tr>"
            "<th scope='col'>exercise</th><th scope='col'>points</th><th scope='col'>status</th>"
            f"<th scope='col'>message</th></tr>{rows}</table>\n"
            + (f"<ul>{notes}</ul>\n" if notes else "") + "</body></html>\n")


def grade(layout: HubLayout, chapter: str, *, log=print) -> list:
    """Grade every collected submission of ``chapter`` with the course's grader; write the
    scores (``course/grades/CHAPTER.json``) and each student's feedback page where nbgrader's
    ``release_feedback`` looks for it."""
    from ..grader import grade_batch

    _notebook(chapter)
    subs = sorted(layout.course.glob(f"submitted/*/{chapter}/{chapter}.ipynb"))
    if not subs:
        raise HubError(f"no collected submission of {chapter} in {layout.course / 'submitted'}"
                       f": run ./course.sh class collect {chapter} first")
    grades = layout.course / "grades"
    grades.mkdir(exist_ok=True)
    os.chmod(grades, 0o700)
    # nothing of the class is visible to the code being graded: the exchange (everyone's
    # submissions), the course folder (sources, grades, feedback), the hub's state
    results = grade_batch(subs, instructor_dir=ROOT / "notebooks",
                          json_path=grades / f"{chapter}.json", log=log,
                          hide=[layout.exchange, layout.course, layout.state])
    for g, sub in zip(results, subs):
        student = sub.parents[1].name
        out = layout.course / "feedback" / student / chapter
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{chapter}.html").write_text(feedback_page(g))
        for name in ("timestamp.txt", "submission_secret.txt"):
            if (sub.parent / name).exists():
                shutil.copyfile(sub.parent / name, out / name)
    return results


def feedback(layout: HubLayout, chapter: str) -> None:
    """Every student's feedback page of ``chapter`` into the exchange."""
    _notebook(chapter)
    if not list(layout.course.glob(f"feedback/*/{chapter}/{chapter}.html")):
        raise HubError(f"no feedback for {chapter} yet: run ./course.sh class grade {chapter}")
    _nbgrader(layout, "release_feedback", chapter)


ACTIONS = {"release": release, "collect": collect, "grade": grade, "feedback": feedback}
