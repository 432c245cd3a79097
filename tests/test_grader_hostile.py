"""Hostile submissions through the real grader, as a class hub runs it: ``python -m annslam_lib
grade`` started as root with bubblewrap, then the same batch again in a new process, then the
same batch graded by an ordinary user.

The attacks (tests/hostile_support.py) try from inside a solution cell everything a student's
code must not do: remount or unmount anything, write outside the sandbox, rewrite another
submission, plant bytecode next to the library, trace or read the grader's process, raise its
limits, fork past the process limit, read the course's history, a file only its owner reads,
the other submissions and the gradebook, reach a socket of the machine, call a forbidden
library function from a thread or through a helper, redraw the terminal. Each submission's
score is what its honest content earns, nothing outside the sandbox changes (the course's
files, ``__pycache__`` and ``.git`` included, hashed; a canary folder with a world-writable
folder, an owner-only file and three listening sockets), and the honest students of the
batch keep full marks.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import pytest

from annslam_lib.course import sandbox
from annslam_lib.course.hub.classroom import feedback_page
from annslam_lib.data import fetch

import grading_support as gs
import hostile_support as hs

ROOT = Path(__file__).resolve().parents[1]
SPEED = gs.POINTS["ex-speed-tests"]
FULL = sum(gs.POINTS.values())
USER = 4242                         # an ordinary user: no account needed
as_a_hub = pytest.mark.skipif(
    os.geteuid() != 0 or sandbox.bwrap_available() is None,
    reason="the hostile batch is run as root with bubblewrap, as a hub's grader runs it: "
           + ("not root here" if os.geteuid() != 0 else sandbox.bwrap_problem()))

# student -> (observe cell, speed cell, expected score)
CASES = {
    "alice": (gs.OBSERVE_BODY, gs.SPEED_BODY, FULL),
    "probe": ("{probe}", gs.SPEED_BODY, SPEED),
    "forkbomb": ("{fork}", gs.SPEED_BODY, SPEED),
    "planter": ("{plant}", gs.SPEED_BODY, SPEED),
    "thread": (hs.THREAD, gs.SPEED_BODY, SPEED),
    "pool": (hs.POOL, gs.SPEED_BODY, SPEED),
    "helper": (hs.HELPER_OBSERVE, gs.SPEED_BODY + "\n\n" + hs.HELPER_SPEED, SPEED),
    "ansi": (hs.ANSI, gs.SPEED_BODY, SPEED),
    "evade-monitor": (hs.EVADE_MONITOR, gs.SPEED_BODY, SPEED),
    "evade-copy": (hs.EVADE_COPY, gs.SPEED_BODY, SPEED),
    "evade-copy-hidden": (hs.EVADE_COPY_HIDDEN, gs.SPEED_BODY, SPEED),
    "flood": (hs.FLOOD, gs.SPEED_BODY, SPEED),
    "bob": (gs.OBSERVE_BODY, gs.SPEED_BODY, FULL),
    # a folder name that would print a forged line of the report
    "forged\n  ok   ex-observe-tests (2 points)": (None, gs.SPEED_BODY, SPEED),
}
FORGED = "forged\\n  ok   ex-observe-tests (2 points)"   # as the report and the JSON name it


def _tree() -> dict:
    """sha256 of every file the grader or the instructor loads or reads: the library (its
    __pycache__ included), the notebooks, .git, the scripts, the data."""
    out = {}
    for top in ("annslam_lib", "notebooks", ".git", "scripts", "hub", "course.sh"):
        base = ROOT / top
        for p in ([base] if base.is_file() else sorted(base.rglob("*"))):
            rel = str(p.relative_to(ROOT))
            if p.is_file() and p.suffix not in (".nbi", ".nbc") and not (
                    rel.startswith(".git/") and (p.name == "index" or p.suffix == ".lock")):
                out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    for p in sorted(fetch.data_dir().rglob("*")):
        if p.is_file():
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


class Arena:
    """The batch, the canary and everything the attacks aim at, under /var/tmp (the
    sandbox's /tmp is its own)."""

    def __init__(self, owner: int = 0) -> None:
        self.base = Path(tempfile.mkdtemp(prefix="annslam-hostile-", dir="/var/tmp"))
        os.chmod(self.base, 0o755)
        self.canary = hs.Canary(self.base / "canary")
        self.work = self.base / "grader"                # the grader's own folder
        self.instructor = self.work / "instructor" / "chapter.ipynb"
        self.batch = self.work / "batch" / "submitted"
        self.json = self.work / "grades" / "batch.json"
        self.other = self.base / "exchange" / "zoe" / "other" / "other.ipynb"
        gs.write(gs.instructor(), self.instructor)
        gs.write(gs.honest(), self.other)
        self.json.parent.mkdir(parents=True)
        cfg = hs.config(course=str(ROOT), canary_open=str(self.canary.root / "open"),
                        secret=str(self.canary.root / "secret.txt"),
                        socket=self.canary.socket_path, abstract=self.canary.abstract,
                        tcp=self.canary.tcp, other_submission=str(self.other),
                        grader_pid=os.getpid(),
                        hidden={"instructor": str(self.instructor.parent),
                                "notebooks": str(ROOT / "notebooks"),
                                "git": str(ROOT / ".git"),
                                "batch": str(self.batch / "alice"),
                                "grades": str(self.json),
                                "exchange": str(self.other.parent)})
        fill = {"probe": hs.PROBE.replace("{cfg}", cfg), "fork": hs.FORK_BOMB.replace("{cfg}", cfg),
                "plant": hs.PLANT.replace("{cfg}", cfg)}
        for student, (observe, speed, _) in CASES.items():
            if observe is not None and observe.startswith("{"):
                observe = fill[observe[1:-1]]
            gs.write(gs.submission(observe, speed),
                     self.batch / student / "chapter" / "chapter.ipynb")
        if owner:
            for p in [self.work, *self.work.rglob("*")]:
                os.chown(p, owner, owner)

    def close(self) -> None:
        self.canary.close()
        shutil.rmtree(self.base, ignore_errors=True)


def _exposed() -> list[str]:
    """bwrap arguments that let another user reach this interpreter where a folder on its
    way is closed to others (a venv made from a Python under /root): that folder becomes
    an empty, open one with only the interpreter's folders bound back."""
    args, made = [], set()
    for p in sandbox.interpreter_paths():
        chain = [*reversed(p.parents), p][1:]
        closed = next((a for a in chain if not os.stat(a).st_mode & 0o001), None)
        if closed is None:
            continue
        for a in chain[chain.index(closed):-1]:        # open folders on the way
            if a not in made:
                made.add(a)
                args += ["--perms", "0755"] + (["--tmpfs", str(a)] if a == closed else
                                               ["--dir", str(a)])
        args += ["--ro-bind", str(p), str(p)]
    return args


def _grade(arena: Arena, *, user: int = 0, home: Path | None = None):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "COLUMNS")}
    env["ANNSLAM_DATA"] = str(fetch.data_dir())
    cmd = [sys.executable, "-m", "annslam_lib", "grade", str(arena.batch), "--instructor",
           str(arena.instructor.parent), "--json", str(arena.json), "--timeout", "20",
           "--call-timeout", "10", "--deadline", "90"]
    if user:
        env["HOME"] = str(home)
        cmd = ["bwrap", "--dev-bind", "/", "/", *_exposed(), "--", "setpriv",
               f"--reuid={user}", f"--regid={user}", "--clear-groups", *cmd]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, cwd=ROOT)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
    rows = {row["student"]: row for row in json.loads(arena.json.read_text())}
    return r, rows


def _by_id(row) -> dict:
    return {e["grade_id"]: e for e in row["exercises"]}


@pytest.fixture(scope="module")
def as_root():
    """The batch graded twice as root, each time by a new grader process."""
    before = _tree()
    arena = Arena()
    try:
        first = _grade(arena)
        files_after_first = arena.canary.files()
        second = _grade(arena)
        yield SimpleNamespace(arena=arena, first=first, second=second, before=before,
                              after=_tree(), canary_first=files_after_first,
                              canary=arena.canary.files(), accepted=dict(arena.canary.accepted))
    finally:
        arena.close()


@pytest.fixture(scope="module")
def as_user():
    """The batch graded by an ordinary user (uid 4242, no account)."""
    arena = Arena(owner=USER)
    home = arena.base / "home"
    home.mkdir()
    os.chown(home, USER, USER)
    try:
        r, rows = _grade(arena, user=USER, home=home)
        yield SimpleNamespace(arena=arena, run=r, rows=rows, canary=arena.canary.files(),
                              accepted=dict(arena.canary.accepted))
    finally:
        arena.close()


def _scores(rows) -> dict:
    return {s: (r["score"], [(e["grade_id"], e["status"]) for e in r["exercises"]])
            for s, r in rows.items()}


@as_a_hub
def test_every_submission_scores_what_its_honest_content_earns(as_root):
    _, rows = as_root.first
    assert sorted(rows) == sorted(FORGED if "\n" in c else c for c in CASES)
    for student, (_, _, expected) in CASES.items():
        student = FORGED if "\n" in student else student
        assert rows[student]["graded"], rows[student]
        assert rows[student]["score"] == expected, (student, rows[student])
        assert rows[student]["isolation"] == "bwrap"
    assert _scores(as_root.second[1]) == _scores(rows)      # a second batch: the same


@as_a_hub
def test_nothing_outside_the_sandbox_changed(as_root):
    assert as_root.after == as_root.before, "a course file changed"
    assert as_root.canary == as_root.canary_first
    assert set(as_root.canary) == {"open", "secret.txt", "owner.sock"}, as_root.canary
    assert as_root.accepted == {"socket": 0, "abstract": 0, "tcp": 0}


def _probe(rows) -> dict:
    e = _by_id(rows["probe"])["ex-observe-tests"]
    assert e["status"] == "solution error", e
    return hs.seen(e["message"])


@as_a_hub
def test_student_code_holds_no_privilege_and_sees_nothing_of_the_machine(as_root):
    s = _probe(as_root.first[1])
    uid = int(s["uid"][0])
    assert uid in sandbox.SANDBOX_IDS and s["uid"] == [str(uid)] * 4 and s["gid"] == s["uid"]
    for k in ("CapEff", "CapPrm", "CapBnd", "CapAmb"):
        assert int(s[k], 16) == 0, (k, s[k])
    assert s["NoNewPrivs"] == "1" and s["Seccomp"] == "2"
    _assert_confined(s)


def _assert_confined(s) -> None:
    for k in ("remount /", "remount course", "umount /"):
        assert s[k] == [-1, "EPERM"], (k, s[k])
    hidden = [k[7:] for k in s if k.startswith("exists ")]
    assert set(hidden) == {"instructor", "notebooks", "git", "batch", "grades", "exchange"}
    for name in hidden:
        assert s["exists " + name] is False, name
        assert s["umount " + name] == [-1, "EPERM"], (name, s["umount " + name])
        assert s["read " + name] == "ENOENT", (name, s["read " + name])
    for k in ("write canary", "write library", "rewrite other submission", "read secret",
              "read shadow"):
        assert s[k] == "ENOENT", (k, s[k])
    assert s["write snapshot"] in ("EROFS", "EACCES"), s["write snapshot"]
    assert s["git show"][0] != 0 and s["git show"][1] == 0
    assert s["host socket"] == "ENOENT"
    assert s["abstract socket"] == "ECONNREFUSED"             # its own network namespace
    assert s["tcp"] in ("ECONNREFUSED", "ENETUNREACH")
    assert s["pids"] == [1, 2], s["pids"]          # alone with its launcher (PID 1)
    assert s["ptrace grader"] == [-1, "EPERM"] and s["ptrace 1"] == [-1, "EPERM"]
    assert s["mem grader"] == "ENOENT"
    assert s["unshare user"] == [-1, "EPERM"]
    for name in ("packet", "vsock"):
        assert s["socket " + name] == "EPERM", (name, s["socket " + name])
    assert s["socket unix"] == "made" and s["socket netlink"] == "made"
    assert s["write sockets folder"] == "EACCES"                 # closed once the kernel is up
    assert s["unlink shell socket"] == "EACCES"
    for name in ("RLIMIT_NPROC", "RLIMIT_AS", "RLIMIT_CPU", "RLIMIT_FSIZE"):
        assert s["raise " + name] == "ValueError", (name, s["raise " + name])
    assert s["limit RLIMIT_NPROC"] == [256, 256]
    assert s["limit RLIMIT_AS"] == [4 << 30, 4 << 30]


@as_a_hub
def test_a_fork_bomb_stops_at_the_process_limit(as_root, as_user):
    for rows in (as_root.first[1], as_user.rows):
        s = hs.seen(_by_id(rows["forkbomb"])["ex-observe-tests"]["message"])
        assert s["error"] == "EAGAIN", s
        assert s["forked"] + s["threads"] <= 256, s
        assert s["forked"] >= 100, s                  # the limit, not something else, stopped it


@as_a_hub
def test_planted_bytecode_never_reaches_the_course(as_root):
    s = hs.seen(_by_id(as_root.first[1]["planter"])["ex-observe-tests"]["message"])
    assert s == {"library": "ENOENT", "checks": "ENOENT", "snapshot": "EROFS"}, s
    assert "planted-ran" not in " ".join(as_root.canary)


@as_a_hub
def test_forbidden_calls_from_threads_and_helpers_score_zero(as_root):
    rows = as_root.first[1]
    for student, said in (("thread", "uses __import__(), getattr() with a computed name"),
                          ("pool", "uses __import__(), getattr() with a computed name"),
                          ("helper", "calls annslam_lib.models.observation.observe: write it "
                                     "yourself"),
                          ("evade-monitor", "uses __import__(), annslam_lib.course, getattr()"),
                          ("evade-copy", "calls annslam_lib.models.observation.observe"),
                          ("evade-copy-hidden", "uses __code__, __globals__, __import__()")):
        e = _by_id(rows[student])["ex-observe-tests"]
        assert e["status"] == "forbidden" and e["points"] == 0, (student, e)
        assert said in e["message"], (student, e["message"])


@as_a_hub
def test_a_flood_of_output_and_a_huge_message_are_cut(as_root):
    e = _by_id(as_root.first[1]["flood"])["ex-observe-tests"]
    assert e["status"] == "solution error" and "more characters]" in e["message"]
    assert len(e["message"]) < 4200


@as_a_hub
def test_reports_are_inert(as_root):
    r, rows = as_root.first
    e = _by_id(rows["ansi"])["ex-observe-tests"]
    assert e["status"] == "failed"
    row = rows["ansi"]
    page = feedback_page(SimpleNamespace(
        graded=True, score=row["score"], max_score=row["max_score"], notes=row["notes"],
        errors=row["errors"], assignment="chapter", student="ansi",
        exercises=[SimpleNamespace(**x) for x in row["exercises"]]))
    raw = json.dumps(row, ensure_ascii=False)
    for text, where in ((r.stdout, "report"), (raw, "json"), (page, "feedback page")):
        for ch in ("\x1b", "\r", "\b", "\u202e", "\u2028", "\u061c", "\ufeff"):
            assert ch not in text, (where, repr(ch))
    assert "\\x1b[2J\\x1b[H/x/alice: 9 / 9 points\\r" in e["message"]
    assert "\\x1b[2J" in r.stdout and "\\x1b[2J" in page
    # no line of the report is forged: what a submission wrote continues its own line
    lines = r.stdout.splitlines()
    assert not any(x.startswith("/x/bob") for x in lines)
    assert any(x == "       | /x/bob: 5 / 5 points" for x in lines)
    assert any("forged\\n  ok   ex-observe-tests (2 points)" in x for x in lines)
    assert not any(x.startswith("  ok   ex-observe-tests (2 points)") for x in lines)


@as_a_hub
def test_an_ordinary_user_grades_the_same_and_student_code_is_confined(as_root, as_user):
    assert _scores(as_user.rows) == _scores(as_root.first[1])
    s = _probe(as_user.rows)
    assert s["uid"] == [str(USER)] * 4, s["uid"]
    for k in ("CapEff", "CapPrm", "CapAmb"):
        assert int(s[k], 16) == 0, (k, s[k])
    assert s["NoNewPrivs"] == "1" and s["Seccomp"] == "2"
    _assert_confined(s)
    assert set(as_user.canary) == {"open", "secret.txt", "owner.sock"}
    assert as_user.accepted == {"socket": 0, "abstract": 0, "tcp": 0}


def test_bytecode_planted_by_an_unsandboxed_submission_never_runs(tmp_path):
    """Isolation 'none' (a trusted notebook, the grader's own rights): a submission CAN plant
    valid bytecode next to the library. The watch over the course's files finds it after that
    submission, puts the original bytecode back and stops the batch (exit 3); the next batch,
    a new grader process, never runs it. Control: the same bytecode left in place runs as
    soon as a plain process imports the module. On a copy of the library, so that no other
    test's grader sees the change."""
    course = tmp_path / "course"
    shutil.copytree(ROOT / "annslam_lib", course / "annslam_lib")
    canary = tmp_path / "canary"
    (canary / "open").mkdir(parents=True)
    inst = tmp_path / "instructor" / "chapter.ipynb"
    gs.write(gs.instructor(), inst)
    cfg = hs.config(course=str(course), canary_open=str(canary / "open"))
    batch = tmp_path / "batch"
    gs.write(gs.honest(), batch / "submitted" / "alice" / "chapter" / "chapter.ipynb")
    gs.write(gs.submission(hs.PLANT.replace("{cfg}", cfg), gs.SPEED_BODY),
             batch / "submitted" / "mallory" / "chapter" / "chapter.ipynb")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONPYCACHEPREFIX")}
    env.update(PYTHONPATH=str(course), ANNSLAM_DATA=str(fetch.data_dir()))

    def grade(folder, out):
        return subprocess.run(
            [sys.executable, "-m", "annslam_lib", "grade", str(folder), "--instructor",
             str(inst.parent), "--json", str(out), "--isolation", "none", "--timeout", "20",
             "--deadline", "90"], capture_output=True, text=True, timeout=600, env=env,
            cwd=course)

    pycs = [course / "annslam_lib" / "course" / "__pycache__" / "grader.cpython-"
            f"{sys.version_info.major}{sys.version_info.minor}.pyc",
            course / "annslam_lib" / "grading" / "__pycache__" / "kinematics.cpython-"
            f"{sys.version_info.major}{sys.version_info.minor}.pyc"]
    r = grade(batch, tmp_path / "g1.json")
    assert r.returncode == 3, r.stdout + r.stderr
    assert "course files changed" in r.stderr and "restored" in r.stderr, r.stderr
    assert "WARNING: UNISOLATED" in r.stderr and "WARNING: UNISOLATED" in r.stdout
    rows = {x["student"]: x for x in json.loads((tmp_path / "g1.json").read_text())}
    assert rows["alice"]["score"] == FULL
    assert rows["mallory"]["score"] == 0
    assert {e["status"] for e in rows["mallory"]["exercises"]} == {"tampered"}
    note = " ".join(rows["mallory"]["notes"])
    assert "changed by this submission" in note and "restored" in note, note
    assert all(str(p) in note for p in pycs), note
    assert not (canary / "open" / "planted-ran").exists()
    restored = {p: p.read_bytes() for p in pycs}
    # the next batch, a new grader process, with honest work only
    again = tmp_path / "again"
    gs.write(gs.honest(), again / "submitted" / "bob" / "chapter" / "chapter.ipynb")
    r = grade(again, tmp_path / "g2.json")
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((tmp_path / "g2.json").read_text())[0]["score"] == FULL
    assert not (canary / "open" / "planted-ran").exists()
    assert {p: p.read_bytes() for p in pycs} == restored
    # control: the planted bytecode is live when left in place
    plant = hs.PLANT.replace("{cfg}", cfg).replace('raise AssertionError("SEEN " + json.dumps(SEEN))',
                                                  'print(SEEN)')
    p = subprocess.run([sys.executable, "-c", plant], capture_output=True, text=True, env=env,
                       timeout=60)
    assert "'library': 'planted'" in p.stdout, p.stdout + p.stderr
    subprocess.run([sys.executable, "-c", "import annslam_lib.course.grader"], env=env,
                   check=True, timeout=120, cwd=tmp_path)
    assert (canary / "open" / "planted-ran").exists()


def _processes_of(uid: int) -> list[int]:
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                if os.stat(f"/proc/{d}").st_uid == uid:
                    out.append(int(d))
            except OSError:
                pass
    return out


@as_a_hub
def test_no_process_outlives_its_sandbox():
    """A kernel killed by the grader (as after a time-out it ignores) takes every process of
    its sandbox with it: its launcher, itself and a child it forked to sleep."""
    import time

    with sandbox.Sandbox(sandbox.Limits(cell_timeout=20, deadline=60)) as sb:
        sb.start()
        res = sb.execute("import os, time\nif os.fork() == 0:\n    time.sleep(600)\n", 20)
        assert res.ok, res.reason()
        assert len(_processes_of(sb.uid)) >= 3          # launcher, kernel, child
        sb.stop()
        end = time.monotonic() + 10
        while _processes_of(sb.uid) and time.monotonic() < end:
            time.sleep(0.1)
        assert _processes_of(sb.uid) == []
