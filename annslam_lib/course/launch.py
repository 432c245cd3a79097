"""Links that open a chapter of the student release somewhere it can run: on any JupyterHub
with nbgitpuller, on Binder, on Google Colab.

The student release (``python -m annslam_lib release``: no solutions, no hidden tests) is
published as a git repository or branch; each link names that repository, a branch or tag,
and the chapter's file in it. nbgitpuller clones the release into the student's home on the
first click and merges it on later clicks, never overwriting a file the student changed.
Binder builds its image from the course repository's ``binder/`` folder (the students'
environment, with nbgitpuller) and pulls the release into it the same way. Colab opens a
notebook straight from GitHub, in Colab's own Python and packages, so only the chapters
without the pinned torch or GTSAM builds are offered there (:data:`NOT_ON_COLAB`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from urllib.parse import quote, urlencode, urlsplit

__all__ = ["LaunchTargets", "nbgitpuller_link", "ref_name", "colab_setup", "COLAB_TAG", "binder_link", "colab_link", "links",
           "NOT_ON_COLAB", "PULL_FOLDER", "BINDER_URL"]

#: The folder nbgitpuller clones the release into, in the student's home.
PULL_FOLDER = "annslam"
BINDER_URL = "https://mybinder.org"
#: Chapters that Colab cannot run as the course does, and why: each needs a build that
#: Colab's own Python does not carry and that replacing would take the session's restart.
NOT_ON_COLAB = {
    "07_ann_training": "it needs the course's pinned PyTorch build",
    "08_ann_slam_verdict": "it needs the course's pinned PyTorch build",
    "10_beyond_the_ekf": "it needs GTSAM, which Colab does not install",
    "11_graph_slam": "it needs GTSAM, which Colab does not install",
}
_GITHUB = re.compile(r"^https://github\.com/([A-Za-z0-9_.-]+)/([A-Za-z0-9_.-]+?)(?:\.git)?/?$")
_REF = re.compile(r"^[A-Za-z0-9._/-]+$")


def _url(value: str, what: str) -> str:
    parts = urlsplit(value)
    if parts.scheme not in ("https", "http") or not parts.netloc or parts.query or \
            parts.fragment:
        raise ValueError(f"{what} must be an http(s) address without query or fragment, "
                         f"got {value!r}")
    return value.rstrip("/")


def ref_name(value: str, what: str) -> str:
    """``value`` if it is a git branch or tag name (letters, digits, ._/-, no ".."), else
    ValueError naming ``what``."""
    if not _REF.match(value) or ".." in value:
        raise ValueError(f"{what} must be a branch or tag name, got {value!r}")
    return value


def _chapter(path: str) -> str:
    if not re.match(r"^[A-Za-z0-9_.-]+\.ipynb$", path):
        raise ValueError(f"a chapter is a notebook's file name, got {path!r}")
    return path


def nbgitpuller_link(hub: str, repo: str, ref: str, notebook: str | None) -> str:
    """The link that pulls the release ``repo`` at ``ref`` into the student's home on the
    JupyterHub at ``hub`` (folder :data:`PULL_FOLDER`) and opens ``notebook`` in JupyterLab
    (None: the release's folder, the whole course).

    Parameters
    ----------
    hub : str
        The hub's address, e.g. ``https://hub.example.edu``.
    repo : str
        The student release's git repository (https).
    ref : str
        Its branch or tag.
    notebook : str or None
        The chapter's file name in the release, e.g. ``05_ekf_slam.ipynb``; None for the
        whole course.

    Returns
    -------
    str
        ``{hub}/hub/user-redirect/git-pull?repo=...&branch=...&urlpath=...&targetpath=...``
        (nbgitpuller's parameters).
    """
    hub, repo = _url(hub, "the hub's address"), _url(repo, "the release repository")
    query = urlencode({"repo": repo, "branch": ref_name(ref, "the release's branch"),
                       "urlpath": f"lab/tree/{PULL_FOLDER}" + (
                           f"/{_chapter(notebook)}" if notebook is not None else ""),
                       "targetpath": PULL_FOLDER})
    return f"{hub}/hub/user-redirect/git-pull?{query}"


def binder_link(env_repo: str, env_ref: str, repo: str, ref: str, notebook: str,
                binder: str = BINDER_URL) -> str:
    """A Binder link: the image built from ``env_repo`` at ``env_ref`` (its ``binder/``
    folder: the students' environment with nbgitpuller), into which nbgitpuller pulls the
    release ``repo`` at ``ref`` and opens ``notebook``.

    Returns
    -------
    str
        ``{binder}/v2/gh/{owner}/{name}/{env_ref}?urlpath=...`` for a GitHub repository,
        ``{binder}/v2/git/{url}/{env_ref}?urlpath=...`` for any other.
    """
    binder, env_repo = _url(binder, "the BinderHub address"), _url(env_repo, "the course repository")
    env_ref = ref_name(env_ref, "the course repository's branch")
    pull = urlencode({"repo": _url(repo, "the release repository"),
                      "branch": ref_name(ref, "the release's branch"),
                      "urlpath": f"lab/tree/{PULL_FOLDER}/{_chapter(notebook)}",
                      "targetpath": PULL_FOLDER})
    m = _GITHUB.match(env_repo)
    spec = f"gh/{m.group(1)}/{m.group(2)}" if m else f"git/{quote(env_repo, safe='')}"
    return f"{binder}/v2/{spec}/{quote(env_ref, safe='')}?" + urlencode(
        {"urlpath": f"git-pull?{pull}"})


def colab_link(repo: str, ref: str, notebook: str) -> str | None:
    """Colab's link to ``notebook`` of the release on GitHub, or None when Colab cannot open
    it (a repository elsewhere than GitHub) or cannot run it (:data:`NOT_ON_COLAB`)."""
    m = _GITHUB.match(_url(repo, "the release repository"))
    if m is None or _chapter(notebook).removesuffix(".ipynb") in NOT_ON_COLAB:
        return None
    return (f"https://colab.research.google.com/github/{m.group(1)}/{m.group(2)}/blob/"
            f"{quote(ref_name(ref, 'the release branch'))}/{notebook}")


#: The tag of the set-up cell :func:`colab_setup` writes.
COLAB_TAG = "colab-setup"


def colab_setup(course_repo: str, course_ref: str) -> str:
    """The source of the first cell of a chapter published for Colab: on Colab only, it
    installs the course's library from ``course_repo`` at ``course_ref`` into Colab's own
    Python (the data are downloaded by the library at first use); anywhere else it does
    nothing."""
    repo = _url(course_repo, "the course repository")
    ref = ref_name(course_ref, "the course's branch or tag")
    return ("# On Google Colab only: install the course's library (elsewhere it is set up "
            "already).\nimport sys\n"
            "if \"google.colab\" in sys.modules:\n"
            f"    %pip install --quiet \"annslam @ git+{repo}@{ref}\"")


@dataclass(frozen=True)
class LaunchTargets:
    """Where a course's launch links lead: the student release (``release_repo`` at
    ``release_ref``), the class hub (``hub``), and the course's own repository
    (``course_repo`` at ``course_ref``: the library, and the ``binder/`` folder Binder
    builds). Any may be None: its links are left out. Every address is checked when the
    targets are made."""
    release_repo: str | None = None
    release_ref: str = "main"
    hub: str | None = None
    course_repo: str | None = None
    course_ref: str = "main"
    binder: str = BINDER_URL

    def __post_init__(self):
        for name in ("release_repo", "hub", "course_repo"):
            if getattr(self, name) is not None:
                _url(getattr(self, name), name)
        ref_name(self.release_ref, "release_ref")
        ref_name(self.course_ref, "course_ref")
        _url(self.binder, "binder")


def links(targets: LaunchTargets, notebook: str) -> list[tuple[str, str | None, str]]:
    """(label, link or None, note) for each place ``notebook`` can be opened from
    ``targets``: the class hub, Binder, Colab, in that order; a None link comes with the
    note saying why there is none."""
    t, out = targets, []
    if t.release_repo is None:
        return out
    if t.hub is not None:
        out.append(("Open on the class hub", nbgitpuller_link(t.hub, t.release_repo,
                                                               t.release_ref, notebook), ""))
    if t.course_repo is not None:
        out.append(("Open on Binder", binder_link(t.course_repo, t.course_ref, t.release_repo,
                                                  t.release_ref, notebook, t.binder),
                    "a public, temporary session: download your work before you leave"))
    stem = notebook.removesuffix(".ipynb")
    colab = colab_link(t.release_repo, t.release_ref, notebook) if t.course_repo else None
    if colab is not None:
        out.append(("Open in Colab", colab, "in Colab's own Python: the chapter's first "
                    "cell installs the course's library there"))
    elif stem in NOT_ON_COLAB:
        out.append(("Colab", None, f"not on Colab: {NOT_ON_COLAB[stem]}"))
    return out
