"""Set up the course's virtual environment: the stages of ``./course.sh setup``.

    python3 scripts/install.py [--venv DIR] [--base FILE] [--wheel] [REQUIREMENTS.txt ...]

``--base`` replaces ``environment.txt`` (``environment-student.txt`` for a class hub's
student environment); ``--wheel`` then installs the library itself as a wheel built from
this checkout (not editable: the students' environment holds no checkout).

Standard library only: it runs on the interpreter that creates the venv. Stages, each
announced by one line and skipped when its stamp says nothing changed:

1. the venv (``ANNSLAM_VENV``, default ``.venv``), created with the interpreter running this;
2. torch, the CPU build. On Linux, PyPI's ``torch==2.13.0`` is the CUDA build (16 NVIDIA
   packages, a 5 GB venv), so torch comes first, alone, from PyTorch's CPU wheel index
   (``ANNSLAM_TORCH_INDEX``, default https://download.pytorch.org/whl/cpu) as
   ``2.13.0+cpu``, the way PyTorch documents CPU-only installs. If that index cannot be
   reached, a ``2.13.0+cpu`` wheel that pip already finds locally (its ``find-links``) is
   used instead; if there is none either, set-up stops before downloading anything, with
   one message saying what to do. On macOS PyPI's wheel is already CPU-only and comes with
   the other requirements (``environment.txt`` selects it by platform marker).
3. each requirements file (``environment.txt``, then any extra ones), with pip's own
   progress output;
4. the environment check (``scripts/check_env.py``: no CUDA build, no NVIDIA packages).

A stage's stamp is written only after the check passed, so an interrupted or failed
install is retried on the next run. Exit code 0 on success; 1 with one message otherwise.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import platform
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TORCH_VERSION = "2.13.0"
TORCH_CPU = f"{TORCH_VERSION}+cpu"
TORCH_INDEX_ENV = "ANNSLAM_TORCH_INDEX"
TORCH_INDEX_DEFAULT = "https://download.pytorch.org/whl/cpu"
#: Interpreters the course supports (environment.txt's pins have wheels for them). 3.11 is
#: the one tested end to end; INSTRUCTOR.md "Python versions" states what is tested for the others.
SUPPORTED = ((3, 11), (3, 12), (3, 13))
PROBE_TIMEOUT_S = 15
STAMP_PREFIX = ".annslam-installed-"


class SetupError(RuntimeError):
    """One message for the user: what failed and the command that fixes it."""


def say(text: str) -> None:
    print(f"== {text}", flush=True)


def _pip(vpy: Path, *args: str, quiet_progress: bool = False) -> subprocess.CompletedProcess:
    cmd = [str(vpy), "-m", "pip", "install", "--disable-pip-version-check", *args]
    if quiet_progress:
        cmd.insert(4, "--progress-bar=off")
    return subprocess.run(cmd)


def _venv_python(venv: Path) -> Path:
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def _installed_version(vpy: Path, dist: str) -> str | None:
    code = ("import importlib.metadata as m, sys\n"
            "try:\n print(m.version(sys.argv[1]))\nexcept m.PackageNotFoundError:\n print('')")
    out = subprocess.run([str(vpy), "-c", code, dist], capture_output=True, text=True)
    return out.stdout.strip() or None


def _cuda_dists(vpy: Path) -> list[str]:
    code = ("import importlib.metadata as m\n"
            "print('\\n'.join(sorted({(d.metadata['Name'] or '') for d in m.distributions()"
            " if (d.metadata['Name'] or '').lower().startswith(('nvidia-', 'triton'))})))")
    out = subprocess.run([str(vpy), "-c", code], capture_output=True, text=True)
    return [s for s in out.stdout.split() if s]


def check_python(version=None) -> None:
    """Refuse an interpreter the course does not support, naming what to use instead."""
    v = tuple(version or sys.version_info[:2])
    if v not in SUPPORTED:
        names = ", ".join(f"{a}.{b}" for a, b in SUPPORTED)
        raise SetupError(
            f"annslam needs Python {names}; this is Python {v[0]}.{v[1]} ({sys.executable}). "
            f"Install Python 3.11 and run: PYTHON=/path/to/python3.11 ./course.sh setup")


def ensure_venv(venv: Path) -> Path:
    """Stage 1: the venv, (re)created when missing, broken or of another Python."""
    vpy = _venv_python(venv)
    mine = f"{sys.version_info[0]}.{sys.version_info[1]}"
    if vpy.exists():
        out = subprocess.run([str(vpy), "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
                             capture_output=True, text=True)
        theirs = out.stdout.strip()
        if out.returncode == 0 and theirs == mine:
            say(f"[1/4] venv {venv} (Python {theirs}) exists")
            return vpy
        why = (f"it is Python {theirs}, set-up runs Python {mine}" if out.returncode == 0
               else f"broken: {out.stderr.strip()[:200]}")
        say(f"[1/4] venv {venv} is replaced ({why})")
        shutil.rmtree(venv)
    say(f"[1/4] creating venv {venv} with {sys.executable} (Python "
        f"{platform.python_version()})")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    return vpy


def probe_index(index: str, timeout: float = PROBE_TIMEOUT_S) -> str | None:
    """None if the simple index answers for torch, else why not (one short line)."""
    url = index.rstrip("/") + "/torch/"
    try:
        with urllib.request.urlopen(url, timeout=timeout) as r:
            r.read(1)
        return None
    except urllib.error.HTTPError as e:
        return f"{url} answered HTTP {e.code}"
    except (urllib.error.URLError, OSError, ValueError) as e:
        reason = getattr(e, "reason", e)
        return f"{url} cannot be reached ({reason})"


def ensure_torch(vpy: Path, venv: Path) -> None:
    """Stage 2 (Linux): torch 2.13.0+cpu first, alone, never PyPI's CUDA build."""
    if not sys.platform.startswith("linux"):
        say(f"[2/4] torch: {platform.system()} wheels on PyPI are CPU-only; installed with "
            "environment.txt")
        return
    have = _installed_version(vpy, "torch")
    if have == TORCH_CPU and not _cuda_dists(vpy):
        say(f"[2/4] torch {have} (CPU build) already in {venv}")
        return
    if have is not None:                       # a CUDA build, or another version: replace it
        gone = ["torch", *_cuda_dists(vpy)]
        say(f"[2/4] removing torch {have} and {len(gone) - 1} CUDA package(s) from {venv}")
        subprocess.run([str(vpy), "-m", "pip", "uninstall", "-y", "-q", *gone], check=True)
    index = os.environ.get(TORCH_INDEX_ENV) or TORCH_INDEX_DEFAULT
    pyver = f"{sys.version_info[0]}.{sys.version_info[1]}"
    req = f"torch=={TORCH_CPU}"
    problem = probe_index(index)
    if problem is None:
        say(f"[2/4] torch {TORCH_CPU} from {index} (about 200 MB)")
        t0 = time.monotonic()
        # --no-deps: the index need only hold torch itself; its dependencies come from
        # PyPI with environment.txt. --retries 1: a failure is reported, not retried for
        # minutes.
        if _pip(vpy, "--no-deps", "--retries", "1", "--index-url", index, req).returncode == 0:
            say(f"     torch installed in {time.monotonic() - t0:.0f} s")
            return
        problem = f"{index} has no {req} wheel for Python {pyver} on {platform.machine()}"
    say(f"[2/4] {problem}; looking for a local {req} wheel (pip's find-links)")
    if _pip(vpy, "--no-deps", "--no-index", req, quiet_progress=True).returncode == 0:
        say("     torch installed from a local wheel")
        return
    raise SetupError(
        f"torch {TORCH_CPU} (the CPU build) could not be installed: {problem}, and pip finds "
        f"no local {req} wheel. Nothing large was downloaded. The course is tested on Python "
        f"3.11; PyPI's own Linux torch is the 5 GB CUDA build, which the course refuses. Fix "
        f"one of: (a) point {TORCH_INDEX_ENV} at a reachable copy of {TORCH_INDEX_DEFAULT} "
        f"(a lab mirror) and run ./course.sh setup again; (b) download "
        f"torch-{TORCH_CPU}-cp{pyver.replace('.', '')}-*.whl into a folder DIR and run "
        f"PIP_FIND_LINKS=DIR ./course.sh setup; (c) use Python 3.11: "
        f"PYTHON=python3.11 ./course.sh setup")


def _stamp_value(req: Path, vpy: Path) -> str:
    h = hashlib.sha256()
    for p in (ROOT / "pyproject.toml", req):
        h.update(p.read_bytes())
    h.update(str(vpy.resolve()).encode())
    return h.hexdigest()


def install_requirements(vpy: Path, venv: Path, reqs: list[Path], stage: str) -> list:
    """Stage 3: each file whose stamp is stale; returns the (stamp, value) pairs to write
    once the environment check passed."""
    pending = []
    for req in reqs:
        stamp = venv / f"{STAMP_PREFIX}{req.stem}"
        want = _stamp_value(req, vpy)
        if stamp.exists() and stamp.read_text().strip() == want:
            say(f"{stage} {req.name}: up to date in {venv}")
            continue
        stamp.unlink(missing_ok=True)            # a failed install below is retried next run
        n = sum(1 for line in req.read_text().splitlines()
                if line.split("#")[0].strip())
        say(f"{stage} installing {req.name} ({n} requirements and their dependencies) into "
            f"{venv}; pip's progress follows")
        t0 = time.monotonic()
        if _pip(vpy, "-r", str(req)).returncode != 0:
            raise SetupError(f"pip could not install {req.name} into {venv} (its message is "
                             "above). Check the network or the package index, then run "
                             "./course.sh setup again: it resumes here.")
        say(f"     {req.name} installed in {time.monotonic() - t0:.0f} s")
        pending.append((stamp, want))
    return pending


def _library_digest() -> str:
    h = hashlib.sha256()
    for p in sorted((ROOT / "annslam_lib").rglob("*.py")) + [ROOT / "pyproject.toml"]:
        h.update(str(p.relative_to(ROOT)).encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def install_wheel(vpy: Path, venv: Path, stage: str) -> list:
    """The library as a wheel built from this checkout, when its sources changed."""
    stamp, want = venv / f"{STAMP_PREFIX}library-wheel", _library_digest()
    if stamp.exists() and stamp.read_text().strip() == want:
        say(f"{stage} the library's wheel: up to date in {venv}")
        return []
    stamp.unlink(missing_ok=True)
    say(f"{stage} building the library's wheel and installing it into {venv}")
    wheels = venv / "annslam-wheel"
    shutil.rmtree(wheels, ignore_errors=True)
    built = subprocess.run([str(vpy), "-m", "pip", "wheel", "--disable-pip-version-check",
                            "--quiet", "--no-deps", "--wheel-dir", str(wheels), str(ROOT)])
    found = sorted(wheels.glob("annslam-*.whl"))
    if built.returncode != 0 or not found:
        raise SetupError("pip could not build the library's wheel (its message is above)")
    if _pip(vpy, "--no-deps", "--force-reinstall", "--quiet", str(found[0])).returncode != 0:
        raise SetupError(f"pip could not install {found[0].name} into {venv}")
    return [(stamp, want)]


def check_environment(vpy: Path, venv: Path) -> None:
    say("[4/4] checking the environment (CPU torch, no CUDA packages)")
    env = dict(os.environ, ANNSLAM_VENV=str(venv))
    if subprocess.run([str(vpy), str(ROOT / "scripts" / "check_env.py")], env=env).returncode:
        raise SetupError(f"the environment check of {venv} failed (above)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--venv", default=os.environ.get("ANNSLAM_VENV", ".venv"))
    ap.add_argument("--base", default="environment.txt",
                    help="the base requirements file (default environment.txt)")
    ap.add_argument("--wheel", action="store_true",
                    help="install the library as a wheel built from this checkout")
    ap.add_argument("requirements", nargs="*", default=[])
    args = ap.parse_args(argv)
    venv = Path(args.venv)
    reqs = [ROOT / args.base] + [ROOT / r for r in args.requirements]
    try:
        check_python()
        vpy = ensure_venv(venv)
        ensure_torch(vpy, venv)
        pending = install_requirements(vpy, venv, reqs, "[3/4]")
        if args.wheel:
            pending += install_wheel(vpy, venv, "[3/4]")
        check_environment(vpy, venv)
    except SetupError as e:
        print(f"\nSET-UP FAILED: {e}", file=sys.stderr)
        return 1
    except subprocess.CalledProcessError as e:
        print(f"\nSET-UP FAILED: {' '.join(map(str, e.cmd))} exited with {e.returncode}",
              file=sys.stderr)
        return 1
    for stamp, value in pending:
        stamp.write_text(value + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
