"""Hostile submissions for tests/test_grader_hostile.py and the class hub's grading test.

Each attack sits in a solution cell. A cell that tries something and reports what it saw
ends by raising ``AssertionError('SEEN {json}')``: its exercise then scores 0 with that
message (the grader's reason for a failed solution cell), and :func:`seen` reads it back.
The attacks read their targets from ``CFG`` (paths of this machine), written into the cell.
"""
from __future__ import annotations

import json
import os
import re
import socket
import threading
from pathlib import Path

HEADER = "import ctypes, errno, json, os, socket, subprocess, resource\nCFG = {cfg}\n"

# Everything a sandboxed kernel must not be able to do, tried and reported in one cell.
PROBE = HEADER + r'''
libc = ctypes.CDLL(None, use_errno=True)
SEEN = {}
def res(rc):
    return [rc, errno.errorcode.get(ctypes.get_errno(), 0) if rc != 0 else "ok"]
def err(e):
    return errno.errorcode.get(getattr(e, "errno", None) or 0, type(e).__name__)
def write(p):
    try:
        with open(p, "w") as f:
            f.write("pwned")
        return "written"
    except OSError as e:
        return err(e)
def read(p):
    try:
        with open(p, "rb") as f:
            f.read(1)
        return "read"
    except OSError as e:
        return err(e)
st = {l.split(":")[0]: l.split(":")[1].split() for l in open("/proc/self/status")}
SEEN["uid"] = st["Uid"]
SEEN["gid"] = st["Gid"]
for k in ("CapEff", "CapPrm", "CapBnd", "CapAmb", "NoNewPrivs", "Seccomp"):
    SEEN[k] = st[k][0]
MS_REMOUNT, MS_BIND, MNT_DETACH = 0x20, 0x1000, 2
SEEN["remount /"] = res(libc.mount(None, b"/", None, MS_REMOUNT | MS_BIND, None))
SEEN["remount course"] = res(libc.mount(None, CFG["course"].encode(), None,
                                        MS_REMOUNT | MS_BIND, None))
SEEN["umount /"] = res(libc.umount2(b"/", MNT_DETACH))
for name, p in CFG["hidden"].items():
    SEEN["exists " + name] = os.path.exists(p)
    SEEN["umount " + name] = res(libc.umount2(p.encode(), MNT_DETACH))
    SEEN["read " + name] = read(p)
SEEN["write canary"] = write(CFG["canary_open"] + "/pwned")
SEEN["write library"] = write(CFG["course"] + "/annslam_lib/pwned.py")
SEEN["write snapshot"] = write(os.environ.get("PYTHONPATH", "/nowhere") + "/annslam_lib/pwned.py")
SEEN["rewrite other submission"] = write(CFG["other_submission"])
SEEN["read secret"] = read(CFG["secret"])
SEEN["read shadow"] = read("/etc/shadow")
r = subprocess.run(["git", "-C", CFG["course"], "show", "HEAD:notebooks/01_kinematics.ipynb"],
                   capture_output=True)
SEEN["git show"] = [r.returncode, len(r.stdout)]
s = socket.socket(socket.AF_UNIX)
try:
    s.connect(CFG["socket"])
    SEEN["host socket"] = "connected"
except OSError as e:
    SEEN["host socket"] = err(e)
s = socket.socket(socket.AF_UNIX)
try:
    s.connect("\0" + CFG["abstract"])
    SEEN["abstract socket"] = "connected"
except OSError as e:
    SEEN["abstract socket"] = err(e)
s = socket.socket()
try:
    s.settimeout(2)
    s.connect(("127.0.0.1", CFG["tcp"]))
    SEEN["tcp"] = "connected"
except OSError as e:
    SEEN["tcp"] = err(e)
SEEN["pids"] = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
PTRACE_ATTACH = 16
SEEN["ptrace grader"] = res(libc.ptrace(PTRACE_ATTACH, CFG["grader_pid"], None, None))
SEEN["ptrace 1"] = res(libc.ptrace(PTRACE_ATTACH, 1, None, None))
SEEN["mem grader"] = read("/proc/%d/mem" % CFG["grader_pid"])
SEEN["mem 1"] = read("/proc/1/mem")
SEEN["environ 1"] = read("/proc/1/environ")
SEEN["unshare user"] = res(libc.unshare(0x10000000))
for fam, name in ((16, "netlink"), (17, "packet"), (40, "vsock"), (1, "unix")):
    try:
        socket.socket(fam, socket.SOCK_DGRAM if fam != 17 else socket.SOCK_RAW).close()
        SEEN["socket " + name] = "made"
    except OSError as e:
        SEEN["socket " + name] = err(e)
import sys
conn = json.load(open(sys.argv[sys.argv.index("-f") + 1]))
sockets = os.path.dirname(conn["ip"])
SEEN["write sockets folder"] = write(sockets + "/filler")
try:
    os.unlink(conn["ip"] + "-%d" % conn["shell_port"])
    SEEN["unlink shell socket"] = "unlinked"
except OSError as e:
    SEEN["unlink shell socket"] = err(e)
for name in ("RLIMIT_NPROC", "RLIMIT_AS", "RLIMIT_CPU", "RLIMIT_FSIZE"):
    lim = getattr(resource, name)
    soft, hard = resource.getrlimit(lim)
    SEEN["limit " + name] = [soft, hard]
    try:
        resource.setrlimit(lim, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
        SEEN["raise " + name] = "raised"
    except (ValueError, OSError) as e:
        SEEN["raise " + name] = type(e).__name__
raise AssertionError("SEEN " + json.dumps(SEEN))
'''

FORK_BOMB = HEADER + r'''
import time
kids, error = [], None
for i in range(600):
    try:
        pid = os.fork()
    except OSError as e:
        error = errno.errorcode.get(e.errno)
        break
    if pid == 0:
        time.sleep(60)
        os._exit(0)
    kids.append(pid)
for k in kids:
    os.kill(k, 9)
for k in kids:
    os.waitpid(k, 0)
threads = int(open("/proc/self/status").read().split("Threads:")[1].split()[0])
raise AssertionError("SEEN " + json.dumps({"forked": len(kids), "error": error,
                                           "threads": threads}))
'''

# Bytecode that, if it were ever loaded, leaves a mark in the canary folder; planted next
# to the course's library (where the grader and the instructor import from) and next to the
# kernel's own snapshot.
PLANT = HEADER + r'''
import importlib.util, importlib._bootstrap_external as be
SEEN = {}
payload = "open(%r, 'a').write('planted bytecode ran\\n')\n" % (CFG["canary_open"] + "/planted-ran")
for label, src in (("library", CFG["course"] + "/annslam_lib/course/grader.py"),
                   ("checks", CFG["course"] + "/annslam_lib/grading/kinematics.py"),
                   ("snapshot", os.environ.get("PYTHONPATH", "/x") + "/annslam_lib/course/codec.py")):
    try:
        st = os.stat(src)
        code = compile(open(src).read() + "\n" + payload, src, "exec")
        data = be._code_to_timestamp_pyc(code, st.st_mtime, st.st_size)
        pyc = importlib.util.cache_from_source(src)
        os.makedirs(os.path.dirname(pyc), exist_ok=True)
        with open(pyc, "wb") as f:
            f.write(data)
        SEEN[label] = "planted"
    except OSError as e:
        SEEN[label] = errno.errorcode.get(e.errno, type(e).__name__)
raise AssertionError("SEEN " + json.dumps(SEEN))
'''

# The library's observe, hidden from the source reading, called from a new thread.
THREAD = '''import threading
def my_observe(pose, landmark):
    m = __import__("annslam_lib.models.observation", fromlist=["x"])
    f = getattr(m, "obs" + "erve")
    out = []
    t = threading.Thread(target=lambda: out.append(f(pose, landmark)[0]))
    t.start()
    t.join()
    return out[0]
'''

# The same from a worker thread started in an earlier cell (before the call monitor).
POOL = '''from concurrent.futures import ThreadPoolExecutor
POOL = ThreadPoolExecutor(1)
POOL.submit(lambda: None).result()
def my_observe(pose, landmark):
    m = __import__("annslam_lib.models.observation", fromlist=["x"])
    return POOL.submit(getattr(m, "obs" + "erve"), pose, landmark).result()[0]
'''

# A helper in the OTHER exercise's cell calls the library; this exercise only calls it.
HELPER_OBSERVE = '''def my_observe(pose, landmark):
    return range_and_bearing(pose, landmark)
'''
HELPER_SPEED = '''def range_and_bearing(pose, landmark):
    return observation.observe(pose, landmark)[0]
'''

# The grader's call monitor switched off from the kernel, then the library reached by a
# computed name; and a copy of the library's function made from its code object.
EVADE_MONITOR = """import contextlib
import annslam_lib.course.kernel_side as _ks
_ks.watch_calls = lambda paths: contextlib.nullcontext([])
def my_observe(pose, landmark):
    m = __import__("annslam_lib.models.observation", fromlist=["x"])
    return getattr(m, "obs" + "erve")(pose, landmark)[0]
"""
EVADE_COPY = """import types
_f = observation.observe
_g = types.FunctionType(_f.__code__, _f.__globals__)
def my_observe(pose, landmark):
    return _g(pose, landmark)[0]
"""

EVADE_COPY_HIDDEN = """import types
_f = getattr(__import__("annslam_lib.models.observation", fromlist=["x"]), "obs" + "erve")
_g = types.FunctionType(_f.__code__, _f.__globals__)
def my_observe(pose, landmark):
    return _g(pose, landmark)[0]
"""

# Output and an error message of tens of megabytes.
FLOOD = """import sys
for _ in range(5):
    print("x" * (20 << 20))
raise ValueError("y" * (10 << 20))
"""

# A message that would redraw a terminal: clear, home, a forged summary, carriage returns.
ANSI = ('def my_observe(pose, landmark):\n'
        '    raise ValueError("\\x1b[2J\\x1b[H/x/alice: 9 / 9 points\\r  ok   ex-observe-tests '
        '(2/2)\\x1b[0m\\b\\b\\u202e\\u2028\\u061c\\ufeff\\n/x/bob: 5 / 5 points\\n'
        '  ok   ex-speed-tests (3/3)")\n')


def config(**kw) -> str:
    return repr(kw)


def seen(message: str) -> dict:
    """The observations an attack cell reported in its exercise's message."""
    m = re.search(r"SEEN (\{.*\})", message)
    assert m, f"no observations in {message!r}"
    return json.loads(m.group(1))


class Canary:
    """A folder of this machine outside every course folder and outside /tmp: a folder
    anyone may write (``open``), a file only its owner may read, a Unix socket only its
    owner may open, an abstract Unix socket and a TCP port on 127.0.0.1; each listener
    counts the connections it accepts."""

    def __init__(self, root: Path) -> None:
        self.root = root
        root.mkdir(mode=0o755)
        (root / "open").mkdir()
        os.chmod(root / "open", 0o777)
        (root / "secret.txt").write_text("only the owner may read this\n")
        os.chmod(root / "secret.txt", 0o600)
        self.accepted = {"socket": 0, "abstract": 0, "tcp": 0}
        self.socket_path = str(root / "owner.sock")
        self.abstract = f"annslam-hostile-{os.getpid()}-{id(self)}"
        self._servers = []
        s = socket.socket(socket.AF_UNIX)
        s.bind(self.socket_path)
        os.chmod(self.socket_path, 0o600)
        self._serve(s, "socket")
        a = socket.socket(socket.AF_UNIX)
        a.bind("\0" + self.abstract)
        self._serve(a, "abstract")
        t = socket.socket()
        t.bind(("127.0.0.1", 0))
        self.tcp = t.getsockname()[1]
        self._serve(t, "tcp")

    def _serve(self, s, name) -> None:
        s.listen()
        s.settimeout(0.2)
        self._servers.append(s)

        def loop():
            while s.fileno() >= 0:
                try:
                    c, _ = s.accept()
                except (socket.timeout, OSError):
                    continue
                self.accepted[name] += 1
                c.close()
        threading.Thread(target=loop, daemon=True).start()

    def files(self) -> dict:
        return {str(p.relative_to(self.root)): (p.read_bytes() if p.is_file() else None)
                for p in sorted(self.root.rglob("*"))}

    def close(self) -> None:
        for s in self._servers:
            s.close()
