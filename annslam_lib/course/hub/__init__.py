"""A class on JupyterHub (``./course.sh hub``). Here: the class list, one Unix account per
student, the hub's folder, each server's environment and each role's Jupyter configuration.
Its modules:

- ``setup``: the hub folder prepared (students' environment, release, data, the class's
  studies, proxy) and JupyterHub started (``python -m annslam_lib hub``)
- ``config``: JupyterHub's settings for the class, what ``hub/jupyterhub_config.py`` applies
- ``classroom``: the instructor's steps through nbgrader's exchange (release, collect, grade,
  feedback, export: ``./course.sh class``)
- ``deadlines``: due dates, late policies and extensions (``course/course.toml``), and which
  submission of each student is collected
- ``gradebook``: the class's grades as CSV files for Canvas and Moodle
- ``lti``: students' login from the LMS with LTI 1.3 (``./course.sh hub --lti FILE``)
- ``roster``: a student added or dropped mid-term (``./course.sh class add|drop NAME``)
- ``limits``: each student's server within memory, CPU and process limits (a control group
  per student, joined before the server runs)
- ``client``: a running hub driven over its REST API as an admin service (the hub's tests
  and load benchmark)

Isolation is the operating system's: the hub runs as root and JupyterHub's
``LocalProcessSpawner`` (with its limits enforced: ``limits``) starts each student's server
as that student's own Unix account
(created when the server first starts, so a start through the REST API works as a login
does; home mode 0700, so no other student's kernel can read it). ``SimpleLocalProcessSpawner``
is refused: it runs every server as the hub's user, so every student could read every home.

The hub folder (``ANNSLAM_HUB_DIR``, default ``/srv/annslam-hub``) holds, world-readable
unless said otherwise:

- ``student-env/``   the students' Python: a venv of a system Python 3.11 (a Python under
  root's home is not readable by students), the library installed as a wheel;
- ``data/``          one verified copy of the course's datasets, read-only for students;
- ``release/``       the student versions; each student's server copies them, as that
  student, into ``~/course`` (added when missing, never overwriting the student's work);
- ``exchange/``      nbgrader's exchange (mode 1777, as nbgrader requires);
- ``course/``        the instructor's nbgrader course folder (source, submitted, grades,
  feedback): the instructor's account's only, mode 0700 (:func:`give_course`);
- ``etc/student/``, ``etc/instructor/``   the Jupyter configuration of each role
  (nbgrader's exchange and course id; formgrader and assignment creation only for the
  instructor);
- ``proxy/``         configurable-http-proxy, pinned, from the npm registry;
- ``state/``         the hub's database, cookie secret, log and ``hub.json`` (mode 0700).
"""
from __future__ import annotations

import json
import os
import pwd
import re
import shutil
import subprocess
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from ... import _settings

__all__ = ["HubError", "HubLayout", "ENV_DIR", "COURSE_ID", "MARK", "read_class",
           "check_name", "account_status", "ensure_account", "give_course", "running_hub",
           "write_role_config", "server_env", "STUDENT_DISABLED", "INSTRUCTOR_DISABLED",
           "system_python", "reachable_by_others", "open_to_all",
           "setup", "config", "classroom", "client", "deadlines", "gradebook", "limits", "lti",
           "roster"]

ENV_DIR = _settings.HUB_DIR
DEFAULT_DIR = _settings.HUB_DIR_DEFAULT
COURSE_ID = "annslam"
#: GECOS field of the accounts the course creates: an existing account without it is not
#: the course's, and a class list naming it (``root``, ``www-data``, a colleague) is refused.
MARK = "annslam course account"
_NAME = re.compile(r"[a-z][a-z0-9_-]{0,30}\Z")      # \Z: no trailing newline slips by

#: JupyterLab plugins and server extensions of nbgrader a student does not get.
STUDENT_DISABLED = {
    "lab": ["@jupyter/nbgrader:formgrader", "@jupyter/nbgrader:create-assignment",
            "@jupyter/nbgrader:course-list"],
    "server": ["nbgrader.server_extensions.formgrader",
               "nbgrader.server_extensions.course_list"],
}
INSTRUCTOR_DISABLED: dict[str, list[str]] = {"lab": [], "server": []}


class HubError(RuntimeError):
    """What stops the hub, said once, with what to do."""


@dataclass(frozen=True)
class HubLayout:
    """The hub's folder and what lies in it (module docstring)."""
    root: Path

    @classmethod
    def from_env(cls) -> "HubLayout":
        return cls((_settings.hub_dir() or Path(DEFAULT_DIR)).resolve())

    env = property(lambda self: self.root / "student-env")
    data = property(lambda self: self.root / "data")
    release = property(lambda self: self.root / "release")
    exchange = property(lambda self: self.root / "exchange")
    course = property(lambda self: self.root / "course")
    etc = property(lambda self: self.root / "etc")
    proxy = property(lambda self: self.root / "proxy")
    state = property(lambda self: self.root / "state")
    studies = property(lambda self: self.root / "studies")   # the class's study cache

    def role_config(self, role: str) -> Path:
        return self.etc / role


def check_name(name: str) -> None:
    """A class member's name must be a plain Unix user name: lower-case letter first, then
    letters, digits, ``_`` or ``-``, at most 31 characters."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise HubError(f"{name!r} is not a user name the hub can give an account: use a "
                       "lower-case letter, then lower-case letters, digits, '_' or '-' "
                       "(at most 31 characters)")


def read_class(path, instructor: str = "instructor") -> list[str]:
    """The student names of a class file: one a line, blank lines and ``#`` comments
    ignored. Invalid or repeated names, and the instructor's name, are refused with their
    line number."""
    check_name(instructor)
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise HubError(f"cannot read the class file {path}: {e}") from None
    names, seen = [], {}
    for n, line in enumerate(lines, 1):
        name = line.split("#", 1)[0].strip()
        if not name:
            continue
        try:
            check_name(name)
        except HubError as e:
            raise HubError(f"{path}, line {n}: {e}") from None
        if name in seen:
            raise HubError(f"{path}, line {n}: {name!r} is already on line {seen[name]}")
        if name == instructor:
            raise HubError(f"{path}, line {n}: {name!r} is the instructor's account")
        seen[name] = n
        names.append(name)
    if not names:
        raise HubError(f"the class file {path} names no student")
    return names


def account_status(name: str) -> str:
    """``"missing"``, or ``"course"`` for an account the course made. Any other existing
    account (a system user, a colleague) raises: the hub never runs a server as it."""
    check_name(name)
    try:
        entry = pwd.getpwnam(name)
    except KeyError:
        return "missing"
    if entry.pw_gecos.split(",")[0] != MARK:
        raise HubError(f"{name!r} is an existing account of this machine that the course did "
                       f"not create (uid {entry.pw_uid}): the hub will not run a server as it. "
                       "Rename the student in the class file")
    return "course"


def ensure_account(name: str) -> pwd.struct_passwd:
    """The Unix account of ``name``, created if missing (``useradd -m``, home mode 0700,
    marked as the course's); an existing course account gets its home back to 0700."""
    if account_status(name) == "missing":
        useradd = shutil.which("useradd") or "/usr/sbin/useradd"
        out = subprocess.run([useradd, "--create-home", "--key", "HOME_MODE=0700",
                              "--comment", MARK, "--shell", "/bin/bash", name],
                             capture_output=True, text=True)
        if out.returncode != 0:
            raise HubError(f"useradd {name} failed ({out.returncode}): {out.stderr.strip()} "
                           "(the hub must run as root to give students accounts)")
    entry = pwd.getpwnam(name)
    os.chmod(entry.pw_dir, 0o700)            # useradd without HOME_MODE support made 0755
    return entry


def give_course(layout: HubLayout, instructor: str) -> bool:
    """The nbgrader course folder (sources, every student's collected submission, grades,
    feedback) to the instructor's account, mode 0700: nobody else's kernel can read it, and
    the instructor's formgrader can work in it. False while that account does not exist yet
    (it is made when the instructor's server first starts)."""
    try:
        if account_status(instructor) != "course":
            return False
    except HubError:
        return False
    entry = pwd.getpwnam(instructor)
    os.chmod(layout.course, 0o700)
    for p in [layout.course, *layout.course.rglob("*")]:
        os.lchown(p, entry.pw_uid, entry.pw_gid)
    return True


def server_env(layout: HubLayout, role: str) -> dict[str, str]:
    """Environment of a student's or the instructor's server (and so of its kernels)."""
    return {
        "PATH": f"{layout.env / 'bin'}:/usr/local/bin:/usr/bin:/bin",
        _settings.DATA: str(layout.data),
        # the studies computed once for the class (setup.warm_class_studies), read-only
        _settings.CLASS_CACHE: str(layout.studies),
        "JUPYTER_CONFIG_DIR": str(layout.role_config(role)),
        # one BLAS thread per kernel: a class shares the machine's cores
        "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
        "PYTHONHASHSEED": "0",
    }


def write_role_config(layout: HubLayout, role: str) -> Path:
    """The Jupyter configuration folder of ``role`` (``student`` or ``instructor``):
    nbgrader's exchange and course id, and the nbgrader parts that role does not get."""
    disabled = STUDENT_DISABLED if role == "student" else INSTRUCTOR_DISABLED
    folder = layout.role_config(role)
    (folder / "labconfig").mkdir(parents=True, exist_ok=True)
    lines = ["c = get_config()  # noqa: F821 (written by annslam_lib.course.hub)",
             f"c.Exchange.root = {str(layout.exchange)!r}",
             f"c.CourseDirectory.course_id = {COURSE_ID!r}"]
    if role == "instructor":
        lines.append(f"c.CourseDirectory.root = {str(layout.course)!r}")
    (folder / "nbgrader_config.py").write_text("\n".join(lines) + "\n")
    (folder / "jupyter_server_config.json").write_text(json.dumps(
        {"ServerApp": {"jpserver_extensions": {e: False for e in disabled["server"]}}},
        indent=1) + "\n")
    (folder / "labconfig" / "page_config.json").write_text(json.dumps(
        {"disabledExtensions": {e: True for e in disabled["lab"]}}, indent=1) + "\n")
    # jupyter_core's one-time migration of an old ~/.ipython configuration writes this
    # marker into the configuration folder, which students cannot write: a server started
    # again after a kernel made ~/.ipython would fail there. Written here, it is skipped.
    (folder / "migrated").write_text("not migrated: the course's role configuration\n")
    for p in [folder, folder / "labconfig", *folder.rglob("*")]:
        os.chmod(p, 0o755 if p.is_dir() else 0o644)
    return folder


def running_hub(layout: HubLayout) -> str | None:
    """The address of a hub already running from this folder, or None."""
    info = layout.state / "hub.json"
    try:
        data = json.loads(info.read_text())
        pid = int(data["pid"])
        if pid <= 0:                       # 0 and -1 would signal a group, not a process
            return None
        os.kill(pid, 0)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    try:
        with urllib.request.urlopen(data["url"].rstrip("/") + "/hub/api", timeout=3) as r:
            if r.status == 200:
                return data["url"]
    except (OSError, ValueError, AttributeError):     # no hub there, or no address
        pass
    return None


def system_python() -> Path:
    """The interpreter of the students' environment: ``ANNSLAM_HUB_PYTHON``, else a
    Python 3.11 that every user can run (a Python under root's home, such as pyenv's, is
    not: students would get ``Permission denied``)."""
    given = _settings.hub_python()
    candidates = [str(given)] if given else ["/usr/bin/python3.11", "/usr/local/bin/python3.11",
                                             shutil.which("python3.11") or ""]
    for c in filter(None, candidates):
        p = Path(c)
        if p.is_file() and _world_runnable(p):
            return p
    raise HubError("no Python 3.11 that every user can run was found (tried "
                   f"{', '.join(filter(None, candidates))}): install one (Debian: apt-get "
                   "install python3.11-venv) or set ANNSLAM_HUB_PYTHON")


def _world_runnable(path: Path) -> bool:
    """Other users can run ``path``: every folder on the way to what it resolves to lets
    them through, and the file lets them run it."""
    return reachable_by_others(path.resolve())


def reachable_by_others(path: Path) -> bool:
    """Other users can reach ``path``: it and every folder above it have the others' ``x``
    bit (a folder they can traverse gives them every file whose name they know)."""
    path = Path(path).absolute()
    return all(p.stat().st_mode & 0o001 for p in [*path.parents, path])


def open_to_all(path: Path) -> None:
    """Folders 0755 and files 0644 (executables 0755) below ``path``, for every user."""
    for p in [path, *path.rglob("*")]:
        if p.is_symlink():
            continue
        mode = p.stat().st_mode
        want = 0o755 if p.is_dir() or mode & 0o100 else 0o644
        if mode & 0o777 != want:
            os.chmod(p, want)
