"""Students joining and leaving mid-term (``./course.sh class add|drop NAME``).

The class is the class file the hub was started with (``hub.json`` in the hub's ``state/``
names it). ``add`` writes the name into it and, on the running hub, lets the student in at
once (a hub user made over the REST API; JupyterHub then allows them). ``drop`` turns the
name's line into ``# dropped: NAME`` and, on the running hub, stops the student's server and
removes them from the hub, so their next login is refused; every process of their account
is stopped and the account expires (no login to the machine either). Their files stay: the
home folder, their submissions in the exchange, their collected work, grades and feedback.
``add`` after ``drop`` gives the same account back, files and all.
"""
from __future__ import annotations

import json
import pwd
import shutil
import subprocess
from pathlib import Path

from . import HubError, HubLayout, account_status, check_name, read_class, running_hub

__all__ = ["add", "drop", "class_file", "DROPPED"]

DROPPED = "# dropped: "


def class_file(layout: HubLayout) -> Path:
    """The class file of the hub of ``layout`` (the one it was last started with)."""
    try:
        return Path(json.loads((layout.state / "hub.json").read_text())["class"])
    except (OSError, ValueError, KeyError, TypeError):
        raise HubError(f"no class file is known for the hub in {layout.root}: start it once "
                       "with ./course.sh hub --class FILE") from None


def _hub(layout: HubLayout):
    """A client of the running hub (as its admin service), or None when none runs."""
    from .client import HubClient

    url = running_hub(layout)
    if url is None:
        return None
    try:
        token = (layout.state / "admin-token").read_text().strip()
    except OSError:
        raise HubError(f"the hub at {url} runs without the course's admin token "
                       f"({layout.state / 'admin-token'}): restart it with ./course.sh hub"
                       ) from None
    return HubClient(url, token)


def _account(name: str, *args: str) -> None:
    if account_status(name) == "course":
        usermod = shutil.which("usermod") or "/usr/sbin/usermod"
        out = subprocess.run([usermod, *args, name], capture_output=True, text=True)
        if out.returncode != 0:
            raise HubError(f"usermod {' '.join(args)} {name}: {out.stderr.strip()}")


def add(layout: HubLayout, name: str, instructor: str = "instructor") -> str:
    """``name`` into the class (module docstring); what was done, in one line."""
    check_name(name)
    account_status(name)                     # a machine account not the course's: refused
    path = class_file(layout)
    students = read_class(path, instructor)
    if name in students:
        raise HubError(f"{name!r} is already in the class ({path})")
    if name == instructor:
        raise HubError(f"{name!r} is the instructor's account")
    text = path.read_text()
    path.write_text(text + ("" if text.endswith("\n") or not text else "\n") + name + "\n")
    _account(name, "--expiredate", "")       # a dropped student's account, back
    hub = _hub(layout)
    if hub is not None:
        status, body = hub.request("POST", f"/hub/api/users/{name}")
        if status not in (201, 409):
            raise HubError(f"the hub did not add {name!r}: {status} {body}")
    where = "can log in now" if hub else "can log in once the hub runs"
    return f"{name} added to the class ({path}): {where}"


def drop(layout: HubLayout, name: str, instructor: str = "instructor") -> str:
    """``name`` out of the class, files kept (module docstring); what was done. The hub,
    the account and its processes are dealt with before the class file changes, so that a
    failure half-way leaves the name in the class and ``drop`` can be run again; a name
    already marked dropped is finished again (its hub user, expiry and processes)."""
    check_name(name)
    path = class_file(layout)
    lines = path.read_text().splitlines()
    dropped_before = DROPPED + name in lines
    if name not in read_class(path, instructor) and not dropped_before:
        raise HubError(f"{name!r} is not in the class ({path})")
    hub = _hub(layout)
    if hub is not None:
        status, body = hub.request("DELETE", f"/hub/api/users/{name}", timeout=120)
        if status not in (204, 404):
            raise HubError(f"the hub did not remove {name!r}: {status} {body}")
    home = None
    if account_status(name) == "course":
        entry = pwd.getpwnam(name)
        home = entry.pw_dir
        _account(name, "--expiredate", "1")
        pkill = shutil.which("pkill") or "/usr/bin/pkill"
        for _ in range(20):                  # until nothing of theirs runs (forks included)
            subprocess.run([pkill, "-KILL", "-U", str(entry.pw_uid)], capture_output=True)
            if subprocess.run([shutil.which("pgrep") or "/usr/bin/pgrep", "-U",
                               str(entry.pw_uid)], capture_output=True).returncode == 1:
                break
    if not dropped_before:
        kept = [DROPPED + name if line.split("#", 1)[0].strip() == name else line
                for line in lines]
        path.write_text("\n".join(kept) + "\n")
    files = f"their files stay in {home}" if home else "they had no account yet"
    again = " (already dropped: finished again)" if dropped_before else ""
    return f"{name} dropped from the class ({path}){again}: logins refused, {files}"
