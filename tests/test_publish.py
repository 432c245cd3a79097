"""The student release published as a git branch (annslam_lib.course.publish) into a bare
repository on this machine, cloned back as nbgitpuller would; the nbgitpuller links the
course prints for a hub (annslam_lib.course.launch)."""
import subprocess
import sys
import types
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import nbformat
import pytest
from annslam_lib.course import launch, publish
from annslam_lib.course.release import ReleaseError
from annslam_lib.course.release import hidden_test_lines, solution_lines

ROOT = Path(__file__).resolve().parents[1]
CHAPTERS = [ROOT / "notebooks" / f"{n}.ipynb" for n in ("01_kinematics", "02_laser_offset")]


def _git(*args, cwd=None) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True,
                          text=True).stdout


@pytest.fixture
def bare(tmp_path):
    repo = tmp_path / "release.git"
    _git("init", "--quiet", "--bare", str(repo))
    return repo


def test_the_branch_holds_the_student_versions_and_a_readme_only(bare, tmp_path):
    done = publish.publish(f"file://{bare}", "fall-2027", CHAPTERS)
    assert done.changed and done.files == ("01_kinematics.ipynb", "02_laser_offset.ipynb",
                                           "README.md")
    clone = tmp_path / "student"
    _git("clone", "--quiet", "--branch", "fall-2027", f"file://{bare}", str(clone))
    assert sorted(p.name for p in clone.iterdir() if p.name != ".git") == list(done.files)
    for src in CHAPTERS:
        instructor = nbformat.read(src, as_version=4)
        text = (clone / src.name).read_text()
        shown = {ln.strip() for c in nbformat.reads(text, as_version=4).cells
                 for ln in c.source.split("\n")}
        leaked = (solution_lines(instructor) | hidden_test_lines(instructor)) & shown
        assert not leaked, f"{src.name}: {sorted(leaked)[:3]}"
        assert "BEGIN SOLUTION" not in text and "BEGIN HIDDEN TESTS" not in text
    assert _git("log", "--format=%s", cwd=clone).strip() == "Student release: 2 chapters"


def test_a_publication_that_changes_nothing_makes_no_commit_and_one_that_does_one(bare):
    first = publish.publish(str(bare), "fall-2027", CHAPTERS)
    again = publish.publish(str(bare), "fall-2027", CHAPTERS)
    assert not again.changed and again.commit == first.commit
    fewer = publish.publish(str(bare), "fall-2027", CHAPTERS[:1], message="chapter 02 later")
    assert fewer.changed and fewer.files == ("01_kinematics.ipynb", "README.md")
    log = _git("log", "--format=%s", "fall-2027", cwd=bare).split("\n")
    assert log[:2] == ["chapter 02 later", "Student release: 2 chapters"]
    other = publish.publish(str(bare), "spring-2028", CHAPTERS[1:])   # a branch of its own
    assert other.files == ("02_laser_offset.ipynb", "README.md")
    assert _git("rev-parse", "fall-2027", cwd=bare).strip() == fewer.commit


def test_what_cannot_be_published_is_refused(bare, tmp_path):
    with pytest.raises(ValueError, match="branch"):
        publish.publish(str(bare), "../main", CHAPTERS)
    with pytest.raises(publish.PublishError, match="clone"):
        publish.publish(str(tmp_path / "no-such-repo"), "fall-2027", CHAPTERS)
    broken = tmp_path / "broken.ipynb"
    broken.write_text("{")
    with pytest.raises(ReleaseError):
        publish.publish(str(bare), "fall-2027", [broken])
    assert _git("branch", "--list", cwd=bare).strip() == ""          # nothing was pushed


def test_the_launch_command_prints_a_link_per_chapter_or_one_for_the_course():
    def run(*args):
        return subprocess.run([sys.executable, "-m", "annslam_lib", "launch", "--hub",
                               "https://hub.example.edu", "--repo",
                               "https://github.com/you/annslam-release", "--branch",
                               "fall-2027", *args], capture_output=True, text=True)
    out = run("05_ekf_slam", "02_laser_offset.ipynb")
    assert out.returncode == 0
    links = out.stdout.split()
    assert links == [launch.nbgitpuller_link("https://hub.example.edu",
                                             "https://github.com/you/annslam-release",
                                             "fall-2027", n)
                     for n in ("05_ekf_slam.ipynb", "02_laser_offset.ipynb")]
    q = {k: v[0] for k, v in parse_qs(urlsplit(links[0]).query).items()}
    assert q == {"repo": "https://github.com/you/annslam-release", "branch": "fall-2027",
                 "urlpath": "lab/tree/annslam/05_ekf_slam.ipynb", "targetpath": "annslam"}
    whole = run()
    assert parse_qs(urlsplit(whole.stdout.strip()).query)["urlpath"] == ["lab/tree/annslam"]
    bad = run("x; rm -rf ~")
    assert bad.returncode == 2 and "notebook's file name" in bad.stderr


def test_a_chapter_published_for_colab_starts_with_its_set_up_cell(bare, tmp_path,
                                                                     monkeypatch):
    """Only where Colab runs it (07 needs the course's PyTorch build): a cell that installs
    the library, pinned, on Colab and does nothing anywhere else."""
    from IPython.core.inputtransformer2 import TransformerManager

    chapters = CHAPTERS[:1] + [ROOT / "notebooks" / "07_ann_training.ipynb"]
    publish.publish(str(bare), "colab", chapters,
                    course_repo="https://github.com/you/annslam", course_ref="v0.1.0")
    clone = tmp_path / "colab"
    _git("clone", "--quiet", "--branch", "colab", str(bare), str(clone))
    first = nbformat.read(clone / "01_kinematics.ipynb", as_version=4).cells[0]
    assert first.cell_type == "code" and first.metadata["tags"] == [launch.COLAB_TAG]
    assert '%pip install --quiet "annslam @ git+https://github.com/you/annslam@v0.1.0"' \
        in first.source
    code = TransformerManager().transform_cell(first.source)     # as IPython runs it
    calls = []

    class Shell:
        def run_line_magic(self, name, line):
            calls.append((name, line))
    exec(code, {"get_ipython": Shell})
    assert calls == []                                           # elsewhere: nothing
    monkeypatch.setitem(sys.modules, "google.colab", types.ModuleType("google.colab"))
    exec(code, {"get_ipython": Shell})                           # on Colab
    assert calls == [("pip", 'install --quiet "annslam @ git+https://github.com/you/annslam'
                             '@v0.1.0"')]
    ann = nbformat.read(clone / "07_ann_training.ipynb", as_version=4)
    assert launch.COLAB_TAG not in ann.cells[0].metadata.get("tags", [])
    with pytest.raises(ValueError, match="course"):
        publish.publish(str(bare), "colab", chapters, course_repo="git@github.com:you/x")
