"""What a notebook's prose states about its results, and whether its outputs show it.

Used by ``test_stated_numbers.py``. Prose is a markdown
cell outside math, code spans and quotes (``"..."`` is the paper's words); it is cut into
``##`` sections, sentences (a list item or a table row is one) and clauses (cut at , ; : ( ) and
'and', 'but', 'while'). Evidence is what the code cells of the sentence's section and of the
one before print (a section that sums the chapter up, its title, 'Summary', 'verdict', may
cite any output of the notebook); printed lines are cut into clauses at ';' and ', ', and
tables (markdown, ``' | '`` or space-aligned) into cells that carry their row label and column
header. Four kinds of statement are checked; each gets an outcome: *bound* (to a printed
line that names what it names), *fallback* (the prose names nothing the scope prints, so any
output of the section may show it), *skipped* (not a result) or *FLAG*.

1. **Numbers**, as before: a decimal, a percentage, an integer of three or more digits, a
   count ``N of M``, a small integer with a unit of ``SMALL_INT_UNITS`` (skipped: headings,
   exercise and section numbers, years), and spelled-out amounts ('a metre', 'a few
   centimetres', 'within a metre', 'a metre and more'), which are checked only where they name
   a printed metric. A number matches a printed one at the precision the prose uses
   ('2.55' by 2.551, 'about 150' by 149.4). *Units (rule 2):* the prose unit (cm, mm, m, km,
   ms, us, s, min, %, deg/°, rad, m/s, ...) and the printed one (the token after the number,
   a unit written once for a range or a tuple, ``(m)``/``[s]``/'in m' in its column header)
   are converted to SI and must be of one kind: 1.5 ms is never a printed 1.50 m. A printed
   number with no unit at all may show a number with a unit only where its line names the
   prose's quantity (91 % shown as 0.913 is a conversion and always allowed). *Quantity
   (rule 3):* the quantity words of ``QUANTITIES`` in the eight words before the number (back
   to the previous number or a ; : . )) and the two after it ('15 cm RMSE', '335 landmarks';
   a number in parentheses takes the words before them) must appear in the printed number's
   line, table row or column: a metric named (NEES, RMSE, median, sigma ... ``METRICS``)
   beside the number, a thing named (map, path, landmark ...) there or in the code that
   printed it ('traj_rmse'). Words are stemmed and mapped by ``SYNONYMS`` (track = path,
   threshold = gate, beacon = tree = landmark, sd = sigma, RMS = RMSE, ANEES also NEES).
   'at best', 'at most', 'up to', 'largest' ask for the extreme of the printed column. A
   literal of the section's code is still evidence for a parameter (not in a summing-up
   section). *Timing (rule 4):* a time in a sentence about cost (takes, costs, CPU, per
   update, ...), or any ms/us beside a timing output, is checked only against the outputs of
   ``NBVAL_IGNORE_OUTPUT`` cells, which are evidence for nothing else, within a factor of 2
   (machines differ by 1.5-2x), and every word of the timing table it names (here or earlier
   in its paragraph: 'the efficient update') must head the printed number's column.
2. **Verdict words** (rule 1, ``PROSE_VERDICTS``): pass(es), fail(s), inside/outside/into/above/
   below its band (or interval, goal), is/are consistent/honest, inconsistent, over-/
   under-confident, better, worse, (nearly, exactly, is) the same / equivalent / identical,
   confirmed, over-stated, 'all of it'/'entirely', 'the opposite'. Each needs the same word
   printed (``PRINTED_VERDICTS``: prose 'passes' by 'pass', 'outside' by 'OUTSIDE' or 'too
   small', 'consistent' by 'consistent', not by 'no evidence against consistency'; 'the same' by
   same/equal/equivalent/agrees, not by 'no detectable difference'; 'inside' by a share of scans
   inside only if the prose speaks of a share: 'almost all the time', 'every scan'). It is
   bound to the quantity its clause names (``QUANTITIES`` and the labels the outputs print,
   'midpoint', 'start exact EKF'): the printed clauses sharing most of those words, less two
   for each of map/pose/path/laser/gps/... that the printed clause has and the sentence lacks.
   A word whose best clauses print only its contrary is flagged ('map NEES ... inside' beside
   'map NEES 1.074 (OUTSIDE)'); 'all of it' is flagged if any printed line of its subject
   says fail/outside; with no quantity named any output of the section may carry it. Not
   results, and skipped: a clause with if, unless, when, whether, would, could, should,
   might, may, must, can, expect; a question; an exercise's prompt (the cell under its
   heading); a relative clause of an indefinite subject ('a filter that ...') or a sentence
   whose subject is one ('A consistent filter stays ...'); a negated word flips
   pass/fail, inside/outside, consistent/inconsistent, and is skipped otherwise; 'passes' or
   'fails' in a sentence that names no test (rule, check, band, NEES, NIS ...).
3. **Multipliers** ('N times', 'twice', 'N-fold', 'a factor of N', 'tens/hundreds of times',
   'several times'): the interval the words allow (3 = 2.5-3.5, 2.5 = 2.45-2.55, ten = 5-15,
   tens = 10-99, hundreds = 100-999, several = 2.5-10; 'more than' opens it) must hold a
   printed ratio (4x, x0.47) or the ratio of two printed numbers of one unit kind: 'X is N
   times the Y' takes X from numbers printed right after X's words and Y after Y's (a pair in
   one clause first); otherwise two numbers of lines naming the clause's subject, or of one
   output; or two evidenced numbers the sentence itself states.

Everything flagged is declared with a reason: numbers by key in ``stated_numbers.toml`` (a
declaration covers every occurrence of its key), verdicts and multipliers by a quote of
their sentence in ``stated_verdicts.toml``.

Known limits: many numbers rely on the section fallback rather than being bound to a
named quantity, and most flagged numbers are declared constants, parameters and
arithmetic. A few verdict words skipped as not results are results (the conditional '4-lap
loop fails all three rules when read as P/1.1', 'a small over-confidence that chapter 10
examines'); many flagged ones are not results the rule recognises (definitions, theory, a
grading rubric, idioms such as 'worse for a filter', 'consistent again' in its everyday
sense), hence the declarations. The fallback
still lets a number match any printed number of its section when the prose names no
quantity; a vocabulary gap ('the laser's 0.10 m' beside a column 'radial sd') flags a right
number; a multiplier's undirected fallback is loose ('more than a factor of two' holds for
almost any pair); a factor-2 timing check cannot tell apart columns that span 0.25 to 3 ms;
timing outputs differ between machines, so the audit's timing rows are tested against the
table the audit saw; binding is by words, so a verdict about one band ('the time average is
inside [2.36, 3.72]') is checked against the printed verdict of another (the ANEES t-test).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from decimal import Decimal, InvalidOperation

import nbformat

# ---------------------------------------------------------------------------------------
# units

_DEG = math.pi / 180
UNITS: dict[str, tuple[str, float]] = {          # unit as written -> (kind, scale to SI)
    "mm": ("length", 1e-3), "cm": ("length", 1e-2), "m": ("length", 1.0), "km": ("length", 1e3),
    "us": ("time", 1e-6), "µs": ("time", 1e-6), "μs": ("time", 1e-6), "ms": ("time", 1e-3),
    "s": ("time", 1.0), "min": ("time", 60.0),
    "°": ("angle", _DEG), "deg": ("angle", _DEG), "degrees": ("angle", _DEG), "rad": ("angle", 1.0),
    "%": ("fraction", 1e-2),
    "m/s": ("speed", 1.0), "Hz": ("frequency", 1.0), "MB": ("memory", 1.0),
    "m^2": ("area", 1.0), "m²": ("area", 1.0), "x": ("ratio", 1.0), "×": ("ratio", 1.0),
}
_UNIT_RE = r"m/s|m\^2|m²|mm|cm|km|ms|us|µs|μs|min|MB|Hz|degrees|deg|rad|m|s|°|%"
# the units the original checker knew: a declaration's key keeps only these ('25ms', '98%')
LEGACY_UNITS = {"%", "cm", "mm", "ms", "°"}
# a small integer is a stated number only with one of these units (or as a count 'N of M')
SMALL_INT_UNITS = LEGACY_UNITS | {"us", "µs", "μs", "deg"}

# ---------------------------------------------------------------------------------------
# prose: what is masked, what is a number

MATH = re.compile(r"\$\$.*?\$\$|\$[^$\n]*\$|`[^`\n]*`|<[^>\n]*>|\]\([^)\n]*\)", re.S)
STATED = re.compile(r"(?<![\w.^_{\\/#])(?<![A-Za-z]-)(\d{1,3}(?:[,\u202f ]\d{3})+(?![\d.])|\d+(?:\.\d+)?)"
                    r"(?:\s?(" + _UNIT_RE + r"))?(?![\w/]|\.\d)")
EXERCISE = re.compile(r"(?:exercise|exercises|section|sections|chapter|chapters|ch\.)\s*$", re.I)
APPROX = re.compile(r"(?:about|around|roughly|nearly|almost|some|~|≈)\s*$", re.I)
SUMMING_UP = re.compile(r"summary|verdict", re.I)
QUOTED = re.compile(r"“[^”]*”|\"[^\"\n]*\"")
# a clause that only supposes, defines or asks states no result (rule of section 'non-results')
CONDITIONAL = re.compile(r"\b(?:if|unless|when|whenever|whether|would|could|should|might|may|must|can|"
                         r"suppose|imagine|expect|expected|predict)\b", re.I)
# 'passes' and 'fails' are verdicts only in a sentence that names a test
TEST_WORDS = re.compile(r"\b(?:tests?|rules?|checks?|band|verdicts?|nees|anees|nis|consistency|"
                        r"criteri(?:on|a)|goal)\b", re.I)
# a verdict inside a relative clause of an indefinite noun describes a kind of thing, not a result
GENERIC = re.compile(r"\b(?:a|an|any|every|no)\s+(?:[\w-]+\s+){0,2}?(?:that|which|whose|who)\b", re.I)
# ... and so does a sentence whose subject is 'a filter', 'an over-confident filter', 'any test'
GENERIC_SUBJECT = re.compile(r"^\W*(?:a|an|any|every)\s+(?:[\w-]+\s+){0,2}?(?:filter|test|estimator|gate|"
                             r"covariance|network|sensor|model)s?\b", re.I)
NEGATION = re.compile(r"\b(?:not|never|no longer|nor|neither|cannot|n't)\b(?:\W+\w+){0,2}\W*$", re.I)
TIMING = re.compile(r"\b(?:take|takes|took|taking|cost|costs|costing|cpu|run time|runtime|per update|"
                    r"per scan|per step|per call|timing|timed|spends?|elapsed|faster|slower|"
                    r"milliseconds|microseconds)\b", re.I)

# ---------------------------------------------------------------------------------------
# words: a tolerant notion of 'the quantity a number or a verdict names'

STOP = set("""a an the of in on at to for from by with without and or but as is are was were be been
being it its it's this that these those there here than then so such very more most less least
much many few each every all any both either no not only also just still even once twice over
under into onto out up down off per via about around near nearly almost some same other another
which what who whom whose where when while how why we our you your they their them he she his her
one two three four five six seven eight nine ten do does did done has have had having can could
would should may might must will shall let lets i e g vs etc ie eg dof""".split())

SYNONYMS = {
    "track": "path", "trajectory": "path", "threshold": "gate", "σ": "sigma", "sd": "sigma",
    "std": "sigma", "deviation": "sigma", "tree": "landmark", "beacon": "landmark", "pole": "landmark",
    "rms": "rmse", "percentile": "p90", "90th": "p90", "maximum": "max", "largest": "max",
    "worst": "max", "highest": "max", "minimum": "min", "smallest": "min", "lowest": "min",
    "prediction": "predict", "predicted": "predict", "covariances": "covariance", "cov": "covariance",
    "jitter": "scatter", "jitters": "scatter", "velocity": "speed", "rotated": "rotation",
    "turned": "rotation", "shifted": "shift", "rejection": "reject", "rejected": "reject",
    "accepted": "accept", "deleted": "removed", "remove": "removed", "created": "create",
    "started": "create", "trace": "covariance", "d²": "d2", "variance": "covariance",
    "innovations": "innovation", "correlated": "correlation", "eigenvalues": "eigenvalue",
    "share": "scan", "seconds": "second", "averaged": "average", "mean": "average",
    "time-averaged": "average", "neighbour": "nn", "neighbours": "nn", "jcbb": "jcbb",
}
# words of printed labels that name no configuration or quantity
LABEL_STOP = set("""with without default value run filter true false after before first last fixed
check number result print table total new old band""".split())
# quantity words too general to bind a verdict to a printed line
SUBJECT_STOP = {"run", "band", "seed", "result", "value", "test", "rule", "time", "step", "count",
                "window", "state"}
# a token that names more than one quantity
EXPANDS = {"anees": {"anees", "nees", "average"}, "nis/dof": {"nis"}, "p90": {"p90"}}

QUANTITIES = set("""nees anees nis rmse median average p90 max min final error map path pose position
heading landmark scan fix sighting detection predict update step sample sigma covariance eigenvalue
asymmetry correlation kurtosis speed steering range bearing d2 gate slope ratio epoch run seed fold
gap interval innovation noise uncertainty residual scatter reject accept spurious duplicate create
removed rotation shift offset bias cpu distance length window count gain weight state gps laser
odometry frame extent dense efficient shape factor""".split())
# the quantities that are a metric of something (the rest name the thing measured: path, map,
# scan ...); a number that names a metric must be printed beside it
METRICS = set("""nees anees nis rmse median average p90 max min sigma covariance eigenvalue asymmetry
correlation kurtosis slope ratio d2 residual offset bias rotation shift speed weight
factor scatter""".split())
# words that tell two quantities of the same name apart ('map NEES' is not 'pose NEES')
MODIFIERS = set("map pose path laser gps joint range bearing position heading".split())


NOSTEM = {"nees", "anees", "nis", "rms", "gps", "dof", "jcbb", "fej", "isam2", "nbval", "axis", "bias",
          "this", "its", "gas", "lens"}


def _stem(w: str) -> str:
    w = w.lower().strip("'’-_")
    if w.endswith("'s") or w.endswith("’s"):
        w = w[:-2]
    if w in NOSTEM:
        return SYNONYMS.get(w, w)
    if len(w) > 4 and w.endswith("ies"):
        w = w[:-3] + "y"
    elif len(w) > 4 and re.search(r"(?:ss|x|ch|sh)es$", w):
        w = w[:-2]
    elif len(w) > 3 and w.endswith("s") and not w.endswith(("ss", "us", "is")):
        w = w[:-1]
    return SYNONYMS.get(w, w)


def words(text: str) -> set[str]:
    """Content words of a text, stemmed and mapped through the synonym table."""
    text = text.replace("d^2", "d2").replace("d²", "d2").replace("σ", " sigma ")
    text = re.sub(r"(?i)\bnis\s*/\s*dof\b", "nis", text)
    out: set[str] = set()
    for tok in re.findall(r"[A-Za-zα-ωÀ-ÿ][\w'’]*(?:-[A-Za-z]\w*)*", text):
        parts = [tok] + (re.split(r"[-_]", tok) if re.search(r"[-_]", tok) else [])
        for p in parts:
            s = _stem(p)
            if len(s) < 2 and s not in {"n", "r", "q", "p", "k"}:
                continue
            if s in STOP:
                continue
            out |= EXPANDS.get(s, {s})
    return out


# ---------------------------------------------------------------------------------------
# verdicts

# the words that may stand between 'is' and 'consistent' in a predicate ('is not quite')
_ADVERBS = r"(?:not|still|now|also|fully|quite|roughly|nearly|both|all|only|then|again|here|\*+)"
# prose: class -> pattern (matched on the masked prose of a clause)
PROSE_VERDICTS = {
    "pass": r"\bpass(?:es|ed)?\b(?!\s+(?:the\s+)?gate|\s+through|\s+over|\s+along)",
    "fail": r"\bfail(?:s|ed)?\b",
    "inside": r"\b(?:inside|within|in|into)\b(?=(?:\W+\w+){0,3}?\W+(?:band|bands|bounds|interval|goal)\b)",
    "outside": r"\b(?:outside|above|below|out\s+of|leaves?|leaving)\b(?=(?:\W+\w+){0,3}?\W+"
               r"(?:band|bands|bounds|interval|goal)\b)",
    "consistent": r"\b(?:is|are|was|were|be|being|stays?|remains?|looks?|seems?|becomes?)\s+"
                  r"(?:" + _ADVERBS + r"\s+){0,2}(?:consistent|honest)\b",
    "inconsistent": r"\b(?:is|are|was|were|be|being|stays?|remains?|looks?|seems?|becomes?)\s+"
                    r"(?:" + _ADVERBS + r"\s+){0,2}(?:inconsistent|dishonest)\b",
    "over-confident": r"(?<!\ban\s)\bover-?confiden(?:t|ce)\b",
    "under-confident": r"(?<!\ban\s)\bunder-?confiden(?:t|ce)\b",
    "better": r"(?<!\ba\s)\bbetter\b(?!\s+than\s+(?:[\d$]|perfect))",
    "worse": r"(?<!\ba\s)\bworse\b(?!\s+than\s+[\d$])",
    "same": r"\b(?:nearly|almost|exactly|essentially|practically|virtually|roughly|much|is|are|was|"
            r"were|stays?|remains?|gives?|looks?)\s+(?:\w+\s+)?the\s+same\b|\bthe\s+same\s*(?=[.;:,)]|$)"
            r"|\b(?:is|are|was|were)\s+(?:\w+\s+)?(?:equivalent|identical)\b",
    "confirmed": r"\bconfirm(?:s|ed)\b",
    "over-stated": r"\bover-?stated\b",
    "all": r"\ball\s+of\s+it\b|\bentirely\b",
    "opposite": r"\bthe\s+opposite\b(?=\s*(?:[.;:,)]|$|of\b))",
}
# printed: class -> pattern (matched on a printed clause)
PRINTED_VERDICTS = {
    "pass": r"\bpass(?:es|ed)?\b",
    "fail": r"\bfail(?:s|ed)?\b",
    "inside": r"(?<!% of )(?<!scans )\binside\b(?!\s+(?:a|the)\s+\d)|\bwithin (?:its|the) band\b",
    "share-inside": r"%\s+of\s+(?:\d+\s+)?(?:the\s+)?scans\s+inside\b",
    "outside": r"\boutside\b|\b(?:above|below) (?:its|the) band\b|\btoo (?:small|large)\b",
    "consistent": r"(?<!')\bconsistent\b(?!')",
    "inconsistent": r"\binconsistent\b",
    "over-confident": r"\bover-?confident\b",
    "under-confident": r"\bunder-?confident\b",
    "better": r"\bbetter\b",
    "worse": r"\bworse\b",
    "same": r"\bsame\b|\bidentical\b|\bequal\b|\bequivalent\b|\bagrees?\b",
    "confirmed": r"(?<![0 ]0 )\bconfirm(?:s|ed)\b",
    "over-stated": r"\bover-?stated\b",
    "opposite": r"\bopposite\b",
}
# which printed classes support a prose class; which contradict it
SUPPORT = {c: {c} for c in PROSE_VERDICTS}
SUPPORT["same"] = {"same"}
SUPPORT["all"] = {"pass", "inside", "consistent", "same", "confirmed"}
SHARE_QUALIFIER = re.compile(r"\b(?:all the time|most of the time|every scan|all (?:the )?scans|"
                             r"most (?:of the )?scans|a minority|a majority|share|% of the scans|"
                             r"of (?:its|the) scans|third of the scans|half of the scans)\b", re.I)
CONTRARY = {
    "pass": {"fail"}, "fail": {"pass"}, "inside": {"outside"}, "outside": {"inside"},
    "consistent": {"inconsistent", "outside", "fail", "over-confident", "under-confident"},
    "inconsistent": {"consistent"}, "over-confident": {"under-confident"},
    "under-confident": {"over-confident"}, "better": {"worse"}, "worse": {"better"},
    "same": {"better", "worse"}, "confirmed": set(), "over-stated": set(),
    "all": {"fail", "outside", "inconsistent", "worse"}, "opposite": set(),
}
FLIP = {"pass": "fail", "fail": "pass", "inside": "outside", "outside": "inside",
        "consistent": "inconsistent", "inconsistent": "consistent"}

# 'N times': the multiplier a phrase states, as an interval
NUMBER_WORDS = {"one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7,
                "eight": 8, "nine": 9, "ten": 10, "eleven": 11, "twelve": 12, "fifteen": 15,
                "twenty": 20, "thirty": 30, "forty": 40, "fifty": 50, "a hundred": 100,
                "hundred": 100, "a thousand": 1000}
RANGE_WORDS = {"tens": (10, 100), "hundreds": (100, 1000), "thousands": (1000, 10000),
               "several": (2.5, 10), "a few": (1.5, 10)}
_MULT_N = r"(\d+(?:\.\d+)?|" + "|".join(sorted(list(NUMBER_WORDS) + list(RANGE_WORDS), key=len,
                                                 reverse=True)) + r")"
_COMPARE = (r"(?=\s+(?:the|as|larger|smaller|more|less|longer|shorter|further|farther|higher|lower|"
            r"faster|slower|bigger|wider|narrower|its|their|that|this|what|worse|better|cheaper|"
            r"dearer|greater|fewer|[a-z]+er\b))")
MULTIPLIER = re.compile(
    r"(?P<q>(?:about|around|roughly|nearly|almost|some|over|more than|less than|at least|~|≈)\s+)?"
    r"(?:\b" + _MULT_N + r"(?:\s+(?:and\s+a\s+half\s+)?)?(?:\s+of)?\s*(?:times|-fold|fold)\b" + _COMPARE +
    r"|\b(?:a\s+)?factor\s+of\s+(?P<q2>(?:about|around|roughly|nearly|almost|some|over|more than|"
    r"~|≈)\s+)?" + _MULT_N + r"\b|\b(twice)\b(?=\s+(?:as|the|its|their)\b))", re.I)


# ---------------------------------------------------------------------------------------
# data classes

@dataclass(frozen=True)
class Stated:
    cell: int
    number: str
    unit: str
    context: str
    approx: bool = False          # 'about 150': its trailing zeros are not digits
    section: int = 0
    quantity: frozenset = frozenset()   # the content words around it (check_number keeps the
    #                                     ones that name a quantity)
    timing: bool = False          # a time in a sentence about run time (rule 4)
    sentence: str = ""
    topic: frozenset = frozenset()  # the words of the paragraph before its sentence
    extreme: str = ""             # 'max', 'min' or 'either': 'at most 0.6', '0.035 at best'
    phrase: str = ""              # a spelled-out amount: 'a metre'
    bounds: tuple = ()            # its interval, in the stated unit

    @property
    def key(self) -> str:
        """How a declaration names it: the number, with the unit if the original checker knew it
        (a spelled-out amount: its words)."""
        if self.phrase:
            return self.phrase
        return self.number + (self.unit if self.unit in LEGACY_UNITS else "")


@dataclass
class PNum:
    raw: str
    unit: str
    words: frozenset
    ratio: bool = False
    near: frozenset = frozenset()      # the words just before it: what it is ('d2 = 422.1')
    col: tuple | None = None           # its table column, if it is in one
    code: bool = False                 # a literal of the code

    @property
    def kind(self):
        return UNITS[self.unit][0] if self.unit in UNITS else None

    @property
    def si(self) -> float:
        return float(self.raw) * (UNITS[self.unit][1] if self.unit in UNITS else 1.0)


@dataclass
class PClause:
    """One printed clause: a line, or a part of one, or a table cell, with its context."""
    cell: int
    section: int
    block: int                     # one output of one cell
    text: str
    words: frozenset
    nums: list
    verdicts: frozenset
    timing: bool = False
    code: bool = False


@dataclass
class Sentence:
    cell: int
    section: int
    text: str            # with math as written
    masked: str          # math, code and quotes blanked
    wtext: str           # math simplified to its letters, for words
    exercise: bool = False


@dataclass
class Finding:
    """One checked statement: a number, a verdict word or a multiplier, and how it was bound."""
    cell: int
    kind: str            # 'number', 'verdict', 'times'
    what: str            # the number's key, the verdict class, the multiplier
    sentence: str
    outcome: str         # 'bound', 'fallback', 'skipped', or 'FLAG'
    why: str = ""
    stated: Stated | None = None
    bounds: tuple = ()   # a multiplier's interval


@dataclass
class Notebook:
    nb: object
    sections: list = field(default_factory=list)        # titles
    summing_up: set = field(default_factory=set)
    clauses: list = field(default_factory=list)
    sentences: list = field(default_factory=list)
    labels: set = field(default_factory=set)
    code_words: dict = field(default_factory=dict)
    stated: list = field(default_factory=list)


# ---------------------------------------------------------------------------------------
# printed outputs

def _text(output) -> str:
    if output.output_type == "stream":
        return output.text
    data = output.get("data", {})
    text = "\n".join(str(data.get(k, "")) for k in ("text/plain", "text/markdown", "text/html"))
    text = re.sub(r"<(?:Figure|IPython|matplotlib)[^>\n]*>", "", text)     # reprs print no result
    if re.match(r"\s*(?:interactive|VBox|HBox|Output|Tab|Accordion)\(", text):
        return ""                          # a widget's repr: its slider values are no result
    return text


def _ignored(cell) -> bool:
    """nbval does not compare this cell's outputs (timings): evidence for timing prose only."""
    return ("NBVAL_IGNORE_OUTPUT" in cell.source
            or "nbval-ignore-output" in cell.get("metadata", {}).get("tags", []))


_PNUM = re.compile(r"(?<![A-Za-wyz_\d.])(?P<pre>[x×]\s?)?[-+−]?(?P<n>\d+(?:\.\d+)?(?:e[-+]?\d+)?)"
                   r"(?:\s?(?P<u>" + _UNIT_RE + r"|x|×)(?![A-Za-z0-9_]))?")
_HEADER_UNIT = re.compile(r"[(\[]\s*(m\^2|m²|cm|mm|ms|us|m|s|deg|rad|%)\s*[,)\]]|\bin (m|cm|s|ms|deg)\b")


def _clean(text: str) -> str:
    return re.sub(r"(?<=\d)[,_\u202f](?=\d{3}(?!\d))", "", text)


def printed_numbers(text: str) -> set[str]:
    """The numbers in a text, unsigned, as written (a set of Decimals would merge 1 and 1.0)."""
    out = set()
    for m in _PNUM.finditer(_clean(text).replace(",", " ")):
        try:
            out.add(str(abs(Decimal(m.group("n")))))
        except InvalidOperation:
            pass
    return out


def _nums(text: str, context: set, default_unit: str = "", col=None) -> list[PNum]:
    out, found, prev = [], [], 0
    text = _clean(text)
    for m in _PNUM.finditer(text):
        try:
            float(m.group("n"))
        except ValueError:
            continue
        found.append([m, m.group("u") or ""])
    # '0.088 / 0.046 m', '4.49 and 9.03 m', '(5.12, 4.25) m': a unit written once for several
    for k in range(len(found) - 1, -1, -1):
        m, unit = found[k]
        if unit:
            continue
        if k + 1 < len(found) and found[k + 1][1] and re.fullmatch(
                r"\s*(?:/|and|to|-|–|\.\.|,)\s*[-+−]?", text[m.end():found[k + 1][0].start()]):
            found[k][1] = found[k + 1][1]
            continue
        close = re.match(r"[^()\[\]]*[)\]]\s?(" + _UNIT_RE + r")(?![A-Za-z0-9_])", text[m.end():])
        if close and re.search(r"[(\[][^()\[\]]*$", text[:m.start()]):
            found[k][1] = close.group(1)
    for m, unit in found:
        ratio = bool(m.group("pre")) or unit in {"x", "×"}
        if not unit and default_unit:
            unit = default_unit
        near = words(" ".join(re.findall(r"[^\W\d][\w'/-]*", text[prev:m.start()])[-3:]))
        prev = m.end()
        out.append(PNum(str(abs(Decimal(m.group("n")))), unit if unit in UNITS else "",
                        frozenset(context), ratio, frozenset(near) or frozenset(context), col))
    return out


def _verdicts(text: str) -> frozenset:
    return frozenset(c for c, p in PRINTED_VERDICTS.items() if re.search(p, text, re.I))


def _header_unit(text: str) -> str:
    m = _HEADER_UNIT.search(text)
    return (m.group(1) or m.group(2)) if m else ""


def _split_clauses(line: str) -> list[str]:
    """A printed line cut at ';' and at ', ' outside brackets."""
    parts, depth, cur = [], 0, ""
    for i, ch in enumerate(line):
        depth += ch in "([{"
        depth -= ch in ")]}"
        if depth <= 0 and (ch == ";" or (ch == "," and line[i + 1:i + 2] == " ")):
            parts.append(cur)
            cur = ""
            depth = 0
            continue
        cur += ch
    parts.append(cur)
    return [p for p in parts if p.strip()]


def _is_aligned(line: str) -> bool:
    return len(re.findall(r"\S\s{2,}(?=\S)", line.strip())) >= 2


def _columns(header: str) -> list[tuple[int, int, str]]:
    return [(m.start(), m.end(), m.group()) for m in re.finditer(r"[^\s|]+(?: [^\s|]+)*", header)]


def _parse_output(text: str, cell: int, section: int, block: int, timing: bool) -> list[PClause]:
    out: list[PClause] = []
    lines = text.splitlines()
    title: set = set()
    title_unit = ""
    header = None          # an aligned table's header line
    md_header = None       # a markdown table's header cells
    pipe_header = None     # the header cells of a table drawn with ' | '
    for line in lines:
        s = line.strip()
        if not s:
            header = None
            continue
        if s.startswith("|") and s.endswith("|"):
            cells = [c.strip() for c in s.strip("|").split("|")]
            if all(re.fullmatch(r":?-{2,}:?", c) for c in cells if c):
                continue
            if md_header is None:
                md_header = cells
                continue
            label = set().union(*(words(c) for c in cells if not re.search(r"\d", c))) | words(cells[0])
            for j, c in enumerate(cells):
                h = md_header[j] if j < len(md_header) else ""
                ctx = label | words(h) | words(c) | title
                unit = _header_unit(h) or title_unit
                nums = _nums(c, ctx, unit, (block, j))
                for p in nums:
                    p.near = frozenset(words(h)) | p.near
                out.append(PClause(cell, section, block, f"{cells[0]} | {h}: {c}", frozenset(ctx),
                                   nums, _verdicts(c), timing))
            continue
        md_header = None
        n_nums = len(_PNUM.findall(_clean(s)))
        n_words = len(re.findall(r"[A-Za-z]{2,}", s))
        if s.count(" | ") >= 2 and not (pipe_header is None and any(
                re.search(r"\S\s{2,}\S", c.strip()) for c in s.split(" | "))):
            # a table drawn with ' | ': each cell takes the words of its column's header
            cells = [c.strip() for c in s.split(" | ")]
            if pipe_header is None or len(pipe_header) != len(cells) or n_words > 2 * n_nums:
                if n_words > n_nums:
                    pipe_header = cells
                    out.append(PClause(cell, section, block, s, frozenset(words(s) | title), [],
                                       _verdicts(s), timing))
                    continue
            else:
                label = words(cells[0])
                for j, c in enumerate(cells):
                    ctx = label | words(pipe_header[j]) | words(c) | title
                    nums = _nums(c, ctx, _header_unit(pipe_header[j]) or title_unit, (block, "|", j))
                    for p in nums:
                        p.near = frozenset(words(pipe_header[j])) | p.near
                    out.append(PClause(cell, section, block, f"{cells[0]} | {pipe_header[j]}: {c}",
                                       frozenset(ctx), nums, _verdicts(c), timing))
                continue
        else:
            pipe_header = None
        if n_nums == 0 or (s.endswith(":") and n_nums <= 1):
            if n_nums == 0 and _is_aligned(line):       # an aligned table's header
                header = line
                continue
            if _verdicts(s):                             # 'same seed, same run: True'
                for p in _split_clauses(s):
                    out.append(PClause(cell, section, block, p.strip(), frozenset(words(p) | title),
                                       [], _verdicts(p), timing))
            title = words(s)
            title_unit = _header_unit(s) or title_unit
            header = None
            continue
        if _is_aligned(line) and header is None and n_nums <= 2 and n_words >= 3 * max(n_nums, 1):
            header = line
            out.append(PClause(cell, section, block, s, frozenset(words(s) | title), [], _verdicts(s),
                               timing))
            continue
        if header is not None and _is_aligned(line):
            # a row of an aligned table: each number takes the words of its column
            label_m = re.match(r"\s*([^\d|]*?)\s*(?=[-+−]?\d|\|)", line)
            label = words(label_m.group(1)) if label_m else set()
            cols = _columns(header)
            nums = []
            for m in _PNUM.finditer(line):
                a, b = m.start(), m.end()
                over = [c for c in cols if c[0] < b + 1 and c[1] > a - 1]
                if not over and cols:
                    over = [min(cols, key=lambda c: abs((c[0] + c[1]) / 2 - (a + b) / 2))]
                seg_start = line.rfind("|", 0, a) + 1
                seg_title = header[seg_start:header.find(":", seg_start)] if ":" in header[
                    seg_start:header.find("|", seg_start) if "|" in header[seg_start:] else None] else ""
                ctx = label | title | words(seg_title) | set().union(*(words(c[2]) for c in over))
                unit = m.group("u") or _header_unit(" ".join(c[2] for c in over)) or title_unit
                raw = m.group("n")
                near = words(seg_title) | set().union(*(words(c[2]) for c in over))
                nums.append(PNum(str(abs(Decimal(raw))), unit if unit in UNITS else "",
                                 frozenset(ctx), bool(m.group("pre")) or unit in {"x", "×"},
                                 frozenset(near), (block, header, over[0][0] if over else -1)))
            out.append(PClause(cell, section, block, s, frozenset(label | title | words(header)), nums,
                               _verdicts(s), timing))
            continue
        header = None
        if re.search(r"\bin (?:m|cm|s|ms|deg)\b", s):        # 'errors against GPS in m, ...'
            title_unit = _header_unit(s)
        # a line of prose-like output: its label (before the first ':') names every clause
        lab = ""
        m = re.match(r"\s*([^:]{2,60}?)\s*:(?!\d)", s)
        if m:
            lab = m.group(1)
        parts = _split_clauses(s)
        # '..., NIS/dof 0.079, 95 % band [0.935, 1.067]: too small': a verdict after the line's
        # last colon, with no number after it, judges the whole line
        tail = s.rsplit(":", 1)[1] if ":" in s else ""
        whole = _verdicts(tail) if tail and not re.search(r"\d", tail) else frozenset()
        for p in parts:
            ctx = words(p) | words(lab) | title
            out.append(PClause(cell, section, block, p.strip(), frozenset(ctx),
                               _nums(p, ctx, _header_unit(p) or title_unit),
                               _verdicts(p) | whole, timing))
    return out


def _code_clauses(cell, i: int, section: int, block: int) -> list[PClause]:
    """The code's own literals: a parameter the prose names is set here (comments are no evidence)."""
    out = []
    for line in cell.source.splitlines():
        code = line.split("#")[0]
        if not re.search(r"\d", code):
            continue
        ctx = words(code)
        nums = [PNum(n, "", frozenset(ctx), code=True) for n in printed_numbers(code)]
        out.append(PClause(i, section, block, code.strip(), frozenset(ctx), nums, frozenset(),
                           code=True))
    return out


# ---------------------------------------------------------------------------------------
# the notebook, cut into sections, sentences and printed clauses

def _headings(nb) -> set[str]:
    nums = set()
    for c in nb.cells:
        if c.cell_type == "markdown":
            for line in c.source.splitlines():
                m = re.match(r"#+\s*(?:Exercise\s+)?(\d+(?:\.\d+)*)", line)
                if m:
                    nums.add(m.group(1))
    return nums


def _simplify_math(m: re.Match) -> str:
    s = m.group(0)
    if s.startswith("`"):
        inner = s[1:-1]
        if re.search(r"[.(=\[]", inner):
            inner = ""                   # a call or an expression names code, not a quantity
    elif s.startswith("$"):
        inner = re.sub(r"\\[A-Za-z]+|[{}^_$\\]", "", s).replace(" ", "")
    else:
        inner = ""
    return (" " + inner).ljust(len(s))[:len(s)] if len(inner) + 1 <= len(s) else " " * len(s)


_SENT_END = re.compile(r"(?<!\b[A-Z])(?<!e\.g)(?<!i\.e)(?<!\bal)(?<!\bcf)(?<!\bvs)(?<!\bch)(?<!Fig)"
                       r"[.!?](?=\s+[\W_]*[A-Z0-9(])|\n\s*\n|\n(?=\s*(?:[-*]|\d+\.)\s)|\n(?=\s*\|)")


def _sentences(part: str, masked: str, wtext: str, cell: int, section: int,
               exercise: bool) -> list[Sentence]:
    out, start = [], 0
    cuts = [m.end() for m in _SENT_END.finditer(masked)] + [len(part)]
    for end in cuts:
        if part[start:end].strip():
            out.append(Sentence(cell, section, part[start:end], masked[start:end], wtext[start:end],
                                exercise))
        start = end
    return out


def parse(nb) -> Notebook:
    """Sections, prose sentences, stated numbers and printed clauses of a notebook."""
    doc = Notebook(nb, sections=[""], summing_up={0})
    heads = _headings(nb)
    section, block, exercise = 0, 0, False
    for i, cell in enumerate(nb.cells):
        if cell.cell_type == "markdown":
            exercise = False             # an exercise's prompt is the cell under its heading
            part_lines: list[str] = []
            parts: list[tuple[int, bool, str]] = []
            for line in cell.source.splitlines():
                h = re.match(r"(#+)\s+(.*)$", line)
                if h:
                    if part_lines:
                        parts.append((section, exercise, "\n".join(part_lines)))
                        part_lines = []
                    if len(h.group(1)) == 2:
                        section += 1
                        doc.sections.append(h.group(2))
                        if SUMMING_UP.search(h.group(2)):
                            doc.summing_up.add(section)
                    exercise = bool(re.match(r"Exercise\b", h.group(2)))
                    continue
                if "<details" in line:
                    exercise = False
                part_lines.append(line)
            if part_lines:
                parts.append((section, exercise, "\n".join(part_lines)))
            for sec, ex, text in parts:
                masked = MATH.sub(lambda m: " " * len(m.group(0)), text)
                wtext = MATH.sub(_simplify_math, text)
                sents = _sentences(text, masked, wtext, i, sec, ex)
                doc.sentences.extend(sents)
                doc.stated.extend(_stated_in(text, masked, wtext, sents, i, sec, heads))
        else:
            doc.code_words[i] = words(cell.source)
            doc.clauses.extend(_code_clauses(cell, i, section, block))
            block += 1
            for o in cell.get("outputs", []):
                if o.output_type == "error":
                    continue
                doc.clauses.extend(_parse_output(_text(o), i, section, block, _ignored(cell)))
                block += 1
    for c in doc.clauses:
        if c.code:
            continue
        m = re.match(r"\s*([^:|]{2,40}?)\s*[:|]", c.text)
        if m and len(words(m.group(1)) - LABEL_STOP) <= 3:      # a name, not a sentence
            doc.labels |= words(m.group(1))
    doc.labels -= LABEL_STOP
    return doc


def _window(wtext: str, start: int, end: int, sent_start: int) -> set[str]:
    """The content words that name the number at wtext[start:end]: those before it back to the
    previous number or clause mark, and the two words after it."""
    before = wtext[sent_start:start]
    punct = max([m.end() for m in re.finditer(r"[;:)]|\.(?=\s)", before)] + [0])
    numbers = max([m.end() for m in re.finditer(r"\d(?:[.,]\d+)?(?:\s*(?:" + _UNIT_RE + r"))?(?=\W)",
                                                before)] + [0])
    cut = max(punct, numbers)
    if numbers > punct:
        # '1.67 cm RMS against 6.32 cm': the words right after a number, up to the first small
        # word, name that number, not this one
        lead = re.match(r"(?:\s*(?!(?:" + "|".join(STOP) + r")\b)[A-Za-z][\w'’/-]*)+", before[cut:])
        if lead and re.match(r"\s+\w", before[cut + lead.end():]):
            cut += lead.end()
    if re.search(r"\(\s*$", before[cut:]) and not words(before[cut:]) & QUANTITIES:
        # '(0.035 at best)': a number in parentheses annotates the phrase before them
        head = before[:len(before.rstrip()) - 1]
        cut = max([m.end() for m in re.finditer(r"[;:)]|\.(?=\s)", head)] + [0])
        before = head[cut:]
    else:
        before = before[cut:]
    count = re.match(r"\s*of\s+\d+(?:\.\d+)?", wtext[end:])     # '42 of 96 fixes': the noun after M
    if count:
        end += count.end()
    after = wtext[end:end + 40]
    after = re.split(r"[;:,.()]|\d", after)[0]
    bw = [w for w in re.findall(r"[\w'’/-]+", before)][-8:]
    aw = []
    for w in re.findall(r"[\w'’/-]+", after)[:2]:       # 'a 335 landmarks', not 'at 241 s the GPS'
        if w.lower() in STOP:
            break
        aw.append(w)
    return words(" ".join(bw + aw))


EXTREME_BEFORE = re.compile(r"\b(?:(up to|at most|largest|highest|maximum|max|peaks? at|worst)|"
                            r"(at least|smallest|lowest|minimum|min)|(at best))\b"
                            r"(?:\s+(?:the|a|of|its|is|was|value|one))*\s*$", re.I)
EXTREME_AFTER = re.compile(r"^\s*(?:" + _UNIT_RE + r")?\s*\(?(?:(at most)|(at least)|(at best))\b", re.I)
WORD_AMOUNT = re.compile(
    r"\b(?P<q>within|under|below|less than|at most|over|more than|at least)?\s*"
    r"\b(?P<n>half a|a few|a|one)\s+(?P<u>metres?|meters?|centimetres?|millimetres?|degrees?|"
    r"milliseconds?|seconds?)\b(?P<more>\s+(?:and|or)\s+more)?", re.I)
WORD_UNITS = {"metre": "m", "meter": "m", "centimetre": "cm", "millimetre": "mm", "degree": "°",
              "millisecond": "ms", "second": "s"}
WORD_VALUES = {"a": (0.5, 1.5), "one": (0.5, 1.5), "half a": (0.25, 0.75), "a few": (2.0, 9.0)}


def _paragraph_start(text: str, pos: int) -> int:
    cuts = [m.end() for m in re.finditer(r"\n\s*\n|\n(?=\s*(?:[-*]|\d+\.)\s)", text[:pos])]
    return cuts[-1] if cuts else 0


def _stated_in(text, masked, wtext, sents, cell, section, heads) -> list[Stated]:
    found = []
    offsets, pos = [], 0
    for s in sents:
        offsets.append(pos)
        pos += len(s.text)

    def sentence_at(at):
        j = max(i for i, o in enumerate(offsets) if o <= at)
        return offsets[j], sents[j]

    # spelled-out amounts ('jitters by a metre and more'): checked where they name a quantity
    for m in WORD_AMOUNT.finditer(masked):
        s0, sent = sentence_at(m.start())
        lo, hi = WORD_VALUES[m.group("n").lower()]
        q = (m.group("q") or "").lower()
        if q in {"within", "under", "below", "less than", "at most"}:
            lo = 0.0
        if q in {"over", "more than", "at least"} or m.group("more"):
            hi = math.inf
        unit = WORD_UNITS[m.group("u").lower().rstrip("s")]
        topic = words(wtext[_paragraph_start(masked, s0):s0])
        found.append(Stated(cell, "1", unit, masked[max(0, m.start() - 50):m.end() + 30].replace(
            "\n", " "), True, section, frozenset(_window(wtext, m.start(), m.end(), s0)), False,
            " ".join(sent.text.split()), frozenset(topic), "", " ".join(m.group(0).split()).lower(),
            (lo, hi)))
    matches = list(STATED.finditer(masked))
    for k, m in enumerate(matches):
        number, unit = re.sub(r"[,\u202f ]", "", m.group(1)), m.group(2) or ""
        if not unit and k + 1 < len(matches) and re.fullmatch(
                r"\s*(?:to|–|-|and)\s*[-+−]?", masked[m.end():matches[k + 1].start()]):
            unit = matches[k + 1].group(2) or ""
        before = masked[:m.start()]
        if EXERCISE.search(before):
            continue
        if number in heads and "." in number and unit not in LEGACY_UNITS:
            continue
        if re.fullmatch(r"(19[5-9]\d|20[0-2]\d|2030)", m.group(1)) and not unit:
            continue
        small_int = "." not in number and len(number) < 3
        count = re.match(r"\s*of\s+\d", masked[m.end():]) or re.search(r"\d\s+of\s+$", before)
        if small_int and unit not in SMALL_INT_UNITS and not count:
            continue
        s0, sent = sentence_at(m.start())
        q = _window(wtext, m.start(), m.end(), s0)
        is_timing = bool(unit in UNITS and UNITS[unit][0] == "time" and TIMING.search(sent.wtext))
        eb = EXTREME_BEFORE.search(masked[max(s0, m.start() - 40):m.start()])
        ea = EXTREME_AFTER.search(masked[m.end():m.end() + 20])
        extreme = ""
        for e in (eb, ea):
            if e:
                extreme = "max" if e.group(1) else "min" if e.group(2) else "either"
        topic = words(wtext[_paragraph_start(masked, s0):s0])
        found.append(Stated(cell, number, unit, masked[max(0, m.start() - 50):m.end() + 30].replace(
            "\n", " "), bool(APPROX.search(before)), section, frozenset(q), is_timing,
            " ".join(sent.text.split()), frozenset(topic), extreme))
    return found


# ---------------------------------------------------------------------------------------
# scope

def scope(doc: Notebook, section: int, timing: bool | None = False) -> list[PClause]:
    """The printed clauses a statement of `section` may cite: its own section and the one before
    (a summing-up section: the whole notebook). timing=False: no timing output; True: timing
    outputs only; None: both."""
    whole = section in doc.summing_up
    return [c for c in doc.clauses
            if (c.section in (section - 1, section) or (whole and not c.code))
            and (timing is None or c.timing == timing or (c.code and not timing))]


# ---------------------------------------------------------------------------------------
# numbers (rules 2, 3, 4)

def _places(number: str, approx: bool) -> Decimal:
    value = Decimal(number)
    places = Decimal(1).scaleb(value.as_tuple().exponent)
    if approx and "." not in number:
        places = Decimal(1).scaleb(len(number) - len(number.rstrip("0")))
    return places


def value_matches(stated: Stated, p: PNum) -> bool:
    """Does printed number p show the stated one, at the prose's precision, units converted?"""
    v, q = float(stated.number), float(_places(stated.number, stated.approx))
    pe = -Decimal(p.raw).as_tuple().exponent if "e" not in p.raw else 12
    pq = 10.0 ** (-pe) if pe > 0 else 1.0
    su = UNITS.get(stated.unit)
    if stated.bounds:                                   # 'a metre and more'
        if p.kind != su[0]:
            return False
        return stated.bounds[0] * su[1] <= p.si <= stated.bounds[1] * su[1]
    if stated.timing:
        if p.kind != "time" or su is None:
            return False
        ratio = p.si / (v * su[1]) if v else math.inf
        return 0.5 <= ratio <= 2.0
    tries = []
    if su is None or p.kind is None:
        tries.append((v, q, float(p.raw), pq))                    # as written (see unit_ok)
    if su is not None and p.kind is None and p.code:
        tries.append((v * su[1], q * su[1], float(p.raw), pq))    # code works in SI units
    if su is not None and su[0] == "fraction" and p.kind is None:
        tries.append((v / 100, q / 100, float(p.raw), pq))       # 91 % shown as 0.913
    if su is not None and p.kind == su[0]:
        sp = UNITS[p.unit][1]
        tries.append((v * su[1], q * su[1], p.si, pq * sp))      # converted to SI
    for vv, qq, pp, ppq in tries:
        if abs(pp - vv) <= qq / 2 * (1 + 1e-9) and ppq <= qq * (1 + 1e-9):
            return True
    return False


def _extreme_ok(doc: Notebook, s: Stated, p: PNum) -> bool:
    """'0.035 at best', 'at most 0.6': the number must be the extreme of its printed column."""
    if not s.extreme or p.col is None:
        return True
    column = [x for c in doc.clauses for x in c.nums if x.col == p.col and x.kind == p.kind]
    hi, lo = max(column, key=lambda x: x.si), min(column, key=lambda x: x.si)
    ends = {"max": [hi], "min": [lo], "either": [hi, lo]}[s.extreme]
    return any(value_matches(s, e) for e in ends)


def check_number(doc: Notebook, s: Stated) -> Finding:
    if not s.timing and UNITS.get(s.unit, ("",))[0] == "time" and s.unit in {"ms", "us", "µs", "μs"} \
            and any(c.timing for c in scope(doc, s.section, True)):
        s = replace(s, timing=True)      # milli- and microseconds beside a timing output: a timing
    clauses = scope(doc, s.section, timing=s.timing)
    hits = [(c, p) for c in clauses for p in c.nums if value_matches(s, p)
            and _extreme_ok(doc, s, p) and not (s.extreme and c.code)]
    # rule 2: a number stated with a unit is shown by a printed number with a unit of its kind;
    # a printed number without any unit may show it only where the line names its quantity
    unit = UNITS.get(s.unit)
    unitless = [(c, p) for c, p in hits if unit and unit[0] != "fraction" and p.kind is None
                and not c.code]               # (91 % shown as 0.913 is a conversion, not a guess)
    named = s.quantity & QUANTITIES
    if s.timing:
        # a timing names what is timed by the words its timing table uses, here or earlier in
        # the paragraph; every one of them must head the printed number's column or line
        timed = set().union(*(c.words for c in clauses)) - {"n"}
        named = (s.quantity & timed) or (s.topic & timed)
        if named:
            bound = [(c, p) for c, p in hits if named <= (p.words | p.near)]
            if bound:
                return Finding(s.cell, "number", s.key, s.sentence, "bound", stated=s)
            return Finding(s.cell, "number", s.key, s.sentence, "FLAG",
                           f"{s.number} {s.unit}: no timing of {'/'.join(sorted(named))} in its "
                           f"section is within a factor of 2 of it", stated=s)
    if s.bounds and not (named & METRICS and any(named & METRICS & c.words for c in clauses)):
        return Finding(s.cell, "number", s.key, s.sentence, "skipped", "names nothing printed",
                       stated=s)
    if named and not any(named & c.words for c in clauses):
        named = frozenset()              # the prose names a quantity no output of the scope names
    if named:
        metrics, objects = named & METRICS, named - METRICS

        def names(c, p):
            ctx = p.words | c.words
            if metrics and not metrics & ctx:
                return False
            # the thing measured may be named only by the code that printed it ('traj_rmse')
            return not objects or bool(objects & (ctx | doc.code_words.get(c.cell, set()))) or (
                bool(metrics))
        bound = [(c, p) for c, p in hits if names(c, p)]
        if bound:
            return Finding(s.cell, "number", s.key, s.sentence, "bound", stated=s)
        code = [(c, p) for c, p in hits if c.code]
        hits = [(c, p) for c, p in hits if not c.code and (c, p) not in unitless]
        if code and not hits and not s.extreme:
            # a parameter the prose names is set in the code, under its own name
            return Finding(s.cell, "number", s.key, s.sentence, "fallback", "a code literal", stated=s)
        if s.extreme and not hits:
            column = [p for c in clauses for p in c.nums if value_matches(s, p) and names(c, p)
                      and not c.code]
            if column:
                return Finding(s.cell, "number", s.key, s.sentence, "FLAG",
                               f"{s.number} {s.unit} is printed as {'/'.join(sorted(named))}, but "
                               f"it is not the {s.extreme} of its column", stated=s)
        if hits:
            return Finding(s.cell, "number", s.key, s.sentence, "FLAG",
                           f"{s.number} {s.unit} is printed, but not as {'/'.join(sorted(named))} "
                           f"(it is: {hits[0][0].text[:60]!r})", stated=s)
    elif [h for h in hits if h not in unitless]:
        return Finding(s.cell, "number", s.key, s.sentence, "fallback", stated=s)
    elif hits:
        return Finding(s.cell, "number", s.key, s.sentence, "FLAG",
                       f"{s.number} {s.unit}: printed only without a unit and with no quantity "
                       f"named (it is: {hits[0][0].text[:60]!r})", stated=s)
    what = "no timing output of its section shows it within a factor of 2" if s.timing else \
        "in no output of its section"
    return Finding(s.cell, "number", s.key, s.sentence, "FLAG", f"{s.number}{s.unit}: {what}",
                   stated=s)


def stated_numbers(nb) -> list[Stated]:
    return parse(nb).stated


# ---------------------------------------------------------------------------------------
# verdicts and multipliers (rule 1)

_CLAUSE_CUT = re.compile(r"[;:,()]|\s[—–]\s|\b(?:and|but|while|whereas|although|though)\b")


def _clauses_of(text: str) -> list[tuple[int, int]]:
    cuts = [0] + [m.start() for m in _CLAUSE_CUT.finditer(text)] + [len(text)]
    return [(a, b) for a, b in zip(cuts, cuts[1:]) if b > a]


def _subject(sent: Sentence, a: int, b: int, vocab: set) -> set[str]:
    return (words(sent.wtext[a:b]) & vocab) - SUBJECT_STOP


def _score(c: PClause, subject: set, sentence_words: set) -> int:
    conflict = (c.words & MODIFIERS) - sentence_words
    return len(subject & c.words) - 2 * len(conflict)


def _verdict_mentions(sent: Sentence):
    vtext = QUOTED.sub(lambda m: " " * len(m.group(0)), sent.masked)
    for cls, pat in PROSE_VERDICTS.items():
        for m in re.finditer(pat, vtext, re.I):
            # the verdict word itself (the pattern may start at a verb before it)
            yield cls, m.start(), m.end()


def check_sentence(doc: Notebook, sent: Sentence) -> list[Finding]:
    out: list[Finding] = []
    text = " ".join(sent.text.split())
    vocab = QUANTITIES | doc.labels
    clauses = _clauses_of(sent.masked)
    sw = words(sent.wtext)
    timing = bool(TIMING.search(sent.wtext))
    pool = scope(doc, sent.section, timing=None if timing else False)
    vpool = [c for c in pool if c.verdicts and not c.code]

    def clause_at(pos):
        for k, (a, b) in enumerate(clauses):
            if a <= pos < b:
                return k
        return len(clauses) - 1

    def subject_at(k):
        for j in range(k, -1, -1):
            s = _subject(sent, *clauses[j], vocab)
            if s:
                return s
        return set()

    question = sent.masked.rstrip().endswith("?")
    if re.match(r"\s*\*\*Next:\*\*", sent.masked):
        return out                                   # navigation, not a statement
    # verdict words
    for cls, a, b in _verdict_mentions(sent):
        if cls in {"pass", "fail"} and not TEST_WORDS.search(sent.masked):
            continue                                 # 'where the linearisation fails': no test
        k = clause_at(a)
        ca, cb = clauses[k]
        ctext = sent.masked[ca:cb]
        why = ("exercise" if sent.exercise else "question" if question else
               "conditional" if CONDITIONAL.search(ctext) else "generic" if GENERIC.search(ctext)
               or GENERIC_SUBJECT.match(sent.masked) else "")
        if why:
            out.append(Finding(sent.cell, "verdict", cls, text, "skipped", f"not a result: {why}"))
            continue
        if NEGATION.search(sent.masked[max(ca, a - 30):a]):
            if cls not in FLIP:
                out.append(Finding(sent.cell, "verdict", cls, text, "skipped", "negated"))
                continue
            cls = FLIP[cls]
        subject = subject_at(k)
        support = set(SUPPORT[cls])
        if cls in {"inside", "outside"} and SHARE_QUALIFIER.search(sent.masked[ca:cb + 40]):
            support.add("share-inside")          # '... for over a third of the scans': a share
        out.append(_bind_verdict(sent, text, cls, support, subject, sw, vpool))
    # multipliers
    vt = QUOTED.sub(lambda m: " " * len(m.group(0)), sent.masked)
    for m in MULTIPLIER.finditer(vt):
        k = clause_at(m.start())
        ctext = sent.masked[clauses[k][0]:clauses[k][1]]
        if sent.exercise or question or CONDITIONAL.search(ctext):
            out.append(Finding(sent.cell, "times", m.group(0).strip(), text, "skipped", "not a result"))
            continue
        lo, hi = _multiplier_range(m)
        subject = subject_at(k)
        # 'X is N times the Y': X named before the phrase, Y after it
        xs = _subject(sent, clauses[k][0], m.start(), vocab)
        rest = sent.wtext[m.end():m.end() + 80]
        if re.match(r"\s*(?:the|as|its|their)\b", rest):         # 'N times the threshold'
            after = " ".join(re.findall(r"[\w'’-]+", rest)[:5])
        else:                                                    # 'N times further than Y'
            than = re.search(r"\bthan\b", rest)
            after = " ".join(re.findall(r"[\w'’-]+", rest[than.end():])[:4]) if than else ""
        ys = words(after) & vocab
        smaller = bool(re.match(r"\s*(?:smaller|less|fewer|lower|shorter|narrower|cheaper)\b",
                                sent.masked[m.end():]))
        if "factor" in m.group(0).lower():           # 'a factor of 7 in RMSE': either way round
            subject, xs, ys = subject | xs | ys, frozenset(), frozenset()
        out.append(_bind_times(sent, text, m.group(0).strip(), lo, hi, subject, sw, pool, xs, ys,
                               smaller))
    return out


def _bind_verdict(sent, text, cls, support, subject, sw, vpool) -> Finding:
    scored = [(c, _score(c, subject, sw)) for c in vpool if subject & c.words] if subject else []
    if scored:
        best = max(s for _, s in scored)
        if best > 0:
            top = [c for c, s in scored if s == best]
            got = set().union(*(c.verdicts for c in top))
            if cls == "all":
                # 'all of it': no printed line that names the subject may say otherwise
                bad = [c for c, _ in scored if c.verdicts & CONTRARY["all"]]
                if bad:
                    return Finding(sent.cell, "verdict", cls, text, "FLAG",
                                   f"'{cls}' but a printed line for {'/'.join(sorted(subject))} "
                                   f"says {'/'.join(sorted(bad[0].verdicts))}: {bad[0].text[:70]!r}")
            if got & support:
                return Finding(sent.cell, "verdict", cls, text, "bound")
            bad = got & CONTRARY[cls]
            if bad:
                return Finding(sent.cell, "verdict", cls, text, "FLAG",
                               f"'{cls}' but the printed line for {'/'.join(sorted(subject))} says "
                               f"{'/'.join(sorted(bad))}: {top[0].text[:70]!r}")
            # the best lines carry other verdicts: any line naming the quantity may support it
            if any(c.verdicts & support for c, s in scored if s > 0):
                return Finding(sent.cell, "verdict", cls, text, "bound")
            return Finding(sent.cell, "verdict", cls, text, "FLAG",
                           f"no printed '{cls}' for {'/'.join(sorted(subject))} in its section "
                           f"(nearest: {top[0].text[:70]!r})")
    if any(c.verdicts & support for c in vpool):
        return Finding(sent.cell, "verdict", cls, text, "fallback")
    return Finding(sent.cell, "verdict", cls, text, "FLAG",
                   f"no output of its section prints '{cls}'" + (
                       f" (nor a verdict for {'/'.join(sorted(subject))})" if subject else ""))


def _multiplier_range(m: re.Match) -> tuple[float, float]:
    g = [x for x in m.groups()[1:] if x]
    q = (m.group("q") or m.group("q2") or "").strip().lower()
    tok = next((x for x in g if x.lower() not in {"about", "around"} and not x.endswith(" ")), None)
    tok = (tok or "").lower().strip()
    if tok == "twice":
        lo, hi = 1.5, 2.5
    elif tok in RANGE_WORDS:
        lo, hi = RANGE_WORDS[tok]
    else:
        n = float(NUMBER_WORDS.get(tok, tok)) if tok in NUMBER_WORDS or re.fullmatch(
            r"\d+(?:\.\d+)?", tok) else None
        if n is None:
            return 0.0, math.inf
        if "and a half" in m.group(0):
            n += 0.5
        if "." in tok:
            half = 0.5 * 10 ** -len(tok.split(".")[1])
        else:
            digits = str(int(n)) if tok not in NUMBER_WORDS or n < 10 else str(int(n))
            zeros = len(digits) - len(digits.rstrip("0")) if n >= 10 else 0
            half = 0.5 * 10 ** zeros if zeros else 0.5
        lo, hi = n - half, n + half
    if q in {"over", "more than", "at least"}:
        hi = math.inf
    if q == "less than":
        lo = 0.0
    return lo, hi


def _bind_times(sent, text, what, lo, hi, subject, sw, pool, xs=frozenset(), ys=frozenset(),
                smaller=False) -> Finding:
    pool = [c for c in pool if not c.code]
    if xs and ys:
        # directed: a number printed as X over one printed as Y
        x = [(c, p) for c in pool for p in c.nums if xs & p.near and float(p.raw) > 0]
        y = [(c, p) for c in pool for p in c.nums if ys & p.near and float(p.raw) > 0]
        pairs = [(a, b, ca is cb) for ca, a in x for cb, b in y if a is not b and a.kind == b.kind]
        if any(same for *_, same in pairs):          # a pair printed in one clause says most
            pairs = [(a, b, same) for a, b, same in pairs if same]
        pairs = [(a, b) for a, b, _ in pairs]
        if pairs:
            for a, b in pairs:
                r = b.si / a.si if smaller else a.si / b.si
                if lo <= r <= hi:
                    return Finding(sent.cell, "times", what, text, "bound")
            return Finding(sent.cell, "times", what, text, "FLAG", bounds=(lo, hi), why=
                           f"'{what}' ({lo:g} to {hi:g}): no printed {'/'.join(sorted(xs))} is that "
                           f"multiple of a printed {'/'.join(sorted(ys))} in its section")

    def ratios(clauses, same_block):
        nums = [(c, p) for c in clauses for p in c.nums if float(p.raw) > 0]
        for c, p in nums:
            if p.ratio and lo <= float(p.raw) <= hi:
                return True
        for i, (c1, p1) in enumerate(nums):
            for c2, p2 in nums[i + 1:]:
                if same_block and c1.block != c2.block:
                    continue
                if p1.kind != p2.kind:
                    continue
                a, b = p1.si, p2.si
                r = max(a, b) / min(a, b)
                if lo <= r <= hi:
                    return True
        return False

    if subject:
        pos = [c for c in pool if subject & c.words]
        if pos:
            if ratios(pos, False):
                return Finding(sent.cell, "times", what, text, "bound")
            return Finding(sent.cell, "times", what, text, "FLAG", bounds=(lo, hi), why=
                           f"'{what}' ({lo:g} to {hi:g}): no two printed numbers of "
                           f"{'/'.join(sorted(subject))} in its section have that ratio")
    if ratios(pool, True):
        return Finding(sent.cell, "times", what, text, "fallback")
    return Finding(sent.cell, "times", what, text, "FLAG", bounds=(lo, hi), why=
                   f"'{what}' ({lo:g} to {hi:g}): no two numbers printed together in its section "
                   f"have that ratio")


# ---------------------------------------------------------------------------------------
# the whole check

def check(nb) -> list[Finding]:
    """Every checked statement of a notebook, with its outcome."""
    doc = parse(nb)
    numbers = [check_number(doc, s) for s in doc.stated]
    findings = list(numbers)
    for sent in doc.sentences:
        findings.extend(check_sentence(doc, sent))
    # '2.2 cm becomes 17.5 cm, about eight times': a multiplier between two numbers its own
    # sentence states, each evidenced, needs no third printed pair
    for f in findings:
        if f.kind != "times" or f.outcome != "FLAG" or not f.bounds:
            continue
        mine = [n.stated for n in numbers if n.sentence == f.sentence and n.outcome in
                {"bound", "fallback"} and not n.stated.bounds]
        for i, a in enumerate(mine):
            for b in mine[i + 1:]:
                ka, kb = UNITS.get(a.unit, (None, 1.0)), UNITS.get(b.unit, (None, 1.0))
                if ka[0] != kb[0] or not float(a.number) or not float(b.number):
                    continue
                x, y = float(a.number) * ka[1], float(b.number) * kb[1]
                if f.bounds[0] <= max(x, y) / min(x, y) <= f.bounds[1]:
                    f.outcome, f.why = "bound", "the ratio of two evidenced numbers it states"
    return findings


def unevidenced(path) -> list[Stated]:
    nb = nbformat.read(path, as_version=4)
    return [f.stated for f in check(nb) if f.kind == "number" and f.outcome == "FLAG"]
