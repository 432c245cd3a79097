"""Fail loudly if the environment pulled a CUDA build of torch or NVIDIA packages.

Run by ./course.sh before anything else; tests/test_environment.py asserts the same.
"""
import sys
from importlib import metadata

problems = []
cuda_dists = sorted(d.metadata["Name"] for d in metadata.distributions()
                    if (d.metadata["Name"] or "").lower().startswith(("nvidia-", "triton")))
if cuda_dists:
    problems.append("CUDA packages were installed: " + ", ".join(cuda_dists))
try:
    import torch
except ImportError as e:  # pragma: no cover - reported, not raised
    problems.append(f"torch does not import: {e}")
else:
    if torch.version.cuda is not None:
        problems.append(f"torch {torch.__version__} is a CUDA build (cuda {torch.version.cuda}); "
                        "the course pins the CPU build torch==2.13.0")
    if not torch.__version__.startswith("2.13.0"):
        problems.append(f"torch {torch.__version__} installed, environment.txt pins 2.13.0")
if problems:
    print("ENVIRONMENT CHECK FAILED:\n  " + "\n  ".join(problems), file=sys.stderr)
    print("Fix: delete the venv (rm -rf .venv) and run ./course.sh setup again.", file=sys.stderr)
    sys.exit(1)
print(f"== environment ok: torch {torch.__version__} (CPU build), no CUDA packages")
