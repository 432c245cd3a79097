"""Find, download and verify the data files of the registry (:mod:`annslam_lib.data.registry`).

Where the files live: ``<data dir>/<folder>/<file>``, the data dir being ``$ANNSLAM_DATA``
if set, else the per-user cache ``platformdirs.user_cache_dir('annslam')/data``.

Where missing files come from: each file's registry URL (raw GitHub at a pinned commit),
or, if ``$ANNSLAM_DATA_URL`` is set, a mirror laid out like the data dir:
``$ANNSLAM_DATA_URL/<folder>/<file>`` (any URL urllib opens: https, http, file).

Every file is checked against its sha256 before use; a download goes to a temporary
file in the target folder and is renamed into place only once its hash matches.
Every problem raises :class:`DataError`, whose message says how to fix it.

Bounds on a download (a slow or hostile mirror): each read waits at most
:data:`TIMEOUT_S`; the whole file gets a deadline of :data:`DEADLINE_BASE_S` plus its
registry size at :data:`MIN_RATE_BPS`; a server that sends more than the registry size
(+ :data:`SIZE_SLACK`) is cut off. Partial files (``.<name>.<random>.part``) that a killed
download left behind are removed by the next download of the same file, once nothing has
written to them for :data:`STALE_PART_S`.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import http.client
import os
import shlex
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import platformdirs
from tqdm.auto import tqdm

from .. import _settings
from . import registry
from .registry import DataFile, DatasetEntry

ENV_DIR = _settings.DATA
ENV_URL = _settings.DATA_URL
TIMEOUT_S = 60
#: A file's download deadline: this many seconds plus its size at MIN_RATE_BPS.
DEADLINE_BASE_S = 60.0
MIN_RATE_BPS = 50_000
#: Bytes a server may send beyond the registry size before the download is cut off.
SIZE_SLACK = 1 << 16
#: A partial file untouched this long belongs to no running download.
STALE_PART_S = 2 * TIMEOUT_S

# path -> stat key of files whose hash matched: a repeated load does not re-hash. The key
# includes ctime and the inode, which a rewrite changes even when it restores the size and
# mtime; verify() re-hashes regardless.
_verified: dict[str, tuple[int, ...]] = {}


class DataError(RuntimeError):
    """A data file is missing, corrupt, unparsable or could not be downloaded."""


def data_dir() -> Path:
    """The data directory: ``$ANNSLAM_DATA``, else the per-user cache. ``ANNSLAM_DATA`` set
    but empty is an error (an unset variable would be the cache; an empty one is a mistake,
    e.g. ``ANNSLAM_DATA=$UNSET_VAR``)."""
    try:
        folder = _settings.data_folder()
    except _settings.SetButEmpty:
        raise DataError(f"${ENV_DIR} is set but empty. Unset it to use the user cache "
                        f"({Path(platformdirs.user_cache_dir('annslam')) / 'data'}), or set it "
                        "to the folder that holds (or will hold) the course's data.") from None
    return folder if folder is not None else Path(platformdirs.user_cache_dir("annslam")) / "data"


def dataset_dir(name: str) -> Path:
    """Folder of dataset ``name`` inside the data directory (it may not exist yet)."""
    return data_dir() / registry.get(name).folder


def url(name: str, filename: str) -> str:
    """Download URL of one file: the ``$ANNSLAM_DATA_URL`` mirror if set, else the registry URL."""
    entry = registry.get(name)
    f = entry.file(filename)
    base = _settings.data_url()
    return f"{base.rstrip('/')}/{entry.folder}/{f.name}" if base else f.url


def ensure(name: str, *, repair: bool = False, progress: bool = True) -> Path:
    """Make sure every file of dataset ``name`` is present and verified; return its folder.

    Missing files are downloaded. A present file with a wrong hash raises
    :class:`DataError`, unless ``repair`` (what ``data fetch`` does): then it is
    downloaded again and replaced."""
    entry = registry.get(name)
    folder = data_dir() / entry.folder
    for f in entry.files:
        _ensure_file(entry, f, folder, repair, progress)
    return folder


def path(name: str, filename: str, *, progress: bool = True) -> Path:
    """Path of one verified file of dataset ``name`` (downloaded if missing)."""
    entry = registry.get(name)
    return _ensure_file(entry, entry.file(filename), data_dir() / entry.folder, False, progress)


def verify(name: str) -> Path:
    """Check every file of dataset ``name`` is present with the right sha256; never downloads.

    Every file is hashed again (not taken from the cache of files already verified).
    Returns the folder; raises :class:`DataError` on the first missing or corrupt file."""
    entry = registry.get(name)
    folder = data_dir() / entry.folder
    for f in entry.files:
        _verified.pop(str(folder / f.name), None)
        if not _check(entry, f, folder):
            raise _error(entry, f, folder, f"data file {f.name!r} of dataset {entry.name!r} is missing")
    return folder


def _error(entry: DatasetEntry, f: DataFile, folder: Path, problem: str, got: str | None = None) -> DataError:
    where = (f"${ENV_DIR}" if _settings.is_set(ENV_DIR)
             else f"the user cache; set ${ENV_DIR} to use another")
    lines = [problem, f"  file:            {folder / f.name}", f"  expected sha256: {f.sha256}"]
    if got:
        lines.append(f"  got sha256:      {got}")
    lines += [
        f"  searched:        {folder}  (data directory from {where})",
        f"Fix: run  {fetch_command(entry.name)}  (needs internet; downloads and verifies it;",
        "     ./course.sh setup in the course folder does the same for every dataset),",
        f"     or set {ENV_DIR} to a writable directory, or to one holding {entry.folder}/{f.name}.",
    ]
    return DataError("\n".join(lines))


def fetch_command(name: str) -> str:
    """The command that downloads dataset ``name``, as it works when pasted: the interpreter
    running this library (the course's venv python), not a bare ``python``."""
    return f"{shlex.quote(sys.executable)} -m annslam_lib data fetch {name}"


def _sha256(p: Path) -> str:
    with open(p, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def _check(entry: DatasetEntry, f: DataFile, folder: Path) -> bool:
    """True if the file is present and verified, False if missing; DataError if corrupt."""
    p = folder / f.name
    try:
        st = p.stat()
        key = (st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_ino, st.st_dev)
        if _verified.get(str(p)) == key:
            return True
        got = _sha256(p)
    except FileNotFoundError:
        return False
    except OSError as e:  # unreadable, a directory...
        raise _error(entry, f, folder, f"cannot read data file {f.name!r} of dataset "
                     f"{entry.name!r}: {e}") from e
    if got != f.sha256:
        raise _error(entry, f, folder, f"data file {f.name!r} of dataset {entry.name!r} is corrupt "
                     "(sha256 mismatch)", got)
    _verified[str(p)] = key
    return True


def _ensure_file(entry: DatasetEntry, f: DataFile, folder: Path, repair: bool, progress: bool) -> Path:
    try:
        if _check(entry, f, folder):
            return folder / f.name
    except DataError:
        if not repair:
            raise
    _download(entry, f, folder, progress)
    if not _check(entry, f, folder):  # re-stat the new file and remember it as verified
        raise _error(entry, f, folder, f"data file {f.name!r} vanished right after its download")
    return folder / f.name


def _remove_stale_parts(folder: Path, name: str) -> int:
    """Delete ``.<name>.*.part`` files in ``folder`` untouched for :data:`STALE_PART_S`
    (left by a killed download); returns how many."""
    removed, now = 0, time.time()
    for part in folder.glob(f".{name}.*.part"):
        with contextlib.suppress(OSError):
            if now - part.stat().st_mtime > STALE_PART_S:
                part.unlink()
                removed += 1
    return removed


def _download(entry: DatasetEntry, f: DataFile, folder: Path, progress: bool) -> None:
    src = url(entry.name, f.name)
    tmp = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        # Respect the mode bits even as root: a read-only shared data dir stays untouched.
        if not (os.access(folder, os.W_OK) and folder.stat().st_mode & 0o222):
            raise PermissionError(errno.EACCES, "directory is read-only", str(folder))
        _remove_stale_parts(folder, f.name)
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{f.name}.", suffix=".part")
        digest = hashlib.sha256()
        limit = f.size + SIZE_SLACK
        deadline_s = DEADLINE_BASE_S + f.size / MIN_RATE_BPS
        t0, got = time.monotonic(), 0
        with (os.fdopen(fd, "wb") as out, urllib.request.urlopen(src, timeout=TIMEOUT_S) as resp,
              tqdm(total=f.size, unit="B", unit_scale=True, desc=f.name, disable=not progress,
                   leave=False) as bar):
            read = getattr(resp, "read1", resp.read)     # read1: returns what has arrived
            while chunk := read(1 << 16):
                got += len(chunk)
                if got > limit:
                    raise ValueError(f"the server sent more than the file's {f.size} bytes "
                                     f"(cut off at {got}); a wrong file or a broken mirror")
                if time.monotonic() - t0 > deadline_s:
                    raise TimeoutError(f"{got} of {f.size} bytes after {deadline_s:.0f} s, the "
                                       f"deadline for this file (at least {MIN_RATE_BPS // 1000} "
                                       "kB/s); the mirror is too slow or stalled, try again later "
                                       f"or set ${ENV_URL} to another")
                out.write(chunk)
                digest.update(chunk)
                bar.update(len(chunk))
        if digest.hexdigest() != f.sha256:
            raise _error(entry, f, folder, f"downloaded {f.name!r} from {src} does not match its "
                         "sha256 (corrupt or wrong file); nothing was saved", digest.hexdigest())
        os.chmod(tmp, 0o644)  # mkstemp makes it private; a data file is not
        os.replace(tmp, folder / f.name)
        tmp = None
    except (OSError, ValueError, http.client.HTTPException) as e:  # URLError, timeouts are OSError
        raise _error(entry, f, folder, f"cannot download data file {f.name!r} of dataset "
                     f"{entry.name!r} from {src}: {e}") from e
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
