"""Which numbers a notebook's prose states, and where its outputs show them.

Used by ``test_stated_numbers.py``. A *stated number* is, in a markdown cell outside math
and code spans: a decimal (``2.55``), a percentage (``91 %``), an integer of three or more
digits (``527``), or a count ``N of M``. It is *evidenced* when a number printed by a code
cell rounds to it at the precision the prose uses (``2.55`` by a printed 2.551; ``91 %`` by
91.3 %; ``about 150`` by 149.4, its trailing zeros not being digits); a prose value in centimetres or milliseconds is also found in metres or seconds.
Evidence is looked for in the outputs and code literals (a parameter the prose names) of
the prose's own ``##`` section and the one before it; prose in a
section that sums the chapter up (its title, the summary, the verdict) may cite any output
of the notebook. Not stated results, and skipped: heading lines, exercise and section
numbers (``Exercise 5.2``, ``(4.4)`` when ``4.4`` heads a section), years (1950-2030).
Everything else is either evidenced or declared in ``stated_numbers.toml`` with a reason.
Comments in code are no evidence.

Limits (measured by a review): a stated number that equals some other printed number of its
section passes (about a third of random one-decimal numbers would, in a section as full of
output as notebook 05's); a declaration covers every occurrence of its number in the
notebook. The test catches a number that drifted to a value printed nowhere nearby, which
is what the audit found.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation

import nbformat

MATH = re.compile(r"\$\$.*?\$\$|\$[^$\n]*\$|`[^`\n]*`|<[^>\n]*>|\]\([^)\n]*\)", re.S)
# a number not glued to a word, a path or a longer number; ``N of M`` counts as two
STATED = re.compile(r"(?<![\w.^_{\\/#])(?<![A-Za-z]-)(\d{1,3}(?:[,\u202f ]\d{3})+(?![\d.])|\d+(?:\.\d+)?)(?:\s?(%|cm|mm|ms|°))?(?![\w]|\.\d)")
PRINTED = re.compile(r"(?<![A-Za-wyz_\d.])[-+−]?(\d+(?:\.\d+)?(?:e[-+]?\d+)?)")
EXERCISE = re.compile(r"(?:exercise|exercises|section|sections|chapter|chapters|ch\.)\s*$", re.I)
APPROX = re.compile(r"(?:about|around|roughly|nearly|almost|some|~|≈)\s*$", re.I)
SUMMING_UP = re.compile(r"summary|verdict", re.I)
SCALE = {"cm": Decimal("0.01"), "mm": Decimal("0.001"), "ms": Decimal("0.001")}


@dataclass(frozen=True)
class Stated:
    cell: int
    number: str
    unit: str
    context: str
    approx: bool = False          # 'about 150': its trailing zeros are not digits


def _text(output) -> str:
    if output.output_type == "stream":
        return output.text
    data = output.get("data", {})
    return "\n".join(str(data.get(k, "")) for k in ("text/plain", "text/markdown", "text/html"))


def _ignored(cell) -> bool:
    """nbval does not compare this cell's outputs (timings): they are no evidence."""
    return ("NBVAL_IGNORE_OUTPUT" in cell.source
            or "nbval-ignore-output" in cell.get("metadata", {}).get("tags", []))


def printed_numbers(text: str) -> set[str]:
    """The numbers in a text, unsigned, as written (a set of Decimals would merge 1 and 1.0)."""
    out = set()
    text = re.sub(r"(?<=\d)[,_\u202f](?=\d{3}(?!\d))", "", text)
    for m in PRINTED.finditer(text.replace(",", " ")):
        try:
            out.add(str(abs(Decimal(m.group(1)))))
        except InvalidOperation:
            pass
    return out


def _headings(nb) -> set[str]:
    nums = set()
    for c in nb.cells:
        if c.cell_type == "markdown":
            for line in c.source.splitlines():
                m = re.match(r"#+\s*(?:Exercise\s+)?(\d+(?:\.\d+)*)", line)
                if m:
                    nums.add(m.group(1))
    return nums


def stated_numbers(nb) -> list[Stated]:
    """Every stated number of every markdown cell, with its cell index and context."""
    sections = _headings(nb)
    found = []
    for i, cell in enumerate(nb.cells):
        if cell.cell_type != "markdown":
            continue
        prose = [ln for ln in MATH.sub(" ", cell.source).splitlines() if not ln.lstrip().startswith("#")]
        for line in [" ".join(prose)]:              # a range may wrap: '(-3.8 to\n+2.7 cm)'
            matches = list(STATED.finditer(line))
            for k, m in enumerate(matches):
                number, unit = re.sub(r"[,\u202f ]", "", m.group(1)), m.group(2) or ""
                # a range shares its unit: '-3.3 to -0.5 cm', '0.84-1.23 m'
                if not unit and k + 1 < len(matches) and re.fullmatch(
                        r"\s*(?:to|–|-|and)\s*[-+−]?", line[m.end():matches[k + 1].start()]):
                    unit = matches[k + 1].group(2) or ""
                before = line[:m.start()]
                if EXERCISE.search(before):
                    continue
                if number in sections and "." in number and not unit:
                    continue
                if re.fullmatch(r"(19[5-9]\d|20[0-2]\d|2030)", m.group(1)) and not unit:
                    continue
                small_int = "." not in number and len(number) < 3
                count = re.match(r"\s*of\s+\d", line[m.end():]) or re.search(r"\d\s+of\s+$", before)
                if small_int and not unit and not count:
                    continue
                approx = bool(APPROX.search(before))
                found.append(Stated(i, number, unit, line[max(0, m.start() - 50):m.end() + 30], approx))
    return found


def evidence(nb) -> dict[int, set[str]]:
    """For each markdown cell, the printed numbers it may cite."""
    whole: set[str] = set()
    per_section: list[set[str]] = [set()]
    cells_of: dict[int, list[int]] = {}      # a cell with a heading inside spans two sections
    summing_up = {0}                         # the chapter's opening cells
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "markdown":
            spans = [len(per_section) - 1]
            title = re.search(r"^##\s+(.*)$", cell.source, re.M)
            if title:
                per_section.append(set())
                if SUMMING_UP.search(title.group(1)):
                    summing_up.add(len(per_section) - 1)
                spans = spans[:0] if title.start() == 0 else spans
                spans.append(len(per_section) - 1)
            cells_of[i] = spans
        else:
            # the code's own literals: a parameter the prose names is set here
            code = "\n".join(line.split("#")[0] for line in cell.source.splitlines())
            per_section[-1] |= printed_numbers(code)          # comments are no evidence
            if _ignored(cell):
                continue                     # timings: they differ on every run
            for o in cell.get("outputs", []):
                nums = printed_numbers(_text(o))
                per_section[-1] |= nums
                whole |= nums
    result = {}
    for i, spans in cells_of.items():
        if any(s in summing_up for s in spans):
            result[i] = whole
        else:
            result[i] = set().union(*(per_section[k] for s in spans for k in (s - 1, s) if k >= 0))
    return result


def is_evidenced(stated: Stated, printed: set[str]) -> bool:
    value = Decimal(stated.number)
    places = Decimal(1).scaleb(value.as_tuple().exponent)    # 0.01 for '2.55'
    if stated.approx and "." not in stated.number:
        places = Decimal(1).scaleb(len(stated.number) - len(stated.number.rstrip("0")))
    candidates = [(value, places)]
    if stated.unit in SCALE:
        candidates.append((value * SCALE[stated.unit], places * SCALE[stated.unit]))
    if stated.unit == "%":
        candidates.append((value / 100, places / 100))
    for v, q in candidates:
        for p in map(Decimal, printed):
            if abs(p - v) <= q / 2 and p.as_tuple().exponent <= v.as_tuple().exponent:
                return True
    return False


def unevidenced(path) -> list[Stated]:
    nb = nbformat.read(path, as_version=4)
    ev = evidence(nb)
    return [s for s in stated_numbers(nb) if not is_evidenced(s, ev[s.cell])]
