"""Run a command and report how long its process tree sat idle: a stall shows as minutes at
near-zero CPU while nothing finishes.

    python benchmarks/idle_monitor.py [--threshold 0.05] [--log FILE] -- COMMAND ...

Samples the machine's busy CPU seconds once a second (run it alone: nothing else may use the
CPUs). An idle stretch is a run of seconds in which less than ``--threshold`` of one CPU was
busy. Prints the command's output as it comes, then: wall seconds, CPU seconds of the tree,
the longest idle stretch (start, length, the processes alive then), and the count of idle
stretches over 60 s. Exits with the command's exit code. Not a test: a measurement.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import threading
import time

import psutil


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--threshold", type=float, default=0.05)
    ap.add_argument("--log", help="also write one line per second (t, CPU share) here")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args(argv)
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd)
    root = psutil.Process(proc.pid)
    samples: list[tuple[float, float, list[str]]] = []      # (t, share of one CPU, alive)
    done = threading.Event()

    def busy() -> float:
        t = psutil.cpu_times()
        return sum(t) - t.idle - getattr(t, "iowait", 0.0)

    def sample():
        # The whole machine's busy CPU seconds (/proc/stat): the command must run alone.
        # (Summing the tree's processes loses the CPU of orphans, which then looks idle.)
        last_busy, last_t = busy(), time.monotonic()
        while not done.wait(1.0):
            now, b = time.monotonic(), busy()
            try:
                alive = [" ".join(p.cmdline()[:4])[:120]
                         for p in [root, *root.children(recursive=True)]]
            except psutil.Error:
                alive = []
            samples.append((now - t0, max(0.0, b - last_busy) / max(now - last_t, 1e-9), alive))
            last_busy, last_t = b, now

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    code = proc.wait()
    done.set()
    th.join(5)
    wall = time.monotonic() - t0
    stretches, start = [], None
    for k, (t, share, _) in enumerate(samples):
        if share < args.threshold and start is None:
            start = k
        elif share >= args.threshold and start is not None:
            stretches.append((start, k))
            start = None
    if start is not None:
        stretches.append((start, len(samples)))
    longest = max(stretches, key=lambda s: s[1] - s[0], default=None)
    cpu = sum(s for _, s, _ in samples)
    print(f"== idle monitor: wall {wall:.0f} s, busy CPU {cpu:.0f} s "
          f"({cpu / max(wall, 1e-9):.2f} CPUs on average)")
    if longest:
        a, b = longest
        print(f"== longest idle stretch: {b - a} s from t = {samples[a][0]:.0f} s; "
              f"alive then: {samples[a][2][:8]}")
    print(f"== idle stretches over 60 s: {sum(1 for a, b in stretches if b - a > 60)}")
    if args.log:
        with open(args.log, "w") as f:
            for t, share, _ in samples:
                f.write(f"{t:.0f} {share:.2f}\n")
    return code


if __name__ == "__main__":
    sys.exit(main())
