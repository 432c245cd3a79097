"""What the grader loads and watches: nothing a submission could have written.

- :func:`prepare_grader`: the grader's own bytecode in a private folder (never the
  ``__pycache__`` next to the sources), the library compiled afresh, and with isolation
  'none' every check module imported before any student code runs;
- :class:`Guard`: every file of the course's folders (the library and its ``__pycache__``,
  the notebooks, ``.git``, the scripts, the data; the Python environment too with isolation
  'none'), watched while a batch is graded; the grader stops at a change
  (:func:`~annslam_lib.course.grader.grade_submission`);
- :func:`inert`: every text a submission can influence, escaped before it is reported.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import re
import sys
import unicodedata
from pathlib import Path

__all__ = ["Guard", "course_folders", "prepare_grader", "inert"]

ROOT = Path(__file__).resolve().parents[2]


# What a terminal or a page acts on instead of showing: control characters (Cc; newline and
# tab are kept only where a text may have lines), format characters (Cf: direction marks and
# overrides, zero-width characters, the byte-order mark), line and paragraph separators
# (Zl, Zp) and surrogates (Cs).
_ACTIVE = frozenset(("Cc", "Cf", "Zl", "Zp", "Cs"))
_PLAIN = re.compile(r"[\x20-\x7e\n\t]*")
MAX_TEXT = 4000


def inert(text: str, *, lines: bool = True, limit: int = MAX_TEXT) -> str:
    """``text`` with every character a terminal or a page would act on written as its
    escape (``\\x1b``, ``\\r``, ``\\u202e``, ``\\u2028``), so that a message from a
    submission cannot redraw a terminal or reorder a line; newlines and tabs stay when
    ``lines`` (else they are escaped too: a path, a name); at most ``limit`` characters are
    kept (the rest counted)."""
    text = str(text)
    if len(text) > limit:
        text = f"{text[:limit]} [... {len(text) - limit} more characters]"
    if _PLAIN.fullmatch(text) and (lines or ("\n" not in text and "\t" not in text)):
        return text
    out = []
    for ch in text:
        if (ch in "\n\t" and lines) or unicodedata.category(ch) not in _ACTIVE:
            out.append(ch)
        else:
            out.append(ch.encode("unicode_escape", "backslashreplace").decode("ascii"))
    return "".join(out)


# numba's on-disk cache (slam.compiled), in __pycache__ next to the module: an index numba
# unpickles and machine code it runs. A process of the instructor may write it while a
# submission runs, so a new or changed cache file is not held against anyone: it is deleted
# (numba compiles again, 0.3 s). Git's index and lock files and Jupyter's checkpoints change
# with the instructor's own work and run no code.
_VOLATILE = re.compile(r"(\.nb[ic]$)|(^|/)\.git/(index|.*\.lock)$|(^|/)\.ipynb_checkpoints(/|$)")


def _state(folders) -> dict[str, tuple]:
    """{path: (inode, size, mtime, ctime, mode)} of every file and link under ``folders``
    (``__pycache__`` and ``.git`` included). The change time cannot be set back by anyone
    but root, so a rewritten file is seen even if its modification time is restored."""
    out: dict[str, tuple] = {}

    def record(path, st) -> None:
        out[path] = (st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns, st.st_mode)

    def walk(folder: str) -> None:
        try:
            entries = list(os.scandir(folder))
        except OSError:
            return
        for e in entries:
            try:
                if e.is_dir(follow_symlinks=False):
                    walk(e.path)
                else:
                    record(e.path, e.stat(follow_symlinks=False))
            except OSError:
                pass

    for folder in folders:
        if os.path.isdir(folder) and not os.path.islink(folder):
            walk(folder)
        else:                                             # a single file
            with contextlib.suppress(OSError):
                record(folder, os.lstat(folder))
    return out


def _digest(path: str) -> str:
    try:
        if os.path.islink(path):
            return "link:" + os.readlink(path)
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return "unreadable"


class Guard:
    """Every file of the course's folders, watched while submissions are graded: what a
    submission must not change, because the grader and the instructor load or read it (the
    library and its bytecode, the instructor notebooks, the history in ``.git``, the data,
    the Python environment where the kernel could write it).

    :meth:`changes` compares the files' status, and the content of those whose status moved,
    with the state when the guard was made; :meth:`restore` puts back what it holds a copy
    of (``restorable`` folders) and removes new files."""

    def __init__(self, folders, *, restorable=()) -> None:
        self.folders = [str(Path(f)) for f in folders if Path(f).exists()]
        self.before = _state(self.folders)
        roots = [str(Path(f)) for f in restorable if Path(f).exists()]
        self.backup = {p: Path(p).read_bytes() for p in self.before
                       if any(p == r or p.startswith(r + os.sep) for r in roots)
                       and not os.path.islink(p) and not _VOLATILE.search(p)}
        # content is compared for the files held (a rewrite with the same bytes is no
        # change); the others (the environment, .git's objects) by their status alone
        self.digests = {p: hashlib.sha256(b).hexdigest() for p, b in self.backup.items()}

    def changes(self) -> list[str]:
        """Paths of files changed, added or removed since the guard was made (numba's cache,
        git's index and lock files and checkpoints excepted; a new or changed numba cache
        file is deleted here)."""
        now = _state(self.folders)
        moved = {p for p, st in now.items() if self.before.get(p) != st}
        moved |= self.before.keys() - now.keys()
        out = []
        for p in sorted(moved):
            if _VOLATILE.search(p):
                if p.endswith((".nbi", ".nbc")) and now.get(p) != self.before.get(p):
                    with contextlib.suppress(OSError):
                        os.unlink(p)
                continue
            if p in now and p in self.digests and _digest(p) == self.digests[p]:
                self.before[p] = now[p]              # rewritten with the same bytes
                continue
            out.append(p)
        return out

    def restore(self, changed) -> list[str]:
        """Put back each changed file held in the backup and remove each new one; the paths
        that could not be restored (a copy not held)."""
        lost = []
        for p in changed:
            try:
                if p in self.backup:
                    if os.path.islink(p) or os.path.isdir(p):
                        os.unlink(p)
                    Path(p).parent.mkdir(parents=True, exist_ok=True)
                    Path(p).write_bytes(self.backup[p])
                elif p not in self.before:
                    os.unlink(p)
                else:
                    lost.append(p)
            except OSError:
                lost.append(p)
        self.before = _state(self.folders)
        return lost


def course_folders(instructor_dir=None, *, isolation: str = "bwrap") -> tuple[list, list]:
    """(guarded, restorable): the folders :class:`Guard` watches while a batch is graded,
    and those it keeps a copy of. The Python environment is watched when the kernel runs
    unsandboxed (isolation 'none'): it could write there, and the grader imports from it."""
    from ..data import fetch

    restorable = [ROOT / "annslam_lib", ROOT / "notebooks", ROOT / "scripts"]
    if instructor_dir is not None:
        restorable.append(Path(instructor_dir))
    guarded = [*restorable, ROOT / ".git", ROOT / "course.sh", fetch.data_dir()]
    if isolation == "none":
        guarded.append(Path(sys.prefix))
    out = []
    for p in guarded:
        p = Path(p).resolve()
        if p.exists() and not any(q == p or q in p.parents for q in out):
            out.append(p)
    return out, restorable


def prepare_grader(isolation: str = "auto") -> None:
    """Make this process load nothing a submission could have written: its bytecode is read
    and written in a private folder of the grader's user (``sys.pycache_prefix``), never in
    ``__pycache__`` next to the sources, where a submission run unsandboxed could plant
    some; the library's own ``__pycache__`` is compiled afresh (for the instructor's other
    processes, and so that no legitimate process writes there while the :class:`Guard`
    watches it). With isolation 'none' every check module is imported now, before any
    student code runs (in the sandbox nothing of the course can be written, so they are
    imported when a test cell needs them)."""
    import compileall
    import importlib
    import pkgutil

    if sys.pycache_prefix is None:
        sys.pycache_prefix = str(_private_bytecode_dir())
    sys.dont_write_bytecode = False              # the private folder is the grader's cache
    if isolation == "none":
        from .. import grading
        for m in pkgutil.iter_modules(grading.__path__):
            importlib.import_module(f"{grading.__name__}.{m.name}")
    prefix, sys.pycache_prefix = sys.pycache_prefix, None
    try:
        compileall.compile_dir(str(ROOT / "annslam_lib"), quiet=2, force=False)
    finally:
        sys.pycache_prefix = prefix


def _private_bytecode_dir() -> Path:
    """The grader's bytecode folder: in the user cache, owned by this user and closed to
    others (a fresh temporary folder if that cannot be had)."""
    import stat
    import tempfile

    from platformdirs import user_cache_dir

    d = Path(user_cache_dir("annslam")) / "grader-bytecode"
    try:
        d.mkdir(parents=True, exist_ok=True, mode=0o700)
        st = d.lstat()
        if stat.S_ISDIR(st.st_mode) and st.st_uid == os.geteuid() and not st.st_mode & 0o077:
            return d
    except OSError:
        pass
    return Path(tempfile.mkdtemp(prefix="annslam-grader-bytecode-"))
