"""Ready to adopt: the licences and the citation exist, agree with the package
metadata, and are linked where an instructor looks first."""
import json
import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_the_code_licence_is_mit_as_the_package_declares():
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License\n") and "WITHOUT WARRANTY OF ANY KIND" in text
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == {"text": "MIT"}


def test_the_content_licence_names_cc_by_and_what_it_does_not_cover():
    text = (ROOT / "LICENSE-CONTENT.md").read_text()
    assert "Creative Commons Attribution 4.0 International" in text and "CC-BY-4.0" in text
    assert "creativecommons.org/licenses/by/4.0/legalcode" in text
    for excluded in ("the 2013 paper", "the data"):
        assert excluded in text


def test_citation_cff_has_the_required_fields_and_the_package_version():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0"
    for key in ("message", "title", "authors", "version", "license"):
        assert cff.get(key), key
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert cff["version"] == meta["version"] and cff["license"] == "MIT"
    titles = [r["title"] for r in cff["references"]]
    assert any(t.startswith("Adapting Enhanced the Simultaneous Localization") for t in titles)
    assert any("real-time implementation" in t for t in titles)         # the ACFR data


def test_the_readme_links_the_licences_and_the_citation_on_its_first_screen():
    first = "\n".join((ROOT / "README.md").read_text().splitlines()[:40])
    for target in ("(LICENSE)", "(LICENSE-CONTENT.md)", "(CITATION.cff)"):
        assert target in first, target


def test_every_notebook_ends_with_its_licence_footer():
    for path in NOTEBOOKS:
        last = json.loads(path.read_text())["cells"][-1]
        text = "".join(last["source"])
        assert last["cell_type"] == "markdown", path.name
        for target in ("(../LICENSE-CONTENT.md)", "(../LICENSE)", "(../CITATION.cff)", "CC-BY-4.0"):
            assert target in text, (path.name, target)
        for link in ("LICENSE-CONTENT.md", "LICENSE", "CITATION.cff"):
            assert (ROOT / link).is_file()
