"""The class hub's limits (annslam_lib.course.hub.limits), as root: a student's server is
started the way the hub's spawner starts it (its own account, joined to its control group
before it runs), and what runs in it, as a notebook kernel would, hoards memory, forks
without end or spins, while another student's work runs beside it."""
import os
import subprocess
import time
from pathlib import Path

import pytest
from annslam_lib.course import cgroup, hub
from annslam_lib.course.hub import limits

pytestmark = pytest.mark.skipif(os.geteuid() != 0 or bool(cgroup.unavailable()),
                                reason="needs root and cgroup controllers "
                                f"({cgroup.unavailable() if os.geteuid() == 0 else 'not root'})")
STUDENT = "annslam-lim"
MB = 1024**2


@pytest.fixture(scope="module")
def spawner():
    pytest.importorskip("jupyterhub")
    subprocess.run(["userdel", "--remove", STUDENT], capture_output=True)
    hub.ensure_account(STUDENT)
    yield limits.spawner_class()()
    subprocess.run(["userdel", "--remove", STUDENT], capture_output=True)


def _start(spawner, code: str, lim: limits.Limits):
    """``code`` run as the student in a fresh group with ``lim``, as the spawner runs a
    server (its preexec function); the group and the process."""
    spawner._group = limits.confine(STUDENT, lim)
    proc = subprocess.Popen([str(hub.system_python()), "-c", code],
                            preexec_fn=spawner.make_preexec_fn(STUDENT),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd="/")
    return spawner._group, proc


HOG = """
import os
print(os.getuid(), flush=True)
blocks = []
for _ in range(40):                        # 40 x 50 MB, every page written
    blocks.append(bytearray(50 * 1024 * 1024))
print("survived", flush=True)
"""

BOMB = """
import os, time
kids = 0
try:
    for _ in range(1000):
        pid = os.fork()
        if pid == 0:
            os.close(1), os.close(2)          # the test reads the parent's output to its end
            time.sleep(30)
            os._exit(0)
        kids += 1
except OSError as e:
    print("stopped", kids, type(e).__name__, flush=True)
"""

SPIN = """
import multiprocessing as mp, time
def spin():
    end = time.monotonic() + 3.0
    while time.monotonic() < end:
        pass
ps = [mp.Process(target=spin) for _ in range(2)]
[p.start() for p in ps]; [p.join() for p in ps]
"""


def test_a_memory_hog_is_killed_at_its_limit_as_the_student(spawner):
    group, proc = _start(spawner, HOG, limits.Limits(300 * MB, 1.0, 64))
    out, err = proc.communicate(timeout=60)
    try:
        assert int(out.split()[0]) == hub.ensure_account(STUDENT).pw_uid   # not root
        assert proc.returncode == -9 and "survived" not in out
        peak = group.peak_memory()
        print(f"memory hog: killed by signal 9 at a peak of {peak / MB:.0f} MB (limit 300 MB)")
        assert peak is None or peak <= 300 * MB + 4 * MB
    finally:
        assert group.remove()


def test_a_fork_bomb_stops_at_the_process_limit(spawner):
    group, proc = _start(spawner, BOMB, limits.Limits(1024 * MB, 1.0, 40))
    try:
        out, _ = proc.communicate(timeout=60)
        words = out.split()
        assert words[0] == "stopped" and words[2] in ("BlockingIOError", "OSError")
        held = len(group.pids())
        print(f"fork bomb: stopped after {words[1]} children; {held} processes in its group "
              "(limit 40)")
        assert int(words[1]) < 40 and 30 <= held <= 40
    finally:
        assert group.remove()                          # its sleeping children too
    assert not any(Path("/proc", str(p)).exists() for p in group.pids())


def _other_student() -> float:
    """Wall seconds of a fixed piece of CPU work in a process of its own (reported only:
    what it costs depends on what else the machine runs)."""
    t0 = time.monotonic()
    subprocess.run([str(hub.system_python()), "-c", "sum(i * i for i in range(10_000_000))"],
                   check=True)
    return time.monotonic() - t0


def test_a_busy_loop_gets_its_cpu_share_and_no_more(spawner):
    """Two processes spinning for 3 s in a group limited to half a processor: together they
    get at most its share (their CPU time as the kernel counts it for the reaped process and
    the children it reaped), however idle the machine."""
    alone = _other_student()
    group, proc = _start(spawner, SPIN, limits.Limits(1024 * MB, 0.5, 64))
    try:
        t0 = time.monotonic()
        beside = _other_student()
        _, status, ru = os.wait4(proc.pid, 0)
        wall = time.monotonic() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        used = ru.ru_utime + ru.ru_stime
        share = used / wall
        print(f"busy loop: {used:.2f} CPU-s in {wall:.2f} s of wall, {share:.2f} processors "
              "(limit 0.50; unlimited, its two spinning processes would take up to 2); "
              f"another student's fixed work took {alone:.2f} s alone, {beside:.2f} s beside it")
        assert proc.returncode == 0 and wall >= 2.9
        assert share <= 0.5 * 1.15
    finally:
        assert group.remove()


def test_an_old_group_of_the_student_is_cleared_at_the_next_start(spawner):
    group, proc = _start(spawner, "import time; time.sleep(60)", limits.Limits(256 * MB, 1.0, 16))
    first = group.pids()
    assert proc.pid in first
    again = limits.confine(STUDENT, limits.Limits(256 * MB, 1.0, 16))
    try:
        assert proc.wait(timeout=10) == -9 and again.pids() == []
    finally:
        assert again.remove()


def test_the_limits_are_the_spawners_settings(spawner):
    s = limits.spawner_class()(mem_limit=3 * 1024**3, cpu_limit=2.0, processes=100)
    assert s.limits() == limits.Limits(3 * 1024**3, 2.0, 100)
    assert limits.spawner_class()().limits() == limits.DEFAULTS
    assert limits.check() == ""


def test_the_class_hub_and_zero_to_jupyterhub_have_the_same_limits():
    import yaml

    conf = yaml.safe_load((Path(limits.__file__).parents[3] / "hub" / "z2jh" / "config.yaml")
                          .read_text())["singleuser"]
    mem = conf["memory"]["limit"]
    assert mem.endswith("M") and int(mem[:-1]) * MB == limits.DEFAULTS.memory
    assert float(conf["cpu"]["limit"]) == limits.DEFAULTS.cpus
