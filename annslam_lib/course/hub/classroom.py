"""The instructor's steps of a class on the hub, one command each, through nbgrader's exchange.

    ./course.sh class release CHAPTER    the chapter's student version, to every student's
                                         Assignments panel (nbgrader release_assignment)
    ./course.sh class collect CHAPTER    each student's latest submission (or the one the
                                         late policy takes), into course/submitted/
    ./course.sh class grade CHAPTER      the course's sandboxed grader on every collected
                                         submission: scores in course/grades/CHAPTER.json,
                                         one feedback page per student
    ./course.sh class feedback CHAPTER   the feedback pages back through the exchange
                                         (nbgrader release_feedback); each student fetches
                                         theirs in the Assignments panel
    ./course.sh class export [CHAPTER]   the gradebook of every graded chapter (or one) as
                                         CSV for Canvas and Moodle (:mod:`.gradebook`)

With a due date for the chapter in ``course/course.toml`` (:mod:`.deadlines`), ``release``
writes it into the chapter's first cell and ``collect`` takes each student's submission by the
late policy, itself, saying which it took for whom (``course/grades/CHAPTER-collected.json``);
``grade`` and ``export`` apply the share of points the policy keeps.

Run as root on the hub's machine, with ``ANNSLAM_HUB_DIR`` as for the hub. ``CHAPTER`` is a
notebook's name without ``.ipynb`` (``03_observation``); it is the nbgrader assignment's
name too. Grading is the course's grader, never ``nbgrader autograde``: there the checks run
in the student's own kernel, which the student's code can disarm.

A submission in the exchange that anything but its student's own plain files and folders
make up (a folder or file of another account: one student submitting as another; a symbolic
link, which the collecting root would follow to any file of the machine; a hard link; a
device or pipe) is not collected: it is moved to ``course/rejected/`` and named.
"""
from __future__ import annotations

import html
import json
import os
import pwd
import shutil
import stat
import subprocess
from pathlib import Path

from . import COURSE_ID, HubError, HubLayout, deadlines, gradebook

__all__ = ["release", "collect", "grade", "feedback", "export", "feedback_page", "unsafe",
           "ACTIONS"]

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
    written = write_release([src], folder)[0]
    policy = _policies(layout).get(chapter)
    if policy is not None:                       # the due date, above the chapter's title
        import nbformat
        nb = nbformat.read(written, as_version=4)
        nb.cells.insert(0, nbformat.v4.new_markdown_cell(deadlines.due_text(policy)))
        nbformat.write(nb, written)
    source = layout.course / "source" / chapter
    source.mkdir(parents=True, exist_ok=True)
    os.chmod(layout.course / "source", 0o700)            # solutions: the instructor's only
    shutil.copyfile(src, source / src.name)
    _nbgrader(layout, "release_assignment", chapter, "--force")
    return folder / src.name


def _owner(st) -> str:
    try:
        return pwd.getpwuid(st.st_uid).pw_name
    except KeyError:
        return f"uid {st.st_uid}"


def unsafe(entry: Path, student: str) -> str | None:
    """Why the exchange entry ``entry`` may not be collected as ``student``'s (module
    docstring), or None: every part of it must be a plain folder or a plain file with one
    link, owned by ``student``. Nothing in it is followed or opened."""
    parts = [entry]
    if not entry.is_symlink() and entry.is_dir():
        for root, dirs, files in os.walk(entry):
            parts += [Path(root, n) for n in dirs + files]
    for part in parts:
        st = part.lstat()
        where = part.relative_to(entry.parent)
        if stat.S_ISLNK(st.st_mode):
            return f"{where} is a symbolic link"
        if not (stat.S_ISDIR(st.st_mode) or stat.S_ISREG(st.st_mode)):
            return f"{where} is not a plain file or folder"
        if stat.S_ISREG(st.st_mode) and st.st_nlink > 1:
            return f"{where} is a hard link ({st.st_nlink} names)"
        if _owner(st) != student:
            return f"{where} names {student} but belongs to {_owner(st)}"
    return None


def _forged(layout: HubLayout, chapter: str) -> list[str]:
    """Move aside every inbound submission of ``chapter`` that is not plainly its student's
    own (:func:`unsafe`)."""
    inbound = layout.exchange / COURSE_ID / "inbound"
    said = []
    for entry in sorted(inbound.glob(f"*+{chapter}+*")) if inbound.is_dir() else []:
        why = unsafe(entry, entry.name.split("+", 1)[0])
        if why:
            dest = layout.course / "rejected" / entry.name
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(entry), dest)
            said.append(f"{entry.name}: {why}; moved to {dest}, not collected")
    return said


def _policies(layout: HubLayout) -> dict:
    try:
        return deadlines.load(layout.course / deadlines.CONFIG_NAME)
    except deadlines.DeadlineError as e:
        raise HubError(str(e)) from None


def _copy_own(src: Path, dest: Path, uid: int) -> None:
    """Copy the submission folder ``src`` to ``dest``, taking only what is still plainly the
    student's (``uid``): each file opened without following a link and without waiting
    (a pipe planted since the check would hang a plain copy), then checked on the opened
    file itself (a regular file, one name, the student's); anything else raises HubError."""
    dest.mkdir(parents=True)
    with os.scandir(src) as entries:
        for e in entries:
            st = e.stat(follow_symlinks=False)
            if stat.S_ISDIR(st.st_mode) and st.st_uid == uid:
                _copy_own(Path(e.path), dest / e.name, uid)
                continue
            try:
                fd = os.open(e.path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
            except OSError as err:
                raise HubError(f"{e.path}: cannot be opened as a plain file ({err})") from None
            try:
                st = os.fstat(fd)
                if not stat.S_ISREG(st.st_mode) or st.st_nlink != 1 or st.st_uid != uid:
                    raise HubError(f"{e.path}: changed while it was collected (no longer a "
                                   "plain file of the student's)")
                with open(dest / e.name, "wb") as out:
                    while chunk := os.read(fd, 1 << 20):
                        out.write(chunk)
            finally:
                os.close(fd)


def _collect(layout: HubLayout, chapter: str, policy) -> list[str]:
    """Each student's submission that counts under ``policy`` (None: their last), copied
    into ``course/submitted`` by :func:`_copy_own` (nbgrader's own collect would follow a
    link a student plants between the check and the copy); the choices in
    ``course/grades/CHAPTER-collected.json``."""
    inbound = layout.exchange / COURSE_ID / "inbound"
    subs = deadlines.inbound(inbound, chapter)
    choices = deadlines.choose(policy, subs) if policy else deadlines.latest(subs)
    said, record = [], []
    for c in choices:
        dest = layout.course / "submitted" / c.student / chapter
        shutil.rmtree(dest, ignore_errors=True)
        if c.submission is not None:
            why = unsafe(c.submission.folder, c.student)    # again: it may have changed since
            if why:
                raise HubError(f"{c.submission.folder.name}: {why}; collect again")
            try:
                _copy_own(c.submission.folder, dest, c.submission.folder.lstat().st_uid)
            except HubError:
                shutil.rmtree(dest, ignore_errors=True)
                raise
        taken = c.submission.at.isoformat(timespec="seconds") if c.submission else None
        claim = c.submission.claimed if c.submission else None
        if claim and abs((c.submission.at - claim).total_seconds()) > 120:
            note = f" (its name claims {claim.isoformat(timespec='seconds')})"
        else:
            note = ""
        said.append(f"{c.student}: {('submitted ' + taken) if taken else 'nothing taken'}"
                    f"{note}: {c.why}")
        record.append({"student": c.student, "submission": taken, "days_late": c.days_late,
                       "factor": c.factor, "why": c.why})
    grades = layout.course / "grades"
    grades.mkdir(exist_ok=True)
    os.chmod(grades, 0o700)
    (grades / f"{chapter}-collected.json").write_text(json.dumps(record, indent=1))
    return said


def collect(layout: HubLayout, chapter: str) -> list[str]:
    """Each student's latest submission of ``chapter`` into ``course/submitted``, or with a
    due date the one its late policy takes (module docstring)."""
    _notebook(chapter)
    said = _forged(layout, chapter)
    said += _collect(layout, chapter, _policies(layout).get(chapter))
    for line in said:
        print(f"== {line}", flush=True)
    return said


def feedback_page(g, late: dict | None = None) -> str:
    """One student's feedback (a :class:`~.grader.SubmissionGrade`) as a self-contained HTML
    page, with what a late policy kept (``late``: the student's entry of
    ``CHAPTER-collected.json``). Every text is escaped: messages can quote the student's own
    output."""
    e = html.escape
    rows = "".join(
        f"<tr><td>{e(r.grade_id)}</td><td>{r.points:g} / {r.max_points:g}</td>"
        f"<td>{e(r.status)}</td><td>{e(r.message)}</td></tr>" for r in g.exercises)
    notes = "".join(f"<li>{e(n)}</li>" for n in [*g.notes, *g.errors])
    head = (f"<p><b>Score: {g.score:g} / {g.max_score:g}</b></p>" if g.graded else
            f"<p><b>Not graded</b>: {e(g.reason)}</p>")
    if g.graded and late and late.get("factor", 1.0) < 1.0:
        head += (f"\n<p><b>After the late policy: {g.score * late['factor']:g} / "
                 f"{g.max_score:g}</b> ({e(late['why'])})</p>")
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
    collected = grades / f"{chapter}-collected.json"
    late = ({c["student"]: c for c in json.loads(collected.read_text())}
            if collected.exists() else {})
    for g, sub in zip(results, subs):
        student = sub.parents[1].name
        out = layout.course / "feedback" / student / chapter
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{chapter}.html").write_text(feedback_page(g, late.get(student)))
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


def export(layout: HubLayout, chapter: str | None = None, *, layouts=gradebook.LAYOUTS,
           log=print) -> list[Path]:
    """The gradebook of ``chapter`` (None: every chapter graded so far, in the course's
    order) as one CSV file per LMS layout in ``course/grades/``; the students are the
    roster's (``course/roster.csv``) and everyone graded or collected. Returns the files."""
    grades = layout.course / "grades"
    if chapter is not None:
        _notebook(chapter)
        chapters = [chapter]
    else:
        chapters = [p.stem for p in sorted((ROOT / "notebooks").glob("*.ipynb"))
                    if (grades / f"{p.stem}.json").exists()]
    if not chapters:
        raise HubError(f"nothing graded yet in {grades}: run ./course.sh class grade CHAPTER")
    try:
        roster = gradebook.read_roster(layout.course / "roster.csv")
        seen = set(roster)
        for ch in chapters:
            for name in (f"{ch}.json", f"{ch}-collected.json"):
                if (grades / name).exists():
                    seen |= {r["student"] for r in json.loads((grades / name).read_text())}
        rows, possible = gradebook.gradebook(grades, sorted(seen), chapters)
        files = []
        for lms in layouts:
            path = grades / f"export-{lms}.csv"
            path.write_text(gradebook.write(rows, possible, lms, roster), encoding="utf-8")
            files.append(path)
    except (gradebook.GradebookError, ValueError) as e:
        raise HubError(str(e)) from None
    for r in rows:
        for note in r.notes:
            log(f"== {r.student}: {note}")
    log(f"== {len(rows)} students, {len(chapters)} assignment(s): "
        + ", ".join(str(f) for f in files))
    return files


ACTIONS = {"release": release, "collect": collect, "grade": grade, "feedback": feedback,
           "export": export}
