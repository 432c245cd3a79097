"""Due dates, late policies, extensions, the collection of submissions from the exchange and
the gradebook for the LMS (annslam_lib.course.hub.deadlines, .gradebook, .classroom), on a
class of three with faked submission times; what a student can plant in the exchange."""
import csv
import datetime as dt
import io
import json
import os
import subprocess
import sys
import time

import nbformat
import pytest
from annslam_lib.course import hub
from annslam_lib.course.hub import classroom, deadlines, gradebook

UTC = dt.timezone.utc
CH = "01_kinematics"
ROOT_ONLY = pytest.mark.skipif(os.geteuid() != 0, reason="needs root: files of other accounts")

CONF = """
timezone = "Europe/Berlin"

[assignments.01_kinematics]
due = 2027-02-01T23:59:00
late = "penalty"
penalty_per_day = 0.25

[assignments.01_kinematics.extensions]
carol = 2027-02-03T23:59:00+01:00

[assignments.03_observation]
due = 2027-02-08T12:00:00Z
late = "grace"
grace_hours = 6
"""


def _policies(tmp_path, text=CONF):
    (tmp_path / "course.toml").write_text(text)
    return deadlines.load(tmp_path / "course.toml")


def test_the_configuration_gives_zoned_due_times_rules_and_extensions(tmp_path):
    p = _policies(tmp_path)
    k = p[CH]
    assert k.due == dt.datetime(2027, 2, 1, 22, 59, tzinfo=UTC)        # 23:59 in Berlin (CET)
    assert (k.late, k.penalty_per_day) == ("penalty", 0.25)
    assert k.due_for("carol") == dt.datetime(2027, 2, 3, 22, 59, tzinfo=UTC)
    assert k.due_for("alice") == k.due
    o = p["03_observation"]
    assert o.due == dt.datetime(2027, 2, 8, 12, tzinfo=UTC) and o.grace == dt.timedelta(hours=6)
    assert deadlines.load(tmp_path / "absent.toml") == {}


@pytest.mark.parametrize("text, words", [
    ('[assignments.a]\ndue = 2027-02-01T23:59:00\n', "no time zone"),
    ('timezone = "Mars/Olympus"\n', "unknown timezone"),
    ('[assignments.a]\ndue = 2027-02-01T23:59:00Z\nlate = "sometimes"\n', "late ="),
    ('[assignments.a]\ndue = 2027-02-01T23:59:00Z\nlate = "penalty"\n', "penalty_per_day > 0"),
    ('[assignments.a]\ndue = 2027-02-01T23:59:00Z\npenalty_per_day = 1.5\n', "from 0 to 1"),
    ('[assignments.a]\ndue = 2027-02-01T23:59:00Z\ngrace_hours = -1\n', "hours from 0"),
    ('[assignments.a]\ndue = "tomorrow"\n', "not a date"),
    ('[assignments.a]\nlate = "none"\n', "'due' is missing"),
    ('[assignments.a]\ndue = 2027-02-01T23:59:00Z\ndeadline = 1\n', "unknown key"),
    ('[assignment.a]\ndue = 2027-02-01T23:59:00Z\n', "unknown setting"),
    ('[assignments.a\n', "cannot read"),
])
def test_a_configuration_it_cannot_use_is_refused_saying_where(tmp_path, text, words):
    with pytest.raises(deadlines.DeadlineError, match=words):
        _policies(tmp_path, text)


def _at(day, hour=12, minute=0):
    return dt.datetime(2027, 2, day, hour, minute, tzinfo=UTC)


def _subs(**times):
    return [deadlines.Submission(s, t) for s, ts in times.items() for t in ts]


def test_penalty_takes_the_last_submission_and_counts_started_days(tmp_path):
    p = _policies(tmp_path)[CH]                                  # due 1 Feb 22:59 UTC
    got = {c.student: c for c in deadlines.choose(p, _subs(
        alice=[_at(1, 10), _at(1, 22, 59)],                     # on time, to the minute
        bob=[_at(1, 20), _at(2, 23, 30)],                       # 1 day 31 min late: 2 days
        carol=[_at(3, 20)],                                     # before her extension
        dave=[_at(9, 0)]))}                                     # 7 days 61 min: 8, none left
    assert (got["alice"].days_late, got["alice"].factor, got["alice"].submission.at) == \
        (0, 1.0, _at(1, 22, 59))
    assert (got["bob"].days_late, got["bob"].factor) == (2, 0.5)
    assert got["bob"].submission.at == _at(2, 23, 30) and "50 %" in got["bob"].why
    assert (got["carol"].days_late, got["carol"].factor) == (0, 1.0)
    assert (got["dave"].days_late, got["dave"].factor) == (8, 0.0)


def test_no_late_work_takes_the_last_on_time_and_grace_extends_it(tmp_path):
    due = _at(8, 12)
    none = deadlines.Policy("x", due, "none")
    grace = _policies(tmp_path)["03_observation"]                # due 8 Feb 12:00, 6 h grace
    subs = _subs(alice=[_at(8, 11), _at(8, 13)], bob=[_at(8, 17)], carol=[_at(8, 19)])
    n = {c.student: c for c in deadlines.choose(none, subs)}
    assert n["alice"].submission.at == _at(8, 11) and "1 later one(s) not taken" in n["alice"].why
    assert n["bob"].submission is None and n["bob"].factor == 0.0
    g = {c.student: c for c in deadlines.choose(grace, subs)}
    assert g["alice"].submission.at == _at(8, 13) and g["bob"].submission.at == _at(8, 17)
    assert g["carol"].submission is None and "grace" in g["carol"].why
    assert all(c.factor in (0.0, 1.0) for c in g.values())
    with pytest.raises(ValueError, match="zone"):
        deadlines.choose(none, [deadlines.Submission("eve", dt.datetime(2027, 2, 8))])


def test_the_due_cell_says_when_and_the_rule():
    p = deadlines.Policy("x", dt.datetime(2027, 2, 1, 23, 59, tzinfo=deadlines.ZoneInfo(
        "Europe/Berlin")), "penalty", 0.25)
    text = deadlines.due_text(p)
    assert text.startswith("**Due Monday 01 February 2027, 23:59 (CET).**")
    assert "loses 25 % of its points per started day" in text


def test_a_submissions_time_is_when_its_files_changed_not_what_it_claims(tmp_path):
    """The folder's name (written by the student) claims a time before the deadline, and its
    files' modification times are set back too: the time taken is the files' ctime."""
    entry = tmp_path / f"alice+{CH}+{dt.datetime(2020, 1, 1):%Y-%m-%d %H:%M:%S}.000000 UTC+abc"
    entry.mkdir()
    (entry / f"{CH}.ipynb").write_text("{}")
    os.utime(entry / f"{CH}.ipynb", (0, 0))
    os.utime(entry, (0, 0))
    (tmp_path / f"bob+{CH}x+{_at(1):%Y-%m-%d %H:%M:%S} UTC+q").mkdir()    # another assignment
    (sub,) = deadlines.inbound(tmp_path, CH)
    assert sub.student == "alice" and sub.claimed == dt.datetime(2020, 1, 1, tzinfo=UTC)
    assert abs(sub.at.timestamp() - time.time()) < 60


# -- what a student can plant in the exchange ----------------------------------------------

@ROOT_ONLY
def test_links_devices_and_foreign_files_in_a_submission_are_named(tmp_path):
    def entry(name):
        e = tmp_path / f"root+{CH}+{_at(1, 10):%Y-%m-%d %H:%M:%S}.000000 UTC+{name}"
        (e / "sub").mkdir(parents=True)
        (e / f"{CH}.ipynb").write_text("{}")
        return e

    assert classroom.unsafe(entry("plain"), "root") is None
    e = entry("link")
    (e / f"{CH}.ipynb").unlink()
    (e / f"{CH}.ipynb").symlink_to("/etc/shadow")
    assert "symbolic link" in classroom.unsafe(e, "root")
    e = entry("deep")
    (e / "sub" / "x").symlink_to("/root")
    assert "sub/x is a symbolic link" in classroom.unsafe(e, "root")
    e = entry("hard")
    os.link(e / f"{CH}.ipynb", tmp_path / "second-name")
    assert "hard link" in classroom.unsafe(e, "root")
    e = entry("fifo")
    os.mkfifo(e / "pipe")
    assert "not a plain file" in classroom.unsafe(e, "root")
    e = entry("foreign")
    os.chown(e / f"{CH}.ipynb", 65534, 65534)
    assert "belongs to" in classroom.unsafe(e, "root")
    assert "belongs to" in classroom.unsafe(entry("other"), "alice")


def _class_of_three(tmp_path, monkeypatch, conf=CONF):
    """A hub folder with three students' submissions in the exchange: alice on time, bob
    twice (on time, then late), carol none; eve plants a link. Owners are faked by uid."""
    layout = hub.HubLayout(tmp_path / "hub")
    inbound = layout.exchange / hub.COURSE_ID / "inbound"
    inbound.mkdir(parents=True)
    layout.course.mkdir(parents=True)
    (layout.course / "course.toml").write_text(conf)
    uids = {"alice": 61001, "bob": 61002, "eve": 61005}
    times = {}
    for student, when, tag in [("alice", _at(1, 20), "a1"), ("bob", _at(1, 21), "b1"),
                               ("bob", _at(2, 23, 30), "b2"), ("eve", _at(1, 9), "e1")]:
        e = inbound / f"{student}+{CH}+{when:%Y-%m-%d %H:%M:%S}.000000 UTC+{tag}"
        e.mkdir()
        (e / f"{CH}.ipynb").write_text(json.dumps({"by": student, "tag": tag}))
        (e / "timestamp.txt").write_text(f"{when:%Y-%m-%d %H:%M:%S}.000000 UTC")
        if student == "eve":
            (e / "notes.txt").symlink_to(tmp_path / "secret")
        for p in [e, *e.iterdir()]:
            os.lchown(p, uids[student], uids[student])
        times[e.name] = when
    names = {v: k for k, v in uids.items()}
    monkeypatch.setattr(classroom, "_owner", lambda st: names.get(st.st_uid, f"uid {st.st_uid}"))
    monkeypatch.setattr(deadlines, "changed_at", lambda folder: times[folder.name])
    return layout


@ROOT_ONLY
def test_collect_takes_by_the_policy_says_which_and_rejects_the_planted_link(tmp_path, monkeypatch):
    (tmp_path / "secret").write_text("root's secret")
    layout = _class_of_three(tmp_path, monkeypatch)
    said = classroom.collect(layout, CH)
    taken = {s: json.loads((layout.course / "submitted" / s / CH / f"{CH}.ipynb").read_text())
             for s in ("alice", "bob")}
    assert taken == {"alice": {"by": "alice", "tag": "a1"}, "bob": {"by": "bob", "tag": "b2"}}
    assert not (layout.course / "submitted" / "eve").exists()
    assert any("eve+" in line and "symbolic link" in line for line in said)
    assert list((layout.course / "rejected").iterdir())[0].name.startswith("eve+")
    record = {r["student"]: r for r in json.loads(
        (layout.course / "grades" / f"{CH}-collected.json").read_text())}
    assert set(record) == {"alice", "bob"}
    assert (record["bob"]["days_late"], record["bob"]["factor"]) == (2, 0.5)   # 1 d 31 min
    assert record["alice"]["factor"] == 1.0
    assert any(line.startswith("bob: submitted 2027-02-02T23:30:00+00:00") and "50 %" in line
               for line in said)
    # without a due date: each student's last submission, in full
    (layout.course / "course.toml").unlink()
    classroom.collect(layout, CH)
    record = json.loads((layout.course / "grades" / f"{CH}-collected.json").read_text())
    assert [(r["student"], r["factor"]) for r in record] == [("alice", 1.0), ("bob", 1.0)]


@ROOT_ONLY
def test_a_link_planted_between_the_check_and_the_copy_is_not_collected(tmp_path, monkeypatch):
    layout = _class_of_three(tmp_path, monkeypatch)
    real, checks = classroom.unsafe, []

    def check_then_plant(entry, student):          # the second check: the one before the copy
        why = real(entry, student)
        checks.append(student)
        if student == "alice" and checks.count("alice") == 2 and not why:
            (entry / "late.txt").symlink_to("/etc/shadow")
        return why
    monkeypatch.setattr(classroom, "unsafe", check_then_plant)
    with pytest.raises(hub.HubError, match="cannot be opened as a plain file"):
        classroom.collect(layout, CH)
    assert not (layout.course / "submitted" / "alice" / CH).exists()


@ROOT_ONLY
@pytest.mark.parametrize("plant", ["pipe", "hard link", "foreign file"])
def test_what_is_planted_between_the_check_and_the_copy_stops_it_without_waiting(
        tmp_path, monkeypatch, plant):
    """A pipe would hang a plain copy (it waits for a writer); a hard link or another
    account's file would take what is not the student's."""
    layout = _class_of_three(tmp_path, monkeypatch)
    real, checks = classroom.unsafe, []
    (tmp_path / "secret").write_text("root's secret")

    def check_then_plant(entry, student):
        why = real(entry, student)
        checks.append(student)
        if student == "alice" and checks.count("alice") == 2 and not why:
            target = entry / "zz-planted"
            if plant == "pipe":
                os.mkfifo(target)
            elif plant == "hard link":
                os.link(entry / f"{CH}.ipynb", target)
            else:
                target.write_text("x")                # root's, in alice's folder
            if plant == "pipe":
                os.lchown(target, 61001, 61001)
        return why
    monkeypatch.setattr(classroom, "unsafe", check_then_plant)
    t0 = time.monotonic()
    with pytest.raises(hub.HubError, match="alice"):
        classroom.collect(layout, CH)
    assert time.monotonic() - t0 < 10
    assert not (layout.course / "submitted" / "alice" / CH).exists()


# -- grades to the LMS ---------------------------------------------------------------------

def _graded(layout, chapter, scores, max_score=7):
    grades = layout.course / "grades"
    grades.mkdir(parents=True, exist_ok=True)
    rows = [{"student": s, "graded": sc is not None, "score": sc or 0.0, "max_score": max_score,
             "reason": "" if sc is not None else "the notebook is not valid JSON"}
            for s, sc in scores.items()]
    (grades / f"{chapter}.json").write_text(json.dumps(rows))


def test_the_gradebook_of_a_class_of_three_with_a_late_and_a_missing_submission(tmp_path):
    layout = hub.HubLayout(tmp_path / "hub")
    _graded(layout, CH, {"alice": 6.0, "bob": 4.0})
    (layout.course / "grades" / f"{CH}-collected.json").write_text(json.dumps([
        {"student": "alice", "submission": "2027-02-01T20:00:00+00:00", "days_late": 0,
         "factor": 1.0, "why": "last of 1, on time"},
        {"student": "bob", "submission": "2027-02-02T23:30:00+00:00", "days_late": 1,
         "factor": 0.75, "why": "last of 2, 1 started day(s) after the due time: 75 %"}]))
    _graded(layout, "02_laser_offset", {"alice": 3.0, "bob": None, "carol": 5.0}, max_score=5)
    (layout.course / "roster.csv").write_text(
        "username,name,lms_id,sis_id,email,section\n"
        "alice,\"Liddell, Alice\",101,S1,alice@uni.example,A\n"
        "bob,,102,,bob@uni.example,A\ncarol,,103,S3,,B\n")
    notes = []
    files = classroom.export(layout, log=notes.append)
    canvas = list(csv.reader(io.StringIO(files[0].read_text())))
    assert canvas[0] == ["Student", "ID", "SIS User ID", "SIS Login ID", "Section",
                         CH, "02_laser_offset"]
    assert canvas[1] == ["Points Possible", "", "", "", "", "7", "5"]
    assert canvas[2:] == [["Liddell, Alice", "101", "S1", "alice", "A", "6", "3"],
                          ["bob", "102", "", "bob", "A", "3", "0"],
                          ["carol", "103", "S3", "carol", "B", "0", "5"]]
    moodle = list(csv.DictReader(io.StringIO(files[1].read_text())))
    assert [(r["Username"], r["Email address"], r[CH], r["02_laser_offset"], r["Total"])
            for r in moodle] == [("alice", "alice@uni.example", "6", "3", "9"),
                                 ("bob", "bob@uni.example", "3", "0", "3"),
                                 ("carol", "", "0", "5", "5")]
    said = "\n".join(notes)
    assert "bob: 01_kinematics: last of 2, 1 started day(s)" in said
    assert "bob: 02_laser_offset: not graded (the notebook is not valid JSON)" in said
    assert "carol: 01_kinematics: no submission that counts" in said
    # one chapter alone, one layout
    one = classroom.export(layout, "02_laser_offset", layouts=("moodle",), log=lambda *a: None)
    assert next(csv.reader(io.StringIO(one[0].read_text()))) == \
        ["Username", "Email address", "ID number", "02_laser_offset", "Total"]


def test_grades_it_cannot_export_are_refused(tmp_path):
    layout = hub.HubLayout(tmp_path / "hub")
    with pytest.raises(hub.HubError, match="nothing graded"):
        classroom.export(layout)
    _graded(layout, CH, {"alice": 6.0})
    (layout.course / "grades" / f"{CH}.json").write_text(json.dumps([
        {"student": "a", "graded": True, "score": 1, "max_score": 7},
        {"student": "b", "graded": True, "score": 1, "max_score": 8}]))
    with pytest.raises(hub.HubError, match="different totals"):
        classroom.export(layout)
    _graded(layout, CH, {"alice": 6.0})
    (layout.course / "roster.csv").write_text("user,name\nalice,A\n")
    with pytest.raises(hub.HubError, match="username"):
        classroom.export(layout)
    (layout.course / "roster.csv").write_text("username,name\nalice,A\nalice,B\n")
    with pytest.raises(hub.HubError, match="line 3"):
        classroom.export(layout)
    with pytest.raises(gradebook.GradebookError, match="layout"):
        gradebook.write([], {}, "blackboard")


def test_feedback_shows_what_the_late_policy_kept():
    from annslam_lib.course.grader import SubmissionGrade

    g = SubmissionGrade(submission="x", notebook=f"{CH}.ipynb", student="bob", assignment=CH,
                        score=4.0, max_score=7.0)
    page = classroom.feedback_page(g, {"factor": 0.75, "why": "1 started day late: 75 %"})
    assert "Score: 4 / 7" in page and "After the late policy: 3 / 7" in page
    assert "After the late policy" not in classroom.feedback_page(g, {"factor": 1.0, "why": ""})


def test_release_writes_the_due_date_above_the_chapter(tmp_path, monkeypatch):
    layout = hub.HubLayout(tmp_path / "hub")
    layout.course.mkdir(parents=True)
    (layout.course / "course.toml").write_text(CONF)
    monkeypatch.setattr(classroom, "_nbgrader", lambda *a: None)     # no exchange here
    nb = nbformat.read(classroom.release(layout, CH), as_version=4)
    assert nb.cells[0].cell_type == "markdown"
    assert nb.cells[0].source.startswith("**Due Monday 01 February 2027, 23:59 (CET).**")
    assert "nbgrader" not in nb.cells[0].metadata
    plain = nbformat.read(classroom.release(layout, "02_laser_offset"), as_version=4)
    assert not plain.cells[0].source.startswith("**Due")


def test_the_class_command_needs_a_chapter_but_for_export(tmp_path):
    env = dict(os.environ, ANNSLAM_HUB_DIR=str(tmp_path / "hub"))
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "class", "grade"], env=env,
                         capture_output=True, text=True)
    assert out.returncode == 2 and "name the chapter" in out.stderr
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "class", "export"], env=env,
                         capture_output=True, text=True)
    assert out.returncode == 2 and "nothing graded yet" in out.stderr
