"""Every reveal comes after its exercise.

An exercise that asks a student to derive, implement or decide something is spoiled by any
cell before it that shows the result: a SymPy print-out of the Jacobian, the formula in the
text, a worked answer. For every notebook, in the version students get
(:func:`annslam_lib.course.release.student_version`):

(a) a cell tagged as a written answer (:data:`release.ANSWER_TAG`) ships only as the stub
    (a markdown cell: the release replaces it; a code cell would ship as it is), and stands
    after its exercise: the last exercise heading above it is an ungraded one's ("(not
    graded)"), and that exercise's solution cell lies between the two;
(b) nothing before an exercise's heading states or prints its QUANTITY, the thing the
    exercise asks for. :data:`QUANTITY` names it per exercise (keyed by the grade id of the
    exercise's solution cell) as patterns of its formula or code; an exercise whose formula
    the chapter gives on purpose (the exercise is to implement it) or that asks for a
    decision (its answer is a tagged box, checked by (a)) says so with no pattern. The text
    before the heading is the student version's source of every earlier cell and of the
    heading cell up to the heading, and the stored output of every earlier cell that is not
    a student's own (solution or test cell);
(c) no line of a solution (:func:`release.solution_lines`) is printed before its exercise.

Every exercise must have an entry, so a new one has to say what its quantity is.
"""
from __future__ import annotations

import copy
import re
from pathlib import Path

import nbformat
import pytest

from annslam_lib.course import release

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))

IMPLEMENT = ()   # the chapter gives the formula on purpose: the code is the exercise
DECIDE = ()      # a decision or prediction from evidence: its answer is a tagged box

#: grade id of the exercise's solution cell -> patterns of its quantity, matched against the
#: text with every space and LaTeX spacing command removed (see :func:`squeeze`).
QUANTITY: dict[str, tuple[str, ...]] = {
    "ex00-gps-gaps": DECIDE,
    # 01 kinematics
    "ex01-axle-speed": (r"v_e/\(1(\.0)?-", r"\\frac\{v_e\}\{1-", r"1-\\frac\{H\\tan\\alpha\}\{L\}",
                        r"1-H\\tan\\alpha/L"),
    "ex01-euler-step": IMPLEMENT,           # the laser's velocity is section 3's
    "ex01-process-jacobians": (r"Matrix\(\[\[1,0,", r"\\begin\{matrix\}1&0&",
                               r"-\\Deltat\(v\\sin\\phi\+"),
    "ex01-initial-heading": DECIDE,
    # 01a Kalman filter
    "ex01a-update-1d": (r"\\sigma\^\{2\+\}=\\frac", r"\\mu\^\{?\+\}?=\\mu\+",
                        r"\\mu\^\{?\+\}?=\\frac"),
    "ex01a-steady-state": (r"\\sqrt\{q\^\{?2\}?\+4qr\}", r"sqrt\(q\*\*2\+4\*q\*r\)",
                           r"sqrt\(q\*q\+4\*q\*r\)"),
    "ex01a-kalman-gain": IMPLEMENT,         # K = P H^T S^-1 for any size
    "ex01a-gate": (r"chi2\.ppf\(p,(nu\.size|len\(nu\)|m)\)",),
    # 02 laser offset
    # 2.1 asks for the INVERSE transform (chapter 01 shows the forward one): the axle pose
    # P_c = P_l - R(phi)(a, b), in vector, LaTeX, plain-text or code form
    "ex02-laser-pose": (r"[Pp]_\{?[cC]\}?=(\\mathbf)?[Pp]_\{?[lL]\}?[-−]", r"[-−]R\((\\phi|φ|phi)\)\(a,b\)",
                        r"x_?l?[-−]a\\cos\\phi\+b\\sin\\phi", r"x_?l?[-−]acosφ\+bsinφ",
                        r"x_?l?-a\*(np\.)?cos\(phi\)\+b\*(np\.)?sin\(phi\)"),
    "ex02-laser-pose-jacobian": (r"-a\\sin\\phi-b\\cos\\phi", r"-a\*(np\.)?sin\(phi\)-b\*(np\.)?cos\(phi\)"),
    "ex02-laser-velocity": IMPLEMENT,       # the chain rule through exercise 2.2's J
    "ex02-offset-experiments": DECIDE,
    # 03 observation
    "ex03-observe": IMPLEMENT,              # "from the formulas of this section"
    "ex03-jacobian": (r"dx/sqrt\(dx\*\*2\+dy\*\*2\)", r"-dy/\(dx\*\*2\+dy\*\*2\)",
                      r"\\frac\{d_\{?y\}?\}\{q\}", r"\\frac\{-?d_\{?x\}?\}\{\\sqrt\{q\}\}"),
    "ex03-inverse": (r"\\phi\+\\beta-\\frac\{\\pi\}\{2\}", r"\\phi\+\\beta-\\pi/2", r"phi\+beta-pi/2",
                     r"pose\[2\]\+z\[1\]-np\.pi/2"),
    "ex03-two-points": (r"-\(x_l\\cos\\theta\+y_l\\sin\\theta\)", r"x_l\\sin\\theta-y_l\\cos\\theta",
                        r"atan2\}?\(y_r-y_l,x_r-x_l\)"),
    "ex03-swapped-edge": DECIDE,
    "ex03-mean-shift": (r"r_?0?\(1-e\^\{-\(?\\sigma",),
    # 04 landmarks and association
    "ex04-mahalanobis": IMPLEMENT,          # d2 and S are the chapter's; the checks are the work
    "ex04-gate": (r"-2\\ln\(1-p\)", r"-2ln\(1-p\)", r"1-e\^\{-[xt]/2\}", r"-2\*(math|np)\.log\(1",
                  r"chi2\.ppf\((p|prob),2\)", r"\\chi\^2_\{?2\}?\(p\)=-2"),
    "ex04-associate": IMPLEMENT,            # the rule is described, the code is the work
    "ex04-gate-coverage": DECIDE,
    # 04a localisation
    "ex04a-beacon-update": IMPLEMENT,       # (4a.1)-(4a.3)
    "ex04a-filter": IMPLEMENT,
    "ex04a-nis-verdict": (r"chi2\.ppf\(\(1-p\)/2,D\)", r"chi2\.ppf\(\(1\+p\)/2,D\)/D"),
    # 05 EKF-SLAM
    "ex05-augment": (r"G_vP_\{?vv\}?G_v\^T\+G_zRG_z\^T", r"G_vP_\{v,?:\}", r"Gv@P\[:3,:\]"),
    "ex05-joseph": (r"\(I-KH\)P(\^-|\^\{-\})?\(I-KH\)\^T\+KRK\^T", r"\(I-KH\)e\+K\\eta", r"\(I-KH\)e-K\\eta",
                    r"I_KH@P@I_KH\.T\+K@R@K\.T", r"\(I-K@H\)@P@\(I-K@H\)\.T"),
    "ex05-ekf-update": IMPLEMENT,           # the five steps are listed
    "ex05-noisy-laser": DECIDE,
    "ex05a-diagnosis": DECIDE,
    # 06 Victoria Park
    "ex06-track-rmse": IMPLEMENT,
    "ex06-gps-outliers": IMPLEMENT,
    "ex06-gps-jump": DECIDE,
    # 07 the network
    "ex07-forward": IMPLEMENT,              # fitnet's formula is section 1's
    "ex07-train-loop": (r"optimizer\.zero_grad\(\)", r"zero_grad\(\).*backward\(\).*step\(\)"),
    "ex07-mapminmax": (r"2\\frac\{x-x_\{min\}\}\{x_\{max\}-x_\{min\}\}-1",
                       r"\(\\tildex\+1\)\\frac\{x_\{max\}-x_\{min\}\}\{2\}", r"a=2/\(x_\{max\}-x_\{min\}\)",
                       r"2(\.0)?\*\(x-xmin\)/", r"\(y\+1(\.0)?\)\*\(?(span|xmax-xmin)"),
    "ex07-inverse-r": DECIDE,
    # 08 the verdict
    "ex08-rigid-align": IMPLEMENT,          # Kabsch's steps are listed
    "ex08-aligned-rmse": (r"s_1\+d\\?s_2", r"s_\{?1\}?\+s_\{?2\}?\)", r"\\operatorname\{tr\}\(RC\)=",
                          r"s\[0\]\+d\*s\[1\]", r"E_\{?min\}?=\\sum"),
    "ex08-regression": (r"\\sum_j\(g_j-\\barg\)\(o_j-\\baro\)\}\{\\sqrt", r"m=S_\{go\}/S_\{gg\}",
                        r"np\.corrcoef\(", r"np\.polyfit\(", r"R=m\\sqrt"),
    "ex08-measurement-features": DECIDE,
    # 09 capstone: the pieces are pasted from the chapters
    "ex09-pieces": IMPLEMENT,
    "ex09-loop": IMPLEMENT,
    # 10 beyond the EKF
    "ex10-between-error": IMPLEMENT,        # (10.4) is given
    # 11 graph-SLAM from scratch: (11.3), (11.4) and (11.6) are given; the code is the exercise
    "ex11-whitened-range-bearing": IMPLEMENT,
    "ex11-gauss-newton-step": IMPLEMENT,
    "ex11-huber-weights": IMPLEMENT,
    "ex10-bearing-range-error": (r"\\mathrm\{wrap\}\(\\hat\\beta-\\beta\)", r"\(10\.5\)",
                                 r"zhat\[1\]-z\[1\]"),
    "ex10-tangent-to-world": (r"\\mathrm\{blockdiag\}\(R\(\\phi", r"B\\Sigma_\{\\text\{tangent\}\}B\^T",
                              r"\(10\.6\)", r"R@out\[:2,:2\]@R\.T"),
}

_SPACING = re.compile(r"\\(?:[,;:! ]|q?quad\b|left\b|right\b|[bB]igg?[lr]?\b)")
_HEADING = re.compile(r"^### Exercise \S+:.*$", re.M)


def squeeze(text: str) -> str:
    """``text`` without spaces and LaTeX spacing commands, the form the patterns match."""
    return re.sub(r"\s+", "", _SPACING.sub("", text))


def _meta(cell) -> dict:
    return cell.get("metadata", {}).get("nbgrader", {})


def _outputs(cell) -> str:
    parts = []
    for out in cell.get("outputs", []):
        if "text" in out:
            parts.append("".join(out["text"]))
        for kind in ("text/plain", "text/latex", "text/markdown", "text/html"):
            data = out.get("data", {}).get(kind)
            if data:
                parts.append("".join(data))
    return "\n".join(parts)


def exercise_spans(nb) -> list[tuple[str, int, int]]:
    """(grade id, heading cell, solution cell) of every exercise with a solution cell: the
    heading is the last ``### Exercise`` cell before the solution cell (the solution cell
    itself when the chapter has no heading for it)."""
    out, heading = [], None
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "markdown" and _HEADING.search(cell.source):
            heading = i
        meta = _meta(cell)
        if meta.get("solution") and not meta.get("grade"):
            out.append((meta["grade_id"], i if heading is None else heading, i))
    return out


def text_before(instructor, student, heading: int) -> list[tuple[str, str]]:
    """(where, text) of what a student reads before the exercise heading in cell ``heading``."""
    found = []
    for i in range(heading + 1):
        src = student.cells[i].source
        if i == heading:
            m = _HEADING.search(src)
            src = src[:m.start()] if m else ""
        found.append((f"cell {i}", src))
        cell = instructor.cells[i]
        if i < heading and cell.cell_type == "code" and not _meta(cell):
            found.append((f"cell {i} (output)", _outputs(cell)))
    return found


def reveals(instructor, name: str = "notebook") -> list[str]:
    """Every reveal before its exercise in ``instructor`` (empty when the order is right)."""
    student = release.student_version(instructor, name)
    problems = []
    tag = release.ANSWER_TAG
    spans = exercise_spans(instructor)
    # (a) answers ship as stubs, after their exercise
    for i, cell in enumerate(instructor.cells):
        if tag not in cell.metadata.get("tags", []):
            continue
        if cell.cell_type != "markdown" or student.cells[i].source != release.ANSWER_STUB:
            problems.append(f"cell {i}: a {cell.cell_type} cell tagged {tag!r} ships to students "
                            "as it is")
        heads = [k for k in range(i) if instructor.cells[k].cell_type == "markdown"
                 and _HEADING.search(instructor.cells[k].source)]
        head = _HEADING.findall(instructor.cells[heads[-1]].source)[-1] if heads else ""
        solved = heads and any(_meta(instructor.cells[k]).get("solution")
                               for k in range(heads[-1], i))
        if not head.endswith("(not graded)") or not solved:
            problems.append(f"cell {i}: the answer (tagged {tag!r}) does not follow its ungraded "
                            "exercise's heading and solution cell: it stands before its exercise")
    # (b) the quantity, and (c) solution lines printed, before the heading
    sol = {line for line in release.solution_lines(instructor) if len(line) >= 12}
    for gid, heading, _ in spans:
        if gid not in QUANTITY:
            problems.append(f"{gid}: no entry in QUANTITY (say what the exercise asks for)")
            continue
        patterns = [re.compile(p) for p in QUANTITY[gid]]
        for where, text in text_before(instructor, student, heading):
            flat = squeeze(text)
            for p in patterns:
                m = p.search(flat)
                if m:
                    problems.append(f"{gid}: {where}, before the exercise (heading in cell "
                                    f"{heading}), shows its quantity: {m.group(0)!r}")
            if where.endswith("(output)"):
                shown = {line.strip() for line in text.split("\n")}
                for line in sorted(sol & shown):
                    problems.append(f"{gid}: {where} prints a solution line {line!r}")
    return problems


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_reveal_comes_after_its_exercise(path):
    found = reveals(release.read_notebook(path), path.name)
    assert not found, f"{path.name}: reveals before their exercises:\n" + "\n".join(found)


def test_every_table_entry_is_an_exercise():
    """An entry whose exercise is gone would hide nothing: the table follows the notebooks."""
    ids = {gid for p in NOTEBOOKS for gid, _, _ in exercise_spans(release.read_notebook(p))}
    assert set(QUANTITY) <= ids, f"QUANTITY lists exercises that do not exist: {set(QUANTITY) - ids}"


def _book(stem: str):
    return release.read_notebook(ROOT / "notebooks" / f"{stem}.ipynb")


def _heading_of(nb, gid: str) -> int:
    return next(h for g, h, _ in exercise_spans(nb) if g == gid)


def test_a_planted_sympy_reveal_fails():
    """The Joseph form printed by a cell before exercise 5.2 is caught, in the output and in
    the source; so is the formula in the text of the heading cell above the heading."""
    nb = copy.deepcopy(_book("05_ekf_slam"))
    assert reveals(nb, "05") == []
    h = _heading_of(nb, "ex05-joseph")
    cell = nbformat.v4.new_code_cell("display(joseph)")
    cell.outputs = [nbformat.v4.new_output(
        "execute_result", data={"text/latex": r"$\left(I - K H\right) P \left(I - K H\right)^T"
                                              r" + K R K^T$"},
        execution_count=1)]
    planted = copy.deepcopy(nb)
    planted.cells.insert(h, cell)
    found = reveals(planted, "05")
    assert any("ex05-joseph" in f and "(output)" in f for f in found), found
    coded = copy.deepcopy(nb)
    coded.cells.insert(h, nbformat.v4.new_code_cell("P_plus = I_KH @ P @ I_KH.T + K @ R @ K.T"))
    assert any("ex05-joseph" in f and "shows its quantity" in f for f in reveals(coded, "05"))
    texted = copy.deepcopy(nb)
    src = texted.cells[h].source
    k = src.index("### Exercise 5.2")
    texted.cells[h].source = (src[:k] + "Its covariance is $(I - KH)\\,P\\,(I - KH)^T + K R K^T$.\n\n"
                              + src[k:])
    assert any("ex05-joseph" in f for f in reveals(texted, "05"))


def test_a_planted_answer_before_its_exercise_fails():
    """A worked answer tagged as one, moved above its exercise, and one in a code cell."""
    nb = copy.deepcopy(_book("04_landmarks_association"))
    assert reveals(nb, "04") == []
    h = _heading_of(nb, "ex04-gate-coverage")
    answer = next(i for i, c in enumerate(nb.cells) if i > h and
                  release.ANSWER_TAG in c.metadata.get("tags", []))
    early = copy.deepcopy(nb)
    early.cells.insert(h, early.cells.pop(answer))
    assert any("before its exercise" in f for f in reveals(early, "04"))
    coded = copy.deepcopy(nb)
    cell = nbformat.v4.new_code_cell("print('the answer')")
    cell.metadata["tags"] = [release.ANSWER_TAG]
    coded.cells.insert(answer + 1, cell)
    assert any("code cell tagged" in f for f in reveals(coded, "04"))


def test_a_printed_solution_line_before_its_exercise_fails():
    nb = copy.deepcopy(_book("10_beyond_the_ekf"))
    h = _heading_of(nb, "ex10-tangent-to-world")
    line = "out[:2, :2] = R @ out[:2, :2] @ R.T"
    cell = nbformat.v4.new_code_cell("print(source)")
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=line + "\n")]
    nb.cells.insert(h, cell)
    found = reveals(nb, "10")
    assert any("prints a solution line" in f for f in found), found


def test_squeeze_reads_latex_and_code_alike():
    assert squeeze(r"$(I - K H)\, P \left(I - KH\right)^T + K R K^T$") == "$(I-KH)P(I-KH)^T+KRK^T$"
    assert re.search(QUANTITY["ex04-gate"][0], squeeze(r"$\chi^2_2(p) = -2\ln(1 - p)$"))


#: Patterns of a library shortcut rather than of the quantity: a later chapter's exercise is
#: not spoiled by an earlier chapter using the shortcut for something else.
SHORTCUTS = {r"np\.corrcoef\(", r"np\.polyfit\("}


def _graded(nb, heading: int) -> bool:
    found = _HEADING.findall(nb.cells[heading].source)
    return bool(found) and not found[-1].endswith("(not graded)")


def _student_text(instructor, student) -> list[tuple[str, str]]:
    """(where, squeezed text) of everything a student reads in a chapter: every cell's
    source in the student version, and the stored output of every course cell."""
    out = []
    for i, cell in enumerate(student.cells):
        out.append((f"cell {i}", squeeze(cell.source)))
        inst = instructor.cells[i]
        if inst.cell_type == "code" and not _meta(inst):
            out.append((f"cell {i} (output)", squeeze(_outputs(inst))))
    return out


def earlier_reveals(books) -> list[str]:
    """A GRADED exercise whose quantity an earlier chapter already shows (``books``: (name,
    instructor notebook) in course order): its points would be for copying."""
    problems, seen = [], []
    for name, inst in books:
        for gid, heading, _ in exercise_spans(inst):
            if not _graded(inst, heading):
                continue
            for p in map(re.compile, set(QUANTITY.get(gid, ())) - SHORTCUTS):
                for where, flat in seen:
                    m = p.search(flat)
                    if m:
                        problems.append(f"{name} {gid} (graded): {where} shows its quantity "
                                        f"{m.group(0)!r} in an earlier chapter")
                        break
        seen += [(f"{name} {w}", t) for w, t in
                 _student_text(inst, release.student_version(inst, name))]
    return problems


def test_no_graded_exercise_asks_for_what_an_earlier_chapter_shows():
    books = [(p.stem, release.read_notebook(p)) for p in NOTEBOOKS]
    found = earlier_reveals(books)
    assert not found, "graded exercises shown in earlier chapters:\n" + "\n".join(found)


def test_a_graded_exercise_shown_in_an_earlier_chapter_is_caught():
    """Exercise 5.2 (the Joseph form, (1a.7) of chapter 01a) made graded again is flagged."""
    books = [(p.stem, release.read_notebook(p)) for p in NOTEBOOKS
             if p.stem in ("01a_kalman_filter", "05_ekf_slam")]
    nb = copy.deepcopy(books[1][1])
    h = _heading_of(nb, "ex05-joseph")
    nb.cells[h].source = nb.cells[h].source.replace("(not graded)", "(2 points)")
    found = earlier_reveals([books[0], ("05_ekf_slam", nb)])
    assert any("ex05-joseph" in f and "01a_kalman_filter" in f for f in found), found


def test_the_inverse_transform_shown_before_exercise_2_1_fails():
    """Exercise 2.1 asks for the way back, laser to axle: chapter 01 shows only the forward
    transform, and the inverse shown above the exercise would hand it over."""
    nb = copy.deepcopy(_book("02_laser_offset"))
    assert reveals(nb, "02") == []
    h = _heading_of(nb, "ex02-laser-pose")
    nb.cells.insert(h, nbformat.v4.new_markdown_cell(r"$$P_c = P_l - R(\phi)\,(a, b)^T$$"))
    assert any(f.startswith("ex02-laser-pose:") for f in reveals(nb, "02"))
