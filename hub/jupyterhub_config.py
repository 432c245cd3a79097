# JupyterHub configuration of a class hub, started by ./course.sh hub (python -m annslam_lib
# hub), which prepares the hub folder and passes the settings in ANNSLAM_HUB_* variables:
# annslam_lib/course/hub/config.py says what each one is, and how to swap the authenticator
# (a university's OAuth or LTI login) or the spawner (DockerSpawner, or KubeSpawner through
# Zero to JupyterHub: hub/z2jh/config.yaml).
from annslam_lib.course.hub.config import check_spawner, configure

c = get_config()  # noqa: F821 (JupyterHub's config loader defines it)
configure(c)

# Changes of your own go here, between configure() and check_spawner(), which refuses a
# spawner that gives no per-student isolation (SimpleLocalProcessSpawner). For example,
# idle servers stopped after 30 minutes instead of an hour:
#   import sys
#   from annslam_lib.course.hub.config import idle_culler
#   c.JupyterHub.services[0] = idle_culler(sys.executable, timeout=1800)

check_spawner(c)
