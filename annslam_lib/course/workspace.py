"""A student's own copy of the course: the student versions, written once, never overwritten.

``./course.sh lab`` opens JupyterLab on this folder, not on the instructor notebooks in
``notebooks/``. :func:`sync` writes the course's release (:func:`release.student_version`)
into it: a chapter that is missing is added; a chapter still exactly as the course wrote it
(its sha256 is in the folder's manifest) is brought up to date when the course changed; a
chapter the student has edited or run is never touched. The folder is
``$ANNSLAM_WORK``, else ``work/<user>/`` in the course checkout (git-ignored).

    python -m annslam_lib workspace            # sync; prints the folder
    python -m annslam_lib running --root DIR   # is a Jupyter server already open on DIR?
"""
from __future__ import annotations

import getpass
import hashlib
import json
import os
import re
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

from .. import _settings
from .release import hidden_test_lines, solution_lines, student_version, validate

__all__ = ["ENV_WORK", "MANIFEST", "SyncReport", "work_dir", "sync", "running_servers"]

ENV_WORK = _settings.WORK
MANIFEST = ".annslam-course.json"
ROOT = Path(__file__).resolve().parents[2]


def work_dir() -> Path:
    """``$ANNSLAM_WORK`` if set (an empty value is an error), else ``work/<user>``."""
    folder = _settings.work_folder()          # set but blank: SetButEmpty, a ValueError
    if folder is not None:
        return folder
    user = re.sub(r"[^A-Za-z0-9_.-]", "_", getpass.getuser()) or "student"
    return ROOT / "work" / user


@dataclass
class SyncReport:
    """What :func:`sync` did, chapter by chapter (file names)."""
    folder: Path
    added: list[str] = field(default_factory=list)
    updated: list[str] = field(default_factory=list)
    kept: list[str] = field(default_factory=list)        # edited by the student: untouched
    unchanged: list[str] = field(default_factory=list)

    def summary(self) -> str:
        parts = [f"{len(self.added)} added", f"{len(self.updated)} updated",
                 f"{len(self.kept)} kept as you left them", f"{len(self.unchanged)} unchanged"]
        return f"your course folder {self.folder}: " + ", ".join(parts)


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sync(folder=None, notebooks=None, *, released: bool = False) -> SyncReport:
    """Write the student versions of ``notebooks`` (default: the course's) into ``folder``
    (default :func:`work_dir`) by the rules of the module docstring.

    ``released``: ``notebooks`` are student versions already (a release folder, as on a
    class hub, where each student's server copies them into its own folder as that
    student); they are checked to be student versions and copied as they are."""
    folder = Path(folder) if folder is not None else work_dir()
    sources = sorted(Path(p) for p in (notebooks or (ROOT / "notebooks").glob("*.ipynb")))
    if any(p.resolve().parent == folder.resolve() for p in sources):
        raise ValueError(f"{folder} holds the instructor notebooks: choose another folder")
    folder.mkdir(parents=True, exist_ok=True)
    man_path = folder / MANIFEST
    try:
        manifest = json.loads(man_path.read_text()) if man_path.exists() else {}
    except (OSError, ValueError):
        manifest = {}                        # unreadable: treat every file as the student's
    report = SyncReport(folder)
    for src in sources:
        nb = nbformat.read(src, as_version=4)
        if released:
            validate(nb, src.name, instructor=False)
            if solution_lines(nb) or hidden_test_lines(nb):
                raise ValueError(f"{src} holds solutions or hidden tests: it is not a "
                                 "student version")
            text = nbformat.writes(nb) + "\n"
        else:
            validate(nb, src.name)
            text = nbformat.writes(student_version(nb, src.name)) + "\n"
        new = _digest(text.encode())
        dest = folder / src.name
        if not dest.exists():
            report.added.append(src.name)
        else:
            have = _digest(dest.read_bytes())
            if have == new:
                report.unchanged.append(src.name)
                manifest[src.name] = new
                continue
            if manifest.get(src.name) != have:
                report.kept.append(src.name)
                continue
            report.updated.append(src.name)
        tmp = dest.with_name(f".{dest.name}.tmp")
        tmp.write_text(text)
        os.replace(tmp, dest)
        manifest[src.name] = new
    man_path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return report


def _alive(server: dict) -> bool:
    url = server.get("url", "").rstrip("/") + "/api/status"
    req = urllib.request.Request(url, headers={"Authorization": f"token {server.get('token', '')}"})
    try:
        with urllib.request.urlopen(req, timeout=3) as r:
            return r.status == 200
    except OSError:
        return False


def running_servers(root) -> list[dict]:
    """Jupyter servers of this user that are alive and serve the folder ``root``."""
    from jupyter_server.serverapp import list_running_servers

    root = Path(root).resolve()
    found = []
    for s in list_running_servers():
        served = s.get("root_dir") or s.get("notebook_dir") or ""
        if served and Path(served).resolve() == root and _alive(s):
            found.append(s)
    return found
