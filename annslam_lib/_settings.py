"""The course's environment variables: every ``ANNSLAM_*`` name, what it sets, its default
and who reads it (:data:`VARIABLES`), and the one place the library reads them.

Each accessor below reads the environment when it is called (never at import, so a change
made by a test or a parent process is seen) and returns a typed value: a folder as a
``Path``, a switch as a ``bool``, a port as an ``int``. ``None`` means "not set": the
caller's default applies (the data and study folders' defaults are ``platformdirs``'
per-user cache, which this module, standard library only, does not import). Accessors take
an optional ``env`` mapping for a configuration read from an environment other than this
process's (the hub's config file).

Unless an accessor says otherwise, a variable set to the empty string counts as unset.
Two do not: ``ANNSLAM_DATA`` and ``ANNSLAM_WORK`` set but blank raise
:class:`SetButEmpty` (an empty value is a mistake such as ``ANNSLAM_DATA=$UNSET_VAR``, not a
wish for the default).

``ANNSLAM_LIFELINE`` is read by ``course/confine.py`` itself: it runs as a script of the
standard library only, outside the package, before a submission's code runs.
"""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import NamedTuple

__all__ = ["VARIABLES", "Variable", "SetButEmpty", "HUB_SETTINGS", "is_set", "temporarily",
           "cache_off", "cache_folder", "class_cache_folder", "data_folder", "data_url",
           "full_feedback", "kernel", "work_folder", "hub_dir", "hub_class", "hub_instructor",
           "hub_port", "hub_password", "hub_instructor_password", "hub_admin_token",
           "hub_python", "hub_lti", "CACHE", "CLASS_CACHE", "DATA", "DATA_URL", "FEEDBACK", "KERNEL",
           "LIFELINE", "WORK", "HUB_DIR", "HUB_CLASS", "HUB_INSTRUCTOR", "HUB_PORT",
           "HUB_PASSWORD", "HUB_INSTRUCTOR_PASSWORD", "HUB_ADMIN_TOKEN", "HUB_PYTHON", "HUB_LTI",
           "HUB_TEST_DIR", "VENV", "TORCH_INDEX", "UNAME", "HUB_DIR_DEFAULT",
           "HUB_INSTRUCTOR_DEFAULT", "HUB_PORT_DEFAULT"]

CACHE = "ANNSLAM_CACHE"
CLASS_CACHE = "ANNSLAM_CLASS_CACHE"
DATA = "ANNSLAM_DATA"
DATA_URL = "ANNSLAM_DATA_URL"
FEEDBACK = "ANNSLAM_FEEDBACK"
KERNEL = "ANNSLAM_KERNEL"
LIFELINE = "ANNSLAM_LIFELINE"
WORK = "ANNSLAM_WORK"
HUB_DIR = "ANNSLAM_HUB_DIR"
HUB_CLASS = "ANNSLAM_HUB_CLASS"
HUB_INSTRUCTOR = "ANNSLAM_HUB_INSTRUCTOR"
HUB_PORT = "ANNSLAM_HUB_PORT"
HUB_PASSWORD = "ANNSLAM_HUB_PASSWORD"
HUB_INSTRUCTOR_PASSWORD = "ANNSLAM_HUB_INSTRUCTOR_PASSWORD"
HUB_ADMIN_TOKEN = "ANNSLAM_HUB_ADMIN_TOKEN"
HUB_PYTHON = "ANNSLAM_HUB_PYTHON"
HUB_LTI = "ANNSLAM_HUB_LTI"
# read by course.sh, scripts/ and the tests, not by the library
HUB_TEST_DIR = "ANNSLAM_HUB_TEST_DIR"
VENV = "ANNSLAM_VENV"
TORCH_INDEX = "ANNSLAM_TORCH_INDEX"
UNAME = "ANNSLAM_UNAME"

HUB_DIR_DEFAULT = "/srv/annslam-hub"
HUB_INSTRUCTOR_DEFAULT = "instructor"
HUB_PORT_DEFAULT = 8000


class Variable(NamedTuple):
    """One row of :data:`VARIABLES`."""
    sets: str
    default: str
    read_by: str


#: Every ``ANNSLAM_*`` variable of the course, by name.
VARIABLES: dict[str, Variable] = {
    CACHE: Variable(
        "the folder of the study cache; 'off' (any case) turns every study cache off, the "
        "class's too", "platformdirs.user_cache_dir('annslam')/studies",
        "_cache; the grader's sandbox sets it to off, the hub's set-up to the class's folder "
        "while it warms it"),
    CLASS_CACHE: Variable(
        "a class's read-only study folder, read when the user's own has no entry",
        "none", "_cache; set for every hub server (course.hub) and in hub/z2jh"),
    DATA: Variable(
        "the data folder (set but blank: an error)", "platformdirs.user_cache_dir('annslam')/data",
        "data.fetch; set by the grader's sandbox, every hub server, .ci/run and hub/z2jh"),
    DATA_URL: Variable(
        "a mirror laid out like the data folder to download from (any URL urllib opens)",
        "each file's registry URL", "data.fetch; passed on into the grader's sandbox"),
    FEEDBACK: Variable(
        "'full': a kernel's check messages carry their answer", "short messages",
        "grading.core, once, at import"),
    KERNEL: Variable(
        "'numpy' switches the compiled gating loop off, 'auto' leaves it on; anything else "
        "is an error", "auto", "slam.compiled; the grader's sandbox sets numpy"),
    LIFELINE: Variable(
        "the file descriptor of the pipe whose closing ends a grading sandbox",
        "-1 (none)", "course/confine.py (read and removed); set by course.sandbox"),
    WORK: Variable(
        "the student's own course folder (set but blank: an error)",
        "work/<user> in the course checkout", "course.workspace, course.sh"),
    HUB_DIR: Variable(
        "the hub folder", HUB_DIR_DEFAULT,
        "course.hub, course.hub.config; set by course.hub.setup.start and course.sh test"),
    HUB_CLASS: Variable(
        "the class file (student names, one a line)", "none: the hub's config requires it",
        "course.hub.config; set by course.hub.setup.start"),
    HUB_INSTRUCTOR: Variable(
        "the instructor's account name", HUB_INSTRUCTOR_DEFAULT,
        "course.hub.config; set by course.hub.setup.start"),
    HUB_PORT: Variable(
        "the port of the hub's public address on 127.0.0.1; the hub's internal API uses the "
        "next one, the proxy's API the one after", str(HUB_PORT_DEFAULT),
        "course.hub.config; set by course.hub.setup.start"),
    HUB_PASSWORD: Variable(
        "the students' password (8 characters or more)", "none: the hub does not start "
        "without it", "course.hub.setup, course.hub.config"),
    HUB_INSTRUCTOR_PASSWORD: Variable(
        "the instructor's password (32 characters or more)",
        "generated once, kept in the hub folder's state/instructor-password",
        "course.hub.setup, course.hub.config"),
    HUB_ADMIN_TOKEN: Variable(
        "optional: an API token with admin rights on users and servers", "none",
        "course.hub.config; set by course.hub.client.launch"),
    HUB_LTI: Variable(
        "the LTI 1.3 settings file: students log in from the LMS", "none: the students' "
        "shared password", "course.hub.config; set by course.hub.setup.start"),
    HUB_PYTHON: Variable(
        "the interpreter of the students' environment on a hub",
        "a Python 3.11 every user can run: /usr/bin/python3.11, /usr/local/bin/python3.11, "
        "python3.11 on PATH", "course.hub"),
    HUB_TEST_DIR: Variable(
        "the hub folder of the hub's tests", "/tmp/annslam-hub-test",
        "course.sh test, tests/hub_support.py"),
    VENV: Variable(
        "the course's virtual environment", ".venv",
        "course.sh, scripts/install.py, scripts/check_env.py"),
    TORCH_INDEX: Variable(
        "the index PyTorch's CPU wheel is installed from (a lab's mirror)",
        "https://download.pytorch.org/whl/cpu", "scripts/install.py (through course.sh)"),
    UNAME: Variable(
        "stands for the output of uname -s (the tests of the platform check)", "uname -s",
        "course.sh"),
}

#: The variables ``python -m annslam_lib hub`` passes to ``hub/jupyterhub_config.py``.
HUB_SETTINGS = (HUB_DIR, HUB_CLASS, HUB_INSTRUCTOR, HUB_PORT, HUB_PASSWORD,
                HUB_INSTRUCTOR_PASSWORD, HUB_ADMIN_TOKEN, HUB_LTI)


class SetButEmpty(ValueError):
    """A variable set to a blank value where that is a mistake, not the default."""


def _get(name: str, env: Mapping[str, str] | None) -> str | None:
    return (os.environ if env is None else env).get(name)


def is_set(name: str, env: Mapping[str, str] | None = None) -> bool:
    """``name`` is set to a non-empty value."""
    return bool(_get(name, env))


@contextlib.contextmanager
def temporarily(name: str, value: str) -> Iterator[None]:
    """``name`` set to ``value`` in this process's environment, then put back as it was."""
    before = os.environ.get(name)
    os.environ[name] = value
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = before


def cache_off(env: Mapping[str, str] | None = None) -> bool:
    """``ANNSLAM_CACHE=off`` (any case): no study cache at all."""
    return (_get(CACHE, env) or "").lower() == "off"


def cache_folder(env: Mapping[str, str] | None = None) -> Path | None:
    """The study cache's folder named by ``ANNSLAM_CACHE``; None when unset, empty or off."""
    value = _get(CACHE, env) or ""
    if not value or value.lower() == "off":
        return None
    return Path(value).expanduser()


def class_cache_folder(env: Mapping[str, str] | None = None) -> Path | None:
    """The class's study folder (``ANNSLAM_CLASS_CACHE``); None when unset or empty. Whether
    ``ANNSLAM_CACHE=off`` also turns it off is the caller's to ask (:func:`cache_off`)."""
    value = _get(CLASS_CACHE, env)
    return Path(value).expanduser() if value else None


def data_folder(env: Mapping[str, str] | None = None) -> Path | None:
    """The data folder named by ``ANNSLAM_DATA``, None when unset; set but blank raises
    :class:`SetButEmpty`."""
    value = _get(DATA, env)
    if value is None:
        return None
    if not value.strip():
        raise SetButEmpty(f"${DATA} is set but empty")
    return Path(value).expanduser()


def data_url(env: Mapping[str, str] | None = None) -> str | None:
    """The data mirror's base URL (``ANNSLAM_DATA_URL``); None when unset or empty."""
    return _get(DATA_URL, env) or None


def full_feedback(env: Mapping[str, str] | None = None) -> bool:
    """``ANNSLAM_FEEDBACK=full`` (exactly): check messages carry their answer."""
    return _get(FEEDBACK, env) == "full"


def kernel(env: Mapping[str, str] | None = None) -> str:
    """``ANNSLAM_KERNEL`` as ``"numpy"`` or ``"auto"`` (unset or empty: auto; case and
    surrounding blanks ignored); any other value raises ``ValueError`` (a typo must not
    leave the compiled loop silently on)."""
    raw = _get(KERNEL, env)
    value = (raw or "").strip().lower()
    if value not in ("", "auto", "numpy"):
        raise ValueError(f"{KERNEL} must be 'numpy' (the numpy gating only) or 'auto' "
                         f"(or unset), got {raw!r}")
    return value or "auto"


def work_folder(env: Mapping[str, str] | None = None) -> Path | None:
    """The student's course folder named by ``ANNSLAM_WORK``, absolute; None when unset;
    set but blank raises :class:`SetButEmpty`."""
    value = _get(WORK, env)
    if value is None:
        return None
    if not value.strip():
        raise SetButEmpty(f"{WORK} is set but empty: unset it or name a folder")
    return Path(value).expanduser().resolve()


def hub_dir(env: Mapping[str, str] | None = None) -> Path | None:
    """The hub folder named by ``ANNSLAM_HUB_DIR``, as given; None when unset or empty (the
    default is :data:`HUB_DIR_DEFAULT`)."""
    value = _get(HUB_DIR, env)
    return Path(value) if value else None


def hub_class(env: Mapping[str, str] | None = None) -> Path | None:
    """The class file (``ANNSLAM_HUB_CLASS``); None when unset or empty."""
    value = _get(HUB_CLASS, env)
    return Path(value) if value else None


def hub_instructor(env: Mapping[str, str] | None = None) -> str:
    """The instructor's account name (``ANNSLAM_HUB_INSTRUCTOR``), default ``instructor``."""
    return _get(HUB_INSTRUCTOR, env) or HUB_INSTRUCTOR_DEFAULT


def hub_port(env: Mapping[str, str] | None = None) -> int:
    """The hub's public port (``ANNSLAM_HUB_PORT``), default 8000; a value that is not an
    integer raises ``ValueError``."""
    return int(_get(HUB_PORT, env) or HUB_PORT_DEFAULT)


def hub_password(env: Mapping[str, str] | None = None) -> str:
    """The students' password (``ANNSLAM_HUB_PASSWORD``); "" when unset."""
    return _get(HUB_PASSWORD, env) or ""


def hub_instructor_password(env: Mapping[str, str] | None = None) -> str:
    """The instructor's password (``ANNSLAM_HUB_INSTRUCTOR_PASSWORD``); "" when unset."""
    return _get(HUB_INSTRUCTOR_PASSWORD, env) or ""


def hub_admin_token(env: Mapping[str, str] | None = None) -> str | None:
    """The admin service's API token (``ANNSLAM_HUB_ADMIN_TOKEN``); None when unset or empty."""
    return _get(HUB_ADMIN_TOKEN, env) or None


def hub_lti(env: Mapping[str, str] | None = None) -> Path | None:
    """The LTI settings file (``ANNSLAM_HUB_LTI``); None when unset or empty."""
    value = _get(HUB_LTI, env)
    return Path(value) if value else None


def hub_python(env: Mapping[str, str] | None = None) -> Path | None:
    """The students' interpreter named by ``ANNSLAM_HUB_PYTHON``; None when unset or empty."""
    value = _get(HUB_PYTHON, env)
    return Path(value) if value else None
