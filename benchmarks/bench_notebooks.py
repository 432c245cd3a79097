"""What a student waits for: every notebook's Run All, and one step of every widget.

    ANNSLAM_DATA=<data folder> python benchmarks/bench_notebooks.py [--against REF] [--repeat N]
        [--only 05 06 ...] [--json FILE]

For each notebook in notebooks/, the instructor version and the student version (the
course's release: exercises stubbed, Run All goes past them), on a fresh kernel with one BLAS
thread (``OMP_NUM_THREADS=1``, as on a hub where many kernels share the cores):

- Run All: wall seconds, and the CPU seconds of the kernel process (its own user + system
  time, read inside the kernel before the first cell and after the last: what a class pays);
- every widget (an ipywidgets container a cell returns): the seconds of one step of its first
  slider, measured in the kernel from the value change to the callback's end (figure drawn),
  without the browser's rendering; the figure printed is the median of three steps.

Each Run All starts with an empty study cache (``annslam_lib._cache``: what the first Run All
on a machine costs); ``--warm`` adds a second Run All as a student on the class hub makes it:
an empty cache of one's own and the first run's as the class's (``ANNSLAM_CLASS_CACHE``; a
second Run All on a laptop reads its own cache and costs the same). ``--against REF`` runs the same on the notebooks and library of the git revision REF (checked
out into a temporary worktree; its kernel imports that library first), one notebook after
the other, alternating, so that both see the same machine; the table then gives the ratio
current / REF. Prints figures only: a timing depends on the machine and its load (run it
alone). Targets (a class's Run All costs CPU seconds per student): Run All <= 20 s CPU,
widget step <= 0.25 s.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import nbformat

from annslam_lib.course import kernels, release

ROOT = Path(__file__).resolve().parents[1]
RUN_ALL_TARGET, STEP_TARGET = 20.0, 0.25

_START = ("import resource as _bench_r, time as _bench_t\n"
          "_bench_u = _bench_r.getrusage(_bench_r.RUSAGE_SELF)\n"
          "_bench_w = _bench_t.perf_counter()")

# Run after the last cell: the kernel's CPU since _START, then one step of every widget the
# notebook's cells returned (IPython keeps each cell's displayed result in Out).
_END = r'''
import json as _bench_j, statistics as _bench_s
_bench_v = _bench_r.getrusage(_bench_r.RUSAGE_SELF)
_bench_out = {"cpu": (_bench_v.ru_utime - _bench_u.ru_utime) + (_bench_v.ru_stime - _bench_u.ru_stime),
              "wall": _bench_t.perf_counter() - _bench_w, "widgets": []}
def _bench_step():
    import contextlib, io, ipywidgets
    for n, w in sorted(Out.items()):
        if not isinstance(w, ipywidgets.Box):
            continue
        kids = [c for c in w.children if isinstance(c, (ipywidgets.SelectionSlider,
                ipywidgets.IntSlider, ipywidgets.FloatSlider))]
        if not kids:
            continue
        s, times = kids[0], []
        for _ in range(3):
            t = _bench_t.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()):
                if isinstance(s, ipywidgets.SelectionSlider):
                    s.index = s.index + 1 if s.index + 1 < len(s.options) else s.index - 1
                else:
                    s.value = s.value + s.step if s.value + s.step <= s.max else s.value - s.step
            times.append(_bench_t.perf_counter() - t)
        _bench_out["widgets"].append({"cell": n, "control": s.description,
                                      "step": _bench_s.median(times)})
_bench_step()
import annslam_lib as _bench_lib
_bench_out["library"] = _bench_lib.__file__
print("BENCH" + _bench_j.dumps(_bench_out))
'''


def _measure(path: Path, student: bool, pythonpath: str | None, cache: Path,
             class_cache: Path | None = None) -> dict:
    nb = nbformat.read(path, as_version=4)
    with tempfile.TemporaryDirectory() as tmp:
        if student:
            path = release.release([path], Path(tmp))[0]
            nb = nbformat.read(path, as_version=4)
        nb.cells.insert(0, nbformat.v4.new_code_cell(_START))
        nb.cells.append(nbformat.v4.new_code_cell(_END))
        env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                   MKL_NUM_THREADS="1", ANNSLAM_CACHE=str(cache))
        env.pop("ANNSLAM_CLASS_CACHE", None)
        if class_cache is not None:
            env["ANNSLAM_CLASS_CACHE"] = str(class_cache)
        if pythonpath:
            env["PYTHONPATH"] = pythonpath
        saved = os.environ.copy()
        os.environ.clear()
        os.environ.update(env)          # the kernel inherits this process's environment
        try:
            kernels.run_notebook(nb, path.parent, timeout=600, allow_errors=student)
        finally:
            os.environ.clear()
            os.environ.update(saved)
    text = "".join(o.get("text", "") for o in nb.cells[-1].outputs if o.get("name") == "stdout")
    line = [t for t in text.splitlines() if t.startswith("BENCH")]
    if not line:
        raise RuntimeError(f"{path.name}: the benchmark cell printed nothing: "
                           f"{nb.cells[-1].outputs!r:.2000}")
    return json.loads(line[-1][5:])


def _worktree(ref: str, where: Path) -> Path:
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(where), ref],
                   check=True)
    return where


def _best(runs: list[dict]) -> dict:
    """Medians over repeats: CPU, wall and each widget's step."""
    out = {"cpu": statistics.median(r["cpu"] for r in runs),
           "wall": statistics.median(r["wall"] for r in runs), "widgets": []}
    for i, w in enumerate(runs[0]["widgets"]):
        out["widgets"].append(dict(w, step=statistics.median(r["widgets"][i]["step"] for r in runs)))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--against", metavar="REF", help="a git revision to measure side by side")
    p.add_argument("--repeat", type=int, default=1, help="runs per notebook and version (median)")
    p.add_argument("--only", nargs="*", default=[], help="notebook number prefixes, e.g. 05 08")
    p.add_argument("--json", type=Path, help="also write the figures to this file")
    p.add_argument("--markdown", action="store_true",
                   help="end with the README's table of waiting times (Markdown)")
    p.add_argument("--warm", action="store_true",
                   help="also Run All a second time as a student on the class hub: an empty "
                   "study cache of one's own, the one the first run filled as the class's")
    args = p.parse_args(argv)
    paths = [q for q in sorted((ROOT / "notebooks").glob("*.ipynb"))
             if not args.only or q.name.split("_")[0] in args.only]
    tmp = Path(tempfile.mkdtemp(prefix="bench-nb-"))
    trees = {"now": (ROOT, None)}
    if args.against:
        wt = _worktree(args.against, tmp / "base")
        trees["base"] = (wt, str(wt))
    results: dict = {}
    try:
        for q in paths:
            for student in (False, True):
                key = f"{q.stem} {'student' if student else 'instructor'}"
                runs: dict = {name: [] for name in [*trees, "warm"]}
                for k in range(args.repeat):
                    for name, (tree, pp) in trees.items():    # alternating: same machine state
                        nbq = tree / "notebooks" / q.name
                        if not nbq.exists():
                            continue
                        cache = tmp / f"cache-{name}-{q.stem}-{student}-{k}"   # empty: cold
                        r = _measure(nbq, student, pp, cache)
                        if pp and not r["library"].startswith(pp):
                            raise RuntimeError(f"the {name} kernel imported {r['library']}")
                        runs[name].append(r)
                        if name == "now" and args.warm:    # as on the class hub: an empty
                            own = tmp / f"own-{q.stem}-{student}-{k}"  # own cache, the
                            runs["warm"].append(_measure(nbq, student, pp, own,  # class's
                                                         class_cache=cache))     # filled
                results[key] = {name: _best(rs) for name, rs in runs.items() if rs}
                _print_row(key, results[key])
    finally:
        if args.against:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(tmp / "base")], check=False)
        shutil.rmtree(tmp, ignore_errors=True)
    _print_summary(results)
    if args.markdown:
        print("\n" + markdown_table(results))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


def _print_row(key: str, r: dict) -> None:
    now, base, warm = r["now"], r.get("base"), r.get("warm")
    ratio = f"  ({now['cpu'] / base['cpu']:.2f} x {base['cpu']:.1f} s)" if base else ""
    flag = "" if now["cpu"] <= RUN_ALL_TARGET else "  > target"
    print(f"{key:34s} Run All {now['wall']:6.1f} s wall {now['cpu']:6.1f} s CPU{ratio}{flag}",
          flush=True)
    if warm:
        flag = "" if warm["cpu"] <= RUN_ALL_TARGET else "  > target"
        print(f"{'':34s} with the class's studies: {warm['wall']:6.1f} s wall {warm['cpu']:6.1f} "
              f"s CPU{flag}", flush=True)
    for i, w in enumerate(now["widgets"]):
        b = base["widgets"][i] if base and i < len(base["widgets"]) else None
        ratio = f"  ({w['step'] / b['step']:.2f} x {b['step']:.3f} s)" if b else ""
        flag = "" if w["step"] <= STEP_TARGET else "  > target"
        print(f"{'':34s}   widget Out[{w['cell']}] '{w['control']}' step "
              f"{w['step']:.3f} s{ratio}{flag}", flush=True)


def markdown_table(results: dict) -> str:
    """The README's table: per notebook, CPU seconds of Run All (instructor / student), cold
    and with the class's studies (the study cache filled), and the slowest widget step."""
    rows = ["| notebook | Run All, CPU s (instructor / student) | with the class's studies | "
            "widget step, s |", "|---|---|---|---|"]
    stems = list(dict.fromkeys(k.rsplit(" ", 1)[0] for k in results))
    for stem in stems:
        ins, stu = results.get(f"{stem} instructor", {}), results.get(f"{stem} student", {})

        def pair(kind):
            vals = [r[kind]["cpu"] for r in (ins, stu) if kind in r]
            return " / ".join(f"{v:.1f}" for v in vals) if vals else "not measured"
        steps = [w["step"] for r in (ins, stu) if "now" in r for w in r["now"]["widgets"]]
        rows.append(f"| {stem.split('_')[0]} | {pair('now')} | {pair('warm')} | "
                    f"{max(steps):.2f} |" if steps else
                    f"| {stem.split('_')[0]} | {pair('now')} | {pair('warm')} | no widget |")
    return "\n".join(rows)


def _print_summary(results: dict) -> None:
    now = [r["now"] for r in results.values()]
    steps = [w["step"] for r in now for w in r["widgets"]]
    over = [k for k, r in results.items() if r["now"]["cpu"] > RUN_ALL_TARGET]
    print(f"\nRun All: total {sum(r['cpu'] for r in now):.1f} s CPU over {len(now)} runs; "
          f"largest {max(r['cpu'] for r in now):.1f} s; over {RUN_ALL_TARGET:.0f} s: "
          f"{', '.join(over) or 'none'}")
    warm = {k: r["warm"] for k, r in results.items() if "warm" in r}
    if warm:
        # what the Run All target is judged on where a notebook runs its heavy studies from
        # the study cache, computed once per machine (annslam_lib._cache)
        over_w = [k for k, r in warm.items() if r["cpu"] > RUN_ALL_TARGET]
        print(f"Run All with the class's studies: {len(warm)} runs, largest "
              f"{max(r['cpu'] for r in warm.values()):.1f} s; over {RUN_ALL_TARGET:.0f} s: "
              f"{', '.join(over_w) or 'none'}")
    if steps:
        print(f"widget steps: {len(steps)}, largest {max(steps):.3f} s; over {STEP_TARGET} s: "
              f"{sum(s > STEP_TARGET for s in steps)}")
    both = [k for k, r in results.items() if "base" in r]
    if both:                  # the notebooks both revisions have: totals of the same runs
        t_now = sum(results[k]["now"]["cpu"] for k in both)
        t_base = sum(results[k]["base"]["cpu"] for k in both)
        print(f"against the baseline, over the {len(both)} runs both have: total CPU "
              f"{t_now:.1f} s vs {t_base:.1f} s (ratio {t_now / t_base:.2f})")


if __name__ == "__main__":
    sys.exit(main())
