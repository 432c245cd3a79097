"""Prepare a class hub's folder and start JupyterHub: ``python -m annslam_lib hub``.

Each stage is announced by one line and is cheap when nothing changed: the students'
environment (``scripts/install.py --base environment-student.txt --wheel``, run by a Python
every user can run), the student versions (released afresh), one verified copy of the data,
the class's studies (one Run All of every chapter into a read-only study cache; done
again only when the students' library or the notebooks changed; ``--no-studies`` skips it),
nbgrader's exchange and course folders, each role's Jupyter configuration, and the proxy
(``npm ci`` of ``hub/package.json``). Then JupyterHub starts with ``hub/jupyterhub_config.py``.
"""
from __future__ import annotations

import hashlib
import json
import os
import secrets
import shutil
import subprocess
import sys
from pathlib import Path

from ... import _settings
from . import (HubError, HubLayout, open_to_all, reachable_by_others, read_class, running_hub,
               server_env, system_python, write_role_config)

__all__ = ["ROOT", "PREPARED", "prepare", "start", "admin_token", "check_private", "copy_data", "install_proxy",
           "passwords", "warm_class_studies"]

ROOT = Path(__file__).resolve().parents[3]
PREPARED = ".annslam-hub-prepared"          # written when every stage of prepare() passed


def say(text: str) -> None:
    print(f"== {text}", flush=True)


def _folders(layout: HubLayout) -> None:
    for folder, mode in [(layout.root, 0o755), (layout.state, 0o700), (layout.release, 0o755),
                         (layout.data, 0o755), (layout.course, 0o700), (layout.etc, 0o755),
                         (layout.exchange, 0o1777), (layout.studies, 0o755)]:
        folder.mkdir(parents=True, exist_ok=True)
        os.chmod(folder, mode)


def install_student_env(layout: HubLayout) -> None:
    python = system_python()
    say(f"students' environment in {layout.env} (Python {python}, library as a wheel)")
    out = subprocess.run([str(python), str(ROOT / "scripts" / "install.py"), "--venv",
                          str(layout.env), "--base", "environment-student.txt", "--wheel"])
    if out.returncode != 0:
        raise HubError(f"the students' environment could not be set up in {layout.env} "
                       "(above)")
    open_to_all(layout.env)


def release_notebooks(layout: HubLayout) -> list[Path]:
    from ..release import release

    for old in layout.release.glob("*.ipynb"):
        old.unlink()
    written = release(sorted((ROOT / "notebooks").glob("*.ipynb")), layout.release)
    open_to_all(layout.release)
    say(f"{len(written)} student versions in {layout.release}")
    return written


def copy_data(layout: HubLayout) -> None:
    """One verified copy of the course's datasets in the hub folder, read-only for students:
    copied from the data folder this process uses (``ANNSLAM_DATA``, else the user cache,
    downloaded there first if missing), then verified where it lies."""
    from ...data import fetch, registry

    names = registry.core()
    sources = {n: fetch.ensure(n, progress=False) for n in names}
    with _settings.temporarily(_settings.DATA, str(layout.data)):     # verified where it lies
        for n in names:
            entry = registry.get(n)
            dest = layout.data / entry.folder
            dest.mkdir(parents=True, exist_ok=True)
            for f in entry.files:
                target = dest / f.name
                if not target.exists() or target.stat().st_size != f.size:
                    shutil.copyfile(sources[n] / f.name, target)
            fetch.verify(n)
    open_to_all(layout.data)
    say(f"data: {len(names)} datasets verified in {layout.data}")


def install_proxy(layout: HubLayout) -> Path:
    """configurable-http-proxy at its pinned version, from the npm registry, in the hub
    folder (``npm ci`` of ``hub/package.json`` and its lock file)."""
    exe = layout.proxy / "node_modules" / ".bin" / "configurable-http-proxy"
    lock = (ROOT / "hub" / "package-lock.json").read_bytes()
    stamp = layout.proxy / ".annslam-lock-sha256"
    want = hashlib.sha256(lock).hexdigest()
    if exe.exists() and stamp.exists() and stamp.read_text() == want:
        return exe
    npm = shutil.which("npm")
    if npm is None:
        raise HubError("npm is not installed: the hub's proxy (configurable-http-proxy) comes "
                       "from the npm registry. Install Node.js 20 or newer with npm")
    layout.proxy.mkdir(parents=True, exist_ok=True)
    for name in ("package.json", "package-lock.json"):
        shutil.copyfile(ROOT / "hub" / name, layout.proxy / name)
    say(f"proxy: npm ci in {layout.proxy}")
    out = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--loglevel", "error"],
                         cwd=layout.proxy)
    if out.returncode != 0 or not exe.exists():
        raise HubError(f"npm could not install configurable-http-proxy in {layout.proxy}")
    stamp.write_text(want)
    return exe


def image_files(layout: HubLayout) -> None:
    """What a single-user image holds of the hub folder (``hub/z2jh/Dockerfile``, and
    ``binder/postBuild`` for repo2docker): the student versions and each role's Jupyter
    configuration, laid out as on a local hub. No accounts, data or proxy: on Kubernetes the
    data and the exchange are volumes, and each student is a pod."""
    layout.root.mkdir(parents=True, exist_ok=True)
    release_notebooks(layout)
    for role in ("student", "instructor"):
        write_role_config(layout, role)
    open_to_all(layout.root)


def passwords(layout: HubLayout, env) -> dict[str, str]:
    """The students' password (required) and the instructor's (generated once and kept in
    ``state/instructor-password`` when not given)."""
    student = _settings.hub_password(env)
    if len(student) < 8:
        raise HubError(f"set {_settings.HUB_PASSWORD} to the students' password (8 characters "
                       "or more) before starting the hub")
    instructor = _settings.hub_instructor_password(env)
    kept = layout.state / "instructor-password"
    if not instructor:
        if not kept.exists():
            kept.write_text(secrets.token_urlsafe(32) + "\n")
            os.chmod(kept, 0o600)
        instructor = kept.read_text().strip()
        say(f"the instructor's password is in {kept}")
    if len(instructor) < 32:
        raise HubError(f"{_settings.HUB_INSTRUCTOR_PASSWORD} must have 32 characters or more")
    if instructor == student:
        raise HubError("the instructor's and the students' passwords must differ")
    return {_settings.HUB_PASSWORD: student, _settings.HUB_INSTRUCTOR_PASSWORD: instructor}


def check_private() -> None:
    """Students' kernels must not reach the instructor's notebooks and tests."""
    exposed = [str(p) for p in (ROOT / "notebooks", ROOT / "tests") if reachable_by_others(p)]
    if exposed:
        raise HubError("every student could read the instructor's notebooks (solutions, "
                       f"hidden tests) in {', '.join(exposed)}: run chmod o-rwx "
                       f"{' '.join(exposed)}, or keep the course's checkout in a folder only "
                       "you can open (the hub needs only its own folder to be open)")


def check_grading() -> None:
    """The class's work is graded in the course's sandbox: refuse to start a hub on a
    machine where it cannot be made, naming the cause and the fix."""
    from ..sandbox import bwrap_problem

    why = bwrap_problem()
    if why:
        raise HubError(f"the course's grader could not sandbox the students' code here "
                       f"(./course.sh class grade would refuse): {why}")


def check_limits() -> None:
    """Each student's server runs within memory, CPU and process limits (``limits``):
    refuse to start a hub on a machine where they cannot be enforced."""
    from .limits import check

    why = check()
    if why:
        raise HubError(f"{why} (the hub needs root and the cgroup memory, pids and cpu "
                       "controllers)")


def warm_class_studies(layout: HubLayout, notebooks: Path | None = None) -> None:
    """The class's study cache: Run All of every chapter once, by the students' own
    environment with a student server's settings (the same library code and BLAS threads,
    so the same keys), into ``layout.studies``, then opened read-only to everyone. Every
    server reads it (``ANNSLAM_CLASS_CACHE``), so no student's first Run All of chapters
    05-08 computes the studies again.

    ``notebooks``: the folder run, by default the instructor versions of this checkout (run
    as root): their studies are a superset of the student versions' (measured: 101 entries
    against 99; the two more are chapter 08's exercise on measurement-only features, which a
    student's right answer asks for). Done again only when the students' library or the
    notebooks changed (their hash is kept in ``.sha256-of-inputs``); stale entries are
    removed first."""
    folder = Path(ROOT / "notebooks" if notebooks is None else notebooks)
    python = str(layout.env / "bin" / "python")
    env = {**os.environ, **server_env(layout, "student"), _settings.CACHE: str(layout.studies)}
    del env[_settings.CLASS_CACHE]     # filled as this run's own cache, not read as the class's
    code = subprocess.run([python, "-c", "from annslam_lib._cache import code_hash; "
                           "print(code_hash())"], env=env, capture_output=True, text=True)
    h = hashlib.sha256(code.stdout.encode() if code.returncode == 0 else os.urandom(16))
    for p in sorted(folder.glob("*.ipynb")):
        h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\0")
    stamp = layout.studies / ".sha256-of-inputs"
    if stamp.exists() and stamp.read_text().strip() == h.hexdigest():
        say(f"class studies: up to date in {layout.studies}")
        return
    stamp.unlink(missing_ok=True)
    for old in [*layout.studies.glob("*.pkl"), *layout.studies.glob("*.sha256")]:
        old.unlink()
    say(f"class studies: Run All of the notebooks of {folder} into {layout.studies} "
        "(a few minutes)")
    out = subprocess.run([python, "-m", "annslam_lib", "cache", "warm", "--notebooks",
                          str(folder)], env=env, cwd=str(layout.state))
    if out.returncode != 0:
        raise HubError(f"the class's studies could not be computed into {layout.studies} "
                       "(above)")
    stamp.write_text(h.hexdigest() + "\n")
    open_to_all(layout.studies)


def prepare(layout: HubLayout, class_file=None, instructor: str = "instructor", *,
            studies: bool = True) -> list[str]:
    """Every stage of the module docstring but the start; returns the student names
    (none without a class file: only the folder is prepared). ``studies``: compute the
    class's study cache (:func:`warm_class_studies`)."""
    if os.geteuid() != 0:
        raise HubError("the hub gives every student a Unix account of their own and runs "
                       "their server as it: start it as root")
    students = read_class(class_file, instructor) if class_file is not None else []
    url = running_hub(layout)
    if url:
        raise HubError(f"a hub is already running from {layout.root} at {url} "
                       f"(pid in {layout.state / 'hub.json'}); stop it first")
    (layout.root / PREPARED).unlink(missing_ok=True)
    _folders(layout)
    if not reachable_by_others(layout.root):
        raise HubError(f"students could not reach the hub folder {layout.root}: a folder "
                       "above it is closed to other users. Set ANNSLAM_HUB_DIR to a folder "
                       "they can reach (default /srv/annslam-hub)")
    install_student_env(layout)
    release_notebooks(layout)
    copy_data(layout)
    if studies:
        warm_class_studies(layout)
    for role in ("student", "instructor"):
        write_role_config(layout, role)
    install_proxy(layout)
    (layout.root / PREPARED).write_text("the class hub's folder is prepared\n")
    return students


def admin_token(layout: HubLayout, env) -> str:
    """The API token of the instructor's commands (``class add``, ``class drop``):
    ``ANNSLAM_HUB_ADMIN_TOKEN`` when given, else made once; kept in ``state/admin-token``
    (root's only)."""
    kept = layout.state / "admin-token"
    token = _settings.hub_admin_token(env)
    if token is None:
        token = kept.read_text().strip() if kept.exists() else secrets.token_hex(32)
    fd = os.open(kept, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    return token


def start(layout: HubLayout, class_file, *, port: int = 8000,
          instructor: str = "instructor", env=None, studies: bool = True,
          lti_file=None) -> None:
    """Prepare, then replace this process by JupyterHub (``hub.json`` names it). With
    ``lti_file`` (:mod:`.lti`) students log in from the LMS; without, with the shared
    password."""
    env = dict(os.environ if env is None else env)
    check_private()
    check_grading()
    check_limits()
    if lti_file is not None:
        from .lti import read_settings

        read_settings(lti_file)                  # refused before anything is prepared
    students = prepare(layout, class_file, instructor, studies=studies)
    if lti_file is None:
        env.update(passwords(layout, env))
        say("login: the students' shared password. It does not tell students apart: "
            "for a supervised lab, not for graded work (INSTRUCTOR.md: LTI)")
    else:
        env[_settings.HUB_LTI] = str(Path(lti_file).resolve())
    env.update({_settings.HUB_DIR: str(layout.root),
                _settings.HUB_CLASS: str(Path(class_file).resolve()),
                _settings.HUB_INSTRUCTOR: instructor, _settings.HUB_PORT: str(port),
                _settings.HUB_ADMIN_TOKEN: admin_token(layout, env)})
    url = f"http://127.0.0.1:{port}"
    (layout.state / "hub.json").write_text(json.dumps(
        {"pid": os.getpid(), "url": url, "class": str(Path(class_file).resolve()),
         "instructor": instructor}) + "\n")
    say(f"JupyterHub for {len(students)} students and {instructor!r} at {url}")
    exe = Path(sys.executable).parent / "jupyterhub"
    os.chdir(layout.state)
    os.execve(exe, [str(exe), "-f", str(ROOT / "hub" / "jupyterhub_config.py")], env)
