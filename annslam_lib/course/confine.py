"""The grading kernel's first steps: limits, no privilege, a system-call filter, then the kernel.

Run as a script (``python -I confine.py CONFIG -f CONNECTION_FILE``) inside the sandbox
(:mod:`annslam_lib.course.sandbox`), before any student code exists in the process. It uses
the standard library only, so that it imports nothing a submission could have touched.

In order:

1. **Resource limits** (``setrlimit``): CPU seconds (``SIGXCPU`` at the limit, killed 5 s
   later), address space, largest file written, processes, no core dumps. A process
   without ``CAP_SYS_RESOURCE`` cannot raise a hard limit afterwards.
2. **No privilege.** Started as root (a hub's grader is), the process empties its capability
   bounding set, leaves every supplementary group and becomes the unprivileged user
   ``uid``/``gid`` for real (its real, effective and saved ids), which clears its permitted,
   effective and ambient capabilities. Checked afterwards from ``/proc/self/status``: a
   capability left, or uid 0, stops the launch. (bubblewrap's own user namespace is not used
   for root: it maps the sandbox's user onto uid 0 outside, which still owns root's files
   and is exempt from the process limit.)
3. ``PR_SET_NO_NEW_PRIVS``: no set-user-id program can give privilege back.
4. A **seccomp filter** that refuses, with ``EPERM``, the system calls that change mounts or
   namespaces, inspect other processes or load kernel code (:data:`BLOCKED`), ``clone`` with
   a namespace flag, sockets of another family than Unix, IPv4 and IPv6, and system calls
   of another architecture; ``clone3`` answers ``ENOSYS`` (its flags cannot be read by a
   filter; the C library then uses ``clone``).
5. ``exec`` of the IPython kernel; in the sandbox, as the child of this process, which
   stays as the sandbox's PID 1 (it reaps orphans and passes on the kernel's status).
"""
from __future__ import annotations

import ctypes
import json
import os
import platform
import resource
import signal
import struct
import sys

__all__ = ["BLOCKED", "CLONE_NAMESPACES", "SOCKET_FAMILIES", "seccomp_program", "apply_limits", "drop_privilege",
           "install_filter", "status_ids", "main"]

# System calls the kernel of a submission never needs: mounts and namespaces, other
# processes' memory, kernel modules and BPF, keyrings, userfaultfd, io_uring (whose
# operations a filter does not see), reboot and swap. Numbers per architecture.
_NUMBERS = {
    "x86_64": {
        "mount": 165, "umount2": 166, "pivot_root": 155, "chroot": 161, "unshare": 272,
        "setns": 308, "ptrace": 101, "process_vm_readv": 310, "process_vm_writev": 311,
        "kexec_load": 246, "kexec_file_load": 320, "init_module": 175, "finit_module": 313,
        "delete_module": 176, "bpf": 321, "perf_event_open": 298, "keyctl": 250,
        "add_key": 248, "request_key": 249, "userfaultfd": 323, "open_by_handle_at": 304,
        "reboot": 169, "swapon": 167, "swapoff": 168, "acct": 163, "quotactl": 179,
        "open_tree": 428, "move_mount": 429, "fsopen": 430, "fsconfig": 431, "fsmount": 432,
        "fspick": 433, "mount_setattr": 442, "io_uring_setup": 425, "io_uring_enter": 426,
        "io_uring_register": 427, "clone": 56, "clone3": 435, "socket": 41, "socketpair": 53},
    "aarch64": {
        "mount": 40, "umount2": 39, "pivot_root": 41, "chroot": 51, "unshare": 97,
        "setns": 268, "ptrace": 117, "process_vm_readv": 270, "process_vm_writev": 271,
        "kexec_load": 104, "kexec_file_load": 294, "init_module": 105, "finit_module": 273,
        "delete_module": 106, "bpf": 280, "perf_event_open": 241, "keyctl": 219,
        "add_key": 217, "request_key": 218, "userfaultfd": 282, "open_by_handle_at": 265,
        "reboot": 142, "swapon": 224, "swapoff": 225, "acct": 89, "quotactl": 60,
        "open_tree": 428, "move_mount": 429, "fsopen": 430, "fsconfig": 431, "fsmount": 432,
        "fspick": 433, "mount_setattr": 442, "io_uring_setup": 425, "io_uring_enter": 426,
        "io_uring_register": 427, "clone": 220, "clone3": 435, "socket": 198,
        "socketpair": 199},
}
BLOCKED = tuple(n for n in _NUMBERS["x86_64"]
                if n not in ("clone", "clone3", "socket", "socketpair"))
# Socket families a kernel may open: Unix (its channels to the grader), IPv4 and IPv6 (only
# loopback exists in its network namespace), netlink (the C library lists interfaces with
# it; ZeroMQ aborts without). Packet, vsock (which no network namespace confines),
# Bluetooth, the kernel's crypto sockets and the rest are refused.
SOCKET_FAMILIES = (1, 2, 10, 16)
_AUDIT_ARCH = {"x86_64": 0xC000003E, "aarch64": 0xC00000B7}
# CLONE_NEWNS | NEWCGROUP | NEWUTS | NEWIPC | NEWUSER | NEWPID | NEWNET | NEWTIME
CLONE_NAMESPACES = 0x00020000 | 0x02000000 | 0x04000000 | 0x08000000 | 0x10000000 | \
    0x20000000 | 0x40000000 | 0x00000080
_X32_BIT = 0x40000000

_EPERM, _ENOSYS = 1, 38
_RET_ALLOW = 0x7FFF0000
_RET_ERRNO = 0x00050000
_LD_W_ABS, _JEQ, _JGE, _JSET, _RET = 0x20, 0x15, 0x35, 0x45, 0x06
_PR_SET_NO_NEW_PRIVS, _PR_SET_SECCOMP, _PR_CAPBSET_DROP, _PR_SET_PDEATHSIG = 38, 22, 24, 1
_SECCOMP_MODE_FILTER = 2


def seccomp_program(arch: str | None = None) -> bytes:
    """The classic-BPF program of step 4 for ``arch`` (default this machine's), as the bytes
    of an array of ``struct sock_filter``. Raises ``OSError`` for an architecture without a
    table here (the sandbox then refuses to start: no filter, no grading)."""
    arch = arch or platform.machine()
    if arch not in _NUMBERS:
        raise OSError(f"no system-call table for {arch!r} (known: {', '.join(_NUMBERS)})")
    nr = _NUMBERS[arch]
    prog: list[tuple[int, int, int, int]] = []
    fixups: list[tuple[int, str, str]] = []       # (index, label if true, label if false)

    def emit(code, k=0, jt="", jf=""):
        fixups.append((len(prog), jt, jf))
        prog.append((code, 0, 0, k))

    emit(_LD_W_ABS, 4)                                    # seccomp_data.arch
    emit(_JEQ, _AUDIT_ARCH[arch], jt="next", jf="deny")
    emit(_LD_W_ABS, 0)                                    # seccomp_data.nr
    if arch == "x86_64":                                  # the x32 ABI: same calls, other numbers
        emit(_JGE, _X32_BIT, jt="deny", jf="next")
    for name in BLOCKED:
        emit(_JEQ, nr[name], jt="deny", jf="next")
    labels: dict[str, int] = {}
    emit(_JEQ, nr["clone3"], jt="enosys", jf="next")
    emit(_JEQ, nr["clone"], jt="clone", jf="next")
    emit(_JEQ, nr["socket"], jt="socket", jf="next")
    emit(_JEQ, nr["socketpair"], jt="socket", jf="next")
    emit(_RET, _RET_ALLOW)
    labels["clone"] = len(prog)
    emit(_LD_W_ABS, 16)                                   # low half of args[0]: the flags
    emit(_JSET, CLONE_NAMESPACES, jt="deny", jf="next")
    emit(_RET, _RET_ALLOW)
    labels["socket"] = len(prog)
    emit(_LD_W_ABS, 16)                                   # low half of args[0]: the family
    for k, family in enumerate(SOCKET_FAMILIES):
        last = k == len(SOCKET_FAMILIES) - 1
        emit(_JEQ, family, jt="allow_socket", jf="deny" if last else "next")
    labels["allow_socket"] = len(prog)
    emit(_RET, _RET_ALLOW)
    labels["deny"] = len(prog)
    emit(_RET, _RET_ERRNO | _EPERM)
    labels["enosys"] = len(prog)
    emit(_RET, _RET_ERRNO | _ENOSYS)
    out = []
    for (i, jt, jf), (code, _, _, k) in zip(fixups, prog):
        def off(label):
            if label in ("", "next"):
                return 0
            d = labels[label] - i - 1
            if not 0 <= d <= 255:
                raise AssertionError(f"jump to {label} out of range")
            return d
        out.append(struct.pack("HBBI", code, off(jt), off(jf), k))
    return b"".join(out)


def apply_limits(lim: dict) -> None:
    """Step 1: ``lim`` has cpu (s), mem, fsize (bytes), nproc."""
    for name, soft, hard in (("RLIMIT_CPU", lim["cpu"], lim["cpu"] + 5),   # SIGXCPU, then KILL
                             ("RLIMIT_AS", lim["mem"], lim["mem"]),
                             ("RLIMIT_FSIZE", lim["fsize"], lim["fsize"]), ("RLIMIT_CORE", 0, 0),
                             ("RLIMIT_NPROC", lim["nproc"], lim["nproc"])):
        resource.setrlimit(getattr(resource, name), (soft, hard))


def _libc():
    return ctypes.CDLL(None, use_errno=True)


def drop_privilege(uid: int, gid: int) -> None:
    """Step 2 (as root): empty bounding set, no groups, ``uid``/``gid`` for real."""
    libc = _libc()
    try:
        last = int(open("/proc/sys/kernel/cap_last_cap").read())
    except OSError:
        last = 63
    for cap in range(last + 1):
        if libc.prctl(_PR_CAPBSET_DROP, cap, 0, 0, 0) != 0 and ctypes.get_errno() != 22:
            raise OSError(ctypes.get_errno(), f"cannot drop capability {cap} from the bounding set")
    os.setgroups([])
    os.setresgid(gid, gid, gid)
    os.setresuid(uid, uid, uid)


def status_ids() -> dict:
    """Uid, Gid and the capability sets of this process, from ``/proc/self/status``."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            if key in ("Uid", "Gid", "Groups", "CapInh", "CapPrm", "CapEff", "CapBnd", "CapAmb",
                       "NoNewPrivs", "Seccomp"):
                out[key] = value.split()
    return out


def install_filter(program: bytes) -> None:
    """Steps 3 and 4."""
    libc = _libc()
    if libc.prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "PR_SET_NO_NEW_PRIVS failed")
    n = len(program) // 8
    buf = ctypes.create_string_buffer(program, len(program))

    class SockFprog(ctypes.Structure):
        _fields_ = [("len", ctypes.c_ushort), ("filter", ctypes.c_void_p)]

    fprog = SockFprog(n, ctypes.cast(buf, ctypes.c_void_p))
    if libc.prctl(_PR_SET_SECCOMP, _SECCOMP_MODE_FILTER, ctypes.byref(fprog), 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "the seccomp filter could not be installed")


def main(argv: list[str]) -> None:
    """``argv``: the configuration (JSON: the limits; ``confine``: whether to end without
    privilege and under the filter; ``uid``/``gid``: whom to become when started as root;
    ``reaper``: stay as PID 1 and run the kernel as a child; ``check``: stop before the
    kernel and print the ids), then the kernel's arguments."""
    cfg = json.loads(argv[0])
    apply_limits(cfg)
    if cfg.get("confine", True):
        if os.geteuid() == 0:
            drop_privilege(cfg["uid"], cfg["gid"])
            # a change of user clears the parent-death signal bubblewrap set
            # (--die-with-parent): set it again, or the sandbox would outlive the grader
            if _libc().prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
                raise OSError(ctypes.get_errno(), "PR_SET_PDEATHSIG failed")
        ids = status_ids()
        left = [k for k in ("CapPrm", "CapEff", "CapAmb") if int(ids[k][0], 16)]
        if "0" in ids["Uid"] or "0" in ids["Gid"] or left:
            raise SystemExit(f"confine: privilege left after the drop: uid {ids['Uid']}, "
                             f"gid {ids['Gid']}, capabilities {left}")
        install_filter(seccomp_program())
    if cfg.get("check"):
        print(json.dumps(status_ids()))
        return
    # Inside a PID namespace the grader's pid means nothing: the kernel would think its
    # parent is gone and quit. Its lifetime is bound by the sandbox (--die-with-parent).
    os.environ.pop("JPY_PARENT_PID", None)
    kernel = [sys.executable, "-m", "ipykernel_launcher", *argv[1:]]
    # annslam_lib._settings.LIFELINE, read here: this script imports nothing of the package
    lifeline = int(os.environ.pop("ANNSLAM_LIFELINE", "-1"))
    if not cfg.get("reaper"):
        os.execv(sys.executable, kernel)
    # The sandbox's PID 1: the kernel would ignore signals it has no handler for (the CPU
    # limit's SIGXCPU among them) and leave its orphans unreaped. So PID 1 is this process,
    # with the same user, limits and filter as the kernel (nothing to gain by reaching it):
    # it reaps every orphan and leaves with the kernel's status (128 + a signal's number),
    # or at once when the grader closes its end of the lifeline (a pipe; the parent-death
    # signal does not reach a namespace's PID 1), which ends every process of the sandbox.
    pid = os.fork()
    if pid == 0:
        if lifeline >= 0:
            os.close(lifeline)
        os.execv(sys.executable, kernel)
    _reap(pid, lifeline)


def _reap(kernel: int, lifeline: int) -> None:
    import select
    import time

    while True:
        if lifeline >= 0:
            ready, _, _ = select.select([lifeline], [], [], 0.1)
            if ready and os.read(lifeline, 1) == b"":
                os._exit(137)                   # the grader is gone or stopped the kernel
        else:
            time.sleep(0.1)
        while True:
            try:
                child, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                os._exit(1)
            if child == 0:
                break
            if child == kernel:
                code = os.waitstatus_to_exitcode(status)
                os._exit(128 - code if code < 0 else code)


if __name__ == "__main__":
    main(sys.argv[1:])
