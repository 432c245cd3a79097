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
