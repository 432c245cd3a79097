"""The grader on an ordinary machine: the course anywhere (a clone under /tmp too), and a
broken grading environment reported as the machine's fault, never as a student's zero.

bubblewrap puts an empty tmpfs on /tmp. A course cloned into a temporary folder, or a venv
there, used to vanish from the student's kernel: every exercise of every submission scored 0
("the cell that defines my_observe failed ... it did not run"). The sandbox now binds the
interpreter (its prefixes and every link to the real binary), the library snapshot and the
data back, read-only, wherever they lie; and a kernel that cannot start, or cannot import
the library before any student code ran, stops the grade command with exit code 3 and the
cause.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

import pytest

from annslam_lib.course import grader, sandbox
from annslam_lib.course.grader import GradingEnvironmentError, grade_batch
from annslam_lib.course.sandbox import Limits, Sandbox, bwrap_available

import grading_support as gs

ROOT = Path(__file__).resolve().parents[1]
LIMITS = Limits(cell_timeout=20.0, call_timeout=10.0, deadline=90.0)
FULL = sum(gs.POINTS.values())
needs_bwrap = pytest.mark.skipif(bwrap_available() is None,
                                 reason=f"bubblewrap cannot be used here: {sandbox.bwrap_problem()}")


def _env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "COLUMNS")}
    env.update(extra)
    return env


@pytest.fixture
def hidden_course():
    """A copy of the course's library and a virtual environment, both under /tmp (which
    bubblewrap hides), as a clone in a temporary folder has them. The venv's python links
    to the base interpreter and reaches the packages of the course's own venv through a
    .pth line; the library copy comes first on PYTHONPATH."""
    root = Path(tempfile.mkdtemp(prefix="annslam-clone-", dir="/tmp"))
    try:
        shutil.copytree(ROOT / "annslam_lib", root / "course" / "annslam_lib",
                        ignore=shutil.ignore_patterns("__pycache__"))
        subprocess.run([sys._base_executable, "-m", "venv", "--without-pip",
                        str(root / "venv")], check=True, timeout=120)
        py = root / "venv" / "bin" / "python"
        site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()"
                               "['purelib'])"], capture_output=True, text=True, check=True,
                              timeout=60).stdout.strip()
        Path(site, "course_packages.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
        yield root, py
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _grade_cli(py: Path, course: Path, sub: Path, instructor: Path, out: Path, *extra,
               env=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(py), "-m", "annslam_lib", "grade", str(sub), "--instructor", str(instructor),
         "--json", str(out), "--timeout", "20", "--deadline", "90", *extra],
        capture_output=True, text=True, timeout=400, cwd=str(course),
        env=env or _env(PYTHONPATH=str(course)))


@needs_bwrap
def test_a_course_under_tmp_grades_an_honest_submission_in_full(hidden_course, tmp_path):
    root, py = hidden_course
    course = root / "course"
    probe = subprocess.run([str(py), "-c", "import sys, annslam_lib; print(sys.prefix); "
                            "print(annslam_lib.__file__)"], capture_output=True, text=True,
                           env=_env(PYTHONPATH=str(course)), check=True, timeout=60,
                           cwd=str(course))
    prefix, lib = probe.stdout.split()
    assert prefix.startswith("/tmp/") and lib.startswith(str(course)), probe.stdout
    inst = root / "instructor" / "chapter.ipynb"      # under /tmp as well
    gs.write(gs.instructor(), inst)
    sub = tmp_path / "submitted" / "alice" / "chapter" / "chapter.ipynb"
    gs.write(gs.honest(), sub)
    gs.write(gs.submission(), tmp_path / "submitted" / "bob" / "chapter" / "chapter.ipynb")
    out = tmp_path / "grades.json"
    r = _grade_cli(py, course, tmp_path / "submitted", inst.parent, out, "--isolation", "bwrap")
    assert r.returncode == 0, r.stdout + r.stderr
    rows = {row["student"]: row for row in json.loads(out.read_text())}
    assert rows["alice"]["isolation"] == "bwrap"
    assert rows["alice"]["score"] == FULL == rows["alice"]["max_score"], rows["alice"]
    assert rows["bob"]["score"] == 0 and all(e["status"] == "not written"
                                             for e in rows["bob"]["exercises"])


def test_the_mount_plan_binds_what_is_needed_and_leaves_hidden_folders_out(tmp_path):
    """The sandbox's file system, read without running it (sandbox.mount_plan): a needed
    folder holding a hidden one is rebuilt from its other entries (the hidden one is not
    there at all, not covered); a needed folder inside a hidden one is bound alone; links
    on the way are recreated as links; memory folders come before the binds inside them;
    optional folders that hold or lie in a hidden one are left out."""
    t = tmp_path
    (t / "env" / "secret").mkdir(parents=True)            # a hidden folder inside the env
    (t / "env" / "secret" / "answers.txt").write_text("x")
    (t / "env" / "bin").mkdir()
    (t / "env" / "readme").write_text("x")
    (t / "env" / "lib").symlink_to("bin")
    (t / "course" / ".venv").mkdir(parents=True)          # the venv inside the hidden checkout
    (t / "course" / "notebooks").mkdir()
    (t / "data").mkdir()
    (t / "link-to-data").symlink_to(t / "data")
    (t / "course" / "tests").mkdir()
    steps = sandbox.mount_plan(
        [t / "env", t / "course" / ".venv", t / "link-to-data"],
        [t / "course", t / "course" / "tests", t / "env" / "bin", t],
        [t / "env" / "secret", t / "course"],
        first=[("tmpfs", t, 1 << 20, "1777")], extra=[("bind", t / "ipc", t / "ipc")])
    binds = [s[2] for s in steps if s[0] in ("ro-bind", "bind")]
    made = [s[-1] if s[0] != "tmpfs" else s[1] for s in steps]
    first_bind = next(k for k, s in enumerate(steps) if s[0] in ("ro-bind", "bind", "symlink"))
    assert ("tmpfs", t, 1 << 20, "1777") in steps[:first_bind]   # before every bind under it
    assert t / "env" / "bin" in binds and t / "env" / "readme" in binds
    assert ("symlink", "bin", t / "env" / "lib") in steps
    for gone in (t / "env" / "secret", t / "course" / "notebooks", t / "course" / "tests",
                 t / "course"):
        assert gone not in binds and not any(p == gone or gone in Path(p).parents
                                              for p in binds if p != t / "course" / ".venv"), gone
    assert t / "course" / ".venv" in binds                  # needed, inside a hidden folder
    assert not any(s[0] == "dir" and s[1] == t / "env" / "secret" for s in steps)
    assert ("symlink", str(t / "data"), t / "link-to-data") in steps and t / "data" in binds
    assert binds[-1] == t / "ipc" and t not in binds        # optional t holds hidden folders
    # every folder on the way to a bind is made (world-readable) before it
    for k, s in enumerate(steps):
        if s[0] in ("ro-bind", "bind"):
            for a in s[2].parents:
                if a != Path("/"):
                    assert a in made[:k] or any(x[0] == "tmpfs" and x[1] == a for x in steps[:k]), (a, s)


def test_the_kernel_sees_the_environment_but_not_the_course(tmp_path):
    """A real kernel: the interpreter's folders and the data are there, the course's checkout
    is not (not even its top folder's other entries), nor a hidden folder."""
    if bwrap_available() is None:
        pytest.skip(f"bubblewrap cannot be used here: {sandbox.bwrap_problem()}")
    from annslam_lib.data import fetch

    hidden = tmp_path / "hidden"
    hidden.mkdir()
    probe = (f"import os, sys\nR = repr(["
             f"os.path.exists({str(ROOT / 'notebooks')!r}), os.path.exists({str(ROOT / '.git')!r}),"
             f"os.path.exists({str(ROOT / 'annslam_lib')!r}), os.path.exists({str(hidden)!r}),"
             f"os.path.isdir(sys.prefix), os.path.isdir({str(fetch.data_dir())!r})])")
    with Sandbox(LIMITS, hide=[hidden]) as sb:
        sb.start()
        res = sb.execute(probe, 60, user_expressions={"r": "R"})
        assert res.ok, res.reason()
        assert res.user_expressions["r"]["data"]["text/plain"] == \
            repr("[False, False, False, False, True, True]")


def test_a_bubblewrap_without_rights_stops_the_grade_command_with_its_reason(tmp_path):
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "bwrap").write_text("#!/bin/sh\necho 'bwrap: setting up uid map: Permission denied'"
                                " >&2\nexit 1\n")
    (fake / "bwrap").chmod(0o755)
    inst = tmp_path / "instructor" / "chapter.ipynb"
    gs.write(gs.instructor(), inst)
    gs.write(gs.honest(), tmp_path / "sub" / "chapter.ipynb")
    out = tmp_path / "g.json"
    r = _grade_cli(Path(sys.executable), ROOT, tmp_path / "sub", inst.parent, out,
                   "--isolation", "bwrap",
                   env=_env(PATH=f"{fake}{os.pathsep}{os.environ['PATH']}"))
    assert r.returncode == 3, r.stdout + r.stderr
    assert "grading environment is broken" in r.stderr
    assert "Permission denied" in r.stderr and "user namespaces" in r.stderr, r.stderr
    assert not out.exists()                             # nobody was given a score


def _broken_library(tmp_path) -> Path:
    lib = tmp_path / "broken" / "annslam_lib"
    shutil.copytree(ROOT / "annslam_lib", lib, ignore=shutil.ignore_patterns("__pycache__"))
    (lib / "course" / "kernel_side.py").write_text(
        "raise ImportError('planted: the install is broken')\n")
    return lib


def test_a_library_that_fails_to_import_in_the_kernel_is_no_student_s_zero(tmp_path,
                                                                            monkeypatch):
    monkeypatch.setattr(sandbox, "LIB", _broken_library(tmp_path))
    inst = tmp_path / "instructor" / "chapter.ipynb"
    gs.write(gs.instructor(), inst)
    gs.write(gs.honest(), tmp_path / "sub" / "alice" / "chapter" / "chapter.ipynb")
    out = tmp_path / "g.json"
    with pytest.raises(GradingEnvironmentError, match="cannot be imported in the grading "
                       "kernel.*planted: the install is broken"):
        grade_batch([tmp_path / "sub"], instructor_dir=inst.parent, json_path=out,
                    limits=LIMITS, log=lambda s: None)
    assert not out.exists()
    # grading one submission directly says the same, instead of scoring it 0
    with pytest.raises(GradingEnvironmentError, match="before any student code ran"):
        grader.grade_submission(tmp_path / "sub" / "alice" / "chapter" / "chapter.ipynb", inst,
                                limits=LIMITS)


@pytest.mark.needs_sandbox
def test_the_grade_command_exits_3_when_the_kernel_cannot_import_the_library(tmp_path):
    lib = _broken_library(tmp_path)
    inst = tmp_path / "instructor" / "chapter.ipynb"
    gs.write(gs.instructor(), inst)
    gs.write(gs.honest(), tmp_path / "sub" / "chapter.ipynb")
    code = ("import sys; from pathlib import Path; import annslam_lib.course.sandbox as s; "
            f"s.LIB = Path({str(lib)!r}); from annslam_lib.course.cli import main; "
            "sys.exit(main(sys.argv[1:]))")
    r = subprocess.run([sys.executable, "-c", code, "grade", str(tmp_path / "sub"),
                        "--instructor", str(inst.parent), "--json", str(tmp_path / "g.json")],
                       capture_output=True, text=True, timeout=300, env=_env())
    assert r.returncode == 3, r.stdout + r.stderr
    assert "planted: the install is broken" in r.stderr
    assert not (tmp_path / "g.json").exists()


def test_a_kernel_that_cannot_start_is_the_environment_s_fault(tmp_path, monkeypatch):
    lib = tmp_path / "broken" / "annslam_lib"
    shutil.copytree(ROOT / "annslam_lib", lib, ignore=shutil.ignore_patterns("__pycache__"))
    (lib / "course" / "confine.py").write_text("import sys\nprint('launcher broken', "
                                               "file=sys.stderr)\nsys.exit(3)\n")
    monkeypatch.setattr(sandbox, "LIB", lib)
    inst = tmp_path / "instructor" / "chapter.ipynb"
    gs.write(gs.instructor(), inst)
    sub = tmp_path / "sub" / "chapter.ipynb"
    gs.write(gs.honest(), sub)
    with pytest.raises(GradingEnvironmentError, match="did not start: it exited with code 3.*"
                       "launcher broken"):
        grader.grade_submission(sub, inst, limits=Limits(cell_timeout=20.0, deadline=60.0))
