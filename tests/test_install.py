"""The README's set-up on an ordinary Linux machine: CPU torch from a CPU wheel index.

These machines carry a local CPU wheel of torch that pip finds through its configuration
(find-links). An ordinary machine has none: on the public index ``torch==2.13.0`` is the CUDA
build. So these tests switch pip's configuration and local wheel folder off, serve a stand-in
for PyTorch's CPU index on 127.0.0.1 (a PEP 503 simple index holding only the CPU wheel), and
run ``./course.sh setup`` into a fresh venv the way a newcomer's machine would meet it; every
other package comes from PyPI.
"""
from __future__ import annotations

import http.server
import importlib.util
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from annslam_lib.data import fetch


ROOT = Path(__file__).resolve().parents[1]
TORCH_CPU = "2.13.0+cpu"


def _find_links() -> list[Path]:
    """Folders pip's configuration or environment points find-links at."""
    out = subprocess.run([sys.executable, "-m", "pip", "config", "list"], capture_output=True,
                         text=True).stdout
    found = re.findall(r"find-links='([^']*)'", out)
    found += os.environ.get("PIP_FIND_LINKS", "").split()
    return [Path(p.removeprefix("file://")) for f in found for p in f.split()]


def _cpu_wheel() -> Path:
    env = os.environ.get("ANNSLAM_TEST_TORCH_WHEEL")
    candidates = [Path(env)] if env else []
    for folder in _find_links():
        candidates += sorted(folder.glob(f"torch-{TORCH_CPU}-cp311-cp311-*.whl"))
    for c in candidates:
        if c.is_file():
            return c
    pytest.skip("no local torch 2.13.0+cpu cp311 wheel to serve from a stand-in index (set "
                "ANNSLAM_TEST_TORCH_WHEEL=path/to/torch-2.13.0+cpu-cp311-...whl)")


def _python(minor: int) -> str:
    """An interpreter of Python 3.<minor> that really runs (pyenv shims may not)."""
    names = [shutil.which(f"python3.{minor}")]
    names += sorted(str(p) for p in Path.home().glob(f".pyenv/versions/3.{minor}.*/bin/python3"))
    for n in names:
        if n and subprocess.run([n, "-c", f"import sys; assert sys.version_info[:2] == (3, {minor})"],
                                capture_output=True).returncode == 0:
            return n
    pytest.skip(f"no Python 3.{minor} interpreter on this machine")


class _Index:
    """A PEP 503 simple index on 127.0.0.1 serving ``wheels`` (linked, not copied)."""

    def __init__(self, root: Path, wheels: list[Path]):
        (root / "simple" / "torch").mkdir(parents=True)
        links = []
        for w in wheels:
            (root / "simple" / "torch" / w.name).symlink_to(w)
            digest = subprocess.run(["sha256sum", str(w)], capture_output=True,
                                    text=True).stdout.split()[0]
            links.append(f'<a href="{w.name.replace("+", "%2B")}#sha256={digest}">{w.name}</a>')
        (root / "simple" / "torch" / "index.html").write_text(
            "<html><body>" + "".join(links) + "</body></html>")

        def handler(*a, **k):
            return http.server.SimpleHTTPRequestHandler(*a, directory=str(root), **k)

        http.server.SimpleHTTPRequestHandler.log_message = lambda *a: None
        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/simple"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self):
        self.server.shutdown()


@pytest.fixture(scope="module")
def cpu_index(tmp_path_factory):
    idx = _Index(tmp_path_factory.mktemp("cpu-index"), [_cpu_wheel()])
    yield idx
    idx.close()


def _ordinary_env(**extra) -> dict:
    """This environment as an ordinary machine has it: no pip configuration, no local wheel
    folder, no constraint file."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("PIP_") or k in ("PIP_CERT", "PIP_DEFAULT_TIMEOUT")}
    env.update(PIP_CONFIG_FILE=os.devnull, PIP_DISABLE_PIP_VERSION_CHECK="1",
               ANNSLAM_DATA=str(fetch.data_dir()), **extra)
    return env


def _setup(env: dict, timeout: int = 900) -> tuple[subprocess.CompletedProcess, float]:
    t0 = time.monotonic()
    out = subprocess.run(["bash", str(ROOT / "course.sh"), "setup"], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=timeout)
    return out, time.monotonic() - t0


def _size_gb(folder: Path) -> float:
    return sum(p.lstat().st_size for p in folder.rglob("*")) / 1e9


def _readme_venv_gb() -> float:
    m = re.search(r"a ([0-9.]+) GB virtual environment", (ROOT / "README.md").read_text())
    assert m, "README no longer states the venv size as 'a N.N GB virtual environment'"
    return float(m.group(1))


def _venv_facts(vpy: Path) -> dict:
    code = ("import json, importlib.metadata as m, torch\n"
            "names = sorted((d.metadata['Name'] or '').lower() for d in m.distributions())\n"
            "print(json.dumps({'cuda': torch.version.cuda, 'torch': torch.__version__,\n"
            " 'gpu_pkgs': [n for n in names if n.startswith(('nvidia-', 'triton'))]}))")
    return json.loads(subprocess.run([str(vpy), "-c", code], capture_output=True, text=True,
                                     check=True).stdout)


def test_setup_on_an_ordinary_machine_installs_the_cpu_build(cpu_index, tmp_path):
    venv = tmp_path / "venv"
    env = _ordinary_env(ANNSLAM_TORCH_INDEX=cpu_index.url, ANNSLAM_VENV=str(venv),
                        PYTHON=_python(11))
    out, seconds = _setup(env)
    log = out.stdout + out.stderr
    assert out.returncode == 0, log[-3000:]
    for stage in ("[1/4] creating venv", f"[2/4] torch {TORCH_CPU} from {cpu_index.url}",
                  "[3/4] installing environment.txt", "[4/4] checking the environment",
                  "set-up done"):
        assert stage in log, f"set-up did not announce {stage!r}"
    assert str(venv) in log                                 # messages name the venv used
    facts = _venv_facts(venv / "bin" / "python")
    assert facts["cuda"] is None and facts["torch"] == TORCH_CPU
    assert facts["gpu_pkgs"] == []
    size = _size_gb(venv)
    assert size < 2.5, f"venv is {size:.2f} GB"      # a CUDA build is 5 GB
    stated = _readme_venv_gb()
    assert abs(size - stated) <= 0.1, f"README says a {stated} GB venv, measured {size:.2f} GB"
    print(f"fresh set-up: {seconds:.0f} s, venv {size:.2f} GB")
    # A second run finds everything in place: nothing is installed again.
    again, seconds2 = _setup(env)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "up to date" in again.stdout and "(CPU build) already in" in again.stdout
    assert "installing" not in again.stdout
    assert seconds2 < 30, f"an up-to-date set-up took {seconds2:.0f} s"


@pytest.mark.parametrize("minor", [12, 13])
def test_a_python_without_a_cpu_wheel_is_refused_before_any_download(cpu_index, tmp_path, minor):
    venv = tmp_path / "venv"
    env = _ordinary_env(ANNSLAM_TORCH_INDEX=cpu_index.url, ANNSLAM_VENV=str(venv),
                        PYTHON=_python(minor))
    out, seconds = _setup(env, timeout=300)
    assert out.returncode == 1
    err = out.stderr
    assert f"no torch==2.13.0+cpu wheel for Python 3.{minor}" in err
    assert "SET-UP FAILED" in err and "PYTHON=python3.11 ./course.sh setup" in err
    assert err.count("SET-UP FAILED") == 1
    assert _size_gb(venv) < 0.05, "something large was downloaded"
    assert seconds < 60


def test_unreachable_index_falls_back_to_a_local_wheel_without_retrying(tmp_path):
    wheel = _cpu_wheel()
    with socket.socket() as s:                               # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{s.getsockname()[1]}/simple"
    folder = tmp_path / "wheels"
    folder.mkdir()
    (folder / wheel.name).symlink_to(wheel)
    venv = tmp_path / "venv"
    subprocess.run([_python(11), "-m", "venv", str(venv)], check=True)
    # PIP_COMPILE=0: no bytecode compiled for torch (the fallback is what is tested here,
    # and the size of a full set-up is checked by the test above)
    env = _ordinary_env(ANNSLAM_TORCH_INDEX=dead, PIP_FIND_LINKS=str(folder), PIP_COMPILE="0")
    t0 = time.monotonic()
    code = ("import importlib.util, sys; from pathlib import Path;"
            "spec = importlib.util.spec_from_file_location('install', sys.argv[1]);"
            "install = importlib.util.module_from_spec(spec); spec.loader.exec_module(install);"
            "v = Path(sys.argv[2]); install.ensure_torch(v / 'bin' / 'python', v)")
    out = subprocess.run([sys.executable, "-c", code, str(ROOT / "scripts" / "install.py"),
                          str(venv)],
                         env=env, capture_output=True, text=True, timeout=300)
    seconds = time.monotonic() - t0
    assert out.returncode == 0, out.stderr[-2000:]
    assert "cannot be reached" in out.stdout and "from a local wheel" in out.stdout
    assert seconds < 90, f"fallback took {seconds:.0f} s"
    code = "import importlib.metadata as m; print(m.version('torch'))"
    assert subprocess.run([str(venv / "bin" / "python"), "-c", code], capture_output=True,
                          text=True).stdout.strip() == TORCH_CPU


def test_neither_index_nor_wheel_stops_with_one_message(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        dead = f"http://127.0.0.1:{s.getsockname()[1]}/simple"
    env = _ordinary_env(ANNSLAM_TORCH_INDEX=dead, ANNSLAM_VENV=str(tmp_path / "venv"),
                        PYTHON=_python(11))
    out, seconds = _setup(env, timeout=300)
    assert out.returncode == 1
    assert out.stderr.count("SET-UP FAILED") == 1
    assert "cannot be reached" in out.stderr and "ANNSLAM_TORCH_INDEX" in out.stderr
    assert seconds < 60


def test_a_failed_install_is_retried(tmp_path):
    """The stamp is written only after the environment check passed."""
    spec = importlib.util.spec_from_file_location("install", ROOT / "scripts" / "install.py")
    install = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(install)
    venv = tmp_path / "venv"
    venv.mkdir()
    bad = tmp_path / "broken.txt"
    bad.write_text("annslam-no-such-package-anywhere==0.0.1\n")
    env_before = dict(os.environ)
    os.environ.update(_ordinary_env())
    try:
        with pytest.raises(install.SetupError, match="resumes here"):
            install.install_requirements(Path(sys.executable), venv, [bad], "[3/4]")
    finally:
        os.environ.clear()
        os.environ.update(env_before)
    assert not list(venv.glob(".annslam-installed-*")), "a failed install left a stamp"


@pytest.mark.parametrize("minor", [12, 13])
def test_every_other_pin_has_wheels_for_the_newer_pythons(minor, tmp_path):
    """INSTRUCTOR.md, Python versions: on 3.12 and 3.13 everything but torch resolves from PyPI
    as binary wheels."""
    reqs = [line.split("#")[0].strip() for line in (ROOT / "environment.txt").read_text().splitlines()]
    reqs = [r for r in reqs if r and not r.startswith(("torch", "-e"))]
    report = tmp_path / "report.json"
    out = subprocess.run([sys.executable, "-m", "pip", "install", "--dry-run", "--quiet",
                          "--ignore-installed", "--only-binary=:all:", f"--python-version=3.{minor}",
                          "--target", str(tmp_path / "t"), "--report", str(report), *reqs],
                         env=_ordinary_env(), capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    installed = {d["metadata"]["name"].lower() for d in json.loads(report.read_text())["install"]}
    assert {"numpy", "scipy", "jupyterlab", "matplotlib"} <= installed
