"""The README stays true and short: its commands and chapters exist, it fits on a few screens,
and every relative link of the course's guides (README, INSTRUCTOR.md, MAINTAINING.md, the
errata page) names a file that exists and a heading that exists; the errata page's table is the
library's."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from annslam_lib import paper

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
ERRATA_PAGE = ROOT / "docs" / "errata.md"
#: The documents whose relative links must resolve.
GUIDES = ["README.md", "INSTRUCTOR.md", "MAINTAINING.md", "docs/errata.md"]
README_MAX_LINES = 150


def test_errata_page_table_is_the_library_table():
    text = ERRATA_PAGE.read_text()
    block = re.search(r"<!-- errata:begin -->\n(.*?)\n<!-- errata:end -->", text, re.S)
    assert block, "docs/errata.md lost its errata markers"
    assert block.group(1).strip() == paper.errata_markdown().strip(), (
        "docs/errata.md's table is stale: paste the output of `python -m annslam_lib errata`")
    assert block.group(1).count("\n| ") == len(paper.ERRATA)
    assert "(docs/errata.md)" in README, "the README no longer links the errata"


def test_errata_command_prints_the_table():
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "errata"], capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == paper.errata_markdown().strip()


def test_readme_is_short_and_keeps_the_two_commands():
    lines = README.splitlines()
    assert len(lines) <= README_MAX_LINES, f"README has {len(lines)} lines (at most {README_MAX_LINES})"
    blocks = re.findall(r"```bash\n(.*?)\n```", README, re.S)
    assert "./course.sh lab" in blocks and "./course.sh test" in blocks, (
        "the README lost one of its two commands, each alone in a bash block")
    for guide in ("(INSTRUCTOR.md)", "(MAINTAINING.md)"):
        assert guide in README, guide


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"[`*]", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    return {_slug(m.group(1)) for m in re.finditer(r"^#{1,6} (.+)$", text, re.M)}


@pytest.mark.parametrize("guide", GUIDES)
def test_relative_links_resolve_to_files_and_headings(guide):
    path = ROOT / guide
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    links = re.findall(r"\]\(([^)\s]+)\)", text)
    assert links, f"{guide} has no links"
    for link in links:
        if re.match(r"[a-z]+:", link):
            continue
        target, _, anchor = link.partition("#")
        file = (path.parent / target).resolve() if target else path
        assert file.exists(), f"{guide} links {link}: no such file"
        if anchor and file.suffix == ".md":
            assert anchor in _anchors(file), f"{guide} links {link}: no such heading"


def test_readme_commands_and_notebooks_exist():
    assert (ROOT / ".ci" / "run").read_text().rstrip().endswith("exec ./course.sh test")
    for nb in re.findall(r"\(notebooks/([0-9]{2}[a-z]?_[a-z_]+\.ipynb)\)", README):
        assert (ROOT / "notebooks" / nb).exists(), f"README links a missing notebook {nb}"
    on_disk = sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb"))
    linked = sorted(set(re.findall(r"\(notebooks/([0-9]{2}[a-z]?_[a-z_0-9]+\.ipynb)\)", README)))
    assert on_disk == linked, f"README notebook map {linked} differs from notebooks/ {on_disk}"


def test_notebook_links_point_to_existing_notebooks():
    import json
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(nb.read_text())["cells"]
        text = "".join("".join(c["source"]) for c in cells if c["cell_type"] == "markdown")
        for target in re.findall(r"\]\(([0-9]{2}[a-z]?_[A-Za-z0-9_]+\.ipynb)", text):
            assert (ROOT / "notebooks" / target).exists(), f"{nb.name} links a missing {target}"


def test_course_sh_refuses_an_unsupported_platform_in_one_line():
    out = subprocess.run(["bash", str(ROOT / "course.sh"), "lab"], capture_output=True, text=True,
                         env={**os.environ, "ANNSLAM_UNAME": "MINGW64_NT-10.0-19045"}, timeout=60)
    assert out.returncode == 2 and out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "not on MINGW64_NT-10.0-19045" in lines[0]
    assert "WSL 2" in lines[0] and "Windows and other laptops" in lines[0]
    assert "### Windows and other laptops" in README
