"""The class hub's parts that need no running hub: the class file, the students'
Unix accounts, each role's Jupyter configuration, JupyterHub's settings, the passwords, the
student environment's pins, and a student's folder filled from the release as that student.
The hub itself, started for real, is tested in tests/test_hub.py."""
from __future__ import annotations

import grp
import json
import os
import pwd
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from traitlets.config import Config

from annslam_lib.course import hub, release, workspace
from annslam_lib.course.hub import config as hub_config
from annslam_lib.course.hub import setup as hub_setup

ROOT = Path(__file__).resolve().parents[1]
COURSE = sorted((ROOT / "notebooks").glob("*.ipynb"))
root_only = pytest.mark.skipif(os.geteuid() != 0, reason="creates Unix accounts: needs root")


def _reqs(name: str) -> dict[str, str]:
    out = {}
    for line in (ROOT / name).read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            req, _, marker = line.partition(";")
            pkg, _, version = req.strip().partition("==")
            out[pkg.lower() + (f";{marker.strip()}" if marker else "")] = version
    return out


# -- the class file -------------------------------------------------------------------------

def test_a_class_file_gives_its_names_without_comments_or_blank_lines(tmp_path):
    f = tmp_path / "class.txt"
    f.write_text("# lab group A\nalice\n\n  bob   # second row\ncarol_2\nd-e\n")
    assert hub.read_class(f) == ["alice", "bob", "carol_2", "d-e"]


@pytest.mark.parametrize("text, says", [
    ("alice\nAlice\n", "line 2: 'Alice' is not a user name"),
    ("alice\nbob smith\n", "line 2: 'bob smith'"),
    ("alice\n../etc\n", "line 2: '../etc'"),
    ("alice\n1bob\n", "line 2: '1bob'"),
    ("x" * 32 + "\n", "line 1"),
    ("alice\nbob\nalice\n", "line 3: 'alice' is already on line 1"),
    ("alice\ninstructor\n", "line 2: 'instructor' is the instructor's account"),
    ("# nobody\n\n", "names no student"),
])
def test_a_bad_class_file_is_refused_with_its_line(tmp_path, text, says):
    f = tmp_path / "class.txt"
    f.write_text(text)
    with pytest.raises(hub.HubError, match=None) as e:
        hub.read_class(f)
    assert says in str(e.value)


def test_an_unreadable_class_file_is_named(tmp_path):
    with pytest.raises(hub.HubError, match="cannot read the class file"):
        hub.read_class(tmp_path / "missing.txt")
    (tmp_path / "bin.txt").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(hub.HubError, match="cannot read the class file"):
        hub.read_class(tmp_path / "bin.txt")


# -- accounts -------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["root", "daemon", "nobody"])
def test_an_account_the_course_did_not_make_is_refused(name):
    with pytest.raises(hub.HubError, match="did not create"):
        hub.account_status(name)


@root_only
def test_a_student_account_is_made_once_private_and_marked():
    name = f"annslamt{os.getpid() % 100000}"
    try:
        assert hub.account_status(name) == "missing"
        entry = hub.ensure_account(name)
        assert entry.pw_gecos.split(",")[0] == hub.MARK
        assert os.stat(entry.pw_dir).st_mode & 0o777 == 0o700
        assert os.stat(entry.pw_dir).st_uid == entry.pw_uid
        os.chmod(entry.pw_dir, 0o755)                    # opened by hand: closed again
        again = hub.ensure_account(name)
        assert again.pw_uid == entry.pw_uid and hub.account_status(name) == "course"
        assert os.stat(entry.pw_dir).st_mode & 0o777 == 0o700
    finally:
        subprocess.run(["userdel", "--remove", name], capture_output=True)
    with pytest.raises(KeyError):
        pwd.getpwnam(name)


@root_only
def test_the_course_folder_goes_to_the_instructors_account_only(tmp_path):
    layout = hub.HubLayout(tmp_path / "hub")
    (layout.course / "submitted" / "alice").mkdir(parents=True)
    (layout.course / "submitted" / "alice" / "x.ipynb").write_text("{}")
    os.chmod(layout.course, 0o755)
    assert hub.give_course(layout, "root") is False            # not an account of the course
    assert hub.give_course(layout, f"nobody{os.getpid() % 1000}x") is False      # missing
    name = f"annslami{os.getpid() % 100000}"
    try:
        entry = hub.ensure_account(name)
        assert hub.give_course(layout, name) is True
        assert layout.course.stat().st_mode & 0o777 == 0o700
        assert {p.stat().st_uid for p in [layout.course, *layout.course.rglob("*")]} == {
            entry.pw_uid}
    finally:
        subprocess.run(["userdel", "--remove", name], capture_output=True)


# -- each role's configuration --------------------------------------------------------------

def test_students_get_the_exchange_but_not_formgrader_or_assignment_creation(tmp_path):
    layout = hub.HubLayout(tmp_path)
    st = hub.write_role_config(layout, "student")
    ins = hub.write_role_config(layout, "instructor")
    server = json.loads((st / "jupyter_server_config.json").read_text())
    off = server["ServerApp"]["jpserver_extensions"]
    assert off == {"nbgrader.server_extensions.formgrader": False,
                   "nbgrader.server_extensions.course_list": False}
    lab = json.loads((st / "labconfig" / "page_config.json").read_text())["disabledExtensions"]
    assert set(lab) == {"@jupyter/nbgrader:formgrader", "@jupyter/nbgrader:create-assignment",
                        "@jupyter/nbgrader:course-list"}
    assert json.loads((ins / "labconfig" / "page_config.json").read_text()) == {
        "disabledExtensions": {}}
    # nbgrader reads these files itself: its own loader, not ours
    cfg = {}
    for role, folder in [("student", st), ("instructor", ins)]:
        c = Config()
        exec((folder / "nbgrader_config.py").read_text(), {"get_config": lambda c=c: c})
        cfg[role] = c
        assert c.Exchange.root == str(tmp_path / "exchange")
        assert c.CourseDirectory.course_id == hub.COURSE_ID
    assert cfg["instructor"].CourseDirectory.root == str(tmp_path / "course")
    assert "root" not in cfg["student"].CourseDirectory
    for p in [st, *st.rglob("*")]:
        assert p.stat().st_mode & 0o777 == (0o755 if p.is_dir() else 0o644)


def test_the_lab_plugins_switched_off_exist_in_nbgrader():
    """A misspelt plugin id would switch nothing off: the ids must be nbgrader's own."""
    ext = Path(sys.prefix) / "share" / "jupyter" / "labextensions" / "@jupyter" / "nbgrader"
    if not ext.exists():
        pytest.skip("nbgrader is not installed here (environment-instructor.txt)")
    shipped = "".join(p.read_text(errors="ignore") for p in (ext / "static").glob("*.js"))
    for plugin in hub.STUDENT_DISABLED["lab"]:
        assert f'"{plugin}"' in shipped
    import importlib
    for module in hub.STUDENT_DISABLED["server"]:
        importlib.import_module(module)


def test_a_server_has_one_blas_thread_the_shared_data_and_its_role(tmp_path):
    layout = hub.HubLayout(tmp_path)
    env = hub.server_env(layout, "student")
    assert env["PATH"].split(":")[0] == str(tmp_path / "student-env" / "bin")
    assert env["ANNSLAM_DATA"] == str(tmp_path / "data")
    assert env["JUPYTER_CONFIG_DIR"] == str(tmp_path / "etc" / "student")
    assert env["OMP_NUM_THREADS"] == env["OPENBLAS_NUM_THREADS"] == "1"
    assert env["ANNSLAM_CLASS_CACHE"] == str(tmp_path / "studies")


def test_the_class_studies_are_computed_once_by_the_students_environment(tmp_path, monkeypatch,
                                                                         capsys):
    """hub_setup.warm_class_studies: a Run All of the chapters by the students' interpreter
    with a student server's settings fills the class folder, opened read-only to all; a
    student's process with those settings reads its entry; a second set-up reruns nothing,
    and one after a notebook changed runs again."""
    from annslam_lib import _cache
    from annslam_lib.data import simulate
    from annslam_lib.slam import runner

    layout = hub.HubLayout(tmp_path / "hub")
    chapters = tmp_path / "notebooks"
    for folder in (layout.env / "bin", layout.state, layout.studies, chapters):
        folder.mkdir(parents=True)
    python = layout.env / "bin" / "python"           # the students' interpreter, here this one
    python.write_text(f"#!/bin/sh\nexec {sys.executable} \"$@\"\n")
    python.chmod(0o755)
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(
        "from annslam_lib.data import simulate\nfrom annslam_lib.slam import runner\n"
        "r = runner.run_cached(simulate.simulate(seed=0, laps=1))"),
        nbformat.v4.new_code_cell("raise NotImplementedError('an exercise')")]
    nbformat.write(nb, chapters / "05_small.ipynb")
    hub_setup.warm_class_studies(layout, chapters)
    entries = sorted(layout.studies.glob("*.pkl"))
    assert [p.name.split("-")[0] for p in entries] == ["run_cached"]
    assert (layout.studies / ".sha256-of-inputs").exists()
    assert layout.studies.stat().st_mode & 0o777 == 0o755
    assert {p.stat().st_mode & 0o777 for p in layout.studies.iterdir()} == {0o644}
    # a student's process: its own cache empty, the server's environment
    for k, v in hub.server_env(layout, "student").items():
        if k != "PATH":
            monkeypatch.setenv(k, v)
    monkeypatch.setenv("ANNSLAM_CACHE", str(tmp_path / "own"))
    monkeypatch.setattr(_cache, "STATS", dict.fromkeys(_cache.STATS, 0))
    runner.run_cached(simulate.simulate(seed=0, laps=1))
    assert _cache.STATS["class_hits"] == 1 and _cache.STATS["misses"] == 0
    capsys.readouterr()
    hub_setup.warm_class_studies(layout, chapters)
    assert "class studies: up to date" in capsys.readouterr().out
    assert sorted(layout.studies.glob("*.pkl")) == entries
    nb.cells.append(nbformat.v4.new_code_cell("print('a changed chapter')"))
    nbformat.write(nb, chapters / "05_small.ipynb")
    hub_setup.warm_class_studies(layout, chapters)      # a changed notebook: computed again
    assert "Run All of the notebooks" in capsys.readouterr().out


# -- JupyterHub's settings ------------------------------------------------------------------

def _configured(tmp_path, **extra) -> Config:
    f = tmp_path / "class.txt"
    f.write_text("alice\nbob\n")
    c = Config()
    hub_config.configure(c, {"ANNSLAM_HUB_DIR": str(tmp_path), "ANNSLAM_HUB_CLASS": str(f),
                             "ANNSLAM_HUB_PORT": "8123", "ANNSLAM_HUB_PASSWORD": "p" * 8,
                             "ANNSLAM_HUB_INSTRUCTOR_PASSWORD": "i" * 32, **extra})
    return c


def test_the_hub_listens_on_loopback_and_lets_in_only_the_class(tmp_path):
    c = _configured(tmp_path)
    assert (c.JupyterHub.ip, c.JupyterHub.port, c.JupyterHub.hub_ip) == ("127.0.0.1", 8123,
                                                                         "127.0.0.1")
    assert c.JupyterHub.hub_port == 8124
    assert c.ConfigurableHTTPProxy.api_url == "http://127.0.0.1:8125"
    assert c.Authenticator.allowed_users == {"alice", "bob"}
    assert c.Authenticator.admin_users == {"instructor"}
    assert c.JupyterHub.authenticator_class == "shared-password"
    from jupyterhub.spawner import LocalProcessSpawner

    assert issubclass(c.JupyterHub.spawner_class, LocalProcessSpawner)
    assert c.JupyterHub.spawner_class.__name__ == "LimitedSpawner"       # limits enforced
    assert (c.Spawner.mem_limit, c.Spawner.cpu_limit) == (1536 * 1024**2, 1.0)
    assert c.Spawner.cmd[:4] == [str(tmp_path / "student-env" / "bin" / "python"), "-m",
                                 "annslam_lib", "singleuser"]
    assert str(tmp_path / "state") in c.JupyterHub.db_url
    assert c.Spawner.env_keep == ["LANG", "LC_ALL"]       # no PYTHONPATH of the hub's
    # no admin service without its token; the idle culler with its role, always
    assert [svc["name"] for svc in c.JupyterHub.services] == ["idle-culler"]
    assert c.JupyterHub.services[0]["command"][1:] == [
        "-m", "jupyterhub_idle_culler", "--timeout=3600", "--cull-every=300"]
    assert c.JupyterHub.load_roles == [{"name": "idle-culler", "services": ["idle-culler"],
                                        "scopes": hub_config.IDLE_SCOPES}]
    hub_config.check_spawner(c)


def test_an_lti_settings_file_switches_the_login_to_the_lms(tmp_path):
    pytest.importorskip("ltiauthenticator", reason="jupyterhub-ltiauthenticator "
                        "(environment-hub.txt) is not installed")
    lti = tmp_path / "lti.toml"
    lti.write_text('issuer = "https://lms.example"\nclient_id = "42"\n'
                   'deployment_id = "d1"\nauthorize_url = "https://lms.example/auth"\n'
                   'jwks_url = "https://lms.example/jwks"\ncourse = "c9"\n')
    c = _configured(tmp_path, ANNSLAM_HUB_LTI=str(lti))
    assert c.JupyterHub.authenticator_class.__name__ == "CourseLTIAuthenticator"
    a = c.CourseLTIAuthenticator
    assert (a.issuer, a.client_id, a.jwks_endpoint, a.username_key) == (
        "https://lms.example", {"42"}, "https://lms.example/jwks", "email")
    assert "SharedPasswordAuthenticator" not in c                 # no password login at all
    assert c.Authenticator.allowed_users == {"alice", "bob"}


def test_an_admin_token_becomes_a_service_with_admin_scopes(tmp_path):
    c = _configured(tmp_path, ANNSLAM_HUB_ADMIN_TOKEN="t" * 40)
    assert c.JupyterHub.services[1] == {"name": "course-admin", "api_token": "t" * 40}
    scopes = c.JupyterHub.load_roles[1]["scopes"]
    assert {"admin:users", "admin:servers", "access:servers"} <= set(scopes)


@pytest.mark.parametrize("spawner", ["simple", "jupyterhub.spawner.SimpleLocalProcessSpawner"])
def test_a_spawner_without_isolation_is_refused(tmp_path, spawner):
    c = _configured(tmp_path)
    c.JupyterHub.spawner_class = spawner
    with pytest.raises(hub.HubError, match="any student could read"):
        hub_config.check_spawner(c)


def test_the_config_file_is_refused_without_a_class(tmp_path):
    with pytest.raises(hub.HubError, match="ANNSLAM_HUB_CLASS"):
        hub_config.configure(Config(), {"ANNSLAM_HUB_DIR": str(tmp_path)})


@pytest.mark.parametrize("student, instructor, says", [
    ("", "i" * 32, "ANNSLAM_HUB_PASSWORD"),
    ("short", "i" * 32, "8 characters"),
    ("p" * 8, "i" * 31, "32 characters"),
    ("p" * 40, "p" * 40, "must differ"),
])
def test_weak_or_missing_passwords_are_refused(tmp_path, student, instructor, says):
    layout = hub.HubLayout(tmp_path)
    layout.state.mkdir()
    with pytest.raises(hub.HubError, match=says):
        hub_setup.passwords(layout, {"ANNSLAM_HUB_PASSWORD": student,
                                     "ANNSLAM_HUB_INSTRUCTOR_PASSWORD": instructor})


def test_an_instructor_password_is_made_once_and_kept_private(tmp_path):
    layout = hub.HubLayout(tmp_path)
    layout.state.mkdir()
    first = hub_setup.passwords(layout, {"ANNSLAM_HUB_PASSWORD": "p" * 8})
    again = hub_setup.passwords(layout, {"ANNSLAM_HUB_PASSWORD": "p" * 8})
    assert first == again and len(first["ANNSLAM_HUB_INSTRUCTOR_PASSWORD"]) >= 32
    assert (layout.state / "instructor-password").stat().st_mode & 0o777 == 0o600


def test_the_hub_refuses_to_start_twice_and_says_where(tmp_path):
    import http.server
    import threading

    class Api(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200 if self.path == "/hub/api" else 404)
            self.end_headers()

        def log_message(self, *a):
            pass

    srv = http.server.HTTPServer(("127.0.0.1", 0), Api)
    threading.Thread(target=srv.serve_forever, daemon=True).start()
    try:
        layout = hub.HubLayout(tmp_path)
        layout.state.mkdir()
        url = f"http://127.0.0.1:{srv.server_port}"
        (layout.state / "hub.json").write_text(json.dumps({"pid": os.getpid(), "url": url}))
        assert hub.running_hub(layout) == url
        f = tmp_path / "class.txt"
        f.write_text("alice\n")
        if os.geteuid() == 0:
            with pytest.raises(hub.HubError, match=f"already running from {tmp_path} at {url}"):
                hub_setup.prepare(layout, f)
        (layout.state / "hub.json").write_text(json.dumps({"pid": 2 ** 22 + 7, "url": url}))
        assert hub.running_hub(layout) is None          # its process is gone
    finally:
        srv.shutdown()


# -- the students' environment --------------------------------------------------------------

def test_the_student_environment_is_pinned_like_the_course_without_test_tools():
    student, course, hubreq = (_reqs("environment-student.txt"), _reqs("environment.txt"),
                               _reqs("environment-hub.txt"))
    assert all(v for v in student.values()), "every requirement pinned with =="
    for pkg, version in student.items():
        if pkg in course:
            assert version == course[pkg], pkg
    for tool in ("pytest", "pytest-xdist", "nbval", "hypothesis", "ruff", "playwright",
                 "pytest-timeout", "evo"):
        if tool == "pytest" and "gtsam" in student:
            # not a test tool here: gtsam's wheel requires it (chapter 10), pinned as the course's
            from importlib import metadata
            assert any(r.startswith("pytest") for r in metadata.requires("gtsam") or [])
            assert student["pytest"] == course["pytest"]
            continue
        assert tool not in student
    assert student["jupyterhub"] == hubreq["jupyterhub"]
    assert student["nbgrader"] == _reqs("environment-instructor.txt")["nbgrader"]
    for pkg in ("jupyterlab", "ipykernel", "ipywidgets", "numpy", "scipy", "matplotlib",
                "numba", "llvmlite", 'torch;sys_platform == "linux"'):
        assert pkg in student, pkg
    assert "-e ." not in (ROOT / "environment-student.txt").read_text()


# -- a student's folder, filled as that student ---------------------------------------------

def test_released_versions_are_copied_once_and_the_students_work_is_kept(tmp_path):
    rel = tmp_path / "release"
    release.release(COURSE[:3], rel)
    books = sorted(rel.glob("*.ipynb"))
    mine = tmp_path / "home" / "course"
    r = workspace.sync(mine, books, released=True)
    assert sorted(r.added) == [p.name for p in books]
    for p in books:
        assert nbformat.read(mine / p.name, 4) == nbformat.read(p, 4)
    edited = mine / books[0].name
    edited.write_text(edited.read_text() + " ")
    r2 = workspace.sync(mine, books, released=True)
    assert r2.kept == [books[0].name] and sorted(r2.unchanged) == [p.name for p in books[1:]]
    assert edited.read_text().endswith(" ")


def test_an_instructor_notebook_in_the_release_folder_is_never_copied(tmp_path):
    rel = tmp_path / "release"
    rel.mkdir()
    (rel / COURSE[1].name).write_bytes(COURSE[1].read_bytes())    # solutions inside
    with pytest.raises(ValueError, match="not a student version"):
        workspace.sync(tmp_path / "me", [rel / COURSE[1].name], released=True)
    assert not (tmp_path / "me" / COURSE[1].name).exists()


def test_world_runnable_sees_a_private_folder_on_the_way(tmp_path):
    private = tmp_path / "private"
    private.mkdir()
    exe = private / "python"
    exe.write_text("#!/bin/sh\n")
    os.chmod(exe, 0o755)
    os.chmod(tmp_path, 0o755)
    os.chmod(private, 0o700)
    assert not hub._world_runnable(exe) and not hub.reachable_by_others(private)
    os.chmod(private, 0o755)
    assert hub._world_runnable(exe) == all(
        p.stat().st_mode & 0o001 for p in tmp_path.resolve().parents)
    os.chmod(exe, 0o744)
    assert not hub._world_runnable(exe)


def test_group_of_a_new_account_is_its_own(tmp_path):
    """useradd's default user group: no student shares a group with another."""
    if os.geteuid() != 0:
        pytest.skip("creates Unix accounts: needs root")
    names = [f"annslamg{os.getpid() % 10000}{i}" for i in range(2)]
    try:
        entries = [hub.ensure_account(n) for n in names]
        groups = [grp.getgrgid(e.pw_gid).gr_name for e in entries]
        assert groups == names
    finally:
        for n in names:
            subprocess.run(["userdel", "--remove", n], capture_output=True)


def test_the_hub_refuses_to_open_the_instructors_notebooks_to_students(tmp_path):
    if not hub.reachable_by_others(ROOT / "notebooks"):
        pytest.skip("this checkout's notebooks are already closed to other users")
    f = tmp_path / "class.txt"
    f.write_text("alice\n")
    with pytest.raises(hub.HubError, match="could read the instructor's notebooks") as e:
        hub_setup.start(hub.HubLayout(tmp_path / "hub"), f)
    assert f"chmod o-rwx {ROOT / 'notebooks'}" in str(e.value)
    assert not (tmp_path / "hub").exists()              # refused before anything was made


def test_only_root_may_prepare_a_hub(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "geteuid", lambda: 1000)
    with pytest.raises(hub.HubError, match="start it as root"):
        hub_setup.prepare(hub.HubLayout(tmp_path), tmp_path / "class.txt")


# -- the instructor's grade step ------------------------------------------------------------

def test_a_submission_that_breaks_grading_gets_its_reason_and_the_others_are_graded(tmp_path):
    """``class grade`` over a good and a corrupt submission: the corrupt one is named with
    its reason, the good one scored, and each gets its feedback page."""
    from annslam_lib.course.hub import classroom as hub_class

    chapter = "01_kinematics"
    layout = hub.HubLayout(tmp_path / "hub")
    nb = nbformat.read(release.release([ROOT / "notebooks" / f"{chapter}.ipynb"],
                                       tmp_path / "rel")[0], as_version=4)
    instructor = nbformat.read(ROOT / "notebooks" / f"{chapter}.ipynb", as_version=4)
    for cell, theirs in zip(nb.cells, instructor.cells):
        if cell.metadata.get("nbgrader", {}).get("grade_id") == "ex01-axle-speed":
            cell.source = theirs.source                       # the solution, markers and all
    for student, text in [("alice", nbformat.writes(nb)), ("mallory", '{"cells": [')]:
        sub = layout.course / "submitted" / student / chapter / f"{chapter}.ipynb"
        sub.parent.mkdir(parents=True)
        sub.write_text(text)
    grades = {g.student: g for g in hub_class.grade(layout, chapter, log=lambda *a: None)}
    assert grades["alice"].graded and grades["alice"].score == 2 and grades["alice"].max_score == 7
    assert not grades["mallory"].graded and "notebook" in grades["mallory"].reason.lower()
    alice = (layout.course / "feedback/alice" / chapter / f"{chapter}.html").read_text()
    mallory = (layout.course / "feedback/mallory" / chapter / f"{chapter}.html").read_text()
    assert "Score: 2 / 7" in alice and "Not graded" in mallory
    stored = json.loads((layout.course / "grades" / f"{chapter}.json").read_text())
    assert sorted(g["student"] for g in stored) == ["alice", "mallory"]
    assert (layout.course / "grades").stat().st_mode & 0o777 == 0o700


def test_a_feedback_page_escapes_what_the_student_wrote():
    from annslam_lib.course.grader import ExerciseResult, SubmissionGrade
    from annslam_lib.course.hub.classroom import feedback_page

    evil = "<script>alert(1)</script>"
    g = SubmissionGrade("x.ipynb", "01_kinematics.ipynb", f"bob{evil}", "01_kinematics", 0, 2,
                        [ExerciseResult("ex01-axle-speed", 0, 2, "failed", evil)],
                        errors=[evil])
    page = feedback_page(g)
    assert "<script>" not in page and page.count("&lt;script&gt;") == 3


def test_a_feedback_page_names_its_language_and_its_table_headers():
    """What a screen reader needs from the page (WCAG 2.1 3.1.1 language of page, 1.3.1
    table headers): a lang attribute, a table caption, column headers marked as such."""
    from html.parser import HTMLParser

    from annslam_lib.course.grader import ExerciseResult, SubmissionGrade
    from annslam_lib.course.hub.classroom import feedback_page

    g = SubmissionGrade("x.ipynb", "01_kinematics.ipynb", "ann", "01_kinematics", 2, 4,
                        [ExerciseResult("ex01-axle-speed", 2, 2, "passed", "ok"),
                         ExerciseResult("ex01-heading", 0, 2, "failed", "sign")])
    seen: dict = {"html": [], "th": [], "caption": 0, "td": 0}

    class Tags(HTMLParser):
        def handle_starttag(self, tag, attrs):
            if tag in ("html", "th"):
                seen[tag].append(dict(attrs))
            elif tag in ("caption", "td"):
                seen[tag] += 1

    Tags().feed(feedback_page(g))
    assert seen["html"] == [{"lang": "en"}]
    assert [a.get("scope") for a in seen["th"]] == ["col"] * 4
    assert seen["caption"] == 1 and seen["td"] == 8


def test_class_add_and_drop_edit_the_class_file_the_hub_started_with(tmp_path):
    """Without a running hub: the class file changes, each refusal says why."""
    from annslam_lib.course.hub import roster

    layout = hub.HubLayout(tmp_path)
    layout.state.mkdir()
    f = tmp_path / "class.txt"
    f.write_text("alice\n# a comment\nbob")
    with pytest.raises(hub.HubError, match="no class file is known"):
        roster.add(layout, "carol")
    (layout.state / "hub.json").write_text(json.dumps({"pid": 0, "url": "", "class": str(f)}))
    assert "can log in once the hub runs" in roster.add(layout, "carol")
    assert hub.read_class(f) == ["alice", "bob", "carol"]
    for name, words in [("bob", "already in the class"), ("instructor", "instructor"),
                        ("Bob!", "not a user name")]:
        with pytest.raises(hub.HubError, match=words):
            roster.add(layout, name)
    assert "they had no account yet" in roster.drop(layout, "bob")
    assert hub.read_class(f) == ["alice", "carol"]
    assert "# dropped: bob" in f.read_text().splitlines()
    assert "already dropped: finished again" in roster.drop(layout, "bob")   # idempotent
    assert f.read_text().count("# dropped: bob") == 1
    with pytest.raises(hub.HubError, match="is not in the class"):
        roster.drop(layout, "dave")
    with pytest.raises(hub.HubError, match="not a user name"):
        roster.add(layout, "eve\n")                         # a trailing newline is no name
    roster.add(layout, "bob")
    assert hub.read_class(f) == ["alice", "carol", "bob"]


def test_the_class_file_decides_every_login_and_server_start(tmp_path, monkeypatch):
    """A login (post_auth_hook) or a server start (pre_spawn) of a name the class file no
    longer lists is refused, whatever JupyterHub's database still holds."""
    from types import SimpleNamespace

    f = tmp_path / "class.txt"
    f.write_text("alice\n# dropped: bob\n")
    monkeypatch.setenv("ANNSLAM_HUB_CLASS", str(f))
    monkeypatch.setenv("ANNSLAM_HUB_INSTRUCTOR", "teacher")
    assert hub_config.class_gate(None, None, {"name": "alice"}) == {"name": "alice"}
    assert hub_config.class_gate(None, None, {"name": "teacher"}) == {"name": "teacher"}
    assert hub_config.class_gate(None, None, {"name": "bob"}) is None
    with pytest.raises(hub.HubError, match="'bob' is not in the class"):
        hub_config.pre_spawn(SimpleNamespace(user=SimpleNamespace(name="bob")))
    c = _configured(tmp_path)
    assert c.Authenticator.post_auth_hook is hub_config.class_gate
