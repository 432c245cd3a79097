"""Fail loudly if the environment holds a CUDA build of torch or NVIDIA packages.

Run inside the venv by scripts/install.py (the last stage of ./course.sh setup);
tests/test_environment.py asserts the same.
"""
import os
import sys
from importlib import metadata

venv = os.environ.get("ANNSLAM_VENV", sys.prefix)
problems = []
cuda_dists = sorted(d.metadata["Name"] for d in metadata.distributions()
                    if (d.metadata["Name"] or "").lower().startswith(("nvidia-", "triton")))
if cuda_dists:
    problems.append("CUDA packages are installed: " + ", ".join(cuda_dists))
try:
    import torch
except ImportError as e:  # pragma: no cover - reported, not raised
    problems.append(f"torch does not import: {e}")
else:
    if torch.version.cuda is not None:
        problems.append(f"torch {torch.__version__} is a CUDA build (cuda {torch.version.cuda}); "
                        "the course uses the CPU build 2.13.0+cpu")
    if not torch.__version__.startswith("2.13.0"):
        problems.append(f"torch {torch.__version__} is installed; environment.txt pins 2.13.0")
if problems:
    print(f"ENVIRONMENT CHECK FAILED in {venv}:\n  " + "\n  ".join(problems), file=sys.stderr)
    print("Fix: run ./course.sh setup again: it replaces a CUDA or mismatched torch with the "
          "CPU build and removes the CUDA packages.", file=sys.stderr)
    sys.exit(1)
print(f"== environment ok in {venv}: torch {torch.__version__} (CPU build), no CUDA packages")
