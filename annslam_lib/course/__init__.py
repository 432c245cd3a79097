"""Course layer: what instructors and students run around the notebooks.

- ``release``: the student versions (nbgrader's format), their checks for leaks
- ``workspace``: a student's own copy of the course, never overwritten
- ``grader``: scores from the instructor's notebook, decided outside the student's code
- ``plan``: the instructor's notebook read as the skeleton of a grade; a solution's names
- ``integrity``: what the grader loads and watches (its bytecode, the course's files), inert
  reports
- ``sandbox``: the kernel that runs student code (bubblewrap, no privilege, limits, time-outs)
- ``confine``: the sandbox's launcher (limits, the drop of privilege, the system-call filter)
- ``codec``: data, never code, between the grader and that kernel
- ``kernel_side``: the grader's small helper inside the kernel
- ``kernels``: Run All on a fresh kernel with a client that cannot stall silently
- ``hub``: a class on JupyterHub: the class list, one Unix account per student, the hub folder
- ``hub_config``: JupyterHub's settings for that class (``hub/jupyterhub_config.py``)
- ``hub_setup``: the hub folder prepared (students' environment, release, data, proxy), the start
- ``hub_class``: the instructor's steps through nbgrader's exchange (release, collect, grade,
  feedback)
- ``cli``: ``python -m annslam_lib ...``
"""

__all__ = ["release", "workspace", "grader", "plan", "integrity", "sandbox", "confine", "codec",
           "kernel_side", "kernels", "hub", "hub_config", "hub_setup", "hub_class", "cli"]
