"""Memory, CPU and process limits a student's server and kernels cannot break on the class
hub.

JupyterHub's ``LocalProcessSpawner`` reads ``mem_limit`` and ``cpu_limit`` but enforces
neither. :func:`spawner_class` is that spawner with the limits enforced by a control group
per student (``annslam_lib.course.cgroup``: cgroup v2, or v1's memory, pids and cpu
hierarchies): the server joins its group before it runs a line of its own (in the forked
process, while still root, before it becomes the student), and every kernel it starts is
in it too. Past the memory limit the kernel's kernel kills the group's largest process (a
notebook kernel that hoards memory: the server stays, JupyterLab offers to restart it); a
fork bomb stops at the process limit; a busy loop gets its CPU share and no more. Other
students' servers are in groups of their own. The group is ``annslam-hub/<student>`` in each
hierarchy, made anew at each start and removed, with whatever is left in it, at the stop.

The limits are the spawner's own settings (``c.Spawner.mem_limit``, ``c.Spawner.cpu_limit``)
and ``c.LimitedSpawner.processes``; :data:`DEFAULTS` gives the class hub's. Where no control
group can be made (not root; no cgroup controllers), the hub does not start: a class without
its limits is what this module is for.
"""
from __future__ import annotations

import contextlib
import dataclasses
import os

from .. import cgroup
from . import HubError

__all__ = ["Limits", "DEFAULTS", "PARENT", "confine", "spawner_class", "check"]

#: The folder of the students' control groups in each hierarchy.
PARENT = "annslam-hub"


@dataclasses.dataclass(frozen=True)
class Limits:
    """One student's server and kernels together: memory (bytes, no swap), CPUs (processors'
    worth of time) and processes."""
    memory: int = 1536 * 1024**2
    cpus: float = 1.0
    processes: int = 512


#: The class hub's limits, the same as ``hub/z2jh/config.yaml``'s: an idle server with a
#: kernel that ran a chapter holds well under 1 GiB (``benchmarks/hub_load.py``); a chapter's
#: Run All keeps one core busy.
DEFAULTS = Limits()


def confine(student: str, limits: Limits) -> cgroup.Group:
    """The student's control group, made anew with ``limits`` (an old one, with whatever
    still runs in it, removed first). Raises HubError where none can be made."""
    with contextlib.suppress(OSError):
        for hierarchy in ("", "memory", "pids", "cpu"):
            old = cgroup.ROOT / hierarchy / PARENT / student
            if old.is_dir():
                cgroup.Group([old], 2 if not hierarchy else 1).remove()
    group, why = cgroup.make(limits.memory, limits.processes, limits.cpus, parent=PARENT,
                             name=student)
    if group is None:
        raise HubError(f"the limits of {student}'s server cannot be enforced here: {why}")
    return group


def check() -> str:
    """Why the hub could not enforce its limits here ('' when it can): made and removed."""
    try:
        group = confine("annslam-check", Limits(1 << 30, 1.0, 64))
    except HubError as e:
        return str(e)
    group.remove()
    return ""


def spawner_class():
    """``LocalProcessSpawner`` with its limits enforced (module docstring). Imported by the
    hub's process only (JupyterHub is not in the students' or the course's environment)."""
    from jupyterhub.spawner import LocalProcessSpawner
    from traitlets import Integer

    class LimitedSpawner(LocalProcessSpawner):
        processes = Integer(DEFAULTS.processes, config=True,
                            help="the most processes a student's server and kernels hold")

        def limits(self) -> Limits:
            return Limits(int(self.mem_limit or DEFAULTS.memory),
                          float(self.cpu_limit or DEFAULTS.cpus), int(self.processes))

        def make_preexec_fn(self, name):
            demote = super().make_preexec_fn(name)
            procs = [str(p) for p in self._group.procs]

            def join_then_demote():           # in the forked child, still root
                for p in procs:
                    with open(p, "w") as f:
                        f.write(str(os.getpid()))
                demote()
            return join_then_demote

        async def start(self):
            self._group = confine(self.user.name, self.limits())
            return await super().start()

        async def stop(self, now=False):
            await super().stop(now=now)
            group = getattr(self, "_group", None)
            if group is not None:
                group.remove()                # the kernels the server left behind too

    return LimitedSpawner
