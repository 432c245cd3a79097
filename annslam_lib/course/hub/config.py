"""JupyterHub's configuration for a class: what ``hub/jupyterhub_config.py`` applies.

``python -m annslam_lib hub`` prepares the hub folder (:mod:`annslam_lib.course.hub`) and
starts JupyterHub with the settings below passed in the environment (``ANNSLAM_HUB_*``), so
the config file holds no secret and a hub restarted by hand reads the same settings.

Swapping the parts a university changes:

- **Authenticator.** With an LTI settings file (``ANNSLAM_HUB_LTI``, ``./course.sh hub
  --lti FILE``), students log in from the LMS with LTI 1.3 (:mod:`.lti`). Without one, the
  built-in ``shared-password`` authenticator, for a supervised lab only: one password for the
  students (``ANNSLAM_HUB_PASSWORD``, at least 8 characters), one for the instructor
  (``ANNSLAM_HUB_INSTRUCTOR_PASSWORD``, at least 32). It does not tell students apart: anyone
  with the students' password can log in as any listed student, so it is not for graded
  work. Either way ``c.Authenticator.allowed_users`` is the class file; ``class add`` and
  ``class drop`` change it on the running hub.
- **Idle servers** are stopped by ``jupyterhub-idle-culler``, a service of the hub, after
  :data:`IDLE_TIMEOUT` seconds without activity (a student's files stay; their next visit
  starts a new server); another timeout in ``hub/jupyterhub_config.py``:
  ``c.JupyterHub.services[0] = idle_culler(sys.executable, timeout=1800)``.
- **Spawner.** ``LocalProcessSpawner`` with one Unix account per student is the isolation
  on one machine, its memory and CPU limits enforced by a control group per student
  (:mod:`.limits`; change them with ``c.Spawner.mem_limit``, ``c.Spawner.cpu_limit`` and
  ``c.LimitedSpawner.processes`` in ``hub/jupyterhub_config.py``). For Docker, ``dockerspawner.DockerSpawner`` with the image of
  ``hub/z2jh/Dockerfile`` (its ``cmd`` is the image's; mount the data read-only at
  ``/srv/annslam/data`` and the exchange at ``/srv/annslam/exchange``, and give each student
  a uid of their own, as ``hub/z2jh/config.yaml`` does); for a cluster, Zero to JupyterHub
  (``KubeSpawner``), configured by ``hub/z2jh/config.yaml`` instead of this file.
  ``SimpleLocalProcessSpawner`` is refused: it runs every student's server as the hub's own
  user, so any student could read every home.
"""
from __future__ import annotations

from pathlib import Path

from ... import _settings
from . import HubError, HubLayout, ensure_account, give_course, limits, lti, read_class, server_env

__all__ = ["configure", "check_spawner", "pre_spawn", "in_class", "class_gate", "idle_culler", "REFUSED_SPAWNERS",
           "SETTINGS", "IDLE_TIMEOUT", "IDLE_EVERY"]

#: The environment variables ``python -m annslam_lib hub`` sets for the config file, with
#: what each sets (their defaults and readers: ``annslam_lib._settings.VARIABLES``).
SETTINGS = {name: _settings.VARIABLES[name].sets for name in _settings.HUB_SETTINGS}
REFUSED_SPAWNERS = {"simple", "jupyterhub.spawner.SimpleLocalProcessSpawner"}
#: A server without activity for this long (seconds) is stopped; checked every IDLE_EVERY.
IDLE_TIMEOUT = 3600
IDLE_EVERY = 300
#: The scopes jupyterhub-idle-culler needs (its documentation's list).
IDLE_SCOPES = ["list:users", "read:users:activity", "read:servers", "delete:servers"]


def idle_culler(python: str, timeout: int = IDLE_TIMEOUT, every: int = IDLE_EVERY) -> dict:
    """The hub service that stops servers idle for ``timeout`` seconds (checked every
    ``every`` seconds) and its role."""
    return {"name": "idle-culler",
            "command": [python, "-m", "jupyterhub_idle_culler", f"--timeout={int(timeout)}",
                        f"--cull-every={int(every)}"]}


def _role(spawner) -> str:
    instructor = _settings.hub_instructor()
    return "instructor" if spawner.user.name == instructor else "student"


def in_class(name: str, env=None) -> bool:
    """``name`` is the instructor or on the class file now (``class add`` and ``class drop``
    change it while the hub runs; JupyterHub's own allow-list is only its start's)."""
    instructor = _settings.hub_instructor(env)
    class_file = _settings.hub_class(env)
    return name == instructor or (class_file is not None
                                  and name in read_class(class_file, instructor))


def class_gate(authenticator, handler, authentication):
    """``post_auth_hook``: a login of a name not in the class now is refused (None)."""
    return authentication if in_class(authentication["name"]) else None


def pre_spawn(spawner) -> None:
    """Before a server starts: the user's account (created on the first start), its folder
    ``~/course`` as the server's root, and the role's environment. A user no longer in the
    class (dropped while the hub kept them) gets no server."""
    if not in_class(spawner.user.name):
        raise HubError(f"{spawner.user.name!r} is not in the class: no server")
    layout = HubLayout.from_env()
    entry = ensure_account(spawner.user.name)
    spawner.notebook_dir = str(Path(entry.pw_dir) / "course")
    spawner.popen_kwargs = {**spawner.popen_kwargs, "cwd": entry.pw_dir}  # not the hub's
    spawner.environment = {**spawner.environment, **server_env(layout, _role(spawner))}
    if _role(spawner) == "instructor":
        give_course(layout, spawner.user.name)            # formgrader works in it


def configure(c, env=None) -> None:
    """Apply the class hub's settings (module docstring) to JupyterHub's config ``c``."""
    layout = HubLayout(_settings.hub_dir(env) or HubLayout.from_env().root)
    instructor = _settings.hub_instructor(env)
    class_file = _settings.hub_class(env)
    if class_file is None:
        raise HubError(f"{_settings.HUB_CLASS} is not set: start the hub with ./course.sh hub "
                       "--class FILE")
    students = read_class(class_file, instructor)
    port = _settings.hub_port(env)

    c.JupyterHub.ip = "127.0.0.1"
    c.JupyterHub.port = port
    c.JupyterHub.hub_ip = "127.0.0.1"
    c.JupyterHub.hub_port = port + 1
    c.ConfigurableHTTPProxy.api_url = f"http://127.0.0.1:{port + 2}"
    c.ConfigurableHTTPProxy.command = [str(layout.proxy / "node_modules" / ".bin" /
                                           "configurable-http-proxy")]
    c.ConfigurableHTTPProxy.pid_file = str(layout.state / "proxy.pid")
    c.JupyterHub.db_url = f"sqlite:///{layout.state / 'jupyterhub.sqlite'}"
    c.JupyterHub.cookie_secret_file = str(layout.state / "jupyterhub_cookie_secret")

    lti_file = _settings.hub_lti(env)
    if lti_file is not None:
        lti.configure(c, lti_file)
    else:
        c.JupyterHub.authenticator_class = "shared-password"
        c.SharedPasswordAuthenticator.user_password = _settings.hub_password(env)
        c.SharedPasswordAuthenticator.admin_password = _settings.hub_instructor_password(env)
    c.Authenticator.allowed_users = set(students)
    c.Authenticator.post_auth_hook = class_gate
    c.Authenticator.admin_users = {instructor}

    # LocalProcessSpawner with its memory, CPU and process limits enforced (limits)
    c.JupyterHub.spawner_class = limits.spawner_class()
    c.Spawner.mem_limit = limits.DEFAULTS.memory
    c.Spawner.cpu_limit = limits.DEFAULTS.cpus
    c.Spawner.cmd = [str(layout.env / "bin" / "python"), "-m", "annslam_lib", "singleuser",
                     "--release", str(layout.release), "--"]
    # nothing of the hub's own environment (PYTHONPATH, VIRTUAL_ENV, ...) reaches a server:
    # its environment is server_env's
    c.Spawner.env_keep = ["LANG", "LC_ALL"]
    c.Spawner.default_url = "/lab"
    c.Spawner.pre_spawn_hook = pre_spawn
    # A class on one machine starts servers slowly (about 4 s of imports each, CPU-bound).
    c.Spawner.start_timeout = 120
    c.Spawner.http_timeout = 120

    import sys

    c.JupyterHub.services = [idle_culler(sys.executable)]
    c.JupyterHub.load_roles = [{"name": "idle-culler", "services": ["idle-culler"],
                                "scopes": IDLE_SCOPES}]
    token = _settings.hub_admin_token(env)
    if token:       # the instructor's commands (class add, class drop) and the tests
        c.JupyterHub.services.append({"name": "course-admin", "api_token": token})
        c.JupyterHub.load_roles.append({
            "name": "course-admin", "services": ["course-admin"],
            "scopes": ["admin:users", "admin:servers", "access:servers", "list:users",
                       "read:users", "tokens", "read:services"]})


def check_spawner(c) -> None:
    """Refuse a spawner without per-student isolation (module docstring)."""
    name = c.JupyterHub.spawner_class
    name = name if isinstance(name, str) else f"{name.__module__}.{name.__qualname__}"
    if name in REFUSED_SPAWNERS or name.endswith("SimpleLocalProcessSpawner"):
        raise HubError("SimpleLocalProcessSpawner runs every student's server as the hub's "
                       "user, so any student could read every other's files: use "
                       "LocalProcessSpawner (the default), DockerSpawner or KubeSpawner")
