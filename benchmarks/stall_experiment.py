"""The stall experiment: notebooks run one after another in ONE client process, under load.

    ANNSLAM_DATA=<data folder> python benchmarks/stall_experiment.py [--sequences N] [--load K]
        [--deadline S] [--versions instructor,student] [--client course|plain] [NB ...]

Each sequence executes every notebook (instructor versions from ``notebooks/``, student
versions written by the course's release into a temporary folder) top to bottom on a fresh
kernel with nbclient, in this one process, while K busy-looping processes load the CPUs.
For every notebook it records wall seconds, the kernel's CPU seconds and the longest cell.

A **stall** is a cell that takes longer than ``--stall-after`` seconds while the kernel uses
less than 20 % of one CPU meanwhile (the kernel idle, the client waiting), a cell that
reaches its deadline (``--deadline``), or a :class:`~annslam_lib.course.kernels.
KernelStallError` (the course's client noticing a reply it saw late). With ``--client plain``
(nbclient as it comes) a stalled cell waits for its whole deadline and then carries on
without an error; ``--client course`` is the fix. When a stall is in progress, the sockets
(``ss``) and, if ``py-spy`` is on the PATH, the stacks of the client and the kernel are
written to a file in ``$ANNSLAM_STALL_DIAG`` (default: the temporary folder).

Prints one line per notebook and a summary (stalls per sequence); exits 1 if any stall.
Not a test: it takes minutes and measures the machine.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("PYTHONHASHSEED", "0")

import nbformat  # noqa: E402
import psutil  # noqa: E402

from nbclient import NotebookClient  # noqa: E402

from annslam_lib.course.kernels import CourseNotebookClient  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BUSY = "while True: pass"


class Stall(Exception):
    pass


def _kernel_cpu(km) -> float:
    proc = getattr(km.provisioner, "process", None)
    try:
        t = psutil.Process(proc.pid).cpu_times()
        return t.user + t.system
    except (psutil.Error, AttributeError):
        return float("nan")


def run_notebook(path: Path, *, deadline: float, stall_after: float, client_class,
                 allow_errors: bool) -> dict:
    nb = nbformat.read(path, as_version=4)
    cells: list[tuple[int, float, float]] = []     # (index, wall, kernel cpu)
    marks: dict = {}

    def start(cell, cell_index):
        marks["t"], marks["cpu"] = time.monotonic(), _kernel_cpu(client.km)

    def done(cell, cell_index, execute_reply):
        wall = time.monotonic() - marks["t"]
        cpu = _kernel_cpu(client.km) - marks["cpu"]
        cells.append((cell_index, wall, cpu))

    stop = threading.Event()

    def watch():                  # a stall in progress: keep what the processes were doing
        while not stop.wait(1.0):
            t = marks.get("t")
            if t is None or time.monotonic() - t < stall_after or marks.get("dumped") == t:
                continue
            cpu = _kernel_cpu(client.km) - marks["cpu"]
            if cpu < 0.2 * (time.monotonic() - t):
                marks["dumped"] = t
                _diagnose(client.km, path.name, len(cells))

    t0 = time.monotonic()
    threading.Thread(target=watch, daemon=True).start()
    client = client_class(nb, timeout=deadline, kernel_name="python3",
                          allow_errors=allow_errors, record_timing=False,
                          resources={"metadata": {"path": str(path.parent)}},
                          on_cell_execute=start, on_cell_executed=done)
    error = ""
    cpu_total = float("nan")
    try:
        with client.setup_kernel(cwd=str(path.parent)):
            for index, cell in enumerate(client.nb.cells):
                client.execute_cell(cell, index)
            cpu_total = _kernel_cpu(client.km)
    except Exception as e:                      # a deadline, a dead kernel, a cell error
        error = f"{type(e).__name__}: {str(e).strip().splitlines()[0][:160] if str(e) else ''}"
    stop.set()
    wall = time.monotonic() - t0
    stalls = [(k, w, c) for k, w, c in cells if w > stall_after and c < 0.2 * w]
    if any(w in error for w in ("KernelStallError", "CellTimeoutError", "timed out")):
        stalls.append((-1, deadline, float("nan")))
    slowest = max(cells, key=lambda x: x[1]) if cells else (-1, 0.0, 0.0)
    return {"notebook": path.name, "wall": wall, "cpu": cpu_total, "slowest_cell": slowest,
            "stalls": stalls, "error": error}


DIAG = Path(os.environ.get("ANNSLAM_STALL_DIAG", tempfile.gettempdir())) / "annslam-stalls"


def _diagnose(km, name: str, cell: int) -> None:
    """Sockets and stacks of the client and the kernel, written to DIAG (py-spy if found)."""
    DIAG.mkdir(exist_ok=True)
    out = DIAG / f"{time.strftime('%H%M%S')}-{name}-cell{cell}.txt"
    proc = getattr(km.provisioner, "process", None)
    lines = [f"connection: {json.dumps(km.get_connection_info(session=False), default=str)}"]
    cmds = [["ss", "-tanp"], ["ss", "-xanp"]]
    spy = shutil.which("py-spy")
    if spy and proc is not None:
        cmds += [[spy, "dump", "--pid", str(proc.pid)], [spy, "dump", "--pid", str(os.getpid())]]
    for cmd in cmds:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        lines += [f"$ {' '.join(cmd)}", r.stdout, r.stderr]
    out.write_text("\n".join(lines))
    print(f"   (a stall in progress: diagnostics in {out})", flush=True)


def student_versions(folder: Path) -> list[Path]:
    subprocess.run([sys.executable, "-m", "annslam_lib", "release", "--out", str(folder)],
                   check=True, capture_output=True)
    return sorted(folder.glob("*.ipynb"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("notebooks", nargs="*", help="default: every notebook of notebooks/")
    ap.add_argument("--sequences", type=int, default=5)
    ap.add_argument("--load", type=int, default=2, help="busy processes beside the run")
    ap.add_argument("--deadline", type=float, default=120.0, help="seconds per cell")
    ap.add_argument("--stall-after", type=float, default=15.0)
    ap.add_argument("--versions", default="instructor,student")
    ap.add_argument("--client", default="course", choices=["course", "plain"],
                    help="course: annslam_lib.course.kernels.CourseNotebookClient (the fix); "
                         "plain: nbclient's NotebookClient as it comes (without the fix)")
    ap.add_argument("--json", help="write every record here")
    args = ap.parse_args(argv)

    inst = [Path(p).resolve() for p in args.notebooks] or sorted(
        (ROOT / "notebooks").glob("*.ipynb"))
    tmp = tempfile.TemporaryDirectory(prefix="annslam-stall-")
    lists = []
    if "instructor" in args.versions:
        lists.append(("instructor", inst, False))
    if "student" in args.versions:
        names = {p.name for p in inst}
        lists.append(("student", [p for p in student_versions(Path(tmp.name))
                                  if p.name in names], True))
    client_class = CourseNotebookClient if args.client == "course" else NotebookClient
    load = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(args.load)]
    records, stalled_sequences = [], 0
    print(f"{args.sequences} sequence(s), {args.load} busy process(es), client "
          f"{args.client}, cell deadline {args.deadline:g} s, stall: a cell over "
          f"{args.stall_after:g} s at under 20 % CPU", flush=True)
    try:
        for s in range(args.sequences):
            n_stalls = 0
            for version, paths, allow in lists:
                for p in paths:
                    r = run_notebook(p, deadline=args.deadline, stall_after=args.stall_after,
                                     client_class=client_class, allow_errors=allow)
                    r.update(sequence=s, version=version)
                    records.append(r)
                    n_stalls += len(r["stalls"])
                    k, w, c = r["slowest_cell"]
                    print(f"seq {s} {version:10s} {r['notebook']:32s} wall {r['wall']:6.1f} s  "
                          f"kernel cpu {r['cpu']:6.1f} s  slowest cell {k} {w:5.1f} s"
                          f" ({c:4.1f} s cpu)"
                          + (f"  STALL {r['stalls']}" if r["stalls"] else "")
                          + (f"  [{r['error']}]" if r["error"] and not allow else ""),
                          flush=True)
            stalled_sequences += n_stalls > 0
    finally:
        for p in load:
            p.kill()
        tmp.cleanup()
    total = sum(len(r["stalls"]) for r in records)
    print(f"== {total} stall(s) in {args.sequences} sequence(s); {stalled_sequences} "
          "sequence(s) with a stall", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1, default=str))
    return 1 if total else 0


if __name__ == "__main__":
    sys.exit(main())
