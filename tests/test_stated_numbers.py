"""A number the prose states about a result is found in the evidence (issue 21).

Every stated number of a notebook's markdown (``stated_numbers.py`` says which count) is
either shown by the outputs of its section, or declared in ``stated_numbers.toml``: a result
printed in another cell, which is then checked there, or a number that is not a result (a
constant, a parameter, theory), with its reason. A number that drifted from its output, or
that no cell prints, fails here.
"""
import re
import tomllib
from pathlib import Path

import nbformat
import pytest

from stated_numbers import Stated, _text, evidence, is_evidenced, printed_numbers, stated_numbers

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted(p for p in (ROOT / "notebooks").glob("*.ipynb") if re.match(r"\d\d[a-z]?_", p.name))
DECLARED = tomllib.loads((Path(__file__).with_name("stated_numbers.toml")).read_text())
KINDS = ("data", "constant", "parameter", "theory", "arithmetic", "paper", "example")
PRINTED_IN = re.compile(r"printed in (?:chapter (\d\d[a-z]?) )?cell (\d+)$")


def _key(s: Stated) -> str:
    return s.number + s.unit


def _cell_outputs(chapter: str, cell: int) -> set[str]:
    path = next(p for p in NOTEBOOKS if p.stem == chapter or p.name.startswith(chapter + "_"))
    c = nbformat.read(path, as_version=4).cells[cell]
    assert c.cell_type == "code", f"{path.name} cell {cell} is not a code cell"
    return set().union(*(printed_numbers(_text(o)) for o in c.outputs))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_every_stated_number_is_evidenced_or_declared(path):
    nb = nbformat.read(path, as_version=4)
    declared = DECLARED.get(path.stem, {})
    ev = evidence(nb)
    problems, used = [], set()
    for s in stated_numbers(nb):
        if is_evidenced(s, ev[s.cell]):
            continue
        why = declared.get(_key(s))
        if why is None:
            problems.append(f"cell {s.cell}: {_key(s)} is in no output of its section and not "
                            f"declared: ...{s.context}...")
            continue
        used.add(_key(s))
        m = PRINTED_IN.match(why)
        if m:
            where = _cell_outputs(m.group(1) or path.stem, int(m.group(2)))
            if not is_evidenced(s, where):
                problems.append(f"cell {s.cell}: {_key(s)} is declared '{why}', but that cell "
                                f"does not print it")
        elif why.split(":")[0] not in KINDS:
            problems.append(f"{_key(s)}: declared with an unknown kind: {why!r}")
    stale = sorted(set(declared) - used)
    assert not stale, f"{path.name}: declared but no longer stated (or now evidenced): {stale}"
    assert problems == [], f"{path.name}:\n" + "\n".join(problems)


def test_only_the_course_notebooks_are_declared():
    assert set(DECLARED) <= {p.stem for p in NOTEBOOKS}


def _nb(*cells):
    nb = nbformat.v4.new_notebook()
    for kind, text, out in cells:
        if kind == "md":
            nb.cells.append(nbformat.v4.new_markdown_cell(text))
        else:
            c = nbformat.v4.new_code_cell(text)
            c.outputs = [nbformat.v4.new_output("stream", name="stdout", text=out)]
            nb.cells.append(c)
    return nb


def _unevidenced(nb):
    ev = evidence(nb)
    return [_key(s) for s in stated_numbers(nb) if not is_evidenced(s, ev[s.cell])]


def test_a_drifted_number_fails_and_a_rounded_one_passes():
    """The checker itself, on notebooks made to fail: the error that issue 21 found (prose
    2.46 m beside a printed 2.55 m), a rounded statement, units, counts, and what it skips."""
    out = "mean 2.55 m; NIS/dof 1.13; share 0.913; step 0.0125 s; 42 of 96 accepted"
    ok = _nb(("code", "x = 1", out),
             ("md", "The mean error, 2.55 m (2.6 m rounded), a NIS of 1.13, 91 % inside, "
                    "a 12.5 ms step, 42 of 96 fixes. Exercise 5.2 uses $x = 3.14159$ and `7.77`.",
              None))
    assert _unevidenced(ok) == []
    bad = _nb(("code", "x = 1", out),
              ("md", "The mean error, 2.46 m; 74.4 of NIS; 92 % inside; 43 of 96 fixes; 1.135.", None))
    assert _unevidenced(bad) == ["2.46", "74.4", "92%", "43", "1.135"]


def test_evidence_is_looked_for_in_the_section_not_the_whole_notebook():
    nb = _nb(("md", "## 1 · One", None), ("code", "", "value 7.25"),
             ("md", "## 2 · Two", None), ("code", "", "other 1.5"),
             ("md", "## 3 · Three\nIt was 7.25 and 1.5.", None),
             ("md", "## Summary\nIt was 7.25.", None))
    assert _unevidenced(nb) == ["7.25"]


@pytest.mark.parametrize("chapter,old,new", [
    ("06", "The mean error (2.55 m", "The mean error (2.46 m"),      # the audit's drifted mean
    ("06", "its map holds 335 trees", "its map holds 200 trees"),    # ... in a summary
    ("05", "1.074", "1.064"),                                        # a band edge, digit by digit
])
def test_the_errors_the_audit_found_would_be_caught(chapter, old, new):
    path = next(p for p in NOTEBOOKS if p.stem == chapter or p.name.startswith(chapter + "_"))
    nb = nbformat.read(path, as_version=4)
    assert any(old in c.source for c in nb.cells if c.cell_type == "markdown")
    before = _unevidenced(nb)
    for c in nb.cells:
        if c.cell_type == "markdown":
            c.source = c.source.replace(old, new)
    stated = re.search(r"\d+(?:\.\d+)?", new).group(0)
    assert stated in _unevidenced(nb) and stated not in before
