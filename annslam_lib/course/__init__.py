"""Course layer: what instructors and students run around the notebooks.

- ``release``: the student versions (nbgrader's format), their checks for leaks
- ``site``: the course as a static website, read from the stored outputs
- ``site_render``: the website's notebook renderer (pictures keep their alt text)
- ``launch``: links that open a chapter on a JupyterHub (nbgitpuller), Binder or Colab
- ``publish``: the student release as a branch of a git repository, for those links to pull
- ``workspace``: a student's own copy of the course, never overwritten
- ``pacing``: how long each chapter takes a student, estimated from the notebooks
- ``grader``: scores from the instructor's notebook, decided outside the student's code
- ``plan``: the instructor's notebook read as the skeleton of a grade; a solution's names
- ``similarity``: copied code found by comparing solutions' normalised syntax trees
- ``integrity``: what the grader loads and watches (its bytecode, the course's files), inert
  reports
- ``sandbox``: the kernel that runs student code (bubblewrap, no privilege, limits, time-outs)
- ``cgroup``: a control group per sandbox (or student's server), bounding its processes'
  memory, number and CPU together
- ``confine``: the sandbox's launcher (limits, the drop of privilege, the system-call filter)
- ``codec``: data, never code, between the grader and that kernel
- ``kernel_side``: runs inside the sandboxed kernel: the grader's calls of the student's
  functions
- ``kernels``: runs in the course's own tools: Run All of a notebook on a fresh kernel, with a
  notebook client that cannot stall silently
- ``warm``: the study cache filled for a class by one Run All of every notebook
- ``hub``: a class on JupyterHub (a subpackage): the class list, one Unix account per
  student, the hub folder, its set-up, JupyterHub's settings and the instructor's steps
- ``cli``: ``python -m annslam_lib ...``
"""

__all__ = ["release", "site", "site_render", "launch", "publish", "workspace", "pacing", "grader", "plan", "similarity", "integrity",
           "sandbox", "cgroup", "confine", "codec", "kernel_side", "kernels", "warm", "hub",
           "cli"]
