"""Copied-code detection for the grader: how alike two solutions are once the
names a student chooses, the constants and the formatting are taken away.

A solution is reduced to its syntax tree (:func:`normalised`): the sequence of node types
in the order the tree is walked, with every variable, argument and function name replaced
by its order of first use (``v0``, ``v1``...) and every constant by its type. Attribute
names (``np.linalg.svd``, ``.T``) are kept: they are the API a solution calls, not names a
student picks, and they are what tells two honest solutions of one algorithm apart.
Comments, docstrings, blank lines and layout never reach the tree. Two solutions are
compared by :func:`similarity`, the share of matching tokens (``difflib``'s ratio, 0 to 1).

:func:`flag_copies` compares each student's solution with the library's reference and with
every other student's of the batch, and returns a :class:`Flag` for each pair at or above
the threshold: with the similarity and the matching source. A flag is for the instructor
to read, never a score: short solutions of one textbook algorithm can look alike.
"""
from __future__ import annotations

import ast
import difflib
import textwrap
from dataclasses import dataclass

__all__ = ["THRESHOLD", "Flag", "normalised", "similarity", "flag_copies"]

#: Similarity at or above which a pair is flagged (measured in tests/test_similarity.py on
#: chapter 08's rigid alignment: a renamed copy of the library scores 1.0, a reformatted one
#: with a statement split in two 0.985, two honest solutions 0.37 and 0.55 against the
#: library and 0.44 against each other).
THRESHOLD = 0.9


@dataclass(frozen=True)
class Flag:
    """A pair of solutions that look copied: ``student``'s solution against ``other`` (a
    student of the batch, or ``library: <name>``), their similarity, and the other source."""

    student: str
    other: str
    similarity: float
    other_source: str

    def as_json(self) -> dict:
        return {"student": self.student, "other": self.other,
                "similarity": round(self.similarity, 3), "other_source": self.other_source}


def _tree(source: str, function: str | None) -> ast.AST:
    if not isinstance(source, str):
        raise TypeError(f"source must be a str, got {type(source).__name__}")
    try:
        tree = ast.parse(textwrap.dedent(source))
    except SyntaxError as e:
        raise ValueError(f"the solution is not valid Python: {e.msg} (line {e.lineno})") from None
    if function is None:
        return tree
    found = [n for n in ast.walk(tree)
             if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name == function]
    if not found:
        raise ValueError(f"no function {function!r} in the solution")
    return found[0]


def _is_docstring(node: ast.AST) -> bool:
    return (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str))


def normalised(source: str, function: str | None = None) -> tuple[str, ...]:
    """The token sequence of ``source`` (or of its function ``function``) described in the
    module docstring. Raises ValueError for code that does not parse or lacks ``function``."""
    names: dict[str, str] = {}
    out: list[str] = []

    def name(n: str) -> str:
        return names.setdefault(n, f"v{len(names)}")

    def visit(node: ast.AST) -> None:
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and _is_docstring(body[0]):
            body = body[1:]
        out.append(type(node).__name__)
        if isinstance(node, ast.Name):
            out.append(name(node.id))
        elif isinstance(node, ast.arg):
            out.append(name(node.arg))
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.append(name(node.name))
        elif isinstance(node, ast.Attribute):
            out.append("." + node.attr)
        elif isinstance(node, ast.Constant):
            out.append(type(node.value).__name__)
        for field, value in ast.iter_fields(node):
            if field == "body" and body is not None:
                value = body
            if isinstance(value, list):
                for item in value:
                    if isinstance(item, ast.AST):
                        visit(item)
            elif isinstance(value, ast.AST):
                visit(value)

    visit(_tree(source, function))
    return tuple(out)


def similarity(a: str, b: str, function: str | None = None) -> float:
    """Similarity (0 to 1) of two solutions' :func:`normalised` token sequences."""
    ta, tb = normalised(a, function), normalised(b, function)
    return difflib.SequenceMatcher(None, ta, tb, autojunk=False).ratio()


def flag_copies(solutions: dict[str, str], references: dict[str, str] | None = None, *,
                function: str | None = None, threshold: float = THRESHOLD) -> list[Flag]:
    """Flags for one exercise: ``solutions`` {student: source}, ``references`` {name: source}
    (the library's implementations of the same function). Each student is compared with each
    reference and with each other student (a shared pair is flagged once, under the first
    student in sorted order). A solution that does not parse is skipped: grading reports it.
    Flags are sorted by similarity, highest first."""
    if not 0.0 < float(threshold) <= 1.0:
        raise ValueError(f"threshold must lie in (0, 1], got {threshold!r}")
    sources = {**{f"library: {k}": v for k, v in (references or {}).items()}, **solutions}
    tokens = {}
    for who, src in sources.items():
        try:
            tokens[who] = normalised(src, function)
        except ValueError:
            continue
    students = sorted(s for s in solutions if s in tokens)
    refs = [r for r in tokens if r.startswith("library: ")]
    flags = []
    for i, s in enumerate(students):
        for other in refs + students[i + 1:]:
            r = difflib.SequenceMatcher(None, tokens[s], tokens[other], autojunk=False).ratio()
            if r >= threshold:
                flags.append(Flag(s, other, r, sources[other]))
    return sorted(flags, key=lambda f: -f.similarity)
