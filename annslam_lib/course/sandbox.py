"""A Jupyter kernel for untrusted student code: no privilege, nothing but its own notebook.

Each submission gets a fresh scratch folder (mode 700, deleted afterwards) holding a
read-only snapshot of ``annslam_lib`` that the kernel imports instead of the instructor's
editable source, the kernel's connection file and its IPC sockets. The kernelspec and the
kernel's log stay in the scratch folder's private part, which the kernel never sees.

**Isolation 'bwrap'** (the default, and the only one a class is graded with): the kernel is
started by bubblewrap in a file system built from nothing: the system's programs and
libraries (``/usr`` and its links, a few files of ``/etc``), the Python environment and the
course's data, all read-only, the library snapshot and connection file read-only, the IPC
folder writable, and size-limited memory folders for its working directory, its home,
``/tmp`` and ``/dev/shm``. Nothing else exists there: not the course's checkout (its
``.git`` and instructor notebooks), not the folders the grader names in ``hide`` (other
submissions, the exchange, the gradebook). A folder the environment needs that holds a
hidden one is rebuilt from its other entries. Its own PID, IPC, UTS and network namespaces
(the grader talks to it over Unix sockets in the IPC folder), a new session, killed with
the grader.

Whoever starts the grader, the student's code holds no privilege
(:mod:`annslam_lib.course.confine`): started as root, the kernel becomes a user of its own
(:func:`free_id`: an id no account and no process has, so that sandboxes never share a
process limit) with an empty capability set and bounding set; started by an ordinary user,
bubblewrap maps that user into its own user namespace and drops every capability. In both
cases ``no_new_privs`` and a seccomp filter refuse mounts, namespaces, ``ptrace`` and
kernel loading, and the resource limits (CPU seconds, address space, file size, processes)
are set before the drop, so they bind. Started as root, the sandbox's processes together
hold at most the memory limit and the process limit (:mod:`~annslam_lib.course.cgroup`). The only other process in the sandbox is its PID 1,
the launcher that started the kernel, with the same user, limits and filter.

**Isolation 'none'** runs the kernel as the grader's own user, with the limits only: for a
single trusted notebook on a laptop, never for a class (the grader says so in its report).
Without a working bubblewrap, ``auto`` refuses with :class:`GradingEnvironmentError`,
naming the cause and the fix.

A kernel that cannot start raises :class:`KernelStartError` with what it wrote; the grader
turns the first one of a submission (no student code has run yet) into a
:class:`GradingEnvironmentError`, the machine's fault, never a score. Each execution has a
time-out and the whole notebook a wall-clock deadline. A kernel that dies (``os._exit``, a
signal, the CPU limit) is noticed within a fraction of a second and reported as such, not
as a time-out; one that ignores the interrupt after its time-out is killed.
"""
from __future__ import annotations

import contextlib
import functools
import json
import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from .. import _settings
from . import cgroup

__all__ = ["Limits", "ExecResult", "Sandbox", "GradingEnvironmentError", "KernelStartError",
           "bwrap_available", "bwrap_problem", "interpreter_paths", "mount_plan", "ISOLATIONS",
           "SANDBOX_IDS", "free_id", "NO_SANDBOX_WARNING"]

LIB = Path(__file__).resolve().parents[1]          # the annslam_lib package
COURSE = LIB.parent                                # the course's checkout: never in a sandbox
ISOLATIONS = ("auto", "bwrap", "none")
# The user and group ids a sandbox started by root runs as: one per sandbox, that no account
# names and no process uses, so that two sandboxes never share a process limit (it counts
# per user) and nothing of the machine's own runs as the sandbox's user.
SANDBOX_IDS = range(0x60000000, 0x60000000 + (1 << 24))
_POLL_S = 0.1
# What the kernel needs of the system, read-only; everything else of /etc stays out.
SYSTEM = ("/usr", "/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32")
ETC = ("ld.so.cache", "ld.so.conf", "ld.so.conf.d", "passwd", "group", "nsswitch.conf",
       "localtime", "timezone", "alternatives", "mime.types", "os-release")
NO_SANDBOX_WARNING = ("UNISOLATED: the student's code ran with the grader's own rights "
                      "(isolation 'none'); use it only for a trusted notebook")


def _fix() -> str:
    return ("install bubblewrap (Debian/Ubuntu: apt-get install bubblewrap) and, when the "
            "grader does not run as root, allow unprivileged user namespaces; or, for a single "
            "trusted notebook only, pass --isolation none")


class GradingEnvironmentError(RuntimeError):
    """The grading machine, not the submission, is at fault: the sandbox cannot be made, or
    a kernel with no student code in it cannot start or import the course's library. Never
    turned into a student's score: the grade command stops and names the cause."""


class KernelStartError(RuntimeError):
    """A kernel of the sandbox did not start (the first one: the environment's fault)."""


@dataclass(frozen=True)
class Limits:
    """Bounds on one submission: CPU seconds and address space of the kernel process,
    largest file it may write, processes, seconds per cell and per call of a student's
    function, and the wall-clock deadline of the whole notebook."""
    cpu_seconds: int = 600
    memory_bytes: int = 4 << 30
    file_bytes: int = 256 << 20
    processes: int = 256
    cell_timeout: float = 120.0
    call_timeout: float = 30.0
    deadline: float = 600.0


@dataclass
class ExecResult:
    """One execution: status 'ok', 'error' (ename, evalue), 'timeout' or 'died' (how, in
    ``evalue``); ``alive``: whether the kernel can take the next request; seconds taken."""
    status: str
    ename: str = ""
    evalue: str = ""
    user_expressions: dict | None = None
    seconds: float = 0.0
    alive: bool = True

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def reason(self) -> str:
        if self.status == "error":
            return f"{self.ename}: {self.evalue}"
        return self.evalue


def bwrap_available() -> str | None:
    """Path of a ``bwrap`` that makes the sandbox here (tried once, exactly as a kernel is
    started, the drop of privilege and the filter included), or None; :func:`bwrap_problem`
    says why not."""
    exe, _ = _bwrap_probe()
    return exe


def bwrap_problem() -> str:
    """Why the sandbox cannot be made here, with the fix ('' when it can)."""
    return _bwrap_probe()[1]


@functools.lru_cache(maxsize=1)
def _bwrap_probe() -> tuple[str | None, str]:
    exe = shutil.which("bwrap")
    if exe is None:
        return None, f"bubblewrap (bwrap) is not installed: {_fix()}"
    with tempfile.TemporaryDirectory(prefix="annslam-probe-") as tmp:
        lib = Path(tmp) / "lib"
        (lib / "course").mkdir(parents=True)
        shutil.copyfile(Path(__file__).with_name("confine.py"), lib / "course" / "confine.py")
        os.chmod(tmp, 0o755)
        for p in (lib, lib / "course"):
            os.chmod(p, 0o755)
        os.chmod(lib / "course" / "confine.py", 0o644)
        cfg = {**_limits_config(Limits()), "check": True}
        args = [exe, *_namespace_args(), *_bind_args(mount_plan(
            _needed_paths(), _optional_paths(), [COURSE], first=_memory_folders(1 << 20),
            extra=[("ro-bind", lib, lib)])),
            "--", sys.executable, "-I", str(lib / "course" / "confine.py"), json.dumps(cfg)]
        try:
            r = subprocess.run(args, capture_output=True, timeout=60, env=_base_env())
        except (OSError, subprocess.TimeoutExpired) as e:
            return None, f"{exe} could not be run: {e}"
    if r.returncode != 0:
        said = r.stderr.decode(errors="replace").strip().splitlines() or ["?"]
        return None, (f"{exe} is installed but cannot make the sandbox here (exit code "
                      f"{r.returncode}: {said[-1][:300]}); unprivileged user namespaces may be "
                      f"disabled, or the Python environment is not readable by the sandbox's "
                      f"user (a user id of its own when the grader is root): {_fix()}")
    return exe, ""


def _memory_folders(size: int) -> list[tuple]:
    return [("tmpfs", Path("/tmp"), size, "1777"), ("tmpfs", Path("/dev/shm"), size, "1777")]


def free_id() -> int:
    """A user id of :data:`SANDBOX_IDS` that no account names, no group has and no process
    of this machine runs as (used for the group id too)."""
    import grp
    import pwd
    import random

    used = set()
    for d in os.listdir("/proc"):
        if d.isdigit():
            with contextlib.suppress(OSError):
                st = os.stat(f"/proc/{d}")
                used.add(st.st_uid)
    rng = random.SystemRandom()
    for _ in range(100):
        n = rng.choice(SANDBOX_IDS)
        if n in used:
            continue
        try:
            pwd.getpwuid(n)
            continue
        except KeyError:
            pass
        try:
            grp.getgrgid(n)
            continue
        except KeyError:
            return n
    raise GradingEnvironmentError("no free user id for the sandbox in "
                                  f"{SANDBOX_IDS.start}-{SANDBOX_IDS.stop - 1}")


def _limits_config(limits: Limits, uid: int | None = None) -> dict:
    uid = free_id() if uid is None else uid
    return {"cpu": int(limits.cpu_seconds), "mem": int(limits.memory_bytes),
            "fsize": int(limits.file_bytes), "nproc": int(limits.processes),
            "uid": uid, "gid": uid, "confine": True}


def _base_env() -> dict:
    keep = ("PATH", "LANG", "LC_ALL", "TZ")
    return {k: os.environ[k] for k in keep if k in os.environ}


def _namespace_args() -> list[str]:
    """bubblewrap's namespaces and session. The sandbox's PID 1 is the course's launcher
    (:mod:`~annslam_lib.course.confine`), not bubblewrap's: no process without the drop and
    the filter whose memory the kernel could reach as the same user. Root: bubblewrap's
    own privileged mode, and the launcher drops to a user id of its own (:func:`free_id`):
    a user namespace created by root would map the sandbox's user onto uid 0 outside, which
    owns root's files and is exempt from the process limit. Anyone else: a user namespace,
    no capability."""
    args = ["--unshare-pid", "--as-pid-1", "--unshare-ipc", "--unshare-net", "--unshare-uts",
            "--unshare-cgroup-try", "--new-session", "--die-with-parent",
            "--hostname", "sandbox", "--proc", "/proc", "--dev", "/dev"]
    if os.geteuid() != 0:
        args += ["--unshare-user", "--cap-drop", "ALL"]
    return args


def _chain(path: Path) -> list[Path]:
    """``path`` and each link it leads through, hop by hop (a venv's python links to its
    base interpreter, which may link on)."""
    out = [path]
    for _ in range(40):                           # follow the chain of links, hop by hop
        if not path.is_symlink():
            break
        path = path.parent / os.readlink(path)
        out.append(path)
    return out


def _needed_paths() -> list[Path]:
    """What the kernel cannot run without: the system's folders, the environment's
    prefixes, every folder on the way from ``sys.executable`` to the real binary (a venv's
    python links to its base interpreter), and the course's data."""
    from ..data import fetch

    found = [Path(p) for p in SYSTEM] + [Path("/etc") / n for n in ETC]
    found += [Path(p) for p in {sys.prefix, sys.base_prefix, sys.exec_prefix,
                                 sys.base_exec_prefix}]
    found += [p.parent for p in _chain(Path(sys.executable))]
    found.append(Path(os.path.realpath(sys.executable)).parent)
    found.append(fetch.data_dir())
    return [p.absolute() for p in found if os.path.lexists(p)]


def _optional_paths() -> list[Path]:
    """The folders on ``sys.path`` that belong to the environment: those inside its
    prefixes, and those a ``.pth`` file of its site-packages adds (which may lie outside).
    Never the grader's working directory or ``PYTHONPATH``, which may hold anything; bound
    only when they hold nothing hidden (:func:`mount_plan`)."""
    prefixes = {Path(p).resolve() for p in (sys.prefix, sys.base_prefix, sys.exec_prefix,
                                            sys.base_exec_prefix)}
    inside = [Path(p).resolve() for p in sys.path
              if p and Path(p).is_dir() and any(_within(Path(p).resolve(), q) for q in prefixes)]
    added = set()
    for site in inside:
        for pth in site.glob("*.pth"):
            with contextlib.suppress(OSError, UnicodeDecodeError):
                for line in pth.read_text().splitlines():
                    line = line.strip()
                    if line and not line.startswith(("#", "import ", "import\t")):
                        d = (site / line).resolve()
                        if d.is_dir():
                            added.add(d)
    return [Path(p).absolute() for p in sys.path if p and Path(p).is_dir()
            and (Path(p).resolve() in inside or Path(p).resolve() in added)]


def interpreter_paths() -> list[Path]:
    """Every folder the kernel's interpreter may need (:func:`_needed_paths` but the system
    and the data, and the folders on ``sys.path``), as given and resolved."""
    from ..data import fetch

    skip = {Path(p) for p in SYSTEM} | {fetch.data_dir().absolute()}
    found = [p for p in _needed_paths() if p not in skip and p.parent != Path("/etc")]
    found += _optional_paths()
    out = []
    for p in found:
        for q in (p, p.resolve()):
            if q.exists() and q not in out:
                out.append(q)
    return out


def _within(p: Path, folder: Path) -> bool:
    return p == folder or folder in p.parents


def mount_plan(needed, optional, hidden, *, first=(), extra=()) -> list[tuple]:
    """The sandbox's file system as a list of steps, in order: ('dir', path), ('symlink',
    target, path), ('ro-bind', source, dest), ('bind', source, dest), ('tmpfs', path,
    size in bytes, mode).

    ``needed`` paths are reachable in the sandbox at the same place as on this machine (the
    links on their way recreated as links, the folders they lead to bound read-only);
    ``optional`` ones too, unless they are, hold or lie in a ``hidden`` folder. A needed
    folder that holds a hidden one is rebuilt from its other entries, so the hidden folder
    is not there at all (nothing to unmount); a needed path inside a hidden folder is bound
    alone. ``first`` steps (memory folders such as ``/tmp``) come before the binds, which
    may lie inside them; ``extra`` steps (the scratch folder's parts) come last."""
    hidden = [Path(os.path.realpath(h)) for h in hidden]
    steps: list[tuple] = []
    links: dict[Path, str] = {}
    real_needed: list[Path] = []

    def reach(p: Path) -> Path:
        """Record the links on the way to ``p``; its real path."""
        cur = Path("/")
        parts = p.parts[1:]
        for i, part in enumerate(parts):
            nxt = cur / part
            if nxt.is_symlink():
                links.setdefault(nxt, os.readlink(nxt))
                real = Path(os.path.realpath(nxt))
                return reach(real.joinpath(*parts[i + 1:]))
            cur = nxt
        return cur

    for p in needed:
        real_needed.append(reach(Path(p)))
    for p in optional:
        real = Path(os.path.realpath(p))
        if any(_within(real, h) or _within(h, real) for h in hidden):
            continue
        reach(Path(p))
        real_needed.append(real)
    binds: list[Path] = []

    def covered(r: Path) -> bool:               # by a bind, and not cut out of it as hidden
        return any(_within(r, b) and not any(_within(r, h) and _within(h, b) for h in hidden)
                   for b in binds)

    for r in sorted(set(real_needed), key=lambda q: (len(q.parts), str(q))):
        if r.exists() and not covered(r):
            binds.append(r)
    made: set[Path] = set()

    def ensure_dir(d: Path) -> None:
        for a in [*reversed(d.parents), d]:
            if a != Path("/") and a not in made and a not in links:
                steps.append(("dir", a))
                made.add(a)

    def bind(r: Path) -> None:
        inner = [h for h in hidden if _within(h, r)]
        if not inner:
            ensure_dir(r.parent)
            steps.append(("ro-bind", r, r))
            made.add(r)
            return
        if r in inner or not r.is_dir():
            return                                   # the path itself is hidden
        ensure_dir(r)
        for child in sorted(r.iterdir()):
            if any(child == h for h in inner):
                continue
            if child.is_symlink():
                steps.append(("symlink", os.readlink(child), child))
                made.add(child)
            elif any(_within(h, child) for h in inner):
                bind(child)
            else:
                steps.append(("ro-bind", child, child))
                made.add(child)

    for step in first:
        ensure_dir(_dest(step).parent)
        steps.append(step)
        made.add(_dest(step))
    for link, target in sorted(links.items(), key=lambda kv: len(kv[0].parts)):
        if not covered(link):
            ensure_dir(link.parent)
            steps.append(("symlink", target, link))
            made.add(link)
    for r in binds:
        bind(r)
    for step in extra:
        ensure_dir(_dest(step).parent)
        steps.append(step)
    return steps


def _dest(step) -> Path:
    return Path(step[1] if step[0] in ("dir", "tmpfs") else step[2])


def _bind_args(steps) -> list[str]:
    args = []
    for step in steps:
        kind = step[0]
        if kind == "dir":
            args += ["--perms", "0755", "--dir", str(step[1])]
        elif kind == "symlink":
            args += ["--symlink", str(step[1]), str(step[2])]
        elif kind in ("ro-bind", "bind"):
            args += [f"--{kind}", str(step[1]), str(step[2])]
        elif kind == "tmpfs":                        # ('tmpfs', path, bytes, mode)
            args += ["--perms", step[3], "--size", str(int(step[2])), "--tmpfs", str(step[1])]
        else:
            raise ValueError(f"unknown mount step {step!r}")
    return args


# Run by the grader's user just before bubblewrap: join the sandbox's control group (each
# cgroup.procs file given before "--"), then become bubblewrap, so that nothing of the
# sandbox ever runs outside the group.
_JOIN = 'while [ "$1" != -- ]; do echo $$ > "$1" || exit 97; shift; done; shift; exec "$@"'


def _bounded_channels(kc) -> None:
    """A kernel's messages bounded in the grader: the output channel (which the grader only
    drains) takes messages of at most 1 MB and queues at most 64; the others a reply as
    large as the codec allows. A larger message ends that connection, never the grader."""
    import zmq

    from .codec import MAX_BYTES

    kc.context.setsockopt(zmq.MAXMSGSIZE, 1 << 20)
    kc.context.setsockopt(zmq.RCVHWM, 64)
    kc.iopub_channel                              # made now, with those options  # noqa: B018
    kc.context.setsockopt(zmq.MAXMSGSIZE, 2 * MAX_BYTES + (1 << 20))
    kc.context.setsockopt(zmq.RCVHWM, 1000)


def _describe_exit(code: int | None) -> str:
    if code is None:
        return "it stopped answering"
    sig = -code if code < 0 else code - 128 if code > 128 else None
    if sig is not None and sig in signal.Signals._value2member_map_:
        name = signal.Signals(sig).name
        why = {"SIGXCPU": " (its CPU-time limit)", "SIGKILL": " (killed: memory or a limit)",
               "SIGSEGV": " (a crash)"}.get(name, "")
        return f"it was ended by {name}{why}"
    return f"it exited with code {code}"


class Sandbox:
    """A scratch folder and the kernel that runs one submission (a context manager).

    ``isolation``: 'auto' or 'bwrap' (the sandbox of the module docstring; raises
    :class:`GradingEnvironmentError` with the cause and the fix where it cannot be made),
    or 'none'. ``hide``: folders that must not exist in the sandbox besides the course's
    checkout (the instructor's notebooks, other submissions, the gradebook)."""

    def __init__(self, limits: Limits = Limits(), *, isolation: str = "auto",
                 hide=(), user: str | None = None) -> None:
        if isolation not in ISOLATIONS:
            raise ValueError(f"isolation must be one of {ISOLATIONS}, got {isolation!r}")
        # the hub user the notebook ran as (a lab drawn per student draws the same in the
        # replay); the score never depends on it: checks read the grader's own record
        self.user = user if user and re.fullmatch(r"[A-Za-z0-9_.@+-]{1,64}", user) else None
        if isolation in ("auto", "bwrap"):
            if not bwrap_available():
                raise GradingEnvironmentError(f"the grading sandbox cannot be made here: "
                                              f"{bwrap_problem()}")
            isolation = "bwrap"
        self.isolation = isolation
        self.limits = limits
        self.hide = [Path(h).resolve() for h in hide]
        self.root = Path(tempfile.mkdtemp(prefix="annslam-grade-"))   # mode 700
        self.lib = self.root / "lib"
        self.conn = self.root / "conn"          # connection files: written here, read inside
        self.ipc = self.root / "ipc"            # the kernels' sockets, a folder for each
        self.work = self.root / "work"
        self.home = self.root / "home"
        self.private = self.root / "private"    # kernelspec and logs: never in the sandbox
        for d in (self.conn, self.ipc, self.work, self.home, self.private / "kernels" / "sandbox"):
            d.mkdir(parents=True)
        shutil.copytree(LIB, self.lib / LIB.name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.nb[ic]"))
        for p in [self.lib, *self.lib.rglob("*")]:       # readable, not writable, by the kernel
            os.chmod(p, 0o755 if p.is_dir() else 0o644, follow_symlinks=False)
        os.chmod(self.conn, 0o755)      # bound into the sandbox; the scratch folder stays 700
        self.group = None                 # memory and processes bounded together (cgroup)
        self.group_problem = "no sandbox"
        if self.isolation == "bwrap":
            self.group, self.group_problem = cgroup.make(limits.memory_bytes, limits.processes)
        self.uid = free_id() if self.isolation == "bwrap" and os.geteuid() == 0 else None
        if self.uid is not None:
            for d in (self.work, self.home):
                os.chown(d, self.uid, self.uid)
        os.chmod(self.ipc, 0o755)       # each kernel's sockets in a folder of their own
        self._write_kernelspec()
        self.km = self.kc = None
        self._lifeline: int | None = None
        self.deadline = time.monotonic() + limits.deadline
        self.kernels_started = 0
        self.dead_reason = ""

    # ------------------------------------------------------------------ kernel life
    def mount_steps(self) -> list[tuple]:
        """The sandbox's file system (:func:`mount_plan`): the system, the environment and
        the data read-only; the snapshot and the connection files read-only, the IPC folder
        writable; memory folders (each at most the file-size limit) for the working
        directory, the home, ``/tmp`` and ``/dev/shm``."""
        size = self.limits.file_bytes
        first = _memory_folders(size)
        extra = [("ro-bind", self.lib, self.lib), ("ro-bind", self.conn, self.conn),
                 ("bind", self.ipc, self.ipc), ("tmpfs", self.work, size, "0777"),
                 ("tmpfs", self.home, size, "0777")]
        hidden = [COURSE, *self.hide]
        return mount_plan(_needed_paths(), _optional_paths(), hidden, first=first, extra=extra)

    def _prefix(self) -> list[str]:
        if self.isolation != "bwrap":
            return []
        join = []
        if self.group is not None:               # bubblewrap started inside the group
            join = ["/bin/sh", "-c", _JOIN, "sh", *map(str, self.group.procs), "--"]
        return [*join, bwrap_available(), *_namespace_args(), *_bind_args(self.mount_steps()),
                "--chdir", str(self.work), "--"]

    def _write_kernelspec(self) -> None:
        cfg = _limits_config(self.limits, self.uid or 0)
        cfg["confine"] = cfg["reaper"] = self.isolation == "bwrap"
        argv = [*self._prefix(), sys.executable, "-I", str(self.lib / LIB.name / "course" /
                                                         "confine.py"),
                json.dumps(cfg), "-f", "{connection_file}"]
        spec = {"argv": argv, "display_name": "annslam grading sandbox", "language": "python",
                "interrupt_mode": "message"}
        (self.private / "kernels" / "sandbox" / "kernel.json").write_text(json.dumps(spec))

    def _env(self) -> dict:
        env = _base_env()
        mirror = _settings.data_url()
        if mirror is not None:
            env[_settings.DATA_URL] = mirror
        from ..data import fetch                  # the kernel reads the data where we do
        if self.user:
            env["JUPYTERHUB_USER"] = self.user
        # A grade is computed, never read from a pickle (the study cache off), nor run through
        # machine code compiled and cached by another process: the numpy gating
        # (slam.compiled), and numba's cache (if student code uses numba) in the sandbox's home.
        env.update({_settings.DATA: str(fetch.data_dir()), _settings.CACHE: "off",
                    _settings.KERNEL: "numpy"},
                   HOME=str(self.home), PYTHONPATH=str(self.lib),
                   MPLCONFIGDIR=str(self.home / ".mpl"), IPYTHONDIR=str(self.home / ".ipython"),
                   JUPYTER_RUNTIME_DIR=str(self.home / ".jupyter-runtime"),
                   PYTHONDONTWRITEBYTECODE="1", PYTHONNOUSERSITE="1", OMP_NUM_THREADS="1",
                   OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONHASHSEED="0",
                   MPLBACKEND="agg", USER="student", LOGNAME="student",
                   NUMBA_CACHE_DIR=str(self.home / ".numba"))
        return env

    def start(self) -> None:
        """Start a fresh kernel (after a death, the previous one is cleaned up first)."""
        from jupyter_client.kernelspec import KernelSpecManager
        from jupyter_client.manager import KernelManager

        self.stop()
        ksm = KernelSpecManager(kernel_dirs=[str(self.private / "kernels")])
        # The kernel's sockets in a folder it may write only until it is ready: then it is
        # closed to it, so that nothing can be added (a disk filled) or a socket replaced by a
        # link (the grader would connect wherever it points).
        sockets = self.ipc / f"k{self.kernels_started}"
        sockets.mkdir(mode=0o700)
        if self.uid is not None:
            os.chown(sockets, self.uid, self.uid)
        km = KernelManager(kernel_name="sandbox", kernel_spec_manager=ksm, transport="ipc",
                           ip=str(sockets / "kernel"))
        km.connection_file = str(self.conn / f"kernel-{self.kernels_started}.json")
        remaining = self.remaining()
        if remaining <= 0:
            raise TimeoutError("the notebook's grading deadline passed")
        km.write_connection_file()
        os.chmod(km.connection_file, 0o644)       # the kernel's user reads it; nobody else
        log = open(self.private / f"kernel-{self.kernels_started}.log", "wb")   # can reach it
        env = self._env()
        life_r, self._lifeline = os.pipe()       # the sandbox ends when this end is closed
        env[_settings.LIFELINE] = str(life_r)
        try:
            km.start_kernel(cwd=str(self.work), env=env, stdout=log, stderr=log,
                            pass_fds=(life_r,))
        finally:
            log.close()
            os.close(life_r)
        kc = km.client()
        _bounded_channels(kc)
        kc.start_channels()
        try:
            kc.wait_for_ready(timeout=min(120.0, remaining))
        except RuntimeError as e:          # the kernel died while starting
            code = km.provisioner.process.poll() if km.provisioner else None
            kc.stop_channels()
            with contextlib.suppress(Exception):
                km.shutdown_kernel(now=True)
            km.cleanup_resources()
            said = self.kernel_log(self.kernels_started)
            raise KernelStartError(f"the grading kernel did not start: {_describe_exit(code)} "
                                   f"({e})" + (f"; it said: {said}" if said else "")) from None
        if self.uid is not None:
            os.chown(sockets, os.geteuid(), os.getegid())
        os.chmod(sockets, 0o755 if self.uid is not None else 0o555)
        self.km, self.kc = km, kc
        self.kernels_started += 1
        self.dead_reason = ""

    def kernel_log(self, k: int, lines: int = 4) -> str:
        """The last lines kernel number ``k`` wrote to its stdout and stderr."""
        try:
            text = (self.private / f"kernel-{k}.log").read_text(errors="replace")
        except OSError:
            return ""
        return " | ".join(x.strip() for x in text.strip().splitlines()[-lines:] if x.strip())

    def stop(self) -> None:
        if self._lifeline is not None:
            with contextlib.suppress(OSError):
                os.close(self._lifeline)
            self._lifeline = None
        if self.kc is not None:
            with contextlib.suppress(Exception):
                self.kc.stop_channels()
        if self.km is not None:
            with contextlib.suppress(Exception):
                self.km.shutdown_kernel(now=True)
        self.km = self.kc = None

    @property
    def alive(self) -> bool:
        return self.km is not None and self.km.is_alive()

    def remaining(self) -> float:
        return self.deadline - time.monotonic()

    def _exit_code(self):
        proc = getattr(self.km.provisioner, "process", None) if self.km else None
        return proc.poll() if proc is not None else None

    def _drain_iopub(self) -> None:
        with contextlib.suppress(Exception):
            while True:
                self.kc.get_iopub_msg(timeout=0)

    # ------------------------------------------------------------------ execution
    def execute(self, code: str, timeout: float | None = None, *,
                user_expressions: dict | None = None) -> ExecResult:
        """Run ``code`` and wait for its reply, at most ``timeout`` seconds (default: the
        cell time-out) and never past the notebook's deadline."""
        t0 = time.monotonic()
        if not self.alive:
            return ExecResult("died", evalue=self.dead_reason or "the kernel is not running",
                              alive=False)
        limit = self.limits.cell_timeout if timeout is None else timeout
        budget = min(limit, self.remaining())
        if budget <= 0:
            return ExecResult("timeout", evalue="the notebook's grading deadline "
                              f"({self.limits.deadline:g} s) had passed", alive=True)
        msg_id = self.kc.execute(code, silent=False, store_history=True, allow_stdin=False,
                                 stop_on_error=False, user_expressions=user_expressions or {})
        end = t0 + budget
        while True:
            now = time.monotonic()
            if now >= end:
                return self._timed_out(msg_id, budget, t0, deadline=budget < limit)
            try:
                reply = self.kc.get_shell_msg(timeout=min(_POLL_S, end - now))
            except queue.Empty:
                self._drain_iopub()
                if not self.km.is_alive():
                    self.dead_reason = ("the kernel died while running this code: "
                                        + _describe_exit(self._exit_code()))
                    return ExecResult("died", evalue=self.dead_reason,
                                      seconds=time.monotonic() - t0, alive=False)
                continue
            if reply["parent_header"].get("msg_id") != msg_id:
                continue
            self._drain_iopub()
            content = reply["content"]
            seconds = time.monotonic() - t0
            if content.get("status") == "ok":
                return ExecResult("ok", user_expressions=content.get("user_expressions"),
                                  seconds=seconds)
            if content.get("status") == "error":
                return ExecResult("error", content.get("ename", ""), content.get("evalue", ""),
                                  seconds=seconds)
            return ExecResult("error", "Aborted", f"the kernel answered {content.get('status')!r}",
                              seconds=seconds)

    def _timed_out(self, msg_id, budget, t0, *, deadline: bool) -> ExecResult:
        what = (f"the notebook's grading deadline ({self.limits.deadline:g} s) passed" if
                deadline else f"it did not finish within its time-out ({budget:.3g} s)")
        with contextlib.suppress(Exception):
            self.km.interrupt_kernel()
        end = time.monotonic() + 5.0
        while time.monotonic() < end and self.km.is_alive():
            try:
                reply = self.kc.get_shell_msg(timeout=_POLL_S)
            except queue.Empty:
                self._drain_iopub()
                continue
            if reply["parent_header"].get("msg_id") == msg_id:
                self._drain_iopub()
                return ExecResult("timeout", evalue=what, seconds=time.monotonic() - t0)
        # It ignored the interrupt (or died meanwhile): kill it; the caller restarts.
        self.dead_reason = what + "; it ignored the interrupt and was killed"
        self.stop()
        return ExecResult("timeout", evalue=self.dead_reason, seconds=time.monotonic() - t0,
                          alive=False)

    # ------------------------------------------------------------------ context
    def __enter__(self) -> Sandbox:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.stop()
        if self.group is not None:
            self.group.remove()
        for d in self.ipc.glob("k*"):           # closed to the kernel's user: open again
            with contextlib.suppress(OSError):
                os.chmod(d, 0o700)
        shutil.rmtree(self.root, ignore_errors=True)
