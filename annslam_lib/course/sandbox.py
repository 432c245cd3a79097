"""A Jupyter kernel for untrusted student code: scratch folder, sandbox, limits, deadlines.

Each submission gets a fresh scratch folder (deleted afterwards) holding the kernel's working
directory, its home, its IPC sockets and a snapshot copy of ``annslam_lib`` that the kernel
imports instead of the instructor's editable source. The kernel is started:

- inside **bubblewrap** when ``bwrap`` is installed and works here (Debian's
  ``bubblewrap``): the whole file system read-only, ``/tmp`` and the instructor's and other
  submissions' folders replaced by empty ones, then the interpreter (its prefixes and every
  link from ``sys.executable`` to the real binary) and the data bound back read-only
  wherever they lie, so a course cloned into ``/tmp`` grades as anywhere else; only the
  scratch folder writable, no network (its own network namespace; the grader talks to it
  over Unix sockets in the scratch folder), its own PID namespace, killed with the grader;
- otherwise, when the grader runs as root and the interpreter is readable by others, as
  the unprivileged user ``nobody`` (it can then write nowhere but the scratch folder);
  otherwise as the grader's own user: it could then
  write wherever that user can, which :mod:`annslam_lib.course.grader` detects afterwards
  (a hash of the course's files before and after) and undoes, and the README says so.

A kernel that cannot start raises :class:`KernelStartError` with what it wrote; the grader
turns the first one of a submission (no student code has run yet) into a
:class:`GradingEnvironmentError`, the machine's fault, never a score.

In every case the kernel process has resource limits (``setrlimit``: CPU seconds, address
space, largest file written, no core dumps), each execution a time-out, and the whole
notebook a wall-clock deadline. A kernel that dies (``os._exit``, a signal, the CPU limit) is
noticed within a fraction of a second and reported as such, not as a time-out; one that
ignores the interrupt after its time-out is killed.
"""
from __future__ import annotations

import contextlib
import functools
import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Limits", "ExecResult", "Sandbox", "GradingEnvironmentError", "KernelStartError",
           "bwrap_available", "bwrap_problem", "nobody_available", "interpreter_paths", "ISOLATIONS"]

LIB = Path(__file__).resolve().parents[1]          # the annslam_lib package
ISOLATIONS = ("auto", "bwrap", "nobody", "none")
NOBODY = 65534
_POLL_S = 0.1

# Runs as the kernel's interpreter inside the sandbox: limits first, then the kernel itself.
_LAUNCHER = r"""
import json, os, resource, sys
lim = json.loads(sys.argv[1])
for name, soft, hard in (("RLIMIT_CPU", lim["cpu"], lim["cpu"] + 5),
                         ("RLIMIT_AS", lim["mem"], lim["mem"]),
                         ("RLIMIT_FSIZE", lim["fsize"], lim["fsize"]),
                         ("RLIMIT_CORE", 0, 0), ("RLIMIT_NPROC", lim["nproc"], lim["nproc"])):
    resource.setrlimit(getattr(resource, name), (soft, hard))
if lim.get("uid") is not None:
    os.setgroups([])
    os.setgid(lim["uid"])
    os.setuid(lim["uid"])
# Inside a PID namespace the grader's pid means nothing: the kernel would think its parent
# is gone and quit. Its lifetime is bound by the sandbox (--die-with-parent) or the grader.
os.environ.pop("JPY_PARENT_PID", None)
os.execv(sys.executable, [sys.executable, "-m", "ipykernel_launcher", *sys.argv[2:]])
"""


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
    """Path of a working ``bwrap`` (tried once: user namespaces may be disabled), or None;
    :func:`bwrap_problem` says why not."""
    exe, _ = _bwrap_probe()
    return exe


def bwrap_problem() -> str:
    """Why bubblewrap cannot be used here ('' when it can)."""
    return _bwrap_probe()[1]


@functools.lru_cache(maxsize=1)
def _bwrap_probe() -> tuple[str | None, str]:
    exe = shutil.which("bwrap")
    if exe is None:
        return None, "bwrap is not installed (Debian's package bubblewrap)"
    try:
        r = subprocess.run([exe, "--ro-bind", "/", "/", "--dev", "/dev", "--proc", "/proc",
                            "--unshare-net", "--unshare-pid", "--die-with-parent", "true"],
                           capture_output=True, timeout=20)
    except (OSError, subprocess.TimeoutExpired) as e:
        return None, f"{exe} could not be run: {e}"
    if r.returncode != 0:
        last = (r.stderr.decode(errors="replace").strip().splitlines() or ["?"])[-1]
        return None, (f"{exe} is installed but may not create a sandbox here (exit code "
                      f"{r.returncode}: {last[:200]}); user namespaces may be disabled")
    return exe, ""


def interpreter_paths() -> list[Path]:
    """Every folder the kernel's interpreter needs: the environment's prefixes, the folders
    of each link from ``sys.executable`` to the real binary (a venv's python is a link to
    its base interpreter, which may lie in a temporary folder too), and the folders on
    ``sys.path`` (a ``.pth`` line may add one outside the environment). Bound read-only,
    they are what the kernel would see anyway were they not under ``/tmp``."""
    found = [Path(p) for p in {sys.prefix, sys.base_prefix, sys.exec_prefix,
                                sys.base_exec_prefix}]
    found += [Path(p) for p in sys.path if p and Path(p).is_dir()]
    exe = Path(sys.executable)
    for _ in range(40):                           # follow the chain of links, hop by hop
        found.append(exe.parent)
        if not exe.is_symlink():
            break
        exe = exe.parent / os.readlink(exe)
    found.append(Path(os.path.realpath(sys.executable)).parent)
    out = []
    for p in found:
        for q in (p.absolute(), p.resolve()):
            if q.exists() and q not in out:
                out.append(q)
    return out


@functools.lru_cache(maxsize=1)
def nobody_available() -> str | None:
    """None if this interpreter runs as the user nobody here (needs root, and an
    interpreter nobody may read: not one under /root), else why not."""
    if os.geteuid() != 0:
        return "the grader does not run as root"

    def drop():
        os.setgroups([])
        os.setgid(NOBODY)
        os.setuid(NOBODY)
    try:
        r = subprocess.run([sys.executable, "-c", "import numpy, ipykernel"], preexec_fn=drop,
                           capture_output=True, timeout=60, cwd="/")
    except (OSError, subprocess.SubprocessError) as e:
        return str(e)
    if r.returncode != 0:
        last = (r.stderr.decode(errors="replace").strip().splitlines() or ["?"])[-1]
        return f"{sys.executable} cannot be run as nobody ({last[:160]})"
    return None


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

    ``isolation``: 'auto' (bubblewrap if it works here, else 'nobody' when root, else
    'none'), or one of those explicitly. ``hide``: folders the kernel must not see (the
    instructor's notebooks, other submissions). ``files``: {name: bytes} written into the
    kernel's working directory."""

    def __init__(self, limits: Limits = Limits(), *, isolation: str = "auto", hide=(),
                 files: dict | None = None) -> None:
        if isolation not in ISOLATIONS:
            raise ValueError(f"isolation must be one of {ISOLATIONS}, got {isolation!r}")
        if isolation == "auto":
            isolation = ("bwrap" if bwrap_available() else
                         "nobody" if nobody_available() is None else "none")
        if isolation == "bwrap" and not bwrap_available():
            raise GradingEnvironmentError(f"isolation 'bwrap' is not possible here: "
                                          f"{bwrap_problem()}")
        if isolation == "nobody" and (why := nobody_available()) is not None:
            raise GradingEnvironmentError(f"isolation 'nobody' is not possible here: {why}")
        self.isolation = isolation
        self.limits = limits
        self.hide = [Path(h).resolve() for h in hide]
        self.root = Path(tempfile.mkdtemp(prefix="annslam-grade-"))
        self.work = self.root / "work"
        self.home = self.root / "home"
        self.ipc = self.root / "ipc"
        for d in (self.work, self.home, self.ipc, self.root / "kernels" / "sandbox"):
            d.mkdir(parents=True)
        for name, data in (files or {}).items():
            (self.work / name).write_bytes(data)
        shutil.copytree(LIB, self.root / "lib" / LIB.name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        if isolation == "nobody":
            for p in [self.root, *self.root.rglob("*")]:
                os.chown(p, NOBODY, NOBODY, follow_symlinks=False)
        self._write_kernelspec()
        self.km = self.kc = None
        self.deadline = time.monotonic() + limits.deadline
        self.kernels_started = 0
        self.dead_reason = ""

    # ------------------------------------------------------------------ kernel life
    def _prefix(self) -> list[str]:
        """bubblewrap's arguments: everything read-only, /tmp, /dev/shm and the hidden
        folders empty, the interpreter and the data bound back read-only wherever they lie
        (under /tmp too), and the scratch folder writable. Mounts are applied shallow
        before deep, so a folder inside a hidden one stays visible if the kernel needs it,
        and a hidden folder inside (or equal to) a needed one stays hidden."""
        if self.isolation != "bwrap":
            return []
        from ..data import fetch
        data = fetch.data_dir()
        mounts = [("--tmpfs", Path("/tmp")), ("--tmpfs", Path("/dev/shm"))]
        mounts += [("--ro-bind", p) for p in [*interpreter_paths(), data.absolute(),
                                              data.resolve()] if p.exists()]
        mounts += [("--tmpfs", h) for h in self.hide if h.exists()]
        # shallow first (stable): at equal depth a hidden folder comes last and stays hidden
        mounts.sort(key=lambda m: len(m[1].parts))
        args = [bwrap_available(), "--ro-bind", "/", "/", "--dev", "/dev", "--proc", "/proc"]
        for kind, p in mounts:
            args += [kind, str(p)] if kind == "--tmpfs" else [kind, str(p), str(p)]
        args += ["--bind", str(self.root), str(self.root), "--unshare-net", "--unshare-pid",
                 "--unshare-ipc", "--unshare-uts", "--die-with-parent", "--chdir",
                 str(self.work), "--"]
        return args

    def _write_kernelspec(self) -> None:
        lim = {"cpu": int(self.limits.cpu_seconds), "mem": int(self.limits.memory_bytes),
               "fsize": int(self.limits.file_bytes), "nproc": int(self.limits.processes),
               "uid": NOBODY if self.isolation == "nobody" else None}
        argv = [*self._prefix(), sys.executable, "-c", _LAUNCHER, json.dumps(lim), "-f",
                "{connection_file}"]
        spec = {"argv": argv, "display_name": "annslam grading sandbox", "language": "python",
                "interrupt_mode": "message"}
        (self.root / "kernels" / "sandbox" / "kernel.json").write_text(json.dumps(spec))

    def _env(self) -> dict:
        keep = ("PATH", "LANG", "LC_ALL", "ANNSLAM_DATA", "ANNSLAM_DATA_URL", "TZ")
        env = {k: os.environ[k] for k in keep if k in os.environ}
        from ..data import fetch                  # the kernel reads the data where we do
        env.update(ANNSLAM_DATA=str(fetch.data_dir()), HOME=str(self.home),
                   PYTHONPATH=str(self.root / "lib"), MPLCONFIGDIR=str(self.home / ".mpl"),
                   IPYTHONDIR=str(self.home / ".ipython"), JUPYTER_RUNTIME_DIR=str(self.ipc),
                   PYTHONDONTWRITEBYTECODE="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", PYTHONHASHSEED="0", MPLBACKEND="agg",
                   ANNSLAM_CACHE="off",       # a grade is computed, never read from a pickle
                   # nor run through machine code compiled and cached by another process:
                   # the numpy gating (slam.compiled), numba's cache (if student code uses
                   # numba) kept in the sandbox's own home
                   ANNSLAM_KERNEL="numpy", NUMBA_CACHE_DIR=str(self.home / ".numba"))
        return env

    def start(self) -> None:
        """Start a fresh kernel (after a death, the previous one is cleaned up first)."""
        from jupyter_client.kernelspec import KernelSpecManager
        from jupyter_client.manager import KernelManager

        self.stop()
        ksm = KernelSpecManager(kernel_dirs=[str(self.root / "kernels")])
        km = KernelManager(kernel_name="sandbox", kernel_spec_manager=ksm, transport="ipc",
                           ip=str(self.ipc / f"k{self.kernels_started}"))
        km.connection_file = str(self.ipc / f"kernel-{self.kernels_started}.json")
        remaining = self.remaining()
        if remaining <= 0:
            raise TimeoutError("the notebook's grading deadline passed")
        log = open(self.root / f"kernel-{self.kernels_started}.log", "wb")
        try:
            km.start_kernel(cwd=str(self.work), env=self._env(), stdout=log, stderr=log)
        finally:
            log.close()
        if self.isolation == "nobody":
            os.chmod(km.connection_file, 0o644)
        kc = km.client()
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
        self.km, self.kc = km, kc
        self.kernels_started += 1
        self.dead_reason = ""

    def kernel_log(self, k: int, lines: int = 4) -> str:
        """The last lines kernel number ``k`` wrote to its stdout and stderr."""
        try:
            text = (self.root / f"kernel-{k}.log").read_text(errors="replace")
        except OSError:
            return ""
        return " | ".join(x.strip() for x in text.strip().splitlines()[-lines:] if x.strip())

    def stop(self) -> None:
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
        shutil.rmtree(self.root, ignore_errors=True)
