"""The environment the course runs in: exact pins, CPU-only torch, no CUDA packages."""
import re
from importlib import metadata
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]


def _pins(name: str = "environment.txt") -> dict[str, str]:
    """{package: pinned version} for this platform (lines whose marker does not apply to it,
    e.g. macOS's torch on Linux, are left out)."""
    from packaging.requirements import Requirement

    pins = {}
    for raw in (ROOT / name).read_text().splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line or line == "-e .":
            continue
        req = Requirement(line)
        spec = str(req.specifier)
        m = re.fullmatch(r"==([0-9][A-Za-z0-9.+\-]*)", spec)
        assert m, f"{name}: {raw!r} is not pinned to an exact version"
        if req.marker is None or req.marker.evaluate():
            pins[req.name.lower()] = m.group(1)
    return pins


def test_every_requirement_is_pinned_and_installed_at_that_version():
    pins = _pins()
    for required in ("jupyterlab", "ipywidgets", "numpy", "scipy", "matplotlib", "torch",
                     "nbval", "pytest", "sympy", "gtsam", "numba"):
        assert required in pins, f"{required} missing from environment.txt"
    for name, version in pins.items():
        installed = metadata.version(name)
        assert installed == version, f"{name}: pinned {version}, installed {installed}"


def test_instructor_extras_are_pinned_and_if_installed_at_that_version():
    pins = _pins("environment-instructor.txt")
    assert set(pins) == {"nbgrader", "playwright", "evo", "pytest-timeout",
                         "jupyter-repo2docker", "pyyaml", "jsonschema", "towncrier", "sphinx",
                         "myst-nb", "sphinx-book-theme", "sphinx-mathjax-offline",
                         "axe-playwright-python"}
    for name, version in pins.items():
        try:
            installed = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue  # optional: a lab venv without them is fine (their tests skip and say so)
        assert installed == version, f"{name}: pinned {version}, installed {installed}"


def test_linux_pins_the_cpu_build_and_macos_the_pypi_wheel():
    lines = (ROOT / "environment.txt").read_text().splitlines()
    assert 'torch==2.13.0+cpu; sys_platform == "linux"' in lines
    assert 'torch==2.13.0; sys_platform == "darwin"' in lines
    assert not [x for x in lines if x.startswith("torch") and "sys_platform" not in x]


def test_torch_is_the_cpu_build_without_cuda_packages():
    assert torch.version.cuda is None, f"torch {torch.__version__} is a CUDA build"
    names = [(d.metadata["Name"] or "").lower() for d in metadata.distributions()]
    cuda = sorted(n for n in names if n.startswith(("nvidia-", "triton")))
    assert cuda == [], f"CUDA packages installed: {cuda}"


def test_library_is_installed_not_path_hacked():
    import annslam_lib
    assert Path(annslam_lib.__file__).resolve().parent == ROOT / "annslam_lib"
    # pip's record of the install (an egg-info folder in the checkout may shadow it first)
    urls = [d.read_text("direct_url.json") or "" for d in metadata.distributions(name="annslam")]
    assert any('"editable": true' in u for u in urls), f"annslam is not an editable install: {urls}"
