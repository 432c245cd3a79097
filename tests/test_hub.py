"""The class hub for real: ``python -m annslam_lib hub`` started as root for two
students, each server run by JupyterHub's LocalProcessSpawner as the student's own Unix
account, driven over the REST API. What one student's kernel can reach of another's files is
tried from inside the kernel, not only through the file API."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hub_support import prepared_layout
from browser_support import launch_chromium, why_no_browser
from git_http import GitServer
from hub_browser import Student, cell_index, solution_source

from annslam_lib.course.hub import setup as hub_setup
from annslam_lib.course.hub.client import launch, remove_accounts

ROOT = hub_setup.ROOT
PRIVATE = [ROOT / "notebooks", ROOT / "tests"]


@pytest.fixture(scope="module")
def class_hub(tmp_path_factory):
    layout = prepared_layout()
    modes = {p: p.stat().st_mode & 0o777 for p in PRIVATE}
    for p in PRIVATE:                 # the hub refuses to open them to students (tested below)
        os.chmod(p, modes[p] & ~0o007)
    names = [f"hubt{os.getpid() % 100000}{c}" for c in "abc"]
    tmp = tmp_path_factory.mktemp("hub")
    # the class of this run only: no submission, grade or release of an earlier run
    shutil.rmtree(layout.course, ignore_errors=True)
    shutil.rmtree(layout.exchange, ignore_errors=True)
    h = None
    try:
        h = launch(layout, names, tmp)
        h.users = list(names)
        yield h, names
    finally:
        if h is not None:
            h.stop()
        remove_accounts(names)
        for p, mode in modes.items():
            os.chmod(p, mode)


def test_each_student_runs_as_themselves_in_a_private_home_with_the_course(class_hub):
    h, (a, *_) = class_hub
    h.api.start_server(a)
    status, listing = h.api.request("GET", f"/user/{a}/api/contents/")
    assert status == 200
    released = sorted(p.name for p in h.layout.release.glob("*.ipynb"))
    assert len(released) == len(list((ROOT / "notebooks").glob("*.ipynb")))
    assert sorted(i["name"] for i in listing["content"] if i["type"] == "notebook") == released
    got = h.api.run(a, "import os, pwd, sys, annslam_lib\n"
                   "print(pwd.getpwuid(os.getuid()).pw_name, oct(os.stat(os.path.expanduser("
                   "'~')).st_mode & 0o777), os.environ['OMP_NUM_THREADS'], "
                   "os.environ['ANNSLAM_DATA'], sys.prefix, annslam_lib.__file__)")
    assert got.error is None, got
    user, mode, threads, data, prefix, lib = got.stdout.split()
    assert (user, mode, threads) == (a, "0o700", "1")
    assert data == str(h.layout.data) and prefix == str(h.layout.env)
    assert lib.startswith(str(h.layout.env)) and "site-packages" in lib   # the wheel
    # the kernel is in the student's control group (hub.limits): memory, processes, CPU
    groups = h.api.run(a, "print(open('/proc/self/cgroup').read())")
    assert groups.error is None, groups
    lines = groups.stdout.split()
    mine = [ln for ln in lines if ln.endswith(f"/annslam-hub/{a}")]
    v2 = any(ln.startswith("0::/annslam-hub/") for ln in mine)
    assert v2 or {c for ln in mine for c in ln.split(":")[1].split(",")} >= {
        "memory", "pids", "cpu"}, lines


def test_a_students_kernel_cannot_read_or_change_another_students_files(class_hub):
    h, (a, b, _) = class_hub
    h.api.start_server(a)
    h.api.start_server(b)
    wrote = h.api.run(a, "import os\np = os.path.expanduser('~/course/answer.txt')\n"
                     "open(p, 'w').write('mine')\nprint(p)")
    assert wrote.error is None, wrote
    secret = wrote.stdout.strip()
    notebook = os.path.join(os.path.dirname(secret), sorted(
        p.name for p in h.layout.release.glob("*.ipynb"))[1])
    attempts = {
        "read": f"open({secret!r}).read()",
        "list": f"os.listdir(os.path.dirname({secret!r}))",
        "change": f"open({notebook!r}, 'a').write('x')",
        "remove": f"os.remove({secret!r})",
        "instructor notebooks": f"os.listdir({str(ROOT / 'notebooks')!r})",
        "hub state": f"os.listdir({str(h.layout.state)!r})",
        "collected submissions": f"os.listdir({str(h.layout.course)!r})",
        "shared data": "open(os.path.join(os.environ['ANNSLAM_DATA'], 'x'), 'w')",
        "student environment": f"open({str(h.layout.env / 'pyvenv.cfg')!r}, 'a')",
    }
    code = "import os\nfor what, expr in %r.items():\n" % attempts + (
        "    try:\n        eval(expr)\n        print(what, 'ALLOWED')\n"
        "    except PermissionError:\n        print(what, 'denied')\n")
    got = h.api.run(b, code)
    assert got.error is None, got
    lines = dict(line.rsplit(" ", 1) for line in got.stdout.strip().splitlines())
    assert lines == {what: "denied" for what in attempts}
    again = h.api.run(a, f"print(open({secret!r}).read())")
    assert again.stdout.strip() == "mine"                # b changed nothing


def test_a_students_kernel_reads_the_class_studies_and_cannot_change_them(class_hub, tmp_path):
    """The set-up's own class-study step (on one small notebook: the tests' hub is prepared
    without the course's studies), then a student's kernel, as that student: its first run
    of the study is read from the class's folder, and it cannot write there."""
    import nbformat

    h, (a, *_) = class_hub
    nb = nbformat.v4.new_notebook()
    call = ("from annslam_lib.data import simulate\nfrom annslam_lib.slam import runner\n"
            "r = runner.run_cached(simulate.simulate(seed=0, laps=1))\n")
    nb.cells = [nbformat.v4.new_code_cell(call)]
    nbformat.write(nb, tmp_path / "small.ipynb")
    hub_setup.warm_class_studies(h.layout, notebooks=tmp_path)
    entry = next(h.layout.studies.glob("run_cached-*.pkl"))
    h.api.start_server(a)
    got = h.api.run(a, call + "from annslam_lib import _cache\n"
                    f"print(_cache.STATS['class_hits'], _cache.STATS['misses'], len(r.trajectory))\n"
                    "try:\n"
                    f"    open({str(entry)!r}, 'ab')\n    print('ALLOWED')\n"
                    "except PermissionError:\n    print('denied')\n")
    assert got.error is None, got
    hits, misses, n, write = got.stdout.split()
    assert (hits, misses, write) == ("1", "0", "denied") and int(n) > 100


def test_only_listed_students_log_in_with_the_students_password(class_hub):
    h, (a, *_) = class_hub
    pw = h.passwords["ANNSLAM_HUB_PASSWORD"]
    assert h.api.login(a, pw) == 302
    assert h.api.login("mallory", pw) == 403
    assert h.api.login(a, pw + "x") == 403
    assert h.api.login("instructor", pw) == 403                 # the admin needs the admin's
    status, _ = h.api.request("GET", "/hub/api/users/mallory")
    assert status == 404                                    # no account was made for her
    # the hub said at its start that a shared password is not for graded work
    assert "not for graded work" in h.log.read_text()


def test_formgrader_is_not_served_to_students(class_hub):
    h, (a, *_) = class_hub
    h.api.start_server(a)
    assert h.api.request("GET", f"/user/{a}/formgrader")[0] == 404
    status, body = h.api.request("GET", f"/user/{a}/assignments?course_id=annslam")
    assert status == 200, body                              # the Assignments panel is


def test_a_hub_started_twice_says_where_the_running_one_is(class_hub, tmp_path):
    h, (a, *_) = class_hub
    f = tmp_path / "class.txt"
    f.write_text(f"{a}\n")
    env = dict(os.environ, ANNSLAM_HUB_DIR=str(h.layout.root), **h.passwords)
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "hub", "--class", str(f),
                          "--port", str(h.port + 10)], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2
    assert f"already running from {h.layout.root} at {h.url}" in out.stderr
    assert json.loads((h.layout.state / "hub.json").read_text())["url"] == h.url


def _roster(h, action: str, name: str) -> str:
    env = dict(os.environ, ANNSLAM_HUB_DIR=str(h.layout.root))
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "class", action, name],
                         env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, f"class {action}: {out.stdout[-2000:]}\n{out.stderr[-2000:]}"
    return out.stdout


def _expired(name: str) -> bool:
    """The account's expiry date (shadow's 8th field) is in the past."""
    line = subprocess.run(["getent", "shadow", name], capture_output=True, text=True).stdout
    field = line.split(":")[7] if line.count(":") >= 7 else ""
    return field.strip() not in ("", "-1") and int(field) * 86400 < time.time()


def test_a_student_joins_mid_term_and_leaves_with_their_files_kept(class_hub):
    """``class add`` lets a new student in on the running hub; ``class drop`` stops their
    server, refuses their logins, expires their account and keeps their files; ``class
    add`` again gives them back, files and all."""
    import pwd

    h, names = class_hub
    new = names[0][:-1] + "z"
    pw = h.passwords["ANNSLAM_HUB_PASSWORD"]
    class_file = Path(json.loads((h.layout.state / "hub.json").read_text())["class"])
    try:
        assert h.api.login(new, pw) == 403                         # not in the class yet
        assert "can log in now" in _roster(h, "add", new)
        assert h.api.login(new, pw) == 302
        h.api.start_server(new)
        status, _ = h.api.request("PUT", f"/user/{new}/api/contents/mine.txt",
                                  {"type": "file", "format": "text", "content": "my notes"})
        assert status in (200, 201)
        home = Path(pwd.getpwnam(new).pw_dir)
        out = _roster(h, "drop", new)
        assert f"their files stay in {home}" in out
        assert h.api.login(new, pw) == 403
        assert h.api.request("GET", f"/hub/api/users/{new}")[0] == 404
        assert _expired(new)
        assert subprocess.run(["pgrep", "-U", str(pwd.getpwnam(new).pw_uid)],
                              capture_output=True).returncode == 1     # no process left
        assert (home / "course" / "mine.txt").read_text() == "my notes"
        assert f"# dropped: {new}" in class_file.read_text().splitlines()
        # dropping again finishes the job (nothing to undo); a name never in the class: refused
        assert "already dropped" in _roster(h, "drop", new)
        never = subprocess.run([sys.executable, "-m", "annslam_lib", "class", "drop", "nobodyz"],
                               env=dict(os.environ, ANNSLAM_HUB_DIR=str(h.layout.root)),
                               capture_output=True, text=True, timeout=120)
        assert never.returncode == 2 and "is not in the class" in never.stderr
        _roster(h, "add", new)
        assert h.api.login(new, pw) == 302 and not _expired(new)
        h.api.start_server(new)
        status, model = h.api.request("GET", f"/user/{new}/api/contents/mine.txt")
        assert status == 200 and model["content"] == "my notes"
    finally:
        h.api.stop_server(new)
        h.api.request("DELETE", f"/hub/api/users/{new}")
        class_file.write_text("".join(f"{n}\n" for n in names))
        remove_accounts([new])


CHAPTER = "01_kinematics"
#: what each student answers: (exercise answered correctly, exercise answered wrongly)
WRONG = {
    "ex01-axle-speed": "def my_axle_speed(v_e, alpha, H, L):\n    return v_e\n",
    "ex01-euler-step": "def my_euler_step(pose, control, dt, L, a, b):\n"
                       "    return np.asarray(pose, dtype=float)\n",
}
ANSWERS = [("ex01-axle-speed", "ex01-euler-step"), ("ex01-euler-step", "ex01-axle-speed"),
           ("ex01-process-jacobians", "ex01-axle-speed")]


def _class(h, action: str) -> None:
    env = dict(os.environ, ANNSLAM_HUB_DIR=str(h.layout.root))
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "class", action, CHAPTER],
                         env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, f"class {action}: {out.stdout[-3000:]}\n{out.stderr[-3000:]}"


def test_a_class_of_three_fetches_answers_submits_and_sees_its_own_feedback(class_hub):
    """The whole lab in Chromium: three students log in, fetch the chapter in the
    Assignments panel, each answer one exercise right and one wrong, submit; the instructor
    collects, grades with the course's grader and returns feedback; each student fetches it
    and sees their own score."""
    why = why_no_browser()
    if why:
        pytest.skip(why)
    h, names = class_hub
    source = ROOT / "notebooks" / f"{CHAPTER}.ipynb"
    points = {gid.removesuffix("-tests"): cell["metadata"]["nbgrader"]["points"]
              for cell in json.loads(source.read_text())["cells"]
              for gid in [cell["metadata"].get("nbgrader", {}).get("grade_id", "")]
              if cell["metadata"].get("nbgrader", {}).get("grade")}
    for name in names:              # servers start while the chapter is released
        h.api.start_server(name, wait=False)
    _class(h, "release")
    pw, browser = launch_chromium()
    students = []
    try:
        for name, (right, wrong) in zip(names, ANSWERS):
            s = Student(browser, h.url, name)
            students.append(s)
            s.log_in(h.passwords["ANNSLAM_HUB_PASSWORD"])
            s.assignments()
            s.press("released", "Fetch", f"#fetched_assignments_list :text('{CHAPTER}')")
            s.open_notebook(f"{CHAPTER}/{CHAPTER}.ipynb")
            s.type_cell(cell_index(source, right), solution_source(source, right))
            s.type_cell(cell_index(source, wrong), WRONG[wrong])
            s.save()
            s.assignments()
            s.press("fetched", "Submit", f"#submitted_assignments_list :text('{CHAPTER}')")
        _class(h, "collect")
        _class(h, "grade")
        _class(h, "feedback")
        grades = {g["student"]: g for g in json.loads(
            (h.layout.course / "grades" / f"{CHAPTER}.json").read_text())}
        total = sum(points.values())
        for s, (right, wrong) in zip(students, ANSWERS):
            assert grades[s.name]["score"] == points[right], (s.name, grades[s.name])
            s.refresh_assignments()          # the panel is still open in the student's lab
            s.press("submitted", "Fetch Feedback",
                    "#submitted_assignments_list a:text-is(' (view feedback)')")
            page = s.view_feedback(f"{CHAPTER}.html")
            assert f"{CHAPTER}: feedback for {s.name}\n" in page
            assert f"Score: {points[right]:g} / {total:g}" in page
            others = [n for n in names if n != s.name]
            assert not any(n in page for n in others)
            assert s.fetch_text(f"/user/{others[0]}/files/{CHAPTER}/feedback")[0] == 403
    except Exception:
        for s in students:
            s.shot("failure")
        raise
    finally:
        for s in students:
            s.close()
        browser.close()
        pw.stop()


HOSTILE_CHAPTER = "02_laser_offset"


@pytest.mark.needs_sandbox
def test_hostile_submissions_through_class_grade(class_hub, tmp_path):
    """The same attacks as tests/test_grader_hostile.py through `class grade` on this hub,
    as root: the exchange, the course folder and the hub's state are not in the sandbox,
    each submission scores what its honest content earns, the feedback pages are inert,
    and no file of the exchange or of the other submissions changes."""
    import hashlib

    import grading_support as gs
    import hostile_support as hs
    import nbformat
    from annslam_lib.course import release, sandbox

    h, _ = class_hub
    layout = h.layout
    source = ROOT / "notebooks" / f"{HOSTILE_CHAPTER}.ipynb"
    bodies = gs.solution_bodies(source)
    points = {c.metadata["nbgrader"]["grade_id"]: c.metadata["nbgrader"]["points"]
              for c in nbformat.read(source, as_version=4).cells
              if c.metadata.get("nbgrader", {}).get("grade")}
    first = next(iter(bodies))                          # the exercise the attack replaces
    first_points = points[f"{first}-tests"]
    canary = hs.Canary(tmp_path / "canary")
    os.chmod(tmp_path, 0o755)
    other = layout.course / "submitted" / "honest1" / HOSTILE_CHAPTER / f"{HOSTILE_CHAPTER}.ipynb"
    cfg = hs.config(course=str(ROOT), canary_open=str(canary.root / "open"),
                    secret=str(canary.root / "secret.txt"), socket=canary.socket_path,
                    abstract=canary.abstract, tcp=canary.tcp, other_submission=str(other),
                    grader_pid=os.getpid(),
                    hidden={"exchange": str(layout.exchange), "course": str(layout.course),
                            "state": str(layout.state), "notebooks": str(ROOT / "notebooks"),
                            "git": str(ROOT / ".git")})
    import re
    name = re.search(r"def (\w+)\(", bodies[first]).group(1)
    attacks = {"honest1": None, "prober": hs.PROBE.replace("{cfg}", cfg),
               "ansi": hs.ANSI.replace("my_observe(pose, landmark)", f"{name}(*args, **kw)")}
    for student, attack in attacks.items():
        nb = release.student_version(nbformat.read(source, as_version=4), HOSTILE_CHAPTER)
        for c in nb.cells:
            gid = c.metadata.get("nbgrader", {}).get("grade_id")
            if gid in bodies:
                c.source = bodies[gid]
                if gid == first and attack is not None:
                    c.source = attack
        gs.write(nb, layout.course / "submitted" / student / HOSTILE_CHAPTER /
                 f"{HOSTILE_CHAPTER}.ipynb")

    def digest(folder):
        return {str(p): hashlib.sha256(p.read_bytes()).hexdigest()
                for p in sorted(folder.rglob("*")) if p.is_file()}

    before = {**digest(layout.exchange), **digest(layout.course / "submitted")}
    try:
        _class_chapter(h, "grade", HOSTILE_CHAPTER)
    finally:
        canary.close()
    after = {**digest(layout.exchange), **digest(layout.course / "submitted")}
    assert after == before
    assert set(canary.files()) == {"open", "secret.txt", "owner.sock"}
    assert canary.accepted == {"socket": 0, "abstract": 0, "tcp": 0}
    grades = {g["student"]: g for g in json.loads(
        (layout.course / "grades" / f"{HOSTILE_CHAPTER}.json").read_text())}
    total = sum(points.values())
    assert grades["honest1"]["score"] == total
    assert grades["prober"]["score"] == total - first_points
    assert grades["ansi"]["score"] == total - first_points
    probe = next(e for e in grades["prober"]["exercises"] if e["grade_id"] == f"{first}-tests")
    s = hs.seen(probe["message"])
    assert int(s["uid"][0]) in sandbox.SANDBOX_IDS and int(s["CapEff"], 16) == 0
    for name in ("exchange", "course", "state", "notebooks", "git"):
        assert s["exists " + name] is False and s["umount " + name] == [-1, "EPERM"], name
    assert s["remount /"] == [-1, "EPERM"] and s["write canary"] == "ENOENT"
    assert s["rewrite other submission"] == "ENOENT" and s["host socket"] == "ENOENT"
    page = (layout.course / "feedback" / "ansi" / HOSTILE_CHAPTER /
            f"{HOSTILE_CHAPTER}.html").read_text()
    assert "\\x1b[2J" in page                              # shown, escaped
    for ch in ("\x1b", "\r", "\b", "\u202e"):
        assert ch not in page, repr(ch)


def _class_chapter(h, action: str, chapter: str) -> None:
    env = dict(os.environ, ANNSLAM_HUB_DIR=str(h.layout.root))
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "class", action, chapter],
                         env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, f"class {action}: {out.stdout[-3000:]}\n{out.stderr[-3000:]}"


def _publish(repo: Path, chapters) -> None:
    from annslam_lib.course import publish

    publish.publish(str(repo), "fall", chapters)


def test_an_nbgitpuller_link_pulls_the_published_release_and_keeps_the_students_edit(class_hub):
    """The release published to a git repository served on 127.0.0.1; in Chromium, a
    logged-in student opens the course's nbgitpuller link for chapter 01 and the chapter
    opens in JupyterLab from their home; the student edits it, a new release adds chapter
    02, and the same link again brings it without touching the edit."""
    import nbformat
    from annslam_lib.course.launch import nbgitpuller_link

    why = why_no_browser()
    if why:
        pytest.skip(why)
    h, (_, _, c) = class_hub
    served = h.layout.root / "test-release"
    shutil.rmtree(served, ignore_errors=True)
    served.mkdir(mode=0o755)
    repo = served / "release.git"
    subprocess.run(["git", "init", "--quiet", "--bare", str(repo)], check=True)
    chapters = [ROOT / "notebooks" / f"{n}.ipynb" for n in ("01_kinematics", "02_laser_offset")]
    _publish(repo, chapters[:1])
    server = GitServer(served).__enter__()
    base = server.url
    pw, browser = launch_chromium()
    s = Student(browser, h.url, c)
    try:
        link = nbgitpuller_link(h.url, f"{base}/release.git", "fall", "01_kinematics.ipynb")
        s.log_in(h.passwords["ANNSLAM_HUB_PASSWORD"])
        s.page.goto(link)
        s.page.wait_for_url(f"**/user/{c}/lab/tree/annslam/01_kinematics.ipynb", timeout=120_000)
        s.page.wait_for_selector(".jp-Notebook .jp-Cell", state="attached", timeout=60_000)
        tabs = s.page.locator("#jp-main-dock-panel .lm-TabBar-tabLabel").all_inner_texts()
        assert "01_kinematics.ipynb" in tabs, tabs              # the chapter is open
        status, model = h.api.request("GET", f"/user/{c}/api/contents/annslam/01_kinematics.ipynb")
        assert status == 200
        nb = nbformat.from_dict(model["content"])
        nb.cells.append(nbformat.v4.new_markdown_cell("my own note on the axle speed"))
        status, _ = h.api.request("PUT", f"/user/{c}/api/contents/annslam/01_kinematics.ipynb",
                                  {"type": "notebook", "format": "json", "content": nb})
        assert status == 200
        _publish(repo, chapters)                                      # adds chapter 02
        s.page.goto(link)
        s.page.wait_for_url(f"**/user/{c}/lab/tree/annslam/01_kinematics.ipynb", timeout=120_000)
        status, listing = h.api.request("GET", f"/user/{c}/api/contents/annslam")
        assert sorted(i["name"] for i in listing["content"]) == [
            "01_kinematics.ipynb", "02_laser_offset.ipynb", "README.md"]
        status, model = h.api.request("GET", f"/user/{c}/api/contents/annslam/01_kinematics.ipynb")
        assert model["content"]["cells"][-1]["source"] == "my own note on the axle speed"
    except Exception:
        s.shot("nbgitpuller")
        raise
    finally:
        s.close()
        browser.close()
        pw.stop()
        server.__exit__()
        shutil.rmtree(served, ignore_errors=True)


RUN_ALL = """
import os, time, nbformat, nbclient
nb = nbformat.read(os.path.expanduser('~/course/01_kinematics.ipynb'), as_version=4)
t0 = time.monotonic()
nbclient.NotebookClient(nb, timeout=300, allow_errors=True).execute()
print(round(time.monotonic() - t0, 2))
"""

FORK_BOMB = """
import os, time
kids = []
try:
    while len(kids) < 5000:
        pid = os.fork()
        if pid == 0:
            time.sleep(30)
            os._exit(0)
        kids.append(pid)
except OSError as e:
    print("stopped at", len(kids), type(e).__name__)
for k in kids:
    os.kill(k, 9)
for k in kids:
    os.waitpid(k, 0)
"""


def test_a_runaway_kernel_is_stopped_at_its_limits_and_another_students_run_all_goes_on(class_hub):
    """Student a's kernel hoards memory past the hub's 1.5 GiB, then forks without end; at
    the same time student b runs chapter 01 (Run All in a kernel of b's server). The hog's
    kernel is killed and restarted, the fork bomb stops at the process limit, and b's Run
    All completes, timed beside the runaway and alone (both printed)."""
    import threading

    import websocket
    from annslam_lib.course.hub import limits

    silent = (TimeoutError, websocket.WebSocketTimeoutException)

    h, (a, b, _) = class_hub
    h.api.start_server(a)
    h.api.start_server(b)
    alone = h.api.run(b, RUN_ALL, deadline=300)
    assert alone.error is None, alone
    beside = {}
    runner = threading.Thread(target=lambda: beside.update(r=h.api.run(b, RUN_ALL, 300)))
    with h.api.kernel(a) as k:
        before = k.execute("import os; print(os.getpid())").stdout.strip()
        runner.start()
        with pytest.raises(silent):                  # no reply: the kernel was killed
            k.execute("x = b'x' * (3 * 1024**3)", deadline=25)
        after = None
        for _ in range(60):                          # the server restarts it
            try:
                after = k.execute("import os; print(os.getpid())", deadline=5).stdout.strip()
                break
            except silent:
                continue
        assert after and after != before
        bomb = k.execute(FORK_BOMB, deadline=120)
    runner.join(timeout=300)
    words = bomb.stdout.split()
    assert words[:2] == ["stopped", "at"], bomb
    assert int(words[2]) < limits.DEFAULTS.processes
    assert beside["r"].error is None, beside["r"]
    t_alone, t_beside = (float(r.stdout.split()[-1]) for r in (alone, beside["r"]))
    print(f"runaway kernel: killed past 1.5 GiB and restarted (pid {before} -> {after}); fork "
          f"bomb stopped at {words[2]} processes ({words[3]}); the other student's Run All of "
          f"chapter 01: {t_alone:.1f} s alone, {t_beside:.1f} s beside the runaway")
    assert t_beside < 3 * t_alone + 10


def test_the_idle_culler_stops_a_server_idle_past_its_timeout_and_keeps_a_fresh_one(class_hub):
    """The hub's idle-culler service, its command as the hub runs it but with a timeout of
    seconds, against this hub: a server idle for longer is stopped, one started since is
    kept, and the student stays. The last test of the module: it stops idle servers."""
    from datetime import datetime, timezone

    from annslam_lib.course.hub.config import idle_culler

    h, (a, b, c) = class_hub

    def server(name):
        status, user = h.api.request("GET", f"/hub/api/users/{name}")
        return (user or {}).get("servers", {}).get("") if status == 200 else None

    def idle_for(name):
        stamp = datetime.fromisoformat(server(name)["last_activity"].replace("Z", "+00:00"))
        return (datetime.now(timezone.utc) - stamp).total_seconds()

    for name in (a, b, c):                       # fresh servers: no activity of earlier tests
        h.api.stop_server(name)
    h.api.start_server(a)
    time.sleep(10)
    h.api.start_server(b)
    ages = {n: idle_for(n) for n in (a, b)}
    assert ages[a] - ages[b] >= 8, ages
    timeout = round((ages[a] + ages[b]) / 2)
    command = idle_culler(sys.executable, timeout=timeout, every=600)["command"]
    env = dict(os.environ, JUPYTERHUB_API_TOKEN=h.token, JUPYTERHUB_API_URL=f"{h.url}/hub/api")
    culler = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True)
    try:
        end = time.monotonic() + 30
        while server(a) and time.monotonic() < end:
            time.sleep(0.5)
        assert not server(a), f"the server idle for {ages[a]:.0f} s was not stopped in 30 s"
        assert server(b)                         # idle for less than the timeout
    finally:
        culler.terminate()
        log = culler.communicate(timeout=20)[0]
    culled = [line for line in log.splitlines() if "Culling server" in line]
    assert len(culled) == 1 and a in culled[0], log[-2000:]
    assert h.api.request("GET", f"/hub/api/users/{a}")[0] == 200      # only the server stopped
