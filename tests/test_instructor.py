"""INSTRUCTOR.md against the notebooks it describes: its pacing table is the one
`python -m annslam_lib pacing` computes and its exercises table the one `python -m annslam_lib
exercises` prints, every chapter has its prerequisites and its row in the chapter map, every
ungraded exercise its rubric, its links resolve, and the README's first screen links it."""
import re
from pathlib import Path

from annslam_lib.course import pacing

ROOT = Path(__file__).resolve().parents[1]
GUIDE = (ROOT / "INSTRUCTOR.md").read_text()
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_the_pacing_table_is_computed_from_the_notebooks():
    m = re.search(r"<!-- pacing:begin -->\n(.*?)\n<!-- pacing:end -->", GUIDE, re.S)
    assert m, "INSTRUCTOR.md has no pacing table between its markers"
    assert m.group(1).strip() == pacing.pacing_table(NOTEBOOKS).strip(), (
        "INSTRUCTOR.md's pacing table is stale: paste the output of `python -m annslam_lib pacing`")


def test_the_exercise_table_is_the_notebooks_table():
    from annslam_lib.course.release import exercise_table

    block = re.search(r"<!-- exercises:begin -->\n(.*?)\n?<!-- exercises:end -->", GUIDE, re.S)
    assert block, "INSTRUCTOR.md lost its exercises markers"
    assert block.group(1).strip() == exercise_table(NOTEBOOKS).strip(), (
        "INSTRUCTOR.md's exercise table is stale: paste the output of "
        "`python -m annslam_lib exercises`")


def test_the_chapter_map_links_every_notebook():
    chapter_map = GUIDE.split("## What each chapter does", 1)[1].split("\n## ", 1)[0]
    linked = sorted(set(re.findall(r"\(notebooks/([0-9]{2}[a-z]?_[a-z_0-9]+\.ipynb)\)", chapter_map)))
    assert linked == [nb.name for nb in NOTEBOOKS], "INSTRUCTOR.md's chapter map differs from notebooks/"


def test_the_guide_stands_alone():
    """Everything an instructor needs is here: no section of the README is sent for."""
    assert "README.md#" not in GUIDE and "the README's" not in GUIDE


def test_every_chapter_has_its_prerequisites_and_every_ungraded_exercise_a_rubric():
    prereq = GUIDE.split("## Prerequisites", 1)[1].split("\n## ", 1)[0]
    for nb in NOTEBOOKS:
        assert f"| `{nb.stem}` |" in prereq, nb.stem
    ungraded = [g for r in pacing.chapter_rows(NOTEBOOKS) for g in r["ungraded"]]
    assert len(ungraded) >= 10
    rubrics = GUIDE.split("## Rubrics", 1)[1].split("\n## ", 1)[0]
    for gid in ungraded:
        section = re.search(rf"### `{gid}`.*?\n(.*?)(?=\n### |\Z)", rubrics, re.S)
        assert section and section.group(1).count("\n- ") >= 1, f"no rubric for {gid}"


def test_links_resolve_and_the_readme_first_screen_links_the_guide():
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", GUIDE):
        if not target.startswith("http"):
            assert (ROOT / target).exists(), target
    first_screen = "\n".join((ROOT / "README.md").read_text().splitlines()[:30])
    assert "(INSTRUCTOR.md)" in first_screen


def test_the_estimate_follows_its_stated_assumptions():
    rows = {r["notebook"]: r for r in pacing.chapter_rows(NOTEBOOKS)}
    r = rows["01a_kalman_filter"]
    assert r["points"] == 9 and r["ungraded"] == []
    assert r["exercise_min"] == 5 * round(9 * pacing.MINUTES_PER_POINT / 5)
    assert abs(r["reading_min"] - r["words"] / pacing.WORDS_PER_MINUTE) <= 2.5


def test_the_optional_modules_add_up_and_the_guide_and_map_name_them():
    rows = pacing.chapter_rows(NOTEBOOKS)
    assert {r["notebook"] for r in rows if r["module"] == "paper"} == \
        {"07_ann_training", "08_ann_slam_verdict"}
    table = pacing.pacing_table(NOTEBOOKS)
    hours = {m.group(1): float(m.group(2)) for m in
             re.finditer(r"^\| (core(?: \+ \w+)?|all) \|.*\| ([\d.]+) \|$", table, re.M)}
    minutes = {m: sum(r["total_min"] for r in rows if r["module"] == m)
               for m in ("core", *pacing.OPTIONAL_MODULES)}
    assert hours["core"] == round(minutes["core"] / 60, 1)
    assert hours["core + paper"] == round((minutes["core"] + minutes["paper"]) / 60, 1)
    assert hours["all"] == round(sum(minutes.values()) / 60, 1)
    plans = GUIDE.split("## Two plans", 1)[1].split("\n## ", 1)[0]
    assert "without the paper module" in plans and "core only" in plans
    course_map = (ROOT / "notebooks" / "00_course_map.ipynb").read_text()
    assert "(optional: the paper module)" in course_map and "The paper thread" in course_map
