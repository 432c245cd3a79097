"""The study cache (annslam_lib._cache): a cached study is the study, and a cache that is
wrong, torn, foreign or stale is never believed."""
import dataclasses
import os
import warnings

import numpy as np
import pytest

from annslam_lib import _cache
from annslam_lib.evaluation import consistency


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "studies"
    monkeypatch.setenv("ANNSLAM_CACHE", str(folder))
    monkeypatch.setattr(_cache, "STATS", dict.fromkeys(_cache.STATS, 0))
    return folder


CALLS = []


@_cache.memoize
def _square_sum(a, *, scale=1.0):
    CALLS.append(1)
    return float(np.sum(np.asarray(a) ** 2) * scale)


def test_a_cached_monte_carlo_is_the_one_computed_now(cache):
    """The real study of notebook 05 (3 runs): computed, stored, read back, and equal in every
    number to a computation without the cache."""
    first = consistency.monte_carlo(range(100, 103), "midpoint")
    again = consistency.monte_carlo(range(100, 103), "midpoint")
    assert _cache.STATS["misses"] == 1 and _cache.STATS["hits"] == 1
    fresh = consistency.monte_carlo.uncached(range(100, 103), "midpoint")
    for got in (first, again):
        for part in ("nees", "nis"):
            a, b = getattr(got, part), getattr(fresh, part)
            np.testing.assert_array_equal(a.mean, b.mean)
            np.testing.assert_array_equal(a.inside, b.inside)
        assert got.mapped == fresh.mapped
        np.testing.assert_array_equal(got.map.runs, fresh.map.runs)
        assert got.map.per_dof == fresh.map.per_dof
    assert len(list(cache.glob("monte_carlo-*.pkl"))) == 1


def test_another_argument_or_another_code_is_another_entry(cache, monkeypatch):
    CALLS.clear()
    assert _square_sum([1, 2]) == 5.0
    assert _square_sum([1, 2]) == 5.0                      # hit
    assert _square_sum([1, 3]) == 10.0                     # another argument
    assert _square_sum([1, 2], scale=2.0) == 10.0          # another keyword
    assert _square_sum(np.array([1, 2])) == 5.0            # an array is not a list
    assert len(CALLS) == 4
    _cache.code_hash.cache_clear()
    monkeypatch.setattr(_cache, "code_hash", lambda: "another version of the library")
    assert _square_sum([1, 2]) == 5.0
    assert len(CALLS) == 5, "an entry of other code was reused"
    monkeypatch.setenv("OMP_NUM_THREADS", "7")
    assert _square_sum([1, 2]) == 5.0
    assert len(CALLS) == 6, "an entry of another BLAS thread count was reused"


def test_the_same_call_written_another_way_is_the_same_entry(cache):
    CALLS.clear()
    assert _square_sum([1, 2]) == 5.0
    assert _square_sum(a=[1, 2]) == 5.0                    # named
    assert _square_sum([1, 2], scale=1.0) == 5.0           # the default spelled out
    assert len(CALLS) == 1 and len(list(cache.glob("*.pkl"))) == 1
    with pytest.raises(TypeError):                          # a wrong call is fn's to refuse
        _square_sum([1, 2], 3.0)


def test_content_not_identity_makes_the_key():
    @dataclasses.dataclass
    class Box:
        x: np.ndarray
        name: str

    k = _cache.key_of(_square_sum, (Box(np.arange(3.0), "a"),), {})
    assert k == _cache.key_of(_square_sum, (Box(np.arange(3.0), "a"),), {})
    assert k != _cache.key_of(_square_sum, (Box(np.arange(3.0) + 1e-15, "a"),), {})
    assert k != _cache.key_of(_square_sum, (Box(np.arange(3.0).astype(np.float32), "a"),), {})
    assert k != _cache.key_of(_square_sum, (Box(np.arange(3.0), "b"),), {})
    with pytest.raises(TypeError, match="no content hash"):
        _cache.key_of(_square_sum, (object(),), {})


def test_an_argument_without_a_content_hash_is_computed_not_cached(cache):
    CALLS.clear()

    class Weird:
        def __array__(self, dtype=None, copy=None):
            return np.array([2.0])

    assert _square_sum(Weird()) == 4.0 and _square_sum(Weird()) == 4.0
    assert len(CALLS) == 2 and _cache.STATS["unkeyed"] == 2
    assert not cache.exists() or not list(cache.iterdir())


def test_a_torn_or_edited_entry_is_recomputed_and_rewritten(cache):
    CALLS.clear()
    _square_sum([3.0])
    (entry,) = cache.glob("*.pkl")
    entry.write_bytes(entry.read_bytes()[:-3])             # torn
    with pytest.warns(RuntimeWarning, match="does not match its checksum"):
        assert _square_sum([3.0]) == 9.0
    assert len(CALLS) == 2 and _cache.STATS["repaired"] == 1
    import pickle
    entry.write_bytes(pickle.dumps(123.0))                  # a valid pickle, not ours
    with pytest.warns(RuntimeWarning, match="does not match its checksum"):
        assert _square_sum([3.0]) == 9.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _square_sum([3.0]) == 9.0                    # rewritten: a clean hit now
    assert len(CALLS) == 3


def test_a_folder_others_can_write_is_never_read(cache):
    CALLS.clear()
    _square_sum([4.0])
    os.chmod(cache, 0o777)
    try:
        with pytest.warns(RuntimeWarning, match="not used"):
            assert _square_sum([4.0]) == 16.0
    finally:
        os.chmod(cache, 0o700)
    assert len(CALLS) == 2 and _cache.STATS["unusable"] == 1


def test_off_means_off(cache, monkeypatch):
    monkeypatch.setenv("ANNSLAM_CACHE", "off")
    CALLS.clear()
    _square_sum([5.0])
    _square_sum([5.0])
    assert len(CALLS) == 2 and not cache.exists()


def test_clear_removes_every_entry(cache):
    _square_sum([6.0])
    _square_sum([7.0])
    assert _cache.clear() == 2
    assert not list(cache.iterdir())


def test_the_command_line_says_where_and_clears(cache, capsys):
    from annslam_lib.course import cli

    _square_sum([8.0])
    assert cli.main(["cache", "where"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{cache}: 1 entries, ")
    assert cli.main(["cache", "clear"]) == 0
    assert capsys.readouterr().out == f"removed 1 entries from {cache}\n"
    assert not list(cache.glob("*.pkl"))


# -- the class's read-only folder (ANNSLAM_CLASS_CACHE) --------------------------------------

@pytest.fixture
def class_folder(tmp_path, monkeypatch, cache):
    """A class folder holding one entry (_square_sum([9.0])), computed there; the student's
    own folder (``cache``) empty."""
    shared = tmp_path / "class" / "studies"
    shared.parent.mkdir(mode=0o755)
    monkeypatch.setenv("ANNSLAM_CACHE", str(shared))
    _square_sum([9.0])
    for p in [shared, *shared.iterdir()]:
        os.chmod(p, 0o755 if p.is_dir() else 0o644)
    monkeypatch.setenv("ANNSLAM_CACHE", str(cache))
    monkeypatch.setenv("ANNSLAM_CLASS_CACHE", str(shared))
    monkeypatch.setattr(_cache, "STATS", dict.fromkeys(_cache.STATS, 0))
    CALLS.clear()
    return shared


def test_the_class_folder_is_read_when_ones_own_has_no_entry_and_never_copied(class_folder,
                                                                             cache):
    assert _square_sum([9.0]) == 81.0
    assert CALLS == [] and _cache.STATS["class_hits"] == 1 and _cache.STATS["misses"] == 0
    assert not list(cache.glob("*.pkl"))                   # read there, not copied here
    assert _square_sum([10.0]) == 100.0                    # not in it: computed, stored here
    assert len(CALLS) == 1 and len(list(cache.glob("*.pkl"))) == 1
    assert not (class_folder / next(cache.glob("*.pkl")).name).exists()


@pytest.mark.parametrize("what", ["folder", "entry", "checksum", "parent"])
def test_a_class_folder_others_could_change_is_not_read(class_folder, what):
    entry = next(class_folder.glob("*.pkl"))
    target = {"folder": class_folder, "entry": entry, "checksum": entry.with_suffix(".sha256"),
              "parent": class_folder.parent}[what]
    mode = target.stat().st_mode & 0o7777
    os.chmod(target, mode | 0o022)                          # group and others may write
    try:
        with pytest.warns(RuntimeWarning, match="could be changed by users other than"):
            assert _square_sum([9.0]) == 81.0
    finally:
        os.chmod(target, mode)
    assert len(CALLS) == 1 and _cache.STATS["untrusted"] == 1
    assert _cache.STATS["class_hits"] == 0


def test_a_sticky_folder_above_like_tmp_keeps_the_class_folder_trusted(class_folder):
    parent = class_folder.parent
    os.chmod(parent, 0o1777)
    try:
        assert _square_sum([9.0]) == 81.0
    finally:
        os.chmod(parent, 0o755)
    assert CALLS == [] and _cache.STATS["class_hits"] == 1


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a file to another user needs root")
def test_an_entry_of_another_user_is_not_read(class_folder):
    entry = next(class_folder.glob("*.pkl"))
    os.chown(entry, 54321, 54321)
    with pytest.warns(RuntimeWarning, match="could be changed"):
        assert _square_sum([9.0]) == 81.0
    assert len(CALLS) == 1 and _cache.STATS["class_hits"] == 0


def test_a_torn_class_entry_is_computed_not_believed(class_folder):
    entry = next(class_folder.glob("*.pkl"))
    data = bytearray(entry.read_bytes())
    data[-3] ^= 0xFF
    entry.write_bytes(bytes(data))
    with pytest.warns(RuntimeWarning, match="does not match its checksum"):
        assert _square_sum([9.0]) == 81.0
    assert len(CALLS) == 1 and _cache.STATS["class_hits"] == 0


def test_off_turns_the_class_folder_off_too(class_folder, monkeypatch):
    monkeypatch.setenv("ANNSLAM_CACHE", "off")
    assert _square_sum([9.0]) == 81.0
    assert len(CALLS) == 1 and _cache.STATS["class_hits"] == 0


WARM_CELLS = [
    "from annslam_lib.data import simulate\nfrom annslam_lib.slam import runner\n"
    "r = runner.run_cached(simulate.simulate(seed=0, laps=1))\nprint(len(r.trajectory))",
    "raise NotImplementedError('an exercise left to the student')",
    "print('after the exercise')",
]


def warm_notebooks(folder):
    """A folder with one small notebook: a cached run, an exercise that raises, a cell after."""
    import nbformat

    folder.mkdir(parents=True, exist_ok=True)
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(c) for c in WARM_CELLS]
    nbformat.write(nb, folder / "small.ipynb")
    return folder


def test_warm_runs_every_notebook_past_its_exercises_and_fills_the_cache(cache, tmp_path,
                                                                        capsys):
    from annslam_lib.course import cli
    from annslam_lib.data import simulate
    from annslam_lib.slam import runner

    notebooks = warm_notebooks(tmp_path / "nbs")
    assert cli.main(["cache", "warm", "--notebooks", str(notebooks)]) == 0
    out = capsys.readouterr().out
    assert "small.ipynb: " in out and "1 cell(s) raised" in out
    assert out.strip().endswith(f"{cache}: 1 entries (1 new) after Run All of 1 notebooks")
    assert len(list(cache.glob("run_cached-*.pkl"))) == 1
    # the kernel's entry is this process's key: read back, not recomputed
    runner.run_cached(simulate.simulate(seed=0, laps=1))
    assert _cache.STATS["hits"] == 1 and _cache.STATS["misses"] == 0
    assert cli.main(["cache", "warm", "--notebooks", str(tmp_path / "none")]) == 2


_SLOW_STUDY = """
import json, sys, time
from annslam_lib import _cache

@_cache.memoize
def slow_study(n):
    with open(sys.argv[1], "a") as f:      # one line per computation, from any process
        f.write("computed\\n")
    time.sleep(1.5)
    return [k * k for k in range(n)]

value = slow_study(400)
print(json.dumps({"sum": sum(value), "stats": _cache.STATS}))
"""


def test_two_processes_asking_for_one_study_compute_it_once(cache, tmp_path):
    """Two processes (two test workers, two kernels) asking for the same entry at once: one
    computes it, the other waits on the entry's lock and reads what the first stored."""
    import json
    import subprocess
    import sys

    log = tmp_path / "computations.txt"
    script = tmp_path / "study.py"
    script.write_text(_SLOW_STUDY)
    env = {**os.environ, "ANNSLAM_CACHE": str(cache)}
    procs = [subprocess.Popen([sys.executable, str(script), str(log)], env=env,
                              stdout=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [json.loads(p.communicate(timeout=120)[0]) for p in procs]
    assert log.read_text().splitlines() == ["computed"]
    assert [o["sum"] for o in outs] == [sum(k * k for k in range(400))] * 2
    stats = sorted((o["stats"]["misses"], o["stats"]["waited"], o["stats"]["hits"]) for o in outs)
    # the second either waited on the lock or (started late) found the entry stored
    assert stats[1] == (1, 0, 0) and stats[0] in ((0, 1, 0), (0, 0, 1))
    assert len(list(cache.glob("slow_study-*.pkl"))) == 1
