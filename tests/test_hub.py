"""The class hub for real (issue 20): ``python -m annslam_lib hub`` started as root for two
students, each server run by JupyterHub's LocalProcessSpawner as the student's own Unix
account, driven over the REST API. What one student's kernel can reach of another's files is
tried from inside the kernel, not only through the file API."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from hub_support import prepared_layout

from annslam_lib.course import hub_setup
from annslam_lib.course.hub_client import launch, remove_accounts

ROOT = hub_setup.ROOT
PRIVATE = [ROOT / "notebooks", ROOT / "tests"]


@pytest.fixture(scope="module")
def class_hub(tmp_path_factory):
    layout = prepared_layout()
    modes = {p: p.stat().st_mode & 0o777 for p in PRIVATE}
    for p in PRIVATE:                 # the hub refuses to open them to students (tested below)
        os.chmod(p, modes[p] & ~0o007)
    names = [f"hubt{os.getpid() % 100000}{c}" for c in "ab"]
    tmp = tmp_path_factory.mktemp("hub")
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
    h, (a, _) = class_hub
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


def test_a_students_kernel_cannot_read_or_change_another_students_files(class_hub):
    h, (a, b) = class_hub
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
        "shared data": f"open(os.path.join(os.environ['ANNSLAM_DATA'], 'x'), 'w')",
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


def test_only_listed_students_log_in_with_the_students_password(class_hub):
    h, (a, _) = class_hub
    pw = h.passwords["ANNSLAM_HUB_PASSWORD"]
    assert h.api.login(a, pw) == 302
    assert h.api.login("mallory", pw) == 403
    assert h.api.login(a, pw + "x") == 403
    assert h.api.login("instructor", pw) == 403                 # the admin needs the admin's
    status, _ = h.api.request("GET", "/hub/api/users/mallory")
    assert status == 404                                    # no account was made for her


def test_formgrader_is_not_served_to_students(class_hub):
    h, (a, _) = class_hub
    h.api.start_server(a)
    assert h.api.request("GET", f"/user/{a}/formgrader")[0] == 404
    status, body = h.api.request("GET", f"/user/{a}/assignments?course_id=annslam")
    assert status == 200, body                              # the Assignments panel is


def test_a_hub_started_twice_says_where_the_running_one_is(class_hub, tmp_path):
    h, (a, _) = class_hub
    f = tmp_path / "class.txt"
    f.write_text(f"{a}\n")
    env = dict(os.environ, ANNSLAM_HUB_DIR=str(h.layout.root), **h.passwords)
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "hub", "--class", str(f),
                          "--port", str(h.port + 10)], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2
    assert f"already running from {h.layout.root} at {h.url}" in out.stderr
    assert json.loads((h.layout.state / "hub.json").read_text())["url"] == h.url
