"""The student release published as a branch of a git repository, for nbgitpuller (and
Binder and Colab) to pull: ``python -m annslam_lib publish --repo R --branch B``.

The branch holds the student versions of the chapters (:mod:`.release`: no solutions, no
hidden tests) and a short README, nothing else of the course: no instructor notebook, no
test, no library (students' environments install it), no data (the library downloads and
checks it). Given the course's repository, each chapter Colab can run starts with the cell
that installs the library there (:func:`.launch.colab_setup`; it does nothing elsewhere). Each publication is one commit on the branch, made only when something changed,
so a semester's branch or tag stays what students pulled. The repository may be a folder, a
``file://`` address or a remote one git can push to.
"""
from __future__ import annotations

import dataclasses
import subprocess
import tempfile
from pathlib import Path

import nbformat

from .launch import COLAB_TAG, NOT_ON_COLAB, colab_setup, ref_name
from .release import release

__all__ = ["publish", "Published", "README"]

#: The README at the top of the published branch.
README = """\
# The student release of the annslam course

The chapters of the course, without solutions. Open them on your class's JupyterHub (the
link your instructor gives pulls this folder into your home and never overwrites your
changes), on Binder, or on a machine where the course is set up.
"""


class PublishError(RuntimeError):
    """A publication that could not be made, with git's words."""


@dataclasses.dataclass(frozen=True)
class Published:
    """What a publication did: the branch, its commit, the files it holds, and whether this
    publication changed it."""
    branch: str
    commit: str
    files: tuple
    changed: bool

    def summary(self) -> str:
        what = "published" if self.changed else "unchanged"
        return f"{self.branch} {what} at {self.commit[:12]}: {len(self.files)} files"


def _git(cwd, *args: str) -> str:
    out = subprocess.run(["git", "-c", "user.name=annslam release",
                          "-c", "user.email=release@annslam.invalid", *args],
                         cwd=cwd, capture_output=True, text=True)
    if out.returncode != 0:
        raise PublishError(f"git {args[0]} failed: {out.stderr.strip() or out.stdout.strip()}")
    return out.stdout


def publish(repo: str, branch: str, notebooks, *, message: str | None = None,
            course_repo: str | None = None, course_ref: str = "main") -> Published:
    """Publish the student versions of ``notebooks`` (instructor notebooks) as ``branch`` of
    the git repository ``repo``, with the Colab set-up cell when ``course_repo`` (the
    course's own repository, at ``course_ref``) is given (module docstring)."""
    branch = ref_name(branch, "the release's branch")
    setup = colab_setup(course_repo, course_ref) if course_repo else None
    notebooks = [Path(p) for p in notebooks]
    with tempfile.TemporaryDirectory(prefix="annslam-publish-") as tmp:
        work = Path(tmp) / "release"
        _git(tmp, "clone", "--quiet", "--no-checkout", str(repo), str(work))
        remote = _git(work, "ls-remote", "--heads", "origin", branch).strip()
        if remote:
            _git(work, "checkout", "--quiet", "-B", branch, f"origin/{branch}")
        else:
            _git(work, "checkout", "--quiet", "--orphan", branch)
        _git(work, "rm", "-r", "-q", "--ignore-unmatch", ".")
        for leftover in work.iterdir():              # untracked: none is the release's
            if leftover.name != ".git":
                subprocess.run(["rm", "-rf", str(leftover)], check=True)
        written = release(notebooks, work)
        for path in written if setup else []:
            if path.stem not in NOT_ON_COLAB:
                nb = nbformat.read(path, as_version=4)
                cell = nbformat.v4.new_code_cell(setup)
                cell.metadata["tags"] = [COLAB_TAG]
                nb.cells.insert(0, cell)
                nbformat.write(nb, path)
        (work / "README.md").write_text(README)
        _git(work, "add", "-A")
        changed = bool(_git(work, "status", "--porcelain").strip())
        if changed:
            _git(work, "commit", "--quiet", "-m",
                 message or f"Student release: {len(written)} chapters")
            _git(work, "push", "--quiet", "origin", f"{branch}:refs/heads/{branch}")
        commit = _git(work, "rev-parse", "HEAD").strip()
        files = tuple(sorted(_git(work, "ls-files").splitlines()))
    return Published(branch, commit, files, changed)
