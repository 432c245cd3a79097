"""The diagnose-the-broken-filter lab (chapter 05a): every planted defect shows its
telltale on the lab's runs, and no other defect nor the control shows it (measured, so that
each defect is identifiable from the evidence alone); the draw per student; the grading of
answers, right ones for any student's draw and wrong ones named, in a notebook and through
the sandboxed grader."""
import pytest

from annslam_lib.chapters import ch05a_diagnose as lab
from annslam_lib.grading import diagnose as gd
from annslam_lib.grading.core import GradingError, full_feedback, grading_student

NAMES = [f"student{i:03d}" for i in range(60)] + ["alice", "bob", "demo", "j.smith@uni.example"]


@pytest.fixture(scope="module")
def control():
    return {run: lab.run_filter(lab.LabFilter("control", None), run) for run in lab.LAB_RUNS}


@pytest.mark.parametrize("defect", sorted(lab.DEFECTS))
def test_each_defect_shows_its_telltale_and_no_other_on_every_lab_run(defect, control):
    for run in lab.LAB_RUNS:
        ev = lab.evidence(lab.run_filter(lab.LabFilter("X", defect), run), control[run])
        assert ev["shows"] == [lab.DEFECTS[defect].telltale], (defect, run, ev)
        assert lab.reference_diagnosis(ev["shows"]) == defect


def test_the_control_and_the_worked_example_show_no_telltale(control):
    for run in lab.LAB_RUNS:
        assert lab.evidence(control[run], control[run])["shows"] == []
        ex = lab.evidence(lab.run_filter(lab.example_filter(), run), control[run])
        assert ex["shows"] == [], ex
    assert lab.DEMO not in lab.DEFECTS


def test_the_telltales_are_distinct_and_are_kinds_of_evidence():
    tells = [d.telltale for d in lab.DEFECTS.values()]
    assert len(set(tells)) == len(tells)
    assert set(tells) <= set(lab.EVIDENCE)


def test_a_filter_is_compared_with_the_control_on_the_same_run(control):
    a, b = lab.LAB_RUNS
    with pytest.raises(ValueError, match="same data"):
        lab.evidence(control[a], control[b])


def test_the_draw_is_fixed_by_the_name_and_varies_between_students():
    draws = {n: lab.draw(n) for n in NAMES}
    for n, d in draws.items():
        assert d == lab.draw(n)
        assert sorted(d) == list("ABCD")
        assert len(set(d.values())) == lab.N_FILTERS and set(d.values()) <= set(lab.DEFECTS)
    distinct = {tuple(d.values()) for d in draws.values()}
    assert len(distinct) >= 0.8 * len(NAMES), len(distinct)
    for bad in ("", None, 3):
        with pytest.raises(ValueError):
            lab.draw(bad)


def _right(name):
    return {k: {"defect": v, "evidence": lab.DEFECTS[v].telltale} for k, v in lab.draw(name).items()}


def _score(answers, name):
    """(points out of 8, messages) of ``answers`` graded as student ``name``."""
    points, messages = 0, []
    with grading_student(name):
        for k in "ABCD":
            try:
                gd.check_filter(lambda: answers, k, quiet=True)
                points += 2
            except GradingError as e:
                messages.append(str(e))
    return points, messages


def test_right_answers_score_full_marks_for_every_students_draw():
    for n in NAMES:
        assert _score(_right(n), n) == (8, []), n


def test_a_wrong_defect_and_a_wrong_evidence_are_named():
    name = "alice"
    ans = _right(name)
    d = lab.draw(name)
    other = next(k for k in lab.DEFECTS if k not in d.values())
    ans["B"] = {"defect": other, "evidence": lab.DEFECTS[other].telltale}
    wrong_ev = next(e for e in lab.EVIDENCE if e != lab.DEFECTS[d["C"]].telltale)
    ans["C"] = {"defect": d["C"], "evidence": wrong_ev}
    points, messages = _score(ans, name)
    assert points == 4, messages
    assert messages[0].startswith(f"filter B: its defect is not {other!r}")
    assert messages[1].startswith("filter C: the defect is right, but the evidence cited")
    assert not any("instructor:" in m for m in messages)        # the student's own view
    with full_feedback():
        full = _score(ans, name)[1]
    assert f"the defect is {d['B']!r}" in full[0]
    assert f"its telltale is {lab.DEFECTS[d['C']].telltale!r}" in full[1]


def test_another_students_answers_do_not_pass_for_most_students():
    failing = [n for n in NAMES[1:] if lab.draw(n) != lab.draw(NAMES[0])
               and _score(_right(NAMES[0]), n)[0] < 8]
    differing = [n for n in NAMES[1:] if lab.draw(n) != lab.draw(NAMES[0])]
    assert len(failing) == len(differing) >= 0.9 * (len(NAMES) - 1)
    copied = [_score(_right(NAMES[0]), n)[0] for n in NAMES[1:]]
    assert sum(copied) / len(copied) <= 4, copied          # a copied answer earns little


@pytest.mark.parametrize("answers, says", [
    ([], "returned a list"),
    ({"A": {"defect": "R-halved", "evidence": "nis-twice"}}, "no answer for filter(s) B, C, D"),
    ({**{k: {"defect": "R-halved", "evidence": "nis-twice"} for k in "ABCD"}, "E": {}},
     "which are not yours"),
    ({k: {"defect": "R-halved"} for k in "ABCD"}, "keys 'defect' and 'evidence'"),
    ({k: {"defect": "R halved", "evidence": "nis-twice"} for k in "ABCD"}, "not one of the defects"),
    ({k: {"defect": "R-halved", "evidence": "nis"} for k in "ABCD"}, "not one of the kinds"),
    ({k: {"defect": None, "evidence": None} for k in "ABCD"}, "is not written yet"),
])
def test_an_answer_of_the_wrong_form_is_refused_with_what_is_wrong(answers, says):
    with grading_student("demo"):
        with pytest.raises(GradingError, match=says.replace("(", r"\(").replace(")", r"\)")):
            gd.check_form(lambda: answers)


def test_the_students_own_check_says_nothing_of_whether_an_answer_is_right():
    wrong = {k: {"defect": "R-halved", "evidence": "nis-low"} for k in "ABCD"}
    with grading_student("demo"):
        msg = gd.check_form(lambda: wrong, quiet=True)
    assert "form the grader reads" in msg
    assert not any(k in msg for k in lab.DEFECTS)


def test_the_grader_grades_the_submissions_student_not_the_kernels(tmp_path):
    """Through the sandboxed grader, as student 'alice' (nbgrader's submitted/<student>/
    layout): the notebook's filters are re-run in the kernel for alice's draw; two answers
    read from the evidence score, one wrong defect and one wrong evidence are named."""
    import grading_support as gs
    from annslam_lib.course.sandbox import Limits
    from solutions import ROOT

    notebook = ROOT / "notebooks" / "05a_diagnose_the_filter.ipynb"
    bodies = gs.solution_bodies(notebook)
    d = lab.draw("alice")
    other = next(k for k in lab.DEFECTS if k not in d.values())
    wrong_ev = next(e for e in lab.EVIDENCE if e != lab.DEFECTS[d["D"]].telltale)
    bodies["ex05a-diagnosis"] = bodies["ex05a-diagnosis"].replace(
        "    return answers",
        f"    answers['C'] = {{'defect': {other!r}, 'evidence': {lab.DEFECTS[other].telltale!r}}}\n"
        f"    answers['D'] = {{**answers['D'], 'evidence': {wrong_ev!r}}}\n    return answers")
    folder = tmp_path / "submitted" / "alice" / "lab05a"
    folder.mkdir(parents=True)
    g = gs.grade_chapter(notebook, bodies, folder,
                         Limits(cell_timeout=240.0, call_timeout=120.0, deadline=600.0))
    r = {e.grade_id: e for e in g.exercises}
    assert (g.student, g.score, g.max_score) == ("alice", 4.0, 8.0), g.report()
    assert r["ex05a-filter-a-tests"].status == r["ex05a-filter-b-tests"].status == "passed"
    assert f"filter C: its defect is not {other!r}" in r["ex05a-filter-c-tests"].message
    assert f"instructor: the defect is {d['C']!r}" in r["ex05a-filter-c-tests"].message
    assert "filter D: the defect is right" in r["ex05a-filter-d-tests"].message


def test_reading_the_draw_or_the_courses_rule_is_not_a_diagnosis():
    def my_diagnosis():
        return {k: {"defect": v, "evidence": lab.DEFECTS[v].telltale}
                for k, v in lab.draw(lab.student()).items()}
    with grading_student("demo"):
        with pytest.raises(GradingError, match=r"my_diagnosis calls annslam_lib\.chapters\."
                                               r"ch05a_diagnose\.draw: write it yourself"):
            gd.check_filter(my_diagnosis, "A")
