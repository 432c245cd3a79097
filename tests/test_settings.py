"""The course's environment variables: ``annslam_lib._settings`` is the one module that reads
an ``ANNSLAM_*`` variable (an ast scan of every other module, shown to catch a planted read),
its table names every variable the course mentions, and each accessor returns what its
docstring says for a variable unset, set and empty."""
import ast
import os
import re
import sys
from pathlib import Path

import pytest

import annslam_lib
from annslam_lib import _settings

ROOT = Path(annslam_lib.__file__).parent
COURSE = ROOT.parent
PREFIX = "ANNSLAM_"
# course/confine.py runs as a script (python -I) of the standard library only, outside the
# package, before a submission's code runs: it reads the one variable meant for it itself.
EXEMPT = {"course/confine.py": {_settings.LIFELINE}}


def _is_name(node, known: set[str], local: set[str]) -> bool:
    """``node`` spells an ANNSLAM_* variable's name: a string or f-string starting with it,
    ``"ANNSLAM_" + x``, or a constant bound to one (``ENV_DIR``, ``fetch.ENV_DIR``,
    ``_settings.DATA``)."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str) and node.value.startswith(PREFIX)
    if isinstance(node, ast.JoinedStr):
        return bool(node.values) and _is_name(node.values[0], known, local)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return _is_name(node.left, known, local)
    if isinstance(node, ast.Name):
        return node.id in local
    if isinstance(node, ast.Attribute):
        return node.attr in known
    return False


def _bound_names(tree, known: set[str]) -> set[str]:
    """Module-level names bound to an ANNSLAM_* name, here or imported by name."""
    local: set[str] = set()
    for _ in range(3):                           # ENV = _settings.DATA; OTHER = ENV
        for node in tree.body:
            if isinstance(node, ast.Assign) and _is_name(node.value, known, local):
                local.update(t.id for t in node.targets if isinstance(t, ast.Name))
            elif isinstance(node, ast.ImportFrom):
                local.update(a.asname or a.name for a in node.names if a.name in known)
    return local


def _known(files) -> set[str]:
    """Every module-level name of the package bound to an ANNSLAM_* name."""
    known: set[str] = set()
    trees = [ast.parse(p.read_text()) for p in files]
    for _ in range(3):
        for tree in trees:
            known |= _bound_names(tree, known)
    return known


def _reads(path: Path, known: set[str]) -> list[tuple[int, str, str | None]]:
    """(line, source, the name if a literal) of each read of an ANNSLAM_* variable in
    ``path``: ``x[NAME]``, ``x.get(NAME)``, ``x.pop(NAME)``, ``x.setdefault(NAME)``,
    ``os.getenv(NAME)``, ``NAME in x``, whatever ``x`` is (an environment passed as a
    mapping is read too). Writes (``env[NAME] = v``, ``del env[NAME]``, a dict literal) are not reads."""
    text = path.read_text()
    tree = ast.parse(text)
    local = _bound_names(tree, known)
    found = []
    for n in ast.walk(tree):
        key = None
        if isinstance(n, ast.Subscript) and isinstance(n.ctx, ast.Load):
            key = n.slice
        elif isinstance(n, ast.Call) and n.args:
            f = n.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            key = n.args[0] if name in ("get", "pop", "setdefault", "getenv") else None
        elif isinstance(n, ast.Compare) and any(isinstance(op, (ast.In, ast.NotIn))
                                                for op in n.ops):
            key = n.left
        if key is not None and _is_name(key, known, local):
            literal = key.value if isinstance(key, ast.Constant) else None
            found.append((n.lineno, ast.get_source_segment(text, n), literal))
    return sorted(found)


def scan(root: Path) -> list[str]:
    """Every read of an ANNSLAM_* variable outside ``_settings.py`` (and the exemption)."""
    files = sorted(root.rglob("*.py"))
    known = _known(files)
    out = []
    for path in files:
        rel = path.relative_to(root).as_posix()
        if rel == "_settings.py":
            continue
        for line, src, literal in _reads(path, known):
            if literal not in EXEMPT.get(rel, set()):
                out.append(f"{rel}:{line}: {src}")
    return out


def test_only_settings_reads_an_annslam_variable():
    assert scan(ROOT) == []


def test_the_scan_finds_planted_reads(tmp_path):
    pkg = tmp_path / "annslam_lib"
    (pkg / "course").mkdir(parents=True)
    (pkg / "_settings.py").write_text('DATA = "ANNSLAM_DATA"\nimport os\nos.environ.get(DATA)\n')
    (pkg / "course" / "names.py").write_text('ENV_DIR = "ANNSLAM_HUB_DIR"\n')
    (pkg / "course" / "reads.py").write_text(
        "import os\n"
        "from .. import _settings\n"
        "from .names import ENV_DIR\n"
        "WORK = 'ANNSLAM_WORK'\n"
        "a = os.environ['ANNSLAM_CACHE']\n"                      # 5
        "b = os.environ.get('ANNSLAM_KERNEL', '')\n"
        "c = os.getenv('ANNSLAM_FEEDBACK')\n"
        "d = 'ANNSLAM_DATA_URL' in os.environ\n"
        "e = os.environ.get(f'ANNSLAM_HUB_{b}')\n"
        "f = os.environ.get(WORK)\n"                             # 10
        "g = os.environ.get(_settings.DATA)\n"
        "h = os.environ.get(ENV_DIR)\n"
        "def configure(env):\n"
        "    return env.get('ANNSLAM_HUB_PORT') or 8000\n"
        "i = int(os.environ.pop('ANNSLAM_LIFELINE', '-1'))\n"     # 15
        "j = os.environ.get('ANNSLAM_' + 'CACHE')\n"
        # writes and mentions, not reads:
        "os.environ['ANNSLAM_CACHE'] = 'off'\n"
        "env = {'ANNSLAM_DATA': '/d', **os.environ}\n"
        "del env['ANNSLAM_DATA']\n"
        "print('set ANNSLAM_CACHE=off', os.environ.get('HOME'))\n")
    found = scan(pkg)
    assert [int(f.split(":")[1]) for f in found] == [*range(5, 13), 14, 15, 16], found
    assert all(f.startswith("course/reads.py:") for f in found)
    # the exemption is one name in one file: confine.py reading another variable is caught
    (pkg / "course" / "confine.py").write_text(
        "import os\nx = os.environ.pop('ANNSLAM_LIFELINE', '-1')\n"
        "y = os.environ.get('ANNSLAM_KERNEL')\n")
    assert [f for f in scan(pkg) if f.startswith("course/confine.py")] == [
        "course/confine.py:3: os.environ.get('ANNSLAM_KERNEL')"]


def test_confine_reads_the_lifeline_by_the_settings_name():
    reads = _reads(ROOT / "course" / "confine.py", set())
    assert [(src, literal) for _, src, literal in reads] == [
        (f'os.environ.pop("{_settings.LIFELINE}", "-1")', _settings.LIFELINE)]


def _mentioned() -> dict[str, set[str]]:
    files = [*ROOT.rglob("*.py"), COURSE / "course.sh"]
    for folder in ("scripts", "hub", ".ci"):
        files += [p for p in (COURSE / folder).rglob("*") if p.is_file()]
    names: dict[str, set[str]] = {}
    for p in files:
        try:
            text = p.read_text()
        except UnicodeDecodeError:
            continue
        for name in re.findall(r"ANNSLAM_[A-Z0-9_]*", text):
            names.setdefault(name, set()).add(str(p.relative_to(COURSE)))
    return names


def test_every_variable_mentioned_is_in_the_table():
    mentioned = _mentioned()
    assert len(mentioned) >= 20
    missing = {}
    for name, where in mentioned.items():
        if name.endswith("_"):                   # a prefix: ANNSLAM_HUB_* names a group
            ok = any(v.startswith(name) for v in _settings.VARIABLES)
        else:
            ok = name in _settings.VARIABLES
        if not ok:
            missing[name] = sorted(where)
    assert missing == {}


def test_the_table_is_whole():
    constants = {v for k, v in vars(_settings).items()
                 if k.isupper() and isinstance(v, str) and v.startswith(PREFIX)}
    assert constants == set(_settings.VARIABLES)
    for name, row in _settings.VARIABLES.items():
        assert row.sets and row.default and row.read_by, name
    assert set(_settings.HUB_SETTINGS) <= set(_settings.VARIABLES)
    from annslam_lib.course.hub import config as hub_config
    assert list(hub_config.SETTINGS) == list(_settings.HUB_SETTINGS)
    assert len(hub_config.SETTINGS) == 8


def test_settings_imports_the_standard_library_only():
    tree = ast.parse((ROOT / "_settings.py").read_text())
    imported = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            imported |= {a.name.split(".")[0] for a in n.names}
        elif isinstance(n, ast.ImportFrom):
            assert n.level == 0, "imports the package"
            imported.add(n.module.split(".")[0])
    assert imported and imported <= set(sys.stdlib_module_names) | {"__future__"}, imported


# --- the accessors: unset, set, empty ---------------------------------------------------

@pytest.fixture
def clean(monkeypatch):
    for name in _settings.VARIABLES:
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def test_the_study_cache(clean, tmp_path):
    assert _settings.cache_off() is False and _settings.cache_folder() is None
    clean.setenv("ANNSLAM_CACHE", "")
    assert _settings.cache_off() is False and _settings.cache_folder() is None
    for off in ("off", "OFF", "Off"):
        clean.setenv("ANNSLAM_CACHE", off)
        assert _settings.cache_off() is True and _settings.cache_folder() is None
    clean.setenv("ANNSLAM_CACHE", " off")                  # not the word: a folder's name
    assert _settings.cache_off() is False and _settings.cache_folder() == Path(" off")
    clean.setenv("ANNSLAM_CACHE", str(tmp_path / "c"))
    assert _settings.cache_folder() == tmp_path / "c"
    clean.setenv("HOME", str(tmp_path))
    clean.setenv("ANNSLAM_CACHE", "~/studies")
    assert _settings.cache_folder() == tmp_path / "studies"


def test_the_class_cache_and_the_cache_layer(clean, tmp_path):
    from annslam_lib import _cache

    assert _settings.class_cache_folder() is None and _cache.class_cache_dir() is None
    clean.setenv("ANNSLAM_CLASS_CACHE", "")
    assert _settings.class_cache_folder() is None
    clean.setenv("ANNSLAM_CLASS_CACHE", str(tmp_path / "class"))
    assert _settings.class_cache_folder() == tmp_path / "class"
    assert _cache.class_cache_dir() == tmp_path / "class"
    clean.setenv("ANNSLAM_CACHE", "off")                   # off: the class's folder too
    assert _settings.class_cache_folder() == tmp_path / "class"
    assert _cache.class_cache_dir() is None and _cache.cache_dir() is None
    clean.setenv("ANNSLAM_CACHE", str(tmp_path / "own"))
    assert _cache.cache_dir() == tmp_path / "own"
    clean.delenv("ANNSLAM_CACHE")
    assert _cache.cache_dir().parts[-1] == "studies"


def test_the_data_folder_and_mirror(clean, tmp_path):
    from annslam_lib.data import fetch

    assert _settings.data_folder() is None and fetch.data_dir().parts[-1] == "data"
    assert _settings.is_set("ANNSLAM_DATA") is False
    clean.setenv("ANNSLAM_DATA", str(tmp_path))
    assert _settings.data_folder() == tmp_path == fetch.data_dir()
    assert _settings.is_set("ANNSLAM_DATA") is True
    for blank in ("", "  "):
        clean.setenv("ANNSLAM_DATA", blank)
        with pytest.raises(_settings.SetButEmpty, match=r"^\$ANNSLAM_DATA is set but empty$"):
            _settings.data_folder()
        with pytest.raises(fetch.DataError, match="set but empty. Unset it"):
            fetch.data_dir()
    assert issubclass(_settings.SetButEmpty, ValueError)
    assert _settings.data_url() is None
    clean.setenv("ANNSLAM_DATA_URL", "")
    assert _settings.data_url() is None
    clean.setenv("ANNSLAM_DATA_URL", "file:///mirror/")
    assert _settings.data_url() == "file:///mirror/"
    entry = fetch.registry.get("victoria_park")
    first = entry.files[0].name
    assert fetch.url("victoria_park", first) == f"file:///mirror/{entry.folder}/{first}"


def test_feedback_and_kernel(clean):
    assert _settings.full_feedback() is False
    for value, full in (("", False), ("full", True), ("FULL", False), (" full", False),
                        ("short", False)):
        clean.setenv("ANNSLAM_FEEDBACK", value)
        assert _settings.full_feedback() is full, value
    assert _settings.kernel() == "auto"
    for value, got in (("", "auto"), ("auto", "auto"), (" Numpy ", "numpy"), ("NUMPY", "numpy")):
        clean.setenv("ANNSLAM_KERNEL", value)
        assert _settings.kernel() == got, value
    clean.setenv("ANNSLAM_KERNEL", "off")
    with pytest.raises(ValueError, match=r"ANNSLAM_KERNEL must be 'numpy' \(the numpy gating "
                       r"only\) or 'auto' \(or unset\), got 'off'$"):
        _settings.kernel()


def test_the_work_folder(clean, tmp_path, monkeypatch):
    assert _settings.work_folder() is None
    clean.setenv("ANNSLAM_WORK", " ")
    with pytest.raises(ValueError, match="^ANNSLAM_WORK is set but empty: unset it or name"):
        _settings.work_folder()
    monkeypatch.chdir(tmp_path)
    clean.setenv("ANNSLAM_WORK", "w")                      # relative: made absolute
    assert _settings.work_folder() == tmp_path.resolve() / "w"


def test_the_hub_settings(clean, tmp_path):
    assert _settings.hub_dir() is None and _settings.hub_class() is None
    assert _settings.hub_instructor() == "instructor"
    assert _settings.hub_port() == 8000 and isinstance(_settings.hub_port(), int)
    assert _settings.hub_password() == "" and _settings.hub_instructor_password() == ""
    assert _settings.hub_admin_token() is None and _settings.hub_python() is None
    empty = dict.fromkeys(_settings.HUB_SETTINGS + (_settings.HUB_PYTHON,), "")
    assert (_settings.hub_dir(empty), _settings.hub_class(empty), _settings.hub_instructor(empty),
            _settings.hub_port(empty), _settings.hub_password(empty),
            _settings.hub_admin_token(empty), _settings.hub_python(empty)) == (
        None, None, "instructor", 8000, "", None, None)
    given = {"ANNSLAM_HUB_DIR": "hubdir", "ANNSLAM_HUB_CLASS": str(tmp_path / "class.txt"),
             "ANNSLAM_HUB_INSTRUCTOR": "prof", "ANNSLAM_HUB_PORT": "8123",
             "ANNSLAM_HUB_PASSWORD": "p" * 8, "ANNSLAM_HUB_INSTRUCTOR_PASSWORD": "i" * 32,
             "ANNSLAM_HUB_ADMIN_TOKEN": "t" * 40, "ANNSLAM_HUB_PYTHON": "/usr/bin/python3.11"}
    for env in (given, None):                  # a mapping given, then this process's own
        if env is None:
            for k, v in given.items():
                clean.setenv(k, v)
        assert _settings.hub_dir(env) == Path("hubdir")          # as given, not resolved
        assert _settings.hub_class(env) == tmp_path / "class.txt"
        assert _settings.hub_instructor(env) == "prof"
        assert _settings.hub_port(env) == 8123
        assert _settings.hub_password(env) == "p" * 8
        assert _settings.hub_instructor_password(env) == "i" * 32
        assert _settings.hub_admin_token(env) == "t" * 40
        assert _settings.hub_python(env) == Path("/usr/bin/python3.11")
    with pytest.raises(ValueError, match="invalid literal for int"):
        _settings.hub_port({"ANNSLAM_HUB_PORT": "eighty"})
    from annslam_lib.course import hub
    assert hub.HubLayout.from_env().root == Path("hubdir").resolve()
    clean.delenv("ANNSLAM_HUB_DIR")
    assert hub.HubLayout.from_env().root == Path("/srv/annslam-hub").resolve()


def test_read_at_call_time_and_put_back(clean, tmp_path):
    clean.setenv("ANNSLAM_HUB_PORT", "9000")
    assert _settings.hub_port() == 9000
    clean.setenv("ANNSLAM_HUB_PORT", "9100")
    assert _settings.hub_port() == 9100
    with _settings.temporarily("ANNSLAM_DATA", str(tmp_path)):
        assert _settings.data_folder() == tmp_path
    assert _settings.data_folder() is None and "ANNSLAM_DATA" not in os.environ
    clean.setenv("ANNSLAM_DATA", "/before")
    with pytest.raises(KeyError):
        with _settings.temporarily("ANNSLAM_DATA", str(tmp_path)):
            raise KeyError("inside")
    assert _settings.data_folder() == Path("/before")
