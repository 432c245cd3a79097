"""Course layer: what instructors and students run around the notebooks.

- ``release``: the student versions (nbgrader's format), their checks for leaks
- ``workspace``: a student's own copy of the course, never overwritten
- ``grader``: scores from the instructor's notebook, decided outside the student's code
- ``plan``: the instructor's notebook read as the skeleton of a grade; a solution's names
- ``sandbox``: the kernel that runs student code (bubblewrap, limits, time-outs, deadline)
- ``codec``: data, never code, between the grader and that kernel
- ``kernel_side``: the grader's small helper inside the kernel
- ``kernels``: Run All on a fresh kernel with a client that cannot stall silently
- ``cli``: ``python -m annslam_lib ...``
"""

__all__ = ["release", "workspace", "grader", "plan", "sandbox", "codec", "kernel_side",
           "kernels", "cli"]
