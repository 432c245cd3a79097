"""Grading time per submission: this checkout against git revisions, side by side.

    ANNSLAM_DATA=<data folder> python benchmarks/bench_grading.py --against REF [REF ...] \
        [--chapters 02_laser_offset 03_observation] [--students 3] [--rounds 3]

A batch of honest submissions (every solution cell filled with the instructor's solution,
``--students`` copies of each chapter in ``--chapters``) is graded by ``python -m annslam_lib
grade`` of this checkout and of each revision REF (checked out into a temporary worktree),
each in its own process importing its own library, with its default isolation, alternating
over ``--rounds`` rounds so that all see the same machine. Prints, per code, the median of
the grader's own seconds per submission (the JSON's ``seconds``: sandbox, kernel, the
notebook's cells and the checks) and of the whole command's wall time, every score (the
same work must earn the same), and the ratio current / REF of the per-submission median
against the rule that a sandbox may not make grading slower by more than 20 % (ratio at
most 1.20). Figures only: timings depend on the machine and its load.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
MAX_RATIO = 1.20


def _batch(folder: Path, chapters, students: int) -> None:
    import grading_support as gs

    for ch in chapters:
        nb = ROOT / "notebooks" / f"{ch}.ipynb"
        bodies = gs.solution_bodies(nb)
        import nbformat
        from annslam_lib.course import release

        sub = release.student_version(nbformat.read(nb, as_version=4), ch)
        for c in sub.cells:
            gid = c.metadata.get("nbgrader", {}).get("grade_id")
            if gid in bodies:
                c.source = bodies[gid]
        for k in range(students):
            gs.write(sub, folder / "submitted" / f"s{k}" / ch / f"{ch}.ipynb")


def _grade(tree: Path, batch: Path, out: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONPYCACHEPREFIX")}
    env.update(PYTHONPATH=str(tree), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
               MKL_NUM_THREADS="1")
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "annslam_lib", "grade", str(batch / "submitted"),
                        "--instructor", str(tree / "notebooks"), "--json", str(out)],
                       env=env, cwd=tree, capture_output=True, text=True)
    wall = time.monotonic() - t0
    if r.returncode != 0:
        raise SystemExit(f"grading with {tree} failed ({r.returncode}):\n{r.stdout[-2000:]}\n"
                         f"{r.stderr[-2000:]}")
    rows = json.loads(out.read_text())
    return {"wall": wall, "seconds": [row["seconds"] for row in rows],
            "scores": sorted((row["student"], row["assignment"], row["score"]) for row in rows),
            "isolation": sorted({row["isolation"] for row in rows})}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--against", nargs="+", metavar="REF", required=True)
    p.add_argument("--chapters", nargs="+", default=["02_laser_offset", "03_observation"])
    p.add_argument("--students", type=int, default=3)
    p.add_argument("--rounds", type=int, default=3)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _batch(tmp / "batch", args.chapters, args.students)
        trees = {"current": ROOT}
        for i, ref in enumerate(args.against):
            where = tmp / f"ref{i}"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q",
                            str(where), ref], check=True)
            trees[ref] = where
        got = {name: {"wall": [], "seconds": []} for name in trees}
        try:
            for _ in range(args.rounds):
                for name, tree in trees.items():
                    res = _grade(tree, tmp / "batch", tmp / f"{name}.json")
                    got[name]["wall"].append(res["wall"])
                    got[name]["seconds"] += res["seconds"]
                    got[name]["scores"] = res["scores"]
                    got[name]["isolation"] = res["isolation"]
        finally:
            for name, tree in trees.items():
                if name != "current":
                    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                                    str(tree)], check=False)
    n = len(args.chapters) * args.students
    print(f"{n} honest submissions ({', '.join(args.chapters)}; {args.students} each), "
          f"{args.rounds} rounds, alternating:")
    med = {name: statistics.median(g["seconds"]) for name, g in got.items()}
    for name, g in got.items():
        print(f"  {name:>10}: per submission median {med[name]:.2f} s (min {min(g['seconds']):.2f},"
              f" max {max(g['seconds']):.2f}, of {len(g['seconds'])}); whole command median "
              f"{statistics.median(g['wall']):.1f} s; isolation {g['isolation']}; total score "
              f"{sum(s for _, _, s in g['scores']):g}")
    for ref in args.against:
        same = got[ref]["scores"] == got["current"]["scores"]
        ratio = med["current"] / med[ref]
        print(f"against {ref}: per-submission ratio {ratio:.3f} "
              f"({'within' if ratio <= MAX_RATIO else 'OVER'} the {MAX_RATIO:.2f} allowed); "
              f"scores {'identical' if same else 'DIFFER'}")


if __name__ == "__main__":
    main()
