"""JupyterHub's configuration for a class: what ``hub/jupyterhub_config.py`` applies.

``python -m annslam_lib hub`` prepares the hub folder (:mod:`annslam_lib.course.hub`) and
starts JupyterHub with the settings below passed in the environment (``ANNSLAM_HUB_*``), so
the config file holds no secret and a hub restarted by hand reads the same settings.

Swapping the parts a university changes:

- **Authenticator.** The built-in ``shared-password`` authenticator suits a supervised lab:
  one password for the students (``ANNSLAM_HUB_PASSWORD``, at least 8 characters), one for
  the instructor (``ANNSLAM_HUB_INSTRUCTOR_PASSWORD``, at least 32). It does not tell
  students apart: anyone with the students' password can log in as any listed student. For
  graded work use the university's login: set ``c.JupyterHub.authenticator_class`` to
  ``oauthenticator.GenericOAuthenticator`` (OAuth/OpenID Connect) or ``ltiauthenticator``'s
  LTI 1.3 authenticator (from an LMS), keeping ``c.Authenticator.allowed_users`` from the
  class file.
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
from . import HubError, HubLayout, ensure_account, give_course, limits, read_class, server_env

__all__ = ["configure", "check_spawner", "pre_spawn", "REFUSED_SPAWNERS", "SETTINGS"]

#: The environment variables ``python -m annslam_lib hub`` sets for the config file, with
#: what each sets (their defaults and readers: ``annslam_lib._settings.VARIABLES``).
SETTINGS = {name: _settings.VARIABLES[name].sets for name in _settings.HUB_SETTINGS}
REFUSED_SPAWNERS = {"simple", "jupyterhub.spawner.SimpleLocalProcessSpawner"}


def _role(spawner) -> str:
    instructor = _settings.hub_instructor()
    return "instructor" if spawner.user.name == instructor else "student"


def pre_spawn(spawner) -> None:
    """Before a server starts: the user's account (created on the first start), its folder
    ``~/course`` as the server's root, and the role's environment."""
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

    c.JupyterHub.authenticator_class = "shared-password"
    c.SharedPasswordAuthenticator.user_password = _settings.hub_password(env)
    c.SharedPasswordAuthenticator.admin_password = _settings.hub_instructor_password(env)
    c.Authenticator.allowed_users = set(students)
    c.Authenticator.admin_users = {instructor}

    # LocalProcessSpawner with its memory, CPU and process limits enforced (limits)
    c.JupyterHub.spawner_class = limits.spawner_class()
    c.Spawner.mem_limit = limits.DEFAULTS.memory
    c.Spawner.cpu_limit = limits.DEFAULTS.cpus
    c.Spawner.cmd = [str(layout.env / "bin" / "python"), "-m", "annslam_lib", "singleuser",
                     "--release", str(layout.release), "--"]
    c.Spawner.default_url = "/lab"
    c.Spawner.pre_spawn_hook = pre_spawn
    # A class on one machine starts servers slowly (about 4 s of imports each, CPU-bound).
    c.Spawner.start_timeout = 120
    c.Spawner.http_timeout = 120

    token = _settings.hub_admin_token(env)
    if token:
        c.JupyterHub.services = [{"name": "course-admin", "api_token": token}]
        c.JupyterHub.load_roles = [{
            "name": "course-admin", "services": ["course-admin"],
            "scopes": ["admin:users", "admin:servers", "access:servers", "list:users",
                       "read:users", "tokens"]}]


def check_spawner(c) -> None:
    """Refuse a spawner without per-student isolation (module docstring)."""
    name = c.JupyterHub.spawner_class
    name = name if isinstance(name, str) else f"{name.__module__}.{name.__qualname__}"
    if name in REFUSED_SPAWNERS or name.endswith("SimpleLocalProcessSpawner"):
        raise HubError("SimpleLocalProcessSpawner runs every student's server as the hub's "
                       "user, so any student could read every other's files: use "
                       "LocalProcessSpawner (the default), DockerSpawner or KubeSpawner")
