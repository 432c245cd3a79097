"""Student release: nbgrader markup, stubs, hidden tests, and agreement with nbgrader itself."""
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook


from annslam_lib.course.release import ReleaseError
from annslam_lib.course import kernels, release

ROOT = Path(__file__).resolve().parents[1]
COURSE = sorted((ROOT / "notebooks").glob("*.ipynb"))
MIN_EXERCISES = 2


def _sol(src, gid="ex-a"):
    c = new_code_cell(src)
    c.metadata["nbgrader"] = {"grade": False, "grade_id": gid, "locked": False,
                              "schema_version": 3, "solution": True, "task": False}
    return c


def _test(src, gid="ex-a-tests", points=2):
    c = new_code_cell(src)
    c.metadata["nbgrader"] = {"grade": True, "grade_id": gid, "locked": True, "points": points,
                              "schema_version": 3, "solution": False, "task": False}
    return c


def _toy():
    return new_notebook(cells=[
        new_markdown_cell("### Exercise: double it"),
        new_code_cell("import math"),
        _sol("def my_double(x):\n    \"\"\"2 x\"\"\"\n    ### BEGIN SOLUTION\n    y = 2 * x\n"
             "    return y\n    ### END SOLUTION"),
        _test("# Autograded\nassert my_double(2) == 4, 'my_double(2) should be 4'\n"
              "### BEGIN HIDDEN TESTS\nassert my_double(-3) == -6\n### END HIDDEN TESTS"),
        _sol("def my_half(x):\n    ### BEGIN SOLUTION\n    return x / 3\n    ### END SOLUTION",
             "ex-b"),
        _test("assert my_half(4) == 2, 'my_half(4) should be 2'", "ex-b-tests", 1),
        new_code_cell("print(math.pi > 3)"),
    ], metadata={"kernelspec": {"name": "python3", "display_name": "Python 3",
                                "language": "python"}})


def test_student_version_stubs_solutions_like_nbgrader_and_drops_hidden_tests():
    nb = _toy()
    nb.cells[2].outputs = [nbformat.v4.new_output("stream", text="x")]
    nb.cells[2].execution_count = 3
    st = release.student_version(nb, "toy")
    assert st.cells[2].source == ('def my_double(x):\n    """2 x"""\n    # YOUR CODE HERE\n'
                                  '    raise NotImplementedError()')
    assert st.cells[3].source == "# Autograded\nassert my_double(2) == 4, 'my_double(2) should be 4'"
    assert st.cells[2].outputs == [] and st.cells[2].execution_count is None
    assert st.cells[2].metadata["nbgrader"] == nb.cells[2].metadata["nbgrader"]
    assert nb.cells[2].source.count("BEGIN SOLUTION") == 1  # the instructor copy is untouched
    assert release.solution_lines(nb) == {"y = 2 * x", "return y", "return x / 3"}
    assert release.hidden_test_lines(nb) == {"assert my_double(-3) == -6"}
    assert [(e.grade_id, e.points, e.cell) for e in release.validate(nb, "toy")] == [
        ("ex-a-tests", 2.0, 3), ("ex-b-tests", 1.0, 5)]


def _answer(src, gid="think-a"):
    c = new_markdown_cell(src)
    c.metadata["nbgrader"] = {"grade": False, "grade_id": gid, "locked": False,
                              "schema_version": 3, "solution": True, "task": False}
    return c


def test_top_level_code_exercises_are_stubbed_and_run_all_goes_on(tmp_path):
    nb = _toy()
    nb.cells += [_sol("### BEGIN SOLUTION\nanswer = 42\n### END SOLUTION", "ex-c"),
                 new_code_cell("print('after')")]
    st = release.student_version(nb, "toy")
    assert st.cells[7].source == "# YOUR CODE HERE\nraise NotImplementedError()"
    assert "raises-exception" in st.cells[7].metadata["tags"]
    assert "tags" not in st.cells[2].metadata                  # a def stub does not raise
    kernels.run_notebook(st, tmp_path, timeout=60)
    assert st.cells[8].outputs[0]["text"] == "after\n"


def test_an_ungraded_written_answer_cell_is_refused_like_nbgrader_does():
    nb = _toy()
    nb.cells.append(_answer("**Solution.** Because the gate is a chi-square quantile."))
    with pytest.raises(ReleaseError, match="markdown solution cell 'think-a' is not a grade cell"):
        release.student_version(nb, "toy")
    from nbgrader.nbgraderformat import ValidationError, MetadataValidator
    with pytest.raises(ValidationError, match="not marked as a grade cell"):
        MetadataValidator().validate_nb(nb)


@pytest.mark.parametrize("mutate, message", [
    (lambda nb: nb.cells[5].metadata["nbgrader"].update(grade_id="ex-a-tests"), "already used"),
    (lambda nb: nb.cells[5].metadata["nbgrader"].update(points=0), "needs points > 0"),
    (lambda nb: nb.cells[5].metadata["nbgrader"].update(grade_id="ex b"), "must be letters"),
    (lambda nb: setattr(nb.cells[2], "source", nb.cells[2].source.replace("### END SOLUTION", "")),
     "has no 'END SOLUTION'"),
    (lambda nb: setattr(nb.cells[1], "source", "### BEGIN SOLUTION\nx = 1\n### END SOLUTION"),
     "not marked as a solution"),
    (lambda nb: setattr(nb.cells[6], "source", "### BEGIN HIDDEN TESTS\n### END HIDDEN TESTS"),
     "not marked as autograded"),
    (lambda nb: setattr(nb.cells[4], "source", "def my_half(x):\n    return x / 2"),
     "has no ### BEGIN/END SOLUTION"),
])
def test_broken_markup_is_named(mutate, message):
    nb = _toy()
    mutate(nb)
    with pytest.raises(ReleaseError, match=message):
        release.student_version(nb, "toy")


def test_release_never_writes_over_the_instructor_notebooks(tmp_path):
    src = tmp_path / "toy.ipynb"
    nbformat.write(_toy(), src)
    with pytest.raises(ReleaseError, match="holds the instructor notebooks"):
        release.release([src], tmp_path)
    out = release.release([src], tmp_path / "student")
    assert out == [tmp_path / "student" / "toy.ipynb"]
    assert "raise NotImplementedError()" in nbformat.read(out[0], as_version=4).cells[2].source


def test_plain_assert_test_cells_are_graded_with_the_hidden_tests(tmp_path):
    """Test cells need not use the course's checks: a plain assert works too (run by the
    grader, the student's function behind a proxy). The toy's second solution is wrong
    (x / 3); a first solution that only fits the visible test is caught by the hidden one."""
    from annslam_lib.course.grader import grade_submission
    from annslam_lib.course.sandbox import Limits

    inst = tmp_path / "inst" / "toy.ipynb"
    inst.parent.mkdir()
    nbformat.write(_toy(), inst)
    limits = Limits(cell_timeout=20, deadline=60)
    (tmp_path / "sub").mkdir()
    nbformat.write(_toy(), tmp_path / "sub" / "toy.ipynb")       # the instructor's answers
    g = grade_submission(tmp_path / "sub" / "toy.ipynb", inst, limits=limits)
    assert (g.score, g.max_score) == (2.0, 3.0)
    assert [r.status for r in g.exercises] == ["passed", "failed"]
    assert g.exercises[1].message == "my_half(4) should be 2"
    sub = release.student_version(_toy(), "toy")
    sub.cells[2].source = "def my_double(x):\n    return 4 if x == 2 else 0"
    nbformat.write(sub, tmp_path / "sub" / "toy.ipynb")
    g = grade_submission(tmp_path / "sub" / "toy.ipynb", inst, limits=limits)
    assert g.score == 0.0 and g.exercises[0].status == "failed"     # the hidden assert
    assert [r.status for r in g.exercises] == ["failed", "not written"]


# ------------------------------------------------------------------ the course's notebooks

def test_every_chapter_from_01_has_graded_exercises_with_unique_ids():
    ids, counts = [], {}
    for path in COURSE:
        found = release.exercises(path)
        counts[path.name] = len(found)
        ids += [e.grade_id for e in found]
        nb = nbformat.read(path, as_version=4)
        ids += [c.metadata["nbgrader"]["grade_id"] for c in nb.cells
                if c.metadata.get("nbgrader", {}).get("solution")]
    short = {n: c for n, c in counts.items() if n[:2] != "00" and c < MIN_EXERCISES}
    assert not short, f"chapters with fewer than {MIN_EXERCISES} autograded exercises: {short}"
    assert len(ids) == len(set(ids)), "grade ids must be unique across the course"


@pytest.fixture(scope="module")
def student(tmp_path_factory):
    out = tmp_path_factory.mktemp("student")
    return {p.name: p for p in release.release(COURSE, out)}


@pytest.mark.parametrize("path", COURSE, ids=lambda p: p.stem)
def test_student_version_holds_no_solution_code_no_hidden_tests_no_outputs(path, student):
    inst = nbformat.read(path, as_version=4)
    st = nbformat.read(student[path.name], as_version=4)
    assert len(st.cells) == len(inst.cells)
    text = "\n".join(c.source for c in st.cells)
    for marker in ("BEGIN SOLUTION", "END SOLUTION", "BEGIN HIDDEN TESTS", "END HIDDEN TESTS"):
        assert marker not in text
    lines = {s.strip() for s in text.split("\n")}
    leaked = (release.solution_lines(inst) | release.hidden_test_lines(inst)) & lines
    assert not leaked, f"solution or hidden-test code in the student {path.name}: {leaked}"
    for a, b in zip(inst.cells, st.cells):                     # written answers: whole cells
        if a.metadata.get("nbgrader", {}).get("solution") and "BEGIN SOLUTION" not in a.source:
            assert b.source == release.TEXT_STUB and a.source not in text
    assert all(not c.get("outputs") for c in st.cells if c.cell_type == "code")
    n_stubs = text.count("raise NotImplementedError()")
    n_solutions = sum(1 for c in inst.cells for line in c.source.split("\n")
                      if "BEGIN SOLUTION" in line and c.cell_type == "code")
    assert n_stubs >= n_solutions


def test_cli_release_writes_every_notebook(tmp_path, capsys):
    from annslam_lib.course.cli import main

    assert main(["release", "--out", str(tmp_path / "s")]) == 0
    assert sorted(p.name for p in (tmp_path / "s").glob("*.ipynb")) == [p.name for p in COURSE]
    assert "autograded exercise" in capsys.readouterr().out


# ------------------------------------------------------------------ nbgrader's own tool

def _nbgrader_or_skip():
    if importlib.util.find_spec("nbgrader") is None:
        pytest.skip("nbgrader is not installed, so its generate_assignment cannot be compared: "
                    "pip install -r environment-instructor.txt (./course.sh test does)")


def test_nbgrader_generate_assignment_gives_the_same_student_cells(tmp_path, student):
    """nbgrader 0.9.6's generate_assignment on the instructor notebooks yields cell sources
    identical to ours, cell for cell."""
    _nbgrader_or_skip()
    src = tmp_path / "course" / "source" / "annslam"
    src.mkdir(parents=True)
    for p in COURSE:
        (src / p.name).write_bytes(p.read_bytes())
    # nbgrader runs its helper executables (alembic) from PATH: put this venv's bin first
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    proc = subprocess.run([sys.executable, "-m", "nbgrader", "generate_assignment", "annslam",
                           "--force", "--no-db", f"--CourseDirectory.root={tmp_path / 'course'}"],
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for p in COURSE:
        theirs = json.loads((tmp_path / "course" / "release" / "annslam" / p.name).read_text())
        ours = nbformat.read(student[p.name], as_version=4)
        assert len(theirs["cells"]) == len(ours.cells)
        for i, (a, b) in enumerate(zip(theirs["cells"], ours.cells)):
            src_a = "".join(a["source"]) if isinstance(a["source"], list) else a["source"]
            if release.ANSWER_TAG in a.get("metadata", {}).get("tags", []):
                # the one documented difference: nbgrader keeps a tagged written answer
                assert b.source == release.ANSWER_STUB and src_a != b.source
                continue
            assert src_a == b.source, f"{p.name} cell {i} differs from nbgrader's"


# ------------------------------------------------------------------ what must not leak

def _manual_answer(src, gid="written-a", points=1):
    """A manually graded written answer (nbgrader: markdown, grade + solution)."""
    c = new_markdown_cell(src)
    c.metadata["nbgrader"] = {"grade": True, "grade_id": gid, "locked": False, "points": points,
                              "schema_version": 3, "solution": True, "task": False}
    return c


@pytest.mark.parametrize("marker", ["### begin solution", "### Begin Solution",
                                    "### BEGIN  SOLUTION", "### begin hidden tests"])
def test_a_marker_not_in_capitals_is_refused_not_copied(marker):
    nb = _toy()
    nb.cells[2].source = nb.cells[2].source.replace("### BEGIN SOLUTION", marker) \
        if "solution" in marker.lower() else nb.cells[2].source
    if "hidden" in marker.lower():
        nb.cells[3].source = nb.cells[3].source.replace("### BEGIN HIDDEN TESTS", marker)
    with pytest.raises(ReleaseError, match="not written"):
        release.student_version(nb, "toy")


def test_attachments_and_custom_metadata_of_answers_are_dropped(tmp_path):
    nb = _toy()
    answer = _manual_answer("![my answer](attachment:answer.png)\nThe gate is a chi-square quantile.")
    answer["attachments"] = {"answer.png": {"image/png": "iVBORw0KGgo="}}
    nb.cells.append(answer)
    nb.cells[2].metadata["my_course"] = {"answer": "y = 2 * x"}
    nb.metadata["solutions"] = {"ex-a": "y = 2 * x"}
    st = release.student_version(nb, "toy")
    assert "attachments" not in st.cells[-1] and st.cells[-1].source == release.TEXT_STUB
    assert "my_course" not in st.cells[2].metadata and "solutions" not in st.metadata
    assert st.cells[2].metadata["nbgrader"] == nb.cells[2].metadata["nbgrader"]
    assert release.leaks(nb, st) == []
    # the leak check itself sees each of them in a student copy made carelessly
    careless = nbformat.from_dict(json.loads(json.dumps(nb)))
    careless.cells[3].source = careless.cells[3].source.replace("### BEGIN HIDDEN TESTS\n", "")
    found = "\n".join(release.leaks(nb, careless))
    for expected in ("'y = 2 * x'", "marker", "attachments ['answer.png']", "metadata ['my_course']",
                     "notebook metadata ['solutions']", "outputs"):
        if expected == "outputs":
            careless.cells[2].outputs = [nbformat.v4.new_output("stream", text="x")]
            found = "\n".join(release.leaks(nb, careless))
        assert expected in found, (expected, found)


def test_two_notebooks_with_one_name_and_a_non_notebook_are_named(tmp_path):
    for folder in ("week1", "week2"):
        (tmp_path / folder).mkdir()
        nbformat.write(_toy(), tmp_path / folder / "lab.ipynb")
    with pytest.raises(ReleaseError, match="two notebooks named lab.ipynb"):
        release.release([tmp_path / "week1" / "lab.ipynb", tmp_path / "week2" / "lab.ipynb"],
                        tmp_path / "out")
    assert not (tmp_path / "out").exists()
    broken = tmp_path / "broken.ipynb"
    broken.write_text("{ this is not json")
    with pytest.raises(ReleaseError, match="broken.ipynb: not a readable notebook"):
        release.release([broken], tmp_path / "out")
    with pytest.raises(ReleaseError, match="not a readable notebook"):
        release.exercises(broken)


def test_a_tagged_written_answer_is_stubbed_and_a_copied_one_is_a_leak():
    nb = _toy()
    answer = new_markdown_cell("<details><summary>Answer</summary>\n\nThe gate is a chi-square "
                               "quantile.\n\n</details>")
    answer.metadata["tags"] = [release.ANSWER_TAG]
    nb.cells.append(answer)
    st = release.student_version(nb, "toy")
    assert st.cells[-1].source == release.ANSWER_STUB
    assert release.leaks(nb, st) == []
    careless = nbformat.from_dict(json.loads(json.dumps(st)))
    careless.cells[-1].source = answer.source
    assert any("written answer" in p for p in release.leaks(nb, careless))


def test_every_written_answer_of_the_course_is_tagged():
    """Each <details> answer block of the instructor notebooks carries the tag, so that no
    ungraded exercise's answer reaches the student version."""
    untagged = [(p.name, i) for p in COURSE for i, c in enumerate(nbformat.read(p, 4).cells)
                if c.cell_type == "markdown" and "<details>" in c.source
                and release.ANSWER_TAG not in c.metadata.get("tags", [])]
    assert untagged == []
    tagged = sum(release.ANSWER_TAG in c.metadata.get("tags", [])
                 for p in COURSE for c in nbformat.read(p, 4).cells)
    assert tagged >= 9
