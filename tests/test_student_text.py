"""What students read speaks to students: no development internals in the text or the printed
output of any chapter, and every library name the text gives resolves to something that
exists."""
import ast
import importlib
import importlib.util
import pkgutil
import re
from pathlib import Path
from types import ModuleType

import pytest

import annslam_lib
from annslam_lib.course import release

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))

#: Development internals a student has no use for: the test suite, CI, the notebook-test
#: machinery, the compiler behind the fast gating, the study cache's mechanics, the tracker.
INTERNALS = re.compile(
    r"\btests?/|\btest_\w+\.py|\bbenchmarks?/|(?<!% )\bCI\b|\.ci/|\bnbval\b|\bpytest\b"
    r"|\bnbclient\b|\bconftest\b|\bnumba\b|\bcompiled\b|\b_cache\b|\bstudy cache\b"
    r"|\bissue \d+|\bstop \d+\b|\bcommit [0-9a-f]{7}", re.I)
#: nbval's own output markers stay: nbgrader's generate_assignment keeps them too.
NBVAL_MARKER = re.compile(r"^\s*# NBVAL_\w+\s*$", re.M)

_NAME = re.compile(r"`([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?:\([^`]*\))?`")
#: A dotted name in running text: not the tail of a longer one (``IPython.core.display``),
#: not a pattern (``two_point_*``, an f-string's ``{...}``).
_BARE = re.compile(r"(?<![\w.])([a-z_]\w*(?:\.[A-Za-z_]\w*)+)(?![\w{*])")
_WORD = re.compile(r"`([a-z]\w*_\w*)(?:\([^`]*\))?`")
_FILE_SUFFIXES = {"py", "ipynb", "md", "txt", "csv", "json", "toml", "sh", "mat", "gz", "zip",
                  "npz", "png", "svg", "yaml", "yml", "cfg", "pdf", "html", "tex"}


def student_texts(path):
    """(cell index, kind, text) of everything a student reads in a chapter: the student
    version's markdown and code, and the printed output of the cells that are neither
    solutions nor tests (the outputs a student sees, and the site shows)."""
    nb = release.read_notebook(path)
    st = release.student_version(nb, path.stem)
    for i, (cell, mine) in enumerate(zip(nb.cells, st.cells)):
        yield i, cell.cell_type, NBVAL_MARKER.sub("", mine.source)
        meta = cell.metadata.get("nbgrader", {})
        if cell.cell_type == "code" and not meta.get("solution") and not meta.get("grade"):
            for out in cell.get("outputs", []):
                text = out.get("text") or out.get("data", {}).get("text/plain", "")
                yield i, "output", "".join(text)


def internals(text):
    """The development internals named in ``text``."""
    return [m.group(0) for m in INTERNALS.finditer(text)]


def _library_modules():
    found = {"annslam_lib": ["annslam_lib"]}
    for m in pkgutil.walk_packages(annslam_lib.__path__, "annslam_lib."):
        found.setdefault(m.name.rsplit(".", 1)[1], []).append(m.name)
    return found


MODULES = _library_modules()


def _loaded():
    """(name, module) of every library module that imports here."""
    for mods in MODULES.values():
        for mod in mods:
            try:
                yield mod, importlib.import_module(mod)
            except ImportError:
                continue


def _library_words():
    """Every top-level name, class attribute, dataclass field and identifier-like string
    constant of the library (a feature name such as ``lm_x``)."""
    words = set()
    for _, m in _loaded():
        words |= {k for k, v in vars(m).items() if not isinstance(v, ModuleType)}
        for v in vars(m).values():
            if isinstance(v, type):
                words |= set(vars(v)) | set(getattr(v, "__dataclass_fields__", {}))
        if getattr(m, "__file__", None):
            tree = ast.parse(Path(m.__file__).read_text())
            words |= {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
                      and isinstance(n.value, str) and n.value.isidentifier()}
    return words


WORDS = _library_words()


def _chain(obj, parts):
    for p in parts:
        if not hasattr(obj, p):
            if isinstance(obj, ModuleType):
                try:
                    obj = importlib.import_module(f"{obj.__name__}.{p}")
                    continue
                except ImportError:
                    return False
            fields = getattr(obj, "__dataclass_fields__", {})
            if p in fields:
                return True
            return False
        obj = getattr(obj, p)
    return True


def notebook_names(path):
    """What the notebook's own code binds: {alias: module name} for imports, and the set of
    every other name it assigns (variables, functions, loop targets)."""
    nb = release.read_notebook(path)
    imports, assigned = {}, set()
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        try:
            tree = ast.parse(NBVAL_MARKER.sub("", cell.source).replace("%matplotlib", "#"))
        except SyntaxError:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    imports[a.asname or a.name.split(".")[0]] = a.name if a.asname else \
                        a.name.split(".")[0]
            elif isinstance(node, ast.ImportFrom) and node.module:
                for a in node.names:
                    imports[a.asname or a.name] = f"{node.module}.{a.name}"
            elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                assigned.add(node.id)
            elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                assigned.add(node.name)
            elif isinstance(node, ast.arg):
                assigned.add(node.arg)
    return imports, assigned


def _exported(name):
    """The library's classes called ``name`` (such as SlamConfig), where they are defined."""
    for mod, m in _loaded():
        obj = vars(m).get(name)
        if isinstance(obj, type) and obj.__module__ == mod:
            yield obj


def unresolved(dotted, imports, assigned):
    """Why ``dotted`` (as the text writes it) names nothing that exists, or None."""
    head, *rest = dotted.split(".")
    if rest and rest[-1] in _FILE_SUFFIXES:
        return None                                  # a file name
    if head in imports:
        target = imports[head]
        if not target.startswith("annslam_lib"):
            return None                              # numpy, scipy, torch, ...
        try:
            obj = importlib.import_module(target)
        except ImportError:
            mod, _, attr = target.rpartition(".")
            obj = getattr(importlib.import_module(mod), attr)
        return None if _chain(obj, rest) else f"{target} has no {'.'.join(rest)}"
    if head in assigned:
        return None                                  # a variable of the notebook
    if head not in MODULES and importlib.util.find_spec(head) is not None:
        return None                                  # another package (scipy.stats)
    if head in MODULES:
        for mod in MODULES[head]:
            if _chain(importlib.import_module(mod), rest):
                return None
        return f"no {' or '.join(MODULES[head])} holds {'.'.join(rest)}"
    for obj in _exported(head):
        if _chain(obj, rest):
            return None
    return f"{head!r} is neither a library module nor a name the notebook defines"


def unknown_word(word, imports, assigned):
    """Why ``word`` (one name in backticks, with an underscore: what a library function,
    module or field looks like) names nothing the notebook or the library has, or None."""
    if word in imports or word in assigned or word in MODULES or word in WORDS:
        return None
    return f"{word!r} is no library name and no name the notebook defines"


def library_names(kind, text):
    """Dotted names a text gives: in markdown and code, the ones in backticks; in printed
    output, those whose head is a library module."""
    if kind == "output":
        for m in _BARE.finditer(text):
            if m.group(1).split(".")[0] in MODULES:
                yield m.group(1)
    elif kind == "markdown":
        for m in _NAME.finditer(text):
            yield m.group(1)
    else:
        for m in re.finditer(r"#.*", text):         # names in code comments and strings
            yield from (n.group(1) for n in _NAME.finditer(m.group(0)))
        for m in re.finditer(r"(['\"])(.*?)\1", text):
            for n in _BARE.finditer(m.group(2)):
                if n.group(1).split(".")[0] in MODULES:
                    yield n.group(1)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_no_development_internals_in_what_students_read(path):
    found = [f"cell {i} ({kind}): {hit!r}" for i, kind, text in student_texts(path)
             for hit in internals(text)]
    assert not found, f"{path.name} names development internals:\n" + "\n".join(found)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_library_name_in_the_text_resolves(path):
    imports, assigned = notebook_names(path)
    found = []
    for i, kind, text in student_texts(path):
        for name in library_names(kind, text):
            why = unresolved(name, imports, assigned)
            if why:
                found.append(f"cell {i} ({kind}): `{name}`: {why}")
        if kind == "markdown":
            for m in _WORD.finditer(text):
                why = unknown_word(m.group(1), imports, assigned)
                if why:
                    found.append(f"cell {i} ({kind}): `{m.group(1)}`: {why}")
    assert not found, f"{path.name} names library code that does not exist:\n" + \
        "\n".join(found)


def test_the_checks_catch_planted_internals_and_stale_names():
    planted = ("The test suite checks it (`tests/test_dead_reckoning.py`); on CI the "
               "gating runs compiled with numba, read from the study cache.")
    assert internals(planted) == ["tests/", "test_dead_reckoning.py", "CI", "compiled",
                                  "numba", "study cache"]
    assert internals("the difference is +0.1 (95 % CI -0.2 .. 0.4)") == []
    imports = {"motion": "annslam_lib.models.motion", "np": "numpy"}
    assert unresolved("motion.laser_velocity", imports, set()) is None
    assert "has no laser_speed" in unresolved("motion.laser_speed", imports, set())
    assert "holds laser_velocity" in unresolved("kinematics.laser_velocity", {}, set())
    assert "neither" in unresolved("ekf_dense.augment_landmark", {}, set())
    assert unresolved("dense.augment_landmark", {}, set()) is None
    assert "no library name" in unknown_word("ekf_dense", {}, set())
    assert unknown_word("joseph_covariance", {}, set()) is None
    assert unknown_word("lm_x", {}, set()) is None                 # a feature's name
    assert unresolved("SlamConfig.for_dataset", {}, set()) is None
    assert unresolved("np.linalg.nope", imports, set()) is None      # not ours to check
    assert list(library_names("output", "SymPy = kinematics.laser_velocity on 2000 states")) \
        == ["kinematics.laser_velocity"]


HEADING = re.compile(r"^#+ .*\bExercise\b.*$|\*\*Exercise\b.*?\*\*", re.M)
FORM = re.compile(r"^### Exercise (?P<ch>\w+)\.(?P<k>\d+): \S.* \((?:\d+ points|1 point|not graded)\)$")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_exercise_headings_have_one_form_and_run_in_order(path):
    """``### Exercise <chapter>.<k>: <title> (<n> points | not graded)``, numbered 1, 2, ...
    in the chapter's order, graded or not; and one ``chapter.setup()`` per chapter."""
    nb = release.read_notebook(path)
    chapter = path.stem.split("_")[0].lstrip("0") or "0"
    heads = [m.group(0) for c in nb.cells if c.cell_type == "markdown"
             for m in HEADING.finditer(c.source)]
    bad = [h for h in heads if not FORM.match(h)]
    assert not bad, f"{path.name}: exercise headings not in the course's form: {bad}"
    numbers = [(FORM.match(h)["ch"], int(FORM.match(h)["k"])) for h in heads]
    assert numbers == [(chapter, k) for k in range(1, len(heads) + 1)], \
        f"{path.name}: exercises numbered {numbers}"
    setups = sum(len(re.findall(r"^chapter\.setup\(", c.source, re.M))
                 for c in nb.cells if c.cell_type == "code")
    assert setups == 1, f"{path.name} calls chapter.setup() {setups} times"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_ungraded_exercise_is_followed_by_its_answer_tagged_as_one(path):
    """The written answer or discussion of an ungraded exercise is the next text cell after
    its solution cell, tagged as the answer, so that the student version holds the stub
    instead (an untagged answer ships to students)."""
    from annslam_lib.course import pacing

    nb = release.read_notebook(path)
    ungraded = set(pacing._ungraded(nb))
    for i, cell in enumerate(nb.cells):
        gid = cell.metadata.get("nbgrader", {}).get("grade_id")
        if gid not in ungraded:
            continue
        after = next((c for c in nb.cells[i + 1:] if c.cell_type == "markdown"), None)
        assert after is not None and release.ANSWER_TAG in after.metadata.get("tags", []), \
            f"{path.name}: the text after {gid} is not tagged {release.ANSWER_TAG!r}"
        assert after.source.lstrip().startswith("<details>"), \
            f"{path.name}: the answer to {gid} is not in a closed <details> box"
