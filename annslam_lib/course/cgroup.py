"""A control group per sandbox (or per student's server on the class hub): memory,
processes and, if asked, CPU bounded for the whole submission.

``setrlimit`` bounds each process (its address space, the processes of its user); a
submission that forks spreads past any one of them (256 processes of 4 GB each). A control
group bounds them together: every process of the sandbox, its memory folders' pages
included, within ``memory`` bytes (no swap), at most ``processes`` tasks. Made by root, in
cgroup v2 (``/sys/fs/cgroup`` with the memory and pids controllers) or in cgroup v1's
memory and pids hierarchies; :func:`make` returns None, with the reason, where neither can
be written (an ordinary user, a container without them): the per-process limits are then
all there is, and the grader says so.
"""
from __future__ import annotations

import contextlib
import os
import signal
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Group", "make", "unavailable"]

ROOT = Path("/sys/fs/cgroup")
PARENT = "annslam-grade"


@dataclass
class Group:
    """One sandbox's control group: its folders (one in v2, one per controller in v1)."""
    folders: list[Path]
    version: int

    @property
    def procs(self) -> list[Path]:
        """The files a process joins the group by writing its pid into."""
        return [f / "cgroup.procs" for f in self.folders]

    def pids(self) -> list[int]:
        out = set()
        for f in self.procs:
            with contextlib.suppress(OSError, ValueError):
                out |= {int(x) for x in f.read_text().split()}
        return sorted(out)

    def peak_memory(self) -> int | None:
        """The most memory the group held, in bytes (None where the kernel does not say)."""
        name = "memory.peak" if self.version == 2 else "memory.max_usage_in_bytes"
        for f in self.folders:
            with contextlib.suppress(OSError, ValueError):
                return int((f / name).read_text())
        return None

    def kill(self) -> None:
        """Every process of the group, killed."""
        if self.version == 2 and (self.folders[0] / "cgroup.kill").exists():
            with contextlib.suppress(OSError):
                (self.folders[0] / "cgroup.kill").write_text("1")
        for pid in self.pids():
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)

    def remove(self, wait: float = 5.0) -> bool:
        """Kill what is left and remove the group's folders; False if one stays."""
        end = time.monotonic() + wait
        while True:
            self.kill()
            for f in self.folders:
                with contextlib.suppress(OSError):
                    f.rmdir()
            if not any(f.exists() for f in self.folders) or time.monotonic() > end:
                return not any(f.exists() for f in self.folders)
            time.sleep(0.05)


def _write(path: Path, value) -> None:
    path.write_text(str(value))


#: The scheduler's period for a CPU limit, in microseconds (the kernel's default).
CPU_PERIOD = 100_000


def _v2(memory: int, processes: int, cpus, parent: str, name: str) -> Group:
    want = {"memory", "pids"} | ({"cpu"} if cpus else set())
    controllers = set((ROOT / "cgroup.controllers").read_text().split())
    if not want <= controllers:
        raise OSError(f"cgroup v2 without the {' and '.join(sorted(want))} controllers "
                      f"({sorted(controllers)})")
    enable = " ".join(f"+{c}" for c in sorted(want))
    if not want <= set((ROOT / "cgroup.subtree_control").read_text().split()):
        _write(ROOT / "cgroup.subtree_control", enable)
    top = ROOT / parent
    top.mkdir(exist_ok=True)
    if not want <= set((top / "cgroup.subtree_control").read_text().split()):
        _write(top / "cgroup.subtree_control", enable)
    g = top / name
    g.mkdir()
    _write(g / "memory.max", memory)
    if (g / "memory.swap.max").exists():
        _write(g / "memory.swap.max", 0)
    _write(g / "pids.max", processes)
    if cpus:
        _write(g / "cpu.max", f"{round(cpus * CPU_PERIOD)} {CPU_PERIOD}")
    return Group([g], 2)


def _v1(memory: int, processes: int, cpus, parent: str, name: str) -> Group:
    mem, pids = ROOT / "memory" / parent / name, ROOT / "pids" / parent / name
    folders = [mem, pids] + ([ROOT / "cpu" / parent / name] if cpus else [])
    try:
        for f in folders:
            f.mkdir(parents=True)
        _write(mem / "memory.limit_in_bytes", memory)
        if (mem / "memory.memsw.limit_in_bytes").exists():
            _write(mem / "memory.memsw.limit_in_bytes", memory)
        if (mem / "memory.swappiness").exists():
            with contextlib.suppress(OSError):
                _write(mem / "memory.swappiness", 0)
        _write(pids / "pids.max", processes)
        if cpus:
            _write(folders[2] / "cpu.cfs_period_us", CPU_PERIOD)
            _write(folders[2] / "cpu.cfs_quota_us", round(cpus * CPU_PERIOD))
    except OSError:
        for f in folders:
            with contextlib.suppress(OSError):
                f.rmdir()
        raise
    return Group(folders, 1)


def make(memory: int, processes: int, cpus: float | None = None, *, parent: str = PARENT,
         name: str | None = None) -> tuple[Group | None, str]:
    """A new control group bounding ``memory`` bytes, ``processes`` tasks and, with
    ``cpus``, the CPU time to that many processors' worth, and '' ; or None and why none
    can be made here. It is ``parent/name`` (a fresh name by default) in each hierarchy."""
    if os.geteuid() != 0:
        return None, "the grader does not run as root"
    if cpus is not None and not cpus > 0:
        raise ValueError(f"cpus must be a positive number of processors, got {cpus!r}")
    name = name or uuid.uuid4().hex
    errors = []
    if (ROOT / "cgroup.controllers").exists():
        try:
            return _v2(memory, processes, cpus, parent, name), ""
        except OSError as e:
            errors.append(f"cgroup v2: {e}")
    if ((ROOT / "memory" / "memory.limit_in_bytes").exists() and (ROOT / "pids").is_dir()
            and (not cpus or (ROOT / "cpu" / "cpu.cfs_quota_us").exists())):
        try:
            return _v1(memory, processes, cpus, parent, name), ""
        except OSError as e:
            errors.append(f"cgroup v1: {e}")
    return None, "; ".join(errors) or "no cgroup v2 and no cgroup v1 memory and pids controllers"


def unavailable() -> str:
    """Why no control group can be made here ('' when one can): made and removed once."""
    g, why = make(1 << 30, 64)
    if g is not None:
        g.remove()
    return why
