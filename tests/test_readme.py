"""The README stays true: its errata table is the library's, its commands exist."""
import os
import re
import subprocess
import sys
from pathlib import Path

from annslam_lib import paper

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_readme_errata_table_is_the_library_table():
    block = re.search(r"<!-- errata:begin -->\n(.*?)\n<!-- errata:end -->", README, re.S)
    assert block, "README lost its errata markers"
    assert block.group(1).strip() == paper.errata_markdown().strip(), (
        "README errata table is stale: paste the output of `python -m annslam_lib errata`")
    assert block.group(1).count("\n| ") == len(paper.ERRATA)


def test_readme_exercise_table_is_the_notebooks_table():
    from annslam_lib.course.release import exercise_table

    block = re.search(r"<!-- exercises:begin -->\n(.*?)\n?<!-- exercises:end -->", README, re.S)
    assert block, "README lost its exercises markers"
    table = exercise_table(sorted((ROOT / "notebooks").glob("*.ipynb")))
    assert block.group(1).strip() == table.strip(), (
        "README exercise table is stale: paste the output of `python -m annslam_lib exercises`")


def test_errata_command_prints_the_table():
    out = subprocess.run([sys.executable, "-m", "annslam_lib", "errata"], capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == paper.errata_markdown().strip()


def test_readme_commands_and_notebooks_exist():
    assert "./course.sh lab" in README and "./course.sh test" in README
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
