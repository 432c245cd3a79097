"""One version everywhere, so that an instructor who pins a semester to a release knows what
they have: ``version`` in pyproject.toml's ``[project]`` is the one source; the installed
metadata (``annslam_lib.__version__`` reads it), CITATION.cff, the top entry of CHANGELOG.md
and ``python -m annslam_lib --version`` repeat it. CITATION.cff is valid Citation File Format
1.2.0: checked against the format's own JSON Schema, kept verbatim in tests/vendor/."""
import json
import re
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import annslam_lib

ROOT = Path(__file__).resolve().parents[1]
SCHEMA = ROOT / "tests" / "vendor" / "citation-file-format-1.2.0.schema.json"
START = "<!-- towncrier release notes start -->"
REFRESH = "refresh the editable install's metadata: ./course.sh setup (or pip install -e .)"


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def _version() -> str:
    return _pyproject()["project"]["version"]


def _cff() -> dict:
    yaml = pytest.importorskip("yaml", reason="PyYAML reads CITATION.cff "
                                              "(environment-instructor.txt)")
    return yaml.safe_load((ROOT / "CITATION.cff").read_text())


def _top_entry() -> tuple[str, str]:
    """(version, date) of the newest entry of CHANGELOG.md: the first heading after the
    marker towncrier writes below."""
    text = (ROOT / "CHANGELOG.md").read_text()
    assert text.count(START) == 1, f"CHANGELOG.md must hold towncrier's marker {START!r} once"
    m = re.search(r"^## \[([^\]]+)\] - (\d{4}-\d{2}-\d{2})$", text.split(START, 1)[1], re.M)
    assert m, "CHANGELOG.md has no entry '## [X.Y.Z] - YYYY-MM-DD' below the marker"
    return m.group(1), m.group(2)


def test_the_version_is_a_release_number():
    assert re.fullmatch(r"\d+\.\d+\.\d+", _version()), _version()


def test_pyproject_citation_changelog_and_the_package_agree():
    version = _version()
    assert _cff()["version"] == version, "CITATION.cff's version"
    assert _top_entry()[0] == version, "CHANGELOG.md's top entry"
    assert metadata.version("annslam") == version, REFRESH
    assert annslam_lib.__version__ == version, REFRESH


def test_the_changelog_entry_is_dated_as_the_citation():
    assert _top_entry()[1] == str(_cff()["date-released"])


def test_version_flag_prints_it():
    # from another folder, so that the installed metadata answers, not a folder of the checkout
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "--version"], cwd=ROOT / "tests",
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout == f"annslam {_version()}\n", REFRESH


def test_citation_cff_has_the_required_keys():
    cff = _cff()
    assert cff["cff-version"] == "1.2.0"
    for key in ("message", "title", "authors", "version", "date-released"):
        assert cff.get(key), key
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", str(cff["date-released"]))
    for author in cff["authors"]:
        assert author.get("name") or author.get("family-names") and author.get("given-names"), \
            author


def _validator():
    jsonschema = pytest.importorskip("jsonschema", reason="jsonschema checks CITATION.cff "
                                                          "(environment-instructor.txt)")
    schema = json.loads(SCHEMA.read_text())
    assert schema["$id"] == "https://citation-file-format.github.io/1.2.0/schema.json"
    cls = jsonschema.Draft7Validator
    cls.check_schema(schema)
    return cls(schema, format_checker=cls.FORMAT_CHECKER)


def test_citation_cff_is_valid_against_the_cff_1_2_0_schema():
    errors = sorted(_validator().iter_errors(_cff()), key=lambda e: list(e.path))
    assert not errors, "\n".join(f"{'/'.join(map(str, e.path))}: {e.message}" for e in errors)


@pytest.mark.parametrize("spoil", ["no authors", "a misspelt author key", "a bad date", "no title"])
def test_the_schema_refuses_a_spoilt_citation(spoil):
    cff = dict(_cff())
    if spoil == "no authors":
        del cff["authors"]
    elif spoil == "a misspelt author key":
        cff["authors"] = [{"family_names": "Nebot"}]
    elif spoil == "a bad date":
        cff["date-released"] = "07/12/26"
    else:
        del cff["title"]
    assert list(_validator().iter_errors(cff)), spoil


def test_towncrier_renders_the_next_entry_with_this_configuration():
    pytest.importorskip("towncrier", reason="towncrier writes CHANGELOG.md "
                                            "(environment-instructor.txt)")
    assert _pyproject()["tool"]["towncrier"]["filename"] == "CHANGELOG.md"
    out = subprocess.run([sys.executable, "-m", "towncrier", "build", "--draft",
                          "--version", "9.9.9", "--date", "YYYY-MM-DD"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "## [9.9.9] - YYYY-MM-DD" in out.stdout, out.stdout
