"""The pieces of the grader's confinement, each on its own: the system-call filter (read by an
independent classic-BPF interpreter and applied to a real process), the privilege drop, the
call monitor on every thread, the source reading through helpers, inert reports, the watch
over the course's files, and the refusal to grade without a sandbox."""
from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from annslam_lib.course import confine, integrity, sandbox
from annslam_lib.course.hub import HubError
from annslam_lib.course.hub import setup as hub_setup
from annslam_lib.course.plan import static_forbidden
from annslam_lib.grading.core import watch_calls
from annslam_lib.models import observation

import grading_support as gs

ROOT = Path(__file__).resolve().parents[1]
OBSERVE = "annslam_lib.models.observation:observe"


# ------------------------------------------------------------------ the seccomp filter

def _run_bpf(program: bytes, nr: int, arch: int, args=(0,) * 6) -> int:
    """A classic-BPF interpreter for the instructions a seccomp filter uses (load word
    absolute, jeq/jge/jset with a constant, return), over a seccomp_data record."""
    data = struct.pack("<iIQ6Q", nr, arch, 0, *args)
    insns = [struct.unpack("HBBI", program[k:k + 8]) for k in range(0, len(program), 8)]
    acc, pc = 0, 0
    while True:
        code, jt, jf, k = insns[pc]
        if code == 0x20:                                 # ld [k]
            acc = struct.unpack_from("<I", data, k)[0]
            pc += 1
        elif code in (0x15, 0x35, 0x45):                 # jeq, jge, jset #k
            hit = {0x15: acc == k, 0x35: acc >= k, 0x45: bool(acc & k)}[code]
            pc += 1 + (jt if hit else jf)
        elif code == 0x06:
            return k
        else:
            raise AssertionError(f"unexpected instruction {code:#x}")


ALLOW, EPERM, ENOSYS = 0x7FFF0000, 0x00050001, 0x00050026


@pytest.mark.parametrize("arch", ["x86_64", "aarch64"])
def test_the_filter_refuses_what_it_lists_and_allows_the_rest(arch):
    prog = confine.seccomp_program(arch)
    nrs = confine._NUMBERS[arch]
    audit = confine._AUDIT_ARCH[arch]
    for name in confine.BLOCKED:
        assert _run_bpf(prog, nrs[name], audit) == EPERM, name
    for nr in (0, 1, 2, 3, 9, 59, 60, 63, 202, 231):     # read, write, ... not blocked
        if nr not in nrs.values():
            assert _run_bpf(prog, nr, audit) == ALLOW, nr
    clone = nrs["clone"]
    assert _run_bpf(prog, clone, audit, (0x01200011,) + (0,) * 5) == ALLOW      # fork
    assert _run_bpf(prog, clone, audit, (0x003D0F00,) + (0,) * 5) == ALLOW      # a thread
    for flag in (0x10000000, 0x20000, 0x20000000, 0x40000000, 0x08000000, 0x80):
        assert _run_bpf(prog, clone, audit, (flag | 0x11,) + (0,) * 5) == EPERM, hex(flag)
    assert _run_bpf(prog, nrs["clone3"], audit) == ENOSYS
    for call in ("socket", "socketpair"):
        for family, verdict in ((1, ALLOW), (2, ALLOW), (10, ALLOW), (16, ALLOW), (17, EPERM),
                                (40, EPERM), (31, EPERM), (38, EPERM)):
            assert _run_bpf(prog, nrs[call], audit, (family,) + (0,) * 5) == verdict, (
                call, family)
    other = confine._AUDIT_ARCH["aarch64" if arch == "x86_64" else "x86_64"]
    assert _run_bpf(prog, 0, other) == EPERM                   # another architecture's calls
    if arch == "x86_64":
        assert _run_bpf(prog, 0x40000000 | 0, audit) == EPERM   # the x32 ABI
    with pytest.raises(OSError, match="no system-call table"):
        confine.seccomp_program("sparc64")


def test_the_filter_applied_to_a_real_process():
    code = (f"import sys, ctypes, os, threading; sys.path.insert(0, {str(ROOT)!r})\n"
            "from annslam_lib.course import confine\n"
            "confine.install_filter(confine.seccomp_program())\n"
            "libc = ctypes.CDLL(None, use_errno=True)\n"
            "out = {'mount': [libc.mount(None, b'/', None, 0x1020, None), ctypes.get_errno()],"
            " 'unshare': [libc.unshare(0x10000000), ctypes.get_errno()],"
            " 'vsock': [libc.socket(40, 1, 0), ctypes.get_errno()]}\n"
            "t = threading.Thread(target=lambda: None); t.start(); t.join()\n"
            "pid = os.fork()\n"
            "if pid == 0: os._exit(7)\n"
            "out['fork'] = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])\n"
            "out['ids'] = confine.status_ids()['NoNewPrivs'] + confine.status_ids()['Seccomp']\n"
            "print(out)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    out = eval(r.stdout)
    assert out == {"mount": [-1, 1], "unshare": [-1, 1], "vsock": [-1, 1], "fork": 7,
                   "ids": ["1", "2"]}, out


@pytest.mark.skipif(os.geteuid() != 0, reason="the drop of privilege is root's: not root here")
def test_the_launcher_as_root_ends_without_privilege():
    cfg = {**sandbox._limits_config(sandbox.Limits()), "check": True}
    r = subprocess.run([sys.executable, "-I", str(ROOT / "annslam_lib" / "course" / "confine.py"),
                        json.dumps(cfg)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    ids = json.loads(r.stdout)
    assert ids["Uid"] == [str(cfg["uid"])] * 4 and ids["Gid"] == [str(cfg["gid"])] * 4
    assert cfg["uid"] in sandbox.SANDBOX_IDS and ids["Groups"] == []
    for k in ("CapInh", "CapPrm", "CapEff", "CapBnd", "CapAmb"):
        assert int(ids[k][0], 16) == 0, k
    assert ids["NoNewPrivs"] == ["1"] and ids["Seccomp"] == ["2"]


def test_a_free_id_is_nobody_s():
    import pwd

    ids = {sandbox.free_id() for _ in range(20)}
    assert len(ids) > 1 and all(i in sandbox.SANDBOX_IDS for i in ids)
    for i in ids:
        with pytest.raises(KeyError):
            pwd.getpwuid(i)


# ------------------------------------------------------------------ the call monitor

def _pose():
    return np.array([1.0, 2.0, 0.3]), np.array([4.0, 6.0])


def test_the_monitor_sees_a_call_from_a_new_thread():
    f = getattr(observation, "obs" + "erve")
    with watch_calls([OBSERVE]) as hits:
        t = threading.Thread(target=lambda: f(*_pose()))
        t.start()
        t.join()
    assert OBSERVE in hits


def test_the_monitor_sees_a_call_from_a_thread_started_before_it():
    pool = ThreadPoolExecutor(1)
    pool.submit(lambda: None).result()           # the worker thread exists before the block
    f = observation.observe
    try:
        with watch_calls([OBSERVE]) as hits:
            z = pool.submit(f, *_pose()).result()
        assert OBSERVE in hits
    finally:
        pool.shutdown()
    # the function is itself again afterwards, and gives the same answer
    assert observation.observe.__code__.co_name == "observe"
    np.testing.assert_array_equal(observation.observe(*_pose())[0], z[0])
    with watch_calls([OBSERVE]) as hits:
        observation.observe(*_pose())
    assert hits and set(hits) == {OBSERVE}


def test_the_monitor_keeps_defaults_keywords_and_generators(monkeypatch):
    import types

    mod = types.ModuleType("annslam_watch_test")
    exec("def f(a, b=2, *rest, c=3, **kw):\n    return (a, b, rest, c, kw)\n"
         "def g(n):\n    yield from range(n)\n", mod.__dict__)
    monkeypatch.setitem(sys.modules, mod.__name__, mod)
    f, g = mod.f, mod.g
    with watch_calls(["annslam_watch_test:f", "annslam_watch_test:g"]) as hits:
        assert f(1) == (1, 2, (), 3, {})
        assert f(1, 5, 6, c=7, d=8) == (1, 5, (6,), 7, {"d": 8})
        assert list(g(3)) == [0, 1, 2]
    assert hits.count("annslam_watch_test:f") >= 2 and "annslam_watch_test:g" in hits
    assert f.__code__.co_varnames[:2] == ("a", "b") and "__annslam_tripwire" not in str(
        list(mod.__dict__))


def test_the_source_is_read_through_helpers_in_other_cells():
    ctx = ["import numpy as np\nfrom annslam_lib.models import observation"]
    sol = "def my_observe(pose, landmark):\n    return rb(pose, landmark)\n"
    helper = "def rb(p, l):\n    return deeper(p, l)\n\ndef deeper(p, l):\n    return observation.observe(p, l)[0]\n"
    unrelated = "def other(p, l):\n    return observation.observe(p, l)\n\ndef rb2(p, l):\n    return p\n"
    assert static_forbidden(sol, ctx, [OBSERVE], helpers=[sol, helper]) == [OBSERVE]
    assert static_forbidden(sol, ctx, [OBSERVE]) == []                  # the cell alone
    assert static_forbidden(sol.replace("rb(", "rb2("), ctx, [OBSERVE],
                            helpers=[sol, unrelated]) == []             # only what it uses
    alias = "from annslam_lib.models.observation import observe as o\nF = o\n"
    assert static_forbidden("def my_observe(p, l):\n    return F(p, l)[0]\n", ctx, [OBSERVE],
                            helpers=[alias]) == [OBSERVE]


def test_reading_a_source_imports_nothing_but_the_library():
    before = set(sys.modules)
    static_forbidden("import antigravity_annslam_test\nx = antigravity_annslam_test.f\n"
                     "import this\ny = this.s\n", [], [OBSERVE])
    assert "this" not in set(sys.modules) - before
    assert "antigravity_annslam_test" not in sys.modules


# ------------------------------------------------------------------ inert reports

def test_inert_escapes_what_a_terminal_or_page_would_act_on():
    s = "a\x1b[2J\rb\bc\x07\x00\x7f\x9b\u202eé\tz\nnext"
    out = integrity.inert(s)
    for ch in "\x1b\r\b\x07\x00\x7f\x9b\u202e":
        assert ch not in out
    assert out == "a\\x1b[2J\\rb\\x08c\\x07\\x00\\x7f\\x9b\\u202eé\tz\nnext"


# ------------------------------------------------------------------ the watch over the course

def test_the_guard_sees_a_rewrite_even_with_the_time_set_back(tmp_path):
    lib = tmp_path / "lib"
    (lib / "__pycache__").mkdir(parents=True)
    (lib / "m.py").write_text("x = 1\n")
    (lib / "__pycache__" / "m.pyc").write_bytes(b"code")
    other = tmp_path / "env"
    other.mkdir()
    (other / "site.py").write_text("y = 1\n")
    g = integrity.Guard([lib, other], restorable=[lib])
    assert g.changes() == []
    (lib / "m.py").write_text("x = 1\n")                     # the same bytes: no change
    assert g.changes() == []
    st = os.stat(lib / "__pycache__" / "m.pyc")
    (lib / "__pycache__" / "m.pyc").write_bytes(b"evil")
    os.utime(lib / "__pycache__" / "m.pyc", ns=(st.st_atime_ns, st.st_mtime_ns))
    (lib / "__pycache__" / "new.pyc").write_bytes(b"planted")
    (other / "site.py").write_text("y = 2\n")
    changed = g.changes()
    assert changed == sorted([str(lib / "__pycache__" / "m.pyc"),
                              str(lib / "__pycache__" / "new.pyc"), str(other / "site.py")])
    lost = g.restore(changed)
    assert lost == [str(other / "site.py")]                  # not held: said, not restored
    assert (lib / "__pycache__" / "m.pyc").read_bytes() == b"code"
    assert not (lib / "__pycache__" / "new.pyc").exists()
    assert g.changes() == []


def test_the_course_folders_include_bytecode_history_and_data():
    guarded, restorable = integrity.course_folders()
    assert {ROOT / "annslam_lib", ROOT / ".git", ROOT / "notebooks"} <= set(guarded)
    assert Path(sys.prefix).resolve() not in guarded
    guarded, _ = integrity.course_folders(isolation="none")
    assert Path(sys.prefix).resolve() in guarded or any(
        p in Path(sys.prefix).resolve().parents for p in guarded)


# ------------------------------------------------------------------ no silent downgrade

def test_without_bubblewrap_grading_refuses_naming_the_cause_and_the_fix(tmp_path):
    inst = tmp_path / "instructor" / "chapter.ipynb"
    gs.write(gs.instructor(), inst)
    gs.write(gs.honest(), tmp_path / "sub" / "chapter.ipynb")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PATH"] = str(tmp_path / "no-such-bin")               # no bwrap to be found
    r = subprocess.run([sys.executable, "-m", "annslam_lib", "grade", str(tmp_path / "sub"),
                        "--instructor", str(inst.parent), "--json", str(tmp_path / "g.json")],
                       capture_output=True, text=True, timeout=300, env=env, cwd=ROOT)
    assert r.returncode == 3, r.stdout + r.stderr
    assert "bubblewrap (bwrap) is not installed" in r.stderr
    assert "apt-get install bubblewrap" in r.stderr and "--isolation none" in r.stderr
    assert not (tmp_path / "g.json").exists() and "sandbox: none" not in r.stdout


def test_the_hub_does_not_start_where_grading_would_refuse(monkeypatch):
    monkeypatch.setattr(sandbox, "_bwrap_probe", lambda: (None, "bubblewrap (bwrap) is not "
                                                          "installed: install it"))
    with pytest.raises(HubError, match="could not sandbox the students' code here.*not installed"):
        hub_setup.check_grading()


# ------------------------------------------------------------------ what crosses back

def test_a_module_message_builds_only_what_it_carries():
    """A reply naming a 20000 x 20000 layer without its weights (92 bytes) is refused before
    anything is built; a real module makes the round trip with its weights and dtype."""
    import resource

    import torch

    from annslam_lib.course import codec

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    for bad in ({"t": "module", "layers": [["Linear", 20000, 20000, True]],
                 "dtype": "float32", "state": {}},
                {"t": "module", "layers": [["Linear", 20000, 20000, False]],
                 "dtype": "float32", "state": {"0.weight": codec.encode(np.zeros((2, 2)))}},
                {"t": "module", "layers": [["Linear", 2, 2, False]] * 65, "dtype": "float32",
                 "state": {}},
                {"t": "module", "layers": [["Linear", -2, 2, False]], "state": {}}):
        with pytest.raises(codec.CodecError):
            codec.decode(json.loads(json.dumps(bad)))
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mb < 50, grown_mb                          # not the 1.6 GB of a built layer
    m = torch.nn.Sequential(torch.nn.Linear(3, 5), torch.nn.Tanh(),
                            torch.nn.Linear(5, 2, bias=False)).double()
    back = codec.decode(json.loads(json.dumps(codec.encode(m))))
    assert next(back.parameters()).dtype == torch.float64
    for a, b in zip(m.state_dict().values(), back.state_dict().values()):
        assert torch.equal(a, b)


def test_the_sandbox_binds_the_environment_not_the_grader_s_folder_or_pythonpath(tmp_path):
    """The folders on sys.path that belong to the environment are bound; the grader's
    working directory (sys.path[0] under `python -m`) and PYTHONPATH are not."""
    here, extra = tmp_path / "cwd", tmp_path / "extra"
    here.mkdir()
    extra.mkdir()
    code = ("import sys, json; sys.path.insert(0, %r)\n"
            "from annslam_lib.course import sandbox\n"
            "print(json.dumps([str(p) for p in sandbox._optional_paths()]))" % str(ROOT))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(extra)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=here,
                       env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    bound = json.loads(r.stdout)
    assert str(here) not in bound and str(extra) not in bound and str(ROOT) not in bound
    assert any(p.endswith("site-packages") for p in bound), bound


def test_inert_escapes_every_active_character_and_one_line_fields_stay_one_line():
    s = "a\u2028b\u2029c\u061cd\u200be\ufeff\u2066\u206a\ufff9"
    out = integrity.inert(s)
    assert all(ord(ch) < 128 for ch in out), out
    assert integrity.inert("x\n  ok   (2/2)", lines=False) == "x\\n  ok   (2/2)"
    assert integrity.inert("z" * 5000).endswith("[... 1000 more characters]")


def test_the_report_keeps_a_submission_s_text_under_its_own_line():
    from annslam_lib.course.grader import ExerciseResult, SubmissionGrade

    g = SubmissionGrade("/s/alice/chapter.ipynb\n  ok   forged (9/9)", "chapter.ipynb", "alice",
                        "chapter", score=0, max_score=2,
                        exercises=[ExerciseResult("ex", 0, 2, "failed",
                                                  "wrong\n/s/bob: 2 / 2 points\n  ok   ex (2/2)")],
                        notes=["gone\n/s/carol: 2 / 2 points"], errors=["cell 3\n  ok   x (2/2)"],
                        isolation="bwrap").make_inert()
    lines = g.report().splitlines()
    assert lines[0].startswith("/s/alice/chapter.ipynb\\n  ok   forged (9/9) (alice): 0 / 2")
    heads = [x for x in lines if not x.startswith(("       | ", "    | "))]
    assert not any(x.startswith(("/s/bob", "/s/carol", "  ok ")) for x in heads), lines


# ------------------------------------------------------------------ memory for the whole sandbox

@pytest.mark.needs_sandbox
def test_the_sandbox_s_processes_share_one_memory_limit():
    """Ten children of 150 MB each under a 1 GiB limit (each alone well within its address
    space): the group's peak stays within the limit and some of them are killed."""
    from annslam_lib.course import cgroup

    why = cgroup.unavailable()
    if why:
        pytest.skip(f"no control group here: {why}")
    limits = sandbox.Limits(memory_bytes=1 << 30, cell_timeout=60, deadline=120)
    code = ("import os, time\nkids = []\nfor _ in range(10):\n    pid = os.fork()\n"
            "    if pid == 0:\n        try:\n            b = bytearray(150 << 20)\n"
            "            for i in range(0, len(b), 4096):\n                b[i] = 1\n"
            "            time.sleep(30)\n        finally:\n            os._exit(0)\n"
            "    kids.append(pid)\n"
            "time.sleep(6)\nalive = sum(os.waitpid(k, os.WNOHANG)[0] == 0 for k in kids)\n")
    with sandbox.Sandbox(limits) as sb:
        assert sb.group is not None
        sb.start()
        res = sb.execute(code, 60, user_expressions={"alive": "alive"})
        peak = sb.group.peak_memory()
    assert peak is not None and (900 << 20) < peak <= (1 << 30), peak     # it reached it
    if res.status == "ok":                                  # children killed, not the kernel
        assert int(res.user_expressions["alive"]["data"]["text/plain"]) < 10
    else:
        assert res.status == "died", res.reason()
