"""A study computed once per machine: results of the course's heavy experiments, kept in the
user cache and checked on load (a class's Run All costs CPU seconds per student).

:func:`memoize` wraps a deterministic library function (a Monte Carlo study, a grid of
trained networks). A call's key is the SHA-256 of

- the function's module and name,
- the library's code: every ``.py`` file of ``annslam_lib`` (so any change to the code, or
  to the data checksums it holds, makes every entry stale; nothing is reused across a
  change that could alter a result),
- the BLAS thread settings (``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``,
  ``MKL_NUM_THREADS``): another thread count may change a result at rounding level,
- its arguments by content, bound to the function's parameters with their defaults (so a
  call that names an argument, or spells out a default, finds the same entry): numbers, strings, ``None``, tuples, lists, dicts, ranges,
  dataclasses field by field and NumPy arrays by dtype, shape and bytes (a dataset passed
  in is hashed whole). A call with any other argument is computed and not stored
  (counted in :data:`STATS`): a key must never be a guess.

The entry is a pickle with its own SHA-256 beside it; an entry whose bytes do not match (a
torn or edited file) is recomputed and rewritten, with a warning, and counted in
:data:`STATS`. Writes are atomic (a temporary file renamed), so a reader never sees half an
entry; and a study is computed by one process at a time: a second process (a kernel, a test
worker) asking for the same entry meanwhile waits on the entry's lock file and then reads what
the first stored, instead of computing it again (``waited`` in :data:`STATS`). The folder is ``ANNSLAM_CACHE`` if set, else
``platformdirs.user_cache_dir('annslam')/studies``; ``ANNSLAM_CACHE=off`` turns the cache
off. A pickle can run code when loaded, so entries are read only from a folder that is
owned by the current user and not writable by group or others; any other folder is used as
if it were empty (results computed, nothing written), with a warning.

A class shares one more, read-only folder: ``ANNSLAM_CLASS_CACHE``, filled once for the
whole class (``python -m annslam_lib cache warm``; the hub's set-up does it with the
students' own environment) and consulted when the user's own folder has no entry, so that a
student's first Run All reads the studies instead of computing them. Its entries are read
only when nobody but root or the current user can change them: the folder, every folder
above it (a sticky one such as ``/tmp`` counts as closed) and the entry's two files are owned
by root or the current user and not writable by group or others. Otherwise it is ignored,
with a warning.

The results are the same as computed: the functions are seeded and deterministic, and a
test recomputes a cached study and compares (tests/test_cache.py).
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import inspect
import os
import pickle
import stat
import tempfile
import warnings
from pathlib import Path

import numpy as np

from . import _settings

__all__ = ["memoize", "cache_dir", "class_cache_dir", "clear", "key_of", "code_hash", "STATS"]

#: Per process: hits, class_hits (read from the class's folder), misses (computed and
#: stored), repaired (corrupt entry recomputed), unusable (folder not safe or not writable:
#: computed, not stored), untrusted (a class folder others could change: ignored), unkeyed
#: (an argument without a content hash: computed, not stored), waited (found after waiting
#: for another process computing the same entry).
STATS = {"hits": 0, "class_hits": 0, "misses": 0, "repaired": 0, "unusable": 0,
         "untrusted": 0, "unkeyed": 0, "waited": 0}

_ROOT = Path(__file__).resolve().parent
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def cache_dir() -> Path | None:
    """The cache folder, or None when ``ANNSLAM_CACHE=off``."""
    if _settings.cache_off():
        return None
    folder = _settings.cache_folder()
    if folder is not None:
        return folder
    import platformdirs
    return Path(platformdirs.user_cache_dir("annslam")) / "studies"


def class_cache_dir() -> Path | None:
    """The class's read-only study folder (``ANNSLAM_CLASS_CACHE``), or None."""
    if _settings.cache_off():                      # off: every cache
        return None
    return _settings.class_cache_folder()


def _closed(st, *, sticky_ok: bool = False) -> bool:
    """Owned by root or us, and not writable by group or others (a sticky folder lets
    others add names but not rename or remove ours)."""
    if st.st_uid not in (0, os.getuid()):
        return False
    open_ = st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)
    return not open_ or (sticky_ok and bool(st.st_mode & stat.S_ISVTX))


def _trusted(folder: Path) -> bool:
    """Only root or this user can change what ``folder`` holds (module docstring)."""
    try:
        folder = folder.resolve(strict=True)
        return _closed(folder.stat()) and all(_closed(p.stat(), sticky_ok=True)
                                              for p in folder.parents)
    except OSError:
        return False


def _load_class(name: str):
    """(True, value) from the class's folder, else (False, None)."""
    folder = class_cache_dir()
    if folder is None or not folder.is_dir():
        return False, None
    entry = folder / name
    try:
        files_closed = all(_closed(p.stat()) for p in (entry, entry.with_suffix(".sha256")))
    except FileNotFoundError:
        return False, None
    except OSError:
        files_closed = False
    if not (files_closed and _trusted(folder)):
        STATS["untrusted"] += 1
        warnings.warn(f"the class study cache {folder} (ANNSLAM_CLASS_CACHE) could be changed by "
                      "users other than root and you: not read", RuntimeWarning, stacklevel=3)
        return False, None
    found, value = _load(entry)
    if found:
        STATS["class_hits"] += 1
    return found, value


@functools.lru_cache(maxsize=1)
def code_hash() -> str:
    """SHA-256 over the library's source files (path and bytes), in a fixed order."""
    h = hashlib.sha256()
    for p in sorted(_ROOT.rglob("*.py")):
        h.update(p.relative_to(_ROOT).as_posix().encode() + b"\0")
        h.update(p.read_bytes() + b"\0")
    return h.hexdigest()


def _feed(h, obj, path: str) -> None:
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
    elif isinstance(obj, np.generic):
        _feed(h, obj.item(), path)
    elif isinstance(obj, np.ndarray):
        if obj.dtype == object:
            raise TypeError(f"cache key: {path} is an object array")
        a = np.ascontiguousarray(obj)
        h.update(f"nd:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes())
    elif isinstance(obj, range):
        h.update(f"range:{obj.start}:{obj.stop}:{obj.step};".encode())
    elif isinstance(obj, (tuple, list)):
        h.update(f"{type(obj).__name__}:{len(obj)}[".encode())
        for i, v in enumerate(obj):
            _feed(h, v, f"{path}[{i}]")
        h.update(b"]")
    elif isinstance(obj, dict):
        h.update(f"dict:{len(obj)}{{".encode())
        for k in sorted(obj, key=repr):
            _feed(h, k, f"{path} key")
            _feed(h, obj[k], f"{path}[{k!r}]")
        h.update(b"}")
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"dc:{type(obj).__module__}.{type(obj).__qualname__}(".encode())
        for f in dataclasses.fields(obj):
            h.update(f.name.encode() + b"=")
            _feed(h, getattr(obj, f.name), f"{path}.{f.name}")
        h.update(b")")
    else:
        raise TypeError(f"cache key: {path} is a {type(obj).__name__}, which has no content "
                        "hash (numbers, strings, tuples, lists, dicts, ranges, dataclasses and "
                        "NumPy arrays have)")


def key_of(fn, args: tuple, kwargs: dict) -> str:
    """The entry's key (module docstring)."""
    h = hashlib.sha256()
    h.update(f"{fn.__module__}.{fn.__qualname__};{code_hash()};".encode())
    for var in _THREAD_VARS:
        h.update(f"{var}={os.environ.get(var, '')};".encode())
    _feed(h, tuple(args), "argument")
    _feed(h, dict(kwargs), "keyword")
    return h.hexdigest()


def _safe(folder: Path) -> bool:
    """The folder exists (made 0700 if not), is ours, and only we can write to it."""
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        st = folder.stat()
    except OSError:
        return False
    return st.st_uid == os.getuid() and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _load(entry: Path, report: bool = True):
    """(True, value) for a whole entry, (False, None) for none; a corrupt one is reported
    (unless ``report`` is False: the same entry, looked at again)."""
    try:
        payload = entry.read_bytes()
        digest = entry.with_suffix(".sha256").read_text().strip()
    except FileNotFoundError:
        return False, None
    if hashlib.sha256(payload).hexdigest() != digest:
        if not report:
            return False, None
        warnings.warn(f"cache entry {entry.name} does not match its checksum: recomputed",
                      RuntimeWarning, stacklevel=3)
        STATS["repaired"] += 1
        return False, None
    return True, pickle.loads(payload)


def _store(entry: Path, value) -> None:
    payload = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    for suffix, data in ((".sha256", hashlib.sha256(payload).hexdigest().encode()),
                         (".pkl", payload)):           # the checksum first: a reader that
        fd, tmp = tempfile.mkstemp(dir=entry.parent)   # sees the payload sees its checksum
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, entry.with_suffix(suffix))


@contextlib.contextmanager
def _computing(entry: Path):
    """Hold the entry's lock file while its value is computed and stored: another process
    asking for it waits here (``flock``: released by the kernel if the holder dies)."""
    try:
        import fcntl
        fd = os.open(entry.with_suffix(".lock"), os.O_RDWR | os.O_CREAT, 0o600)
    except (ImportError, OSError):     # no flock here, or the folder refuses: compute
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)                   # closing releases the lock


def memoize(fn=None, *, ignore=()):
    """Decorator: ``fn``'s result is read from the cache when an entry for the same code and
    arguments is there, else computed and stored (module docstring). ``ignore``: keyword
    arguments that cannot change the result (a progress ``log``), left out of the key.
    ``fn.uncached`` is the function itself."""
    if fn is None:
        return functools.partial(memoize, ignore=tuple(ignore))

    signature = inspect.signature(fn)

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        folder = cache_dir()
        if folder is None:
            return fn(*args, **kwargs)
        try:                           # one key however the call names its arguments:
            bound = signature.bind(*args, **kwargs)      # f(d, 12), f(d, beacon=12) and
        except TypeError:                                 # f(d, 12, shifts=DEFAULT) alike
            return fn(*args, **kwargs)                    # fn says what is wrong with the call
        bound.apply_defaults()
        try:
            key = key_of(fn, (), {k: v for k, v in bound.arguments.items() if k not in ignore})
        except TypeError:              # an argument without a content hash: not cached,
            STATS["unkeyed"] += 1      # and fn itself says what it thinks of the argument
            return fn(*args, **kwargs)
        entry = folder / f"{fn.__name__}-{key[:32]}.pkl"
        if not _safe(folder):
            STATS["unusable"] += 1
            warnings.warn(f"the study cache {folder} is not a folder of this user's that only "
                          "they can write: not used (set ANNSLAM_CACHE)", RuntimeWarning,
                          stacklevel=2)
            found, value = _load_class(entry.name)
            return value if found else fn(*args, **kwargs)
        found, value = _load(entry)
        if found:
            STATS["hits"] += 1
            return value
        found, value = _load_class(entry.name)       # the class's, read, never copied
        if found:
            return value
        with _computing(entry):
            found, value = _load(entry, report=False)   # stored by another process meanwhile
            if found:
                STATS["waited"] += 1
                return value
            value = fn(*args, **kwargs)
            STATS["misses"] += 1
            try:
                _store(entry, value)
            except OSError as e:       # a full or read-only disk: the result still stands
                STATS["unusable"] += 1
                warnings.warn(f"could not write the study cache entry {entry}: {e}",
                              RuntimeWarning, stacklevel=2)
        return value

    wrapper.uncached = fn
    return wrapper


def clear() -> int:
    """Remove every entry; return how many."""
    folder = cache_dir()
    if folder is None or not folder.is_dir():
        return 0
    n = 0
    for p in folder.glob("*.pkl"):
        p.unlink(missing_ok=True)
        p.with_suffix(".sha256").unlink(missing_ok=True)
        p.with_suffix(".lock").unlink(missing_ok=True)
        n += 1
    return n
