"""Stored outputs must not depend on the CPU: run the notebooks (strict nbval) and the README
tests as another machine would, on this one.

    ANNSLAM_DATA=<data folder> python scripts/check_other_cpus.py [--profiles avx2,sse] [--workers 1,2]

A profile forces every numerical library onto the code paths of an older CPU, in the pytest
process and the notebook kernels it starts:

- OpenBLAS (NumPy's and SciPy's) through ``OPENBLAS_CORETYPE``,
- NumPy's own SIMD loops (``arctan2``, sums, ...) through ``NPY_DISABLE_CPU_FEATURES``,
- PyTorch's vectorised kernels through ``ATEN_CPU_CAPABILITY`` and its MKL through
  ``MKL_ENABLE_INSTRUCTIONS``.

``avx2`` is a Haswell-class machine (no AVX-512), ``sse`` a generic x86-64 core (OpenBLAS's
Prescott kernels, NumPy's baseline, PyTorch's default kernels). Each profile runs with each
worker count; prints one line per run (passed, failed, seconds) and exits 1 if any failed.
Not a test: it takes several minutes per run.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PROFILES = {
    "avx2": {"OPENBLAS_CORETYPE": "Haswell", "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL",
             "ATEN_CPU_CAPABILITY": "avx2", "MKL_ENABLE_INSTRUCTIONS": "AVX2"},
    "sse": {"OPENBLAS_CORETYPE": "Prescott",
            "NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL",
            "ATEN_CPU_CAPABILITY": "default", "MKL_ENABLE_INSTRUCTIONS": "SSE4_2"},
}
TARGETS = ["notebooks", "tests/test_readme.py"]


def probe(env: dict) -> str:
    """What the libraries say they use under ``env`` (checks that the forcing took)."""
    code = ("import ctypes, numpy, scipy.linalg, torch\n"
            "from numpy._core._multiarray_umath import __cpu_features__ as f\n"
            "cores = []\n"
            "for path in sorted({l.split()[-1] for l in open('/proc/self/maps') if 'openblas' in l}):\n"
            "    lib = ctypes.CDLL(path); lib.gotoblas_corename.restype = ctypes.c_char_p\n"
            "    cores.append(lib.gotoblas_corename().decode())\n"
            "print(f'OpenBLAS {cores}, NumPy AVX-512 {bool(f.get(\"X86_V4\"))} AVX2 '\n"
            "      f'{bool(f.get(\"X86_V3\"))}, torch {torch.backends.cpu.get_cpu_capability()}')")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                       timeout=120)
    return (r.stdout or r.stderr).strip().splitlines()[-1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--profiles", default=",".join(PROFILES))
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--log", help="write each run's full output to LOG.<profile>.<workers>")
    args = ap.parse_args(argv)
    failed = 0
    for name in args.profiles.split(","):
        env = {**os.environ, **PROFILES[name], "OMP_NUM_THREADS": "1",
               "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
        print(f"== profile {name}: {probe(env)}", flush=True)
        for workers in args.workers.split(","):
            t0 = time.monotonic()
            r = subprocess.run([sys.executable, "-m", "pytest", *TARGETS, "-n", workers, "-q",
                                "-rfE"], cwd=ROOT, env=env, capture_output=True, text=True,
                               timeout=3600)
            if args.log:
                Path(f"{args.log}.{name}.{workers}").write_text(r.stdout + r.stderr)
            tail = r.stdout.strip().splitlines()[-1] if r.stdout.strip() else r.stderr[-300:]
            print(f"   {workers} worker(s): {tail} ({time.monotonic() - t0:.0f} s)", flush=True)
            if r.returncode != 0:
                failed += 1
                for line in r.stdout.splitlines():
                    if re.match(r"(FAILED|ERROR) ", line):
                        print("     ", line[:300])
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
