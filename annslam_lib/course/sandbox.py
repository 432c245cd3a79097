"""A Jupyter kernel for untrusted student code: scratch folder, sandbox, limits, deadlines.

Each submission gets a fresh scratch folder (deleted afterwards) holding the kernel's working
directory, its home, its IPC sockets and a snapshot copy of ``annslam_lib`` that the kernel
imports instead of the instructor's editable source. The kernel is started:

- inside **bubblewrap** when ``bwrap`` is installed and works here (Debian's
  ``bubblewrap``): the whole file system read-only, ``/tmp`` and the instructor's and other
  submissions' folders replaced by empty ones, only the scratch folder writable, no network
  (its own network namespace; the grader talks to it over Unix sockets in the scratch
  folder), its own PID namespace, killed with the grader;
- otherwise, when the grader runs as root and the interpreter is readable by others, as
  the unprivileged user ``nobody`` (it can then write nowhere but the scratch folder);
  otherwise as the grader's own user: it could then
  write wherever that user can, which :mod:`annslam_lib.course.grader` detects afterwards
  (a hash of the course's files before and after) and undoes, and the README says so.

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

__all__ = ["Limits", "ExecResult", "Sandbox", "bwrap_available", "nobody_available",
           "ISOLATIONS"]

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


@functools.lru_cache(maxsize=1)
def bwrap_available() -> str | None:
    """Path of a working ``bwrap`` (tried once: user namespaces may be disabled), or None."""
    exe = shutil.which("bwrap")
    if exe is None:
        return None
    try:
        ok = subprocess.run([exe, "--ro-bind", "/", "/", "--dev", "/dev", "--proc", "/proc",
                             "--unshare-net", "--unshare-pid", "--die-with-parent", "true"],
                            capture_output=True, timeout=20).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        ok = False
    return exe if ok else None


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
            raise RuntimeError("bubblewrap (bwrap) is not available or does not work here")
        if isolation == "nobody" and (why := nobody_available()) is not None:
            raise RuntimeError(f"isolation 'nobody' is not possible here: {why}")
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
        if self.isolation != "bwrap":
            return []
        args = [bwrap_available(), "--ro-bind", "/", "/", "--dev", "/dev", "--proc", "/proc",
                "--tmpfs", "/tmp", "--tmpfs", "/dev/shm"]
        from ..data import fetch

        data = fetch.data_dir().resolve()
        keep = [Path(sys.prefix).resolve(), LIB.parent, data]
        for h in self.hide:
            if h.exists() and not any(k == h or h in k.parents for k in keep):
                args += ["--tmpfs", str(h)]
        if data.exists():                       # even if it lies under /tmp: read-only
            args += ["--ro-bind", str(data), str(data)]
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
                   MKL_NUM_THREADS="1", PYTHONHASHSEED="0", MPLBACKEND="agg")
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
            km.cleanup_resources()
            raise RuntimeError(f"the grading kernel did not start: {_describe_exit(code)} "
                               f"({e})") from None
        self.km, self.kc = km, kc
        self.kernels_started += 1
        self.dead_reason = ""

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
