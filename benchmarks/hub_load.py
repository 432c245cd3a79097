"""A class on one machine: how long the hub takes to serve N students at once, and what a
real hub needs per student. Loopback only, bounded (every wait has a deadline), as root.

    sudo ANNSLAM_HUB_DIR=/srv/annslam-hub .venv/bin/python benchmarks/hub_load.py \\
        [--students 10] [--chapter 05_ekf_slam] [--class-size 100] [--window 60]

The hub folder must be prepared (``./course.sh hub --prepare-only``; the class's studies it
computes are read by every student's Run All; a folder prepared with ``--no-studies``
measures each student computing them). The script makes N
short-lived student accounts (``loadNN``), starts all N servers at once and times how long
until every one is ready; then each student opens a kernel and runs every code cell of the
chapter as a student who has finished it would (the instructor version's cells, solutions
included, so that nothing stops early at an unfinished exercise; any error is counted and
printed), all N at the same time. It prints each Run All's wall and kernel CPU time, the
memory of each server and kernel (RSS, from /proc), and derives, for a class of
``--class-size`` whose students all press Run All within ``--window`` seconds, the cores and
GiB it needs. Then it stops the servers and deletes the accounts. Prints figures only (not a test).
"""
from __future__ import annotations

import argparse
import json
import os
import pwd
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

from annslam_lib.course.hub import HubLayout
from annslam_lib.course.hub.client import launch, remove_accounts
from annslam_lib.course.hub.setup import PREPARED

ROOT = Path(__file__).resolve().parents[1]
PAGE = os.sysconf("SC_PAGE_SIZE")
CPU_PROBE = ("import resource as _r; _u = _r.getrusage(_r.RUSAGE_SELF); "
             "print(_u.ru_utime + _u.ru_stime)")


def rss_by_user(uid: int) -> dict[str, float]:
    """Resident memory (MiB) of a user's server and kernels, from /proc."""
    out = {"server": 0.0, "kernels": 0.0, "kernel_count": 0}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            if proc.stat().st_uid != uid:
                continue
            cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            pages = int((proc / "statm").read_text().split()[1])
        except (OSError, ValueError, IndexError):
            continue
        mib = pages * PAGE / 2 ** 20
        if "ipykernel" in cmd:
            out["kernels"] += mib
            out["kernel_count"] += 1
        elif "jupyterhub-singleuser" in cmd or "singleuser" in cmd:
            out["server"] += mib
    return out


def code_cells(notebook: Path) -> list[str]:
    nb = json.loads(notebook.read_text())
    return ["".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code"]


def run_all(api, name: str, cells: list[str], result: dict, deadline: float) -> None:
    try:
        with api.kernel(name) as k:
            cpu0 = float(k.execute(CPU_PROBE, deadline).stdout)
            t0 = time.monotonic()
            errors = 0
            for code in cells:
                errors += k.execute(code, deadline).error is not None
            wall = time.monotonic() - t0
            cpu1 = float(k.execute(CPU_PROBE, deadline).stdout)
            result.update(wall=wall, cpu=cpu1 - cpu0, errors=errors,
                          memory=rss_by_user(pwd.getpwnam(name).pw_uid))
    except Exception as e:                              # reported with the figures
        result["failed"] = f"{type(e).__name__}: {e}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--students", type=int, default=10)
    ap.add_argument("--chapter", default="05_ekf_slam")
    ap.add_argument("--class-size", type=int, default=100)
    ap.add_argument("--window", type=float, default=60.0,
                    help="seconds within which a whole class presses Run All")
    ap.add_argument("--deadline", type=float, default=600.0, help="per cell and per start")
    args = ap.parse_args(argv)
    if os.geteuid() != 0:
        print("hub_load: run as root (it makes student accounts)", file=sys.stderr)
        return 2
    layout = HubLayout.from_env()
    if not (layout.root / PREPARED).exists():
        print(f"hub_load: prepare the hub folder {layout.root} first "
              "(./course.sh hub --prepare-only)", file=sys.stderr)
        return 2
    notebook = ROOT / "notebooks" / f"{args.chapter}.ipynb"
    if not notebook.exists():
        print(f"hub_load: no chapter {args.chapter!r}", file=sys.stderr)
        return 2
    cells = code_cells(notebook)
    names = [f"load{i:02d}" for i in range(args.students)]
    folder = Path(tempfile.mkdtemp(prefix="annslam-hub-load-"))
    hub = launch(layout, names, folder)
    hub.users = list(names)
    api = hub.api
    try:
        t0 = time.monotonic()
        for n in names:
            api.start_server(n, wait=False)
        for n in names:
            api.wait_ready(n, args.deadline)
        ready = time.monotonic() - t0
        idle = {n: rss_by_user(pwd.getpwnam(n).pw_uid)["server"] for n in names}
        print(f"{args.students} servers started at once: all ready after {ready:.1f} s; "
              f"idle server RSS median {statistics.median(idle.values()):.0f} MiB")

        results = {n: {} for n in names}
        threads = [threading.Thread(target=run_all, args=(api, n, cells, results[n],
                                                          args.deadline)) for n in names]
        t0 = time.monotonic()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        span = time.monotonic() - t0
        print(f"\n{args.students} Run Alls of {args.chapter} ({len(cells)} code cells) at "
              f"once: all done after {span:.1f} s")
        print(f"{'student':>8} {'wall s':>7} {'cpu s':>6} {'errors':>6} {'server MiB':>10} "
              f"{'kernel MiB':>10}")
        ok = {n: r for n, r in results.items() if "failed" not in r}
        for n, r in results.items():
            if "failed" in r:
                print(f"{n:>8}  FAILED: {r['failed']}")
            else:
                print(f"{n:>8} {r['wall']:7.1f} {r['cpu']:6.1f} {r['errors']:6d} "
                      f"{r['memory']['server']:10.0f} {r['memory']['kernels']:10.0f}")
        if not ok:
            return 1
        cpu = statistics.median(r["cpu"] for r in ok.values())
        per = statistics.median(r["memory"]["server"] + r["memory"]["kernels"]
                                for r in ok.values())
        cores = args.class_size * cpu / args.window
        gib = args.class_size * per / 1024
        print(f"\nper student: {cpu:.1f} s of CPU for one Run All of {args.chapter}, "
              f"{per:.0f} MiB for a server with its kernel (medians)")
        print(f"a class of {args.class_size} all pressing Run All within {args.window:.0f} s "
              f"needs about {cores:.0f} cores ({args.class_size} x {cpu:.1f} s / "
              f"{args.window:.0f} s) and {gib:.1f} GiB of memory ({args.class_size} x "
              f"{per:.0f} MiB), before any headroom")
        print(f"here ({os.cpu_count()} cores): {args.students} students' Run Alls took "
              f"{span:.1f} s in all, against {cpu:.1f} s for one alone by CPU time")
        return 0
    finally:
        hub.stop()
        remove_accounts(names)


if __name__ == "__main__":
    sys.exit(main())
