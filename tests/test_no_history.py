"""No development history in the product: the course's files say what the code does and why,
never how it came to be. A trace of history is one of

- an issue or pull-request reference: "issue 23", "issues 12 and 23", "(#23)", "fixes #23";
- a work session's name: "stop 37", "this session", "last round", "round 4";
- a review's item: "finding 5";
- a commit hash: seven to forty lower-case hex digits with at least one digit and one letter;
- a date: "2026-12-03";
- the machine the course is developed on: "one process, this machine;", "2.0 s CPU on this
  machine", "measured on this machine", "the development machine".

The patterns are narrow on purpose, so that the words' other meanings pass: JupyterHub's and
pytest's sessions ("a student's browser session", "one cache per test session"), grading cases
named "#0: ...", colours "#CC79A7", a SHA-256 digest (64 hex digits, too long to be a commit),
a paper's year, and "this machine" meaning the machine a command runs on ("an existing
account of this machine", "no Python interpreter on this machine").

What the patterns cannot tell apart is in ALLOWED, each with its reason, and the commits the
data are pinned to are read from the data registry (PINNED). History belongs in the CHANGELOG
(and its ``changelog.d`` fragments) and in git's log, which are not scanned; nor are vendored
third-party files (``vendor/``).

Scanned: every file git tracks, and every new file it does not ignore, with a text suffix
(SUFFIXES) or no suffix (scripts, Dockerfile); of a notebook, the sources of its markdown and
code cells, not its outputs. Each file is its own test case, so a failure names the file and
lists its lines.
"""
import json
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SELF = Path(__file__).resolve().relative_to(ROOT).as_posix()

SUFFIXES = {".py", ".md", ".toml", ".cfg", ".txt", ".sh", ".yml", ".yaml", ".json", ".ipynb",
            ".cff"}

# (name, pattern): a hit is a trace of history unless ALLOWED says otherwise.
PATTERNS = [
    ("issue", re.compile(r"\bissues?\s*#?\d+", re.I)),
    ("issue", re.compile(r"\((?:#\d+(?:,\s*)?)+\)|\b(?:pr|pull request|issue|ticket|bug|fix(?:es|ed)?"
                         r"|close[sd]?|resolve[sd]?|see)\s+#\d+\b", re.I)),
    ("session", re.compile(r"\bstops?\s*#?\d+\b", re.I)),
    ("session", re.compile(r"\b(?:this|last|previous|earlier|next|that) (?:work(?:ing)? |"
                           r"development |dev )?(?:session|round)\b", re.I)),
    ("session", re.compile(r"\b(?:session|round)\s*#?\d+\b", re.I)),
    ("review", re.compile(r"\bfinding\s*#?\d+\b", re.I)),
    ("commit", re.compile(r"\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b")),
    ("date", re.compile(r"\b20\d\d-[01]\d-[0-3]\d\b")),
    ("machine", re.compile(r"\b(?:development|developer'?s?|dev) machine\b|\bthe machine the "
                           r"course is (?:developed|built|written|made) on\b", re.I)),
    ("machine", re.compile(r"[,(;]\s*this machine\s*[;,)]", re.I)),
    ("machine", re.compile(r"(?:\d\s*(?:s|ms|us|µs|cpu-?s|seconds?|minutes?)\b|\bcpu\b|\bmeasured\b"
                           r"|\btimed\b|\bbenchmarked\b)[^.;\n]{0,40}\b(?:on|of|with) this "
                           r"machine\b", re.I)),
]


def _pinned_commits() -> set[str]:
    """The commits of the third-party repositories the data are downloaded from
    (``annslam_lib/data/registry.py``): a pin of what is fetched, not this project's history."""
    text = (ROOT / "annslam_lib" / "data" / "registry.py").read_text()
    return set(re.findall(r'_COMMIT\b[^\n]*?"([0-9a-f]{40})"', text))


PINNED = _pinned_commits()

# (file glob, pattern name, regex on the hit's line, reason): what a pattern cannot tell
# apart. Besides these, a "commit" hit that is a prefix of a PINNED commit passes anywhere.
ALLOWED = [
    ("CITATION.cff", "date", r"^date-released:", "the release date is the citation's metadata"),
]


def _allowed(path: str, name: str, line: str, hit: str) -> bool:
    if name == "commit" and any(pin.startswith(hit) for pin in PINNED):
        return True
    return any(pname == name and Path(path).match(glob) and re.search(rx, line)
               for glob, pname, rx, _ in ALLOWED)


def _lines(path: Path):
    """(where, text) of each line of ``path`` that is read: of a notebook, the sources of its
    cells ("cell 3 line 2"), not its outputs."""
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".ipynb":
        for k, cell in enumerate(json.loads(text)["cells"]):
            src = cell["source"] if isinstance(cell["source"], str) else "".join(cell["source"])
            for j, line in enumerate(src.splitlines(), 1):
                yield f"cell {k} line {j}", line
    else:
        for j, line in enumerate(text.splitlines(), 1):
            yield str(j), line


def scan(path: Path, rel: str | None = None) -> list[str]:
    """Every trace of history in the file at ``path`` as 'rel:where: [pattern] line'."""
    rel = rel or path.name
    found = []
    for where, line in _lines(path):
        for name, rx in PATTERNS:
            hits = [m.group(0) for m in rx.finditer(line)]
            if any(not _allowed(rel, name, line, h) for h in hits):
                found.append(f"{rel}:{where}: [{name}] {line.strip()[:160]}")
                break
    return found


def _excluded(rel: str) -> bool:
    """Not scanned: this file (its examples are history), the CHANGELOG and its fragments
    (history is their job), and vendored third-party files (``vendor/`` folders: not the
    course's words; a schema's examples hold dates and hashes)."""
    name = Path(rel).name
    return (rel == SELF or name.upper().startswith("CHANGELOG")
            or rel.startswith("changelog.d/") or "vendor" in Path(rel).parts)


def _files() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return []
    files = set()
    for rel in out.splitlines():
        p = ROOT / rel
        if _excluded(rel) or not p.is_file():
            continue
        if p.suffix in SUFFIXES or p.suffix == "":
            files.add(rel)
    return sorted(files)


FILES = _files()


def check(path: Path, rel: str) -> None:
    """Fail, listing file:line, if the file at ``path`` holds a trace of history."""
    found = scan(path, rel)
    assert not found, ("development history (say what the code does and why; history goes to "
                       "the CHANGELOG):\n" + "\n".join(found))


@pytest.mark.skipif(not FILES, reason="not a git checkout: nothing to list")
@pytest.mark.parametrize("rel", FILES)
def test_no_history(rel):
    try:
        check(ROOT / rel, rel)
    except UnicodeDecodeError:
        pytest.skip(f"{rel} is not UTF-8 text")


def test_the_data_pins_are_read():
    """The allowed commits are found in the registry (else its layout changed)."""
    assert len(PINNED) >= 3 and all(len(c) == 40 for c in PINNED)


@pytest.mark.parametrize("text", [
    "A robust fit (issue 12).",
    "targets of issues 12 and 23",
    "fixed in (#23)",
    "as decided at stop 37",
    "as measured this session",
    "see 7c540a8 for the old code",
    "measured 2026-12-03",
    "0.022 s (one process, this machine; a benchmark)",
    "2.0 s CPU on this machine",
    "Finding 5 of the review",
])
def test_the_scanner_finds_planted_history(tmp_path, text):
    for name, body in [("planted.py", f'"""Doc.\n\n{text}\n"""\n'),
                       ("planted.ipynb", json.dumps({"cells": [
                           {"cell_type": "markdown", "source": ["# Title\n", text]}]}))]:
        path = tmp_path / name
        path.write_text(body)
        found = scan(path, name)
        assert len(found) == 1 and text.strip() in found[0], (name, found)


@pytest.mark.parametrize("text", [
    "One student's browser session at the hub.",
    "one study cache per test session",
    "case '#0: N = 6 landmarks'",
    'PURPLE = "#CC79A7"',
    "bc03c2f7ff2735a013fd7e7538de3e3b015f216d1074dc5c27747efdf6409371  3212106 Robot1.dat",
    "The 2013 paper the course reproduces",
    "an existing account of this machine that the course did not make",
    "CPU seconds: this machine's, not a result",
    "print(round(x, 3))",
])
def test_the_scanner_passes_other_meanings(tmp_path, text):
    path = tmp_path / "clean.py"
    path.write_text(text + "\n")
    assert scan(path, "clean.py") == []


def test_a_planted_file_fails_the_file_test(tmp_path):
    """The per-file check fails on a file with "issue 12", naming the file and line."""
    path = tmp_path / "module.py"
    path.write_text('x = 1\n"""A robust fit (issue 12)."""\n')
    assert scan(path, "pkg/module.py") == [
        'pkg/module.py:2: [issue] """A robust fit (issue 12)."""']
    with pytest.raises(AssertionError, match=r"pkg/module\.py:2: \[issue\]"):
        check(path, "pkg/module.py")
