"""Where the test suite's CPU goes: a pytest plugin that charges each test with the CPU the
whole machine spent while it ran (every process: kernels, servers, browsers, the grader's
sandboxes), read from /proc/stat (Linux).

    PYTHONPATH=benchmarks ANNSLAM_DATA=<data folder> .venv/bin/python -m pytest -n 0 \\
        -p suite_cpu [--suite-cpu-json FILE]

Run it serially (``-n 0``) on a machine doing nothing else: the counter is machine-wide, so
two tests at once, or anything else running, would be charged to each other. At the end it
prints the CPU seconds per file and the 20 costliest tests, with their wall seconds; their
sum is the least wall time the suite can take on the machine's cores (the sum divided by
the number of cores), whatever the scheduling.
"""
from __future__ import annotations

import collections
import json
import os
import time

_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
_rows: list[tuple[str, float, float]] = []
_start: dict[str, tuple[float, float]] = {}


def busy_seconds() -> float:
    """CPU seconds the machine has spent busy since boot (all cores; not idle, not I/O wait)."""
    with open("/proc/stat") as f:
        fields = [int(x) for x in f.readline().split()[1:]]
    return (sum(fields) - fields[3] - fields[4]) / _TICK


def pytest_addoption(parser):
    parser.addoption("--suite-cpu-json", default=None,
                     help="write [nodeid, CPU s, wall s] per test to this file")


def pytest_runtest_logstart(nodeid, location):
    _start[nodeid] = (busy_seconds(), time.monotonic())


def pytest_runtest_logfinish(nodeid, location):
    cpu0, wall0 = _start.pop(nodeid)
    _rows.append((nodeid, busy_seconds() - cpu0, time.monotonic() - wall0))


def summary(rows, top: int = 20) -> list[str]:
    """Text lines: total, CPU by file, the ``top`` costliest tests."""
    by_file = collections.defaultdict(lambda: [0.0, 0.0, 0])
    for nodeid, cpu, wall in rows:
        f = by_file[nodeid.split("::")[0]]
        f[0] += cpu
        f[1] += wall
        f[2] += 1
    cpu_all = sum(r[1] for r in rows)
    cores = os.cpu_count() or 1
    lines = [f"{len(rows)} tests: {cpu_all:.0f} CPU s in {sum(r[2] for r in rows):.0f} s of wall "
             f"time; on {cores} cores no schedule takes less than {cpu_all / cores:.0f} s",
             "   CPU s   wall s  tests  file"]
    for name, (cpu, wall, n) in sorted(by_file.items(), key=lambda kv: -kv[1][0])[:top]:
        lines.append(f"{cpu:8.1f} {wall:8.1f} {n:6d}  {name}")
    lines.append("   CPU s   wall s  test")
    for nodeid, cpu, wall in sorted(rows, key=lambda r: -r[1])[:top]:
        lines.append(f"{cpu:8.1f} {wall:8.1f}  {nodeid}")
    return lines


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _rows:
        return
    terminalreporter.section("CPU per test (whole machine, /proc/stat)")
    for line in summary(_rows):
        terminalreporter.write_line(line)
    out = config.getoption("--suite-cpu-json")
    if out:
        with open(out, "w") as f:
            json.dump([[n, round(c, 3), round(w, 3)] for n, c, w in _rows], f)
