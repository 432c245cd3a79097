"""The student's own copy of the course (annslam_lib.course.workspace) and `./course.sh lab`:
written once, new chapters added, untouched chapters updated, edited ones never overwritten;
a second `lab` on the same folder says where the open one is instead of starting another."""
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import nbformat
import pytest
from browser_support import start_lab

from annslam_lib.course import release, workspace

ROOT = Path(__file__).resolve().parents[1]
COURSE = sorted((ROOT / "notebooks").glob("*.ipynb"))


def _solution_free(path: Path, instructor: Path) -> bool:
    st = nbformat.read(path, as_version=4)
    return release.leaks(nbformat.read(instructor, as_version=4), st) == []


def test_first_sync_writes_every_student_version_and_a_second_changes_nothing(tmp_path):
    folder = tmp_path / "me"
    r = workspace.sync(folder)
    assert sorted(r.added) == [p.name for p in COURSE] and not (r.updated or r.kept)
    for p in COURSE:
        assert _solution_free(folder / p.name, p)
    manifest = json.loads((folder / workspace.MANIFEST).read_text())
    assert sorted(manifest) == [p.name for p in COURSE]
    before = {p.name: (folder / p.name).read_bytes() for p in COURSE}
    r2 = workspace.sync(folder)
    assert sorted(r2.unchanged) == [p.name for p in COURSE] and not (r2.added or r2.updated)
    assert {p.name: (folder / p.name).read_bytes() for p in COURSE} == before
    assert "9 unchanged" in r2.summary() or f"{len(COURSE)} unchanged" in r2.summary()


def test_a_changed_course_updates_untouched_chapters_and_keeps_edited_ones(tmp_path):
    src = tmp_path / "course"
    src.mkdir()
    for p in COURSE[:3]:
        (src / p.name).write_bytes(p.read_bytes())
    folder = tmp_path / "me"
    workspace.sync(folder, sorted(src.glob("*.ipynb")))
    # the student works in chapter 01 (edits a cell), leaves 00 and 02 alone
    edited = folder / COURSE[1].name
    nb = nbformat.read(edited, as_version=4)
    nb.cells[0].source += "\n\nMy notes: the turning circle."
    nbformat.write(nb, edited)
    mine = edited.read_bytes()
    # the course changes every chapter, and a new chapter appears
    for p in sorted(src.glob("*.ipynb")):
        nb = nbformat.read(p, as_version=4)
        nb.cells[0].source += "\n\n(revised)"
        nbformat.write(nb, p)
    (src / COURSE[3].name).write_bytes(COURSE[3].read_bytes())
    r = workspace.sync(folder, sorted(src.glob("*.ipynb")))
    assert r.added == [COURSE[3].name]
    assert sorted(r.updated) == sorted([COURSE[0].name, COURSE[2].name])
    assert r.kept == [COURSE[1].name]
    assert edited.read_bytes() == mine                       # never overwritten
    assert "(revised)" in nbformat.read(folder / COURSE[0].name, as_version=4).cells[0].source
    assert "1 kept as you left them" in r.summary()


def test_the_work_folder_is_not_the_instructor_folder_and_its_variable_is_checked(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="holds the instructor notebooks"):
        workspace.sync(ROOT / "notebooks")
    monkeypatch.setenv(workspace.ENV_WORK, "")
    with pytest.raises(ValueError, match="set but empty"):
        workspace.work_dir()
    monkeypatch.setenv(workspace.ENV_WORK, str(tmp_path / "w"))
    assert workspace.work_dir() == (tmp_path / "w").resolve()
    monkeypatch.delenv(workspace.ENV_WORK)
    assert workspace.work_dir().parent == ROOT / "work"
    assert "/work/" in (ROOT / ".gitignore").read_text() or "work/" in (ROOT / ".gitignore").read_text()


def test_lab_twice_says_where_the_open_course_is(tmp_path):
    """A JupyterLab on the student's folder, then `./course.sh lab`: it prints the running
    server's address and exits 0 at once, starting no second server."""
    folder = tmp_path / "me"
    workspace.sync(folder)
    server = start_lab(folder, tmp_path / "srv")
    try:
        env = dict(os.environ, ANNSLAM_WORK=str(folder),
                   JUPYTER_RUNTIME_DIR=str(tmp_path / "srv" / "jupyter-runtime"))
        out = subprocess.run([sys.executable, "-m", "annslam_lib", "running", "--root", str(folder)],
                             env=env, capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert f"the course is already open on {folder}" in out.stdout
        assert f"127.0.0.1:{server.port}" in out.stdout and server.token in out.stdout
        other = subprocess.run([sys.executable, "-m", "annslam_lib", "running", "--root",
                                str(tmp_path)], env=env, capture_output=True, text=True, timeout=60)
        assert other.returncode == 1 and other.stdout == ""
        t0 = time.monotonic()
        lab = subprocess.run(["bash", "course.sh", "lab"], cwd=ROOT, env=env, capture_output=True,
                             text=True, timeout=120)
        assert lab.returncode == 0, lab.stdout[-1500:] + lab.stderr[-1500:]
        assert "already open" in lab.stdout and "opening JupyterLab" not in lab.stdout
        print(f"second ./course.sh lab answered in {time.monotonic() - t0:.1f} s")
    finally:
        server.stop()
