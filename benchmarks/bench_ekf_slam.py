"""EKF-SLAM timings: the efficient filter (annslam_lib.slam.efficient) against the dense
textbook reference (annslam_lib.slam.dense), measured side by side in one process.

    OMP_NUM_THREADS=1 ANNSLAM_DATA=<data folder> python benchmarks/bench_ekf_slam.py [--quick]
    OMP_NUM_THREADS=1 ANNSLAM_DATA=<data folder> python benchmarks/bench_ekf_slam.py \
        --against REF [REF ...] [--rounds N]

Prints figures only (not a test: timings depend on the machine and its load).
- per step (one odometry prediction + one update with one observation) at N = 50, 150,
  300 landmarks, both filters, and the ratio;
- the first 200 s of Victoria Park with each backend (the dense one is too slow for the
  whole run), and the ratio;
- the Car Park and the full Victoria Park run with their default configurations (best of
  five, CPU time), against the target of 2.0 s CPU for Victoria Park (a class's Run All
  costs CPU seconds per student).

``--against REF ...`` times only the whole Victoria Park run, of this checkout and of each
git revision REF (checked out into a temporary worktree), each in its own process that
imports that library, alternating over ``--rounds`` rounds of three runs so that all see
the same machine, and of this checkout with ``ANNSLAM_KERNEL=numpy`` (the numpy gating,
``slam.compiled``); prints each one's best and median CPU, a fresh process's CPU up to its
first result, its counts (the same decisions give the same counts) and the ratio current / REF,
with a verdict for each: the 2.0 s target is a ratio of at most 0.83 against a baseline whose
run took 2.41 s, so the verdict means something only when REF is that baseline revision.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from annslam_lib.data import loaders, records  # noqa: E402
from annslam_lib.data.records import Odometry  # noqa: E402
from annslam_lib.evaluation import trajectory  # noqa: E402
from annslam_lib.models import motion  # noqa: E402
from annslam_lib.models.observation import observe  # noqa: E402
from annslam_lib.models.vehicle import ACFR_UTE  # noqa: E402
from annslam_lib.slam import config as slam_config  # noqa: E402
from annslam_lib.slam import efficient, runner  # noqa: E402
from annslam_lib.slam.dense import DenseEkfSlam  # noqa: E402

VP_TARGET_CPU = 2.0            # seconds: a class's Run All costs CPU seconds per student
VP_TARGET_RATIO = 0.83         # 2.0 s against a baseline run of 2.41 s, side by side
ROOT = Path(__file__).resolve().parents[1]

SIGMA_R, SIGMA_B = 0.1, math.radians(1.0)


def make_filter(cls, n_landmarks: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    f = cls(np.array([0.0, 0.0, 0.3]), np.diag([0.01, 0.01, 0.001]), ACFR_UTE)
    z = np.column_stack([rng.uniform(3, 40, n_landmarks), rng.uniform(0.05, 3.1, n_landmarks)])
    f.augment(z, SIGMA_R, SIGMA_B)
    return f


def time_steps(f, steps: int, controls, rng) -> tuple[float, float, float]:
    """Mean seconds per (predict, update, predict + update) over ``steps`` steps."""
    t_pred = t_upd = 0.0
    N = f.n_landmarks
    for k in range(steps):
        u = controls[k % len(controls)]
        j = int(rng.integers(N))
        t0 = time.perf_counter()
        f.predict(u, 0.025)
        f.flush()                      # the efficient filter's deferred work, counted here
        t1 = time.perf_counter()
        zhat, _, _ = observe(f.pose, f.landmarks()[j])
        z = zhat + rng.normal(0, [SIGMA_R, SIGMA_B])
        t2 = time.perf_counter()
        f.update(z[None], [j], SIGMA_R, SIGMA_B)
        t3 = time.perf_counter()
        t_pred += t1 - t0
        t_upd += t3 - t2
    return t_pred / steps, t_upd / steps, (t_pred + t_upd) / steps


def per_step(sizes=(50, 150, 300), quick=False) -> None:
    odo = Odometry(t=np.arange(200) * 0.025, speed=np.full(200, 2.0),
                   steering=0.2 * np.sin(np.arange(200) / 20))
    controls = motion.control_table(odo, ACFR_UTE, 0.7, math.radians(7))
    print("per step: one odometry prediction + one update with one observation")
    print(f"{'N':>5} {'n':>5} | {'predict eff/dense (us)':>24} | {'update eff/dense (us)':>24} | "
          f"{'step eff/dense (us)':>24} | ratio")
    for N in sizes:
        eff = make_filter(efficient.EkfSlam, N)
        dense = make_filter(DenseEkfSlam, N)
        n_eff = 200 if quick else 2000
        n_dense = max(3, int((20 if quick else 60) * (50 / N) ** 2))
        time_steps(eff, 20, controls, np.random.default_rng(1))          # warm up
        time_steps(dense, 2, controls, np.random.default_rng(1))
        pe, ue, se = time_steps(eff, n_eff, controls, np.random.default_rng(2))
        pd, ud, sd = time_steps(dense, n_dense, controls, np.random.default_rng(2))
        print(f"{N:5d} {3 + 2 * N:5d} | {pe * 1e6:10.1f} / {pd * 1e6:11.1f} | "
              f"{ue * 1e6:10.1f} / {ud * 1e6:11.1f} | {se * 1e6:10.1f} / {sd * 1e6:11.1f} | "
              f"{sd / se:7.0f}x")


def backends_side_by_side(seconds: float = 200.0) -> None:
    ds = records.truncate(loaders.load_victoria_park(), seconds)
    cfg = slam_config.SlamConfig.for_dataset("victoria_park")
    cpu = {}
    for backend in ("efficient", "dense"):
        runner.run(ds, cfg, backend=backend)                  # warm (detections, caches)
        best = math.inf
        for _ in range(3 if backend == "efficient" else 1):
            c = time.process_time()
            r = runner.run(ds, cfg, backend=backend)
            best = min(best, time.process_time() - c)
        cpu[backend] = (best, r)
    (te, re), (td, rd) = cpu["efficient"], cpu["dense"]
    dx = float(np.max(np.abs(re.trajectory[:, 1:3] - rd.trajectory[:, 1:3])))
    print(f"Victoria Park, first {seconds:.0f} s ({re.counts['scans']} scans, "
          f"{re.counts['landmarks']} landmarks): efficient {te:.3f} s CPU, dense {td:.3f} s CPU, "
          f"ratio {td / te:.1f}x; largest pose difference {dx:.1e} m")


def whole_run(name: str, repeats: int = 5) -> float:
    ds = loaders.load(name)
    cfg = slam_config.SlamConfig.for_dataset(name)
    runner.run(ds, cfg)                                       # warm (detections, caches)
    cpus, r = [], None
    for _ in range(repeats):
        c = time.process_time()
        r = runner.run(ds, cfg, progress=False)
        cpus.append(time.process_time() - c)
    e = trajectory.trajectory_errors(r.odometry_trajectory, ds.gps)
    c = r.counts
    print(f"  {name}: CPU best {min(cpus):.2f} s, median {float(np.median(cpus)):.2f} s of "
          f"{repeats} ({', '.join(f'{x:.2f}' for x in cpus)}); {c['predicts']} predictions, "
          f"{c['scans']} scans, {c['updates']} batch updates, {c['associated']} associated / "
          f"{c['new']} new / {c['rejected']} rejected observations, {c['landmarks']} landmarks "
          f"({c['landmarks_removed']} tentative removed), state size {r.state.size}, gating "
          f"{getattr(r, 'gating', 'numpy')}")
    print(f"  vs GPS: {e.summary()}; median {np.median(e.error):.2f} m, 90th percentile "
          f"{np.percentile(e.error, 90):.2f} m")
    print(f"  min eigenvalue at checkpoints {r.health['min_eig'].min():.2e}, "
          f"max asymmetry {r.health['asymmetry'].max():.1e}")
    return min(cpus)


def _child(tree: str, repeats: int) -> None:
    """In a process of its own: the whole Victoria Park run of the library in ``tree``
    (warm once, then ``repeats`` timed runs); prints a JSON line."""
    import annslam_lib
    if not Path(annslam_lib.__file__).resolve().is_relative_to(Path(tree).resolve()):
        raise SystemExit(f"imported {annslam_lib.__file__}, not the library in {tree}")
    ds = loaders.load("victoria_park")
    cfg = slam_config.SlamConfig.for_dataset("victoria_park")
    runner.run(ds, cfg, progress=False)
    first = time.process_time()            # the process so far: imports, data, the first run
    cpus = []
    for _ in range(repeats):
        c = time.process_time()
        r = runner.run(ds, cfg, progress=False)
        cpus.append(time.process_time() - c)
    keys = ("scans", "updates", "associated", "new", "rejected", "landmarks")
    print(json.dumps({"cpu": cpus, "first": first, "gating": getattr(r, "gating", "numpy"),
                      "counts": {k: r.counts[k] for k in keys}}))


def side_by_side(refs: list[str], rounds: int) -> None:
    """The Victoria Park run of this checkout against the revisions ``refs`` (module
    docstring)."""
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"current": ROOT, "numpy": ROOT}   # "numpy": this checkout, ANNSLAM_KERNEL=numpy
        for i, ref in enumerate(refs):
            where = Path(tmp) / f"ref{i}"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q",
                            str(where), ref], check=True)
            trees[ref] = where
        try:
            got = {name: {"cpu": [], "first": []} for name in trees}
            for _ in range(rounds):
                for name, tree in trees.items():
                    env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1",
                               OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
                    env.pop("ANNSLAM_KERNEL", None)
                    if name == "numpy":
                        env["ANNSLAM_KERNEL"] = "numpy"
                    out = subprocess.run([sys.executable, __file__, "--child", str(tree)],
                                         env=env, capture_output=True, text=True, check=True)
                    res = json.loads(out.stdout.strip().splitlines()[-1])
                    got[name]["cpu"] += res["cpu"]
                    got[name]["first"].append(res["first"])
                    got[name]["counts"] = res["counts"]
                    got[name]["gating"] = res["gating"]
        finally:
            for name, tree in trees.items():
                if name not in ("current", "numpy"):
                    subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                                    str(tree)], check=False)
    print(f"Victoria Park, whole run, CPU s ({rounds} rounds of 3 runs each, alternating; "
          "'numpy': this checkout with ANNSLAM_KERNEL=numpy; 'fresh': a new process's CPU up to "
          "its first result, imports and data included):")
    best = {name: min(g["cpu"]) for name, g in got.items()}
    for name, g in got.items():
        ratio = "" if name == "current" else f"; current / this = {best['current'] / best[name]:.3f}"
        print(f"  {name:>10}: best {best[name]:.3f}, median {float(np.median(g['cpu'])):.3f} "
              f"(of {len(g['cpu'])}), fresh best {min(g['first']):.2f}, gating {g['gating']}; "
              f"counts {g['counts']}{ratio}")
    verdict = "met" if best["current"] < VP_TARGET_CPU else "NOT met"
    print(f"target under {VP_TARGET_CPU:.1f} s CPU here: {best['current']:.2f} s, "
          f"{verdict}")
    for name in refs:
        ratio = best["current"] / best[name]
        print(f"against {name}: ratio {ratio:.3f}, {'met' if ratio <= VP_TARGET_RATIO else 'NOT met'}"
              f" (at most {VP_TARGET_RATIO}: 2.0 s against a baseline run of 2.41 s; "
              "meaningful only against that baseline revision)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--against", nargs="+", metavar="REF",
                        help="git revisions: time the Victoria Park run side by side")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of --against (3)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child, 3)
        return
    if args.against:
        side_by_side(args.against, args.rounds)
        return
    print(f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, numpy {np.__version__}")
    per_step(quick=args.quick)
    backends_side_by_side(100.0 if args.quick else 200.0)
    print("whole runs (default configurations)")
    whole_run("car_park", 1 if args.quick else 5)
    vp = whole_run("victoria_park", 1 if args.quick else 5)
    verdict = "met" if vp < VP_TARGET_CPU else "NOT met"
    print(f"Victoria Park target: under {VP_TARGET_CPU:.1f} s CPU -> {vp:.2f} s, {verdict}")


if __name__ == "__main__":
    main()
