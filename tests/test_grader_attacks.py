"""Hostile and unlucky submissions against the grader (annslam_lib.course.grader).

Every attack reported against the old grader is replayed here on a two-exercise instructor
notebook (tests/grading_support.py, the course's real checks): nothing written earns 0,
honest work earns full marks, no file outside the scratch folder changes, each notebook
grades within its deadline, and a batch with broken submissions grades all the others.
"""
from __future__ import annotations

import hashlib
import json
import os
import socket
import threading
import time
from pathlib import Path

import nbformat
import pytest


from annslam_lib.course.grader import grade_batch, grade_submission
from annslam_lib.course.grader import GradingEnvironmentError
from annslam_lib.course.sandbox import Limits, bwrap_available
from annslam_lib.data import fetch

import grading_support as gs

ROOT = Path(__file__).resolve().parents[1]
LIMITS = Limits(cell_timeout=4.0, call_timeout=4.0, deadline=45.0)
# The sandbox these run in: 'auto' (bubblewrap where it works); ANNSLAM_TEST_ISOLATION=none
# replays them without one, as on a machine without bubblewrap.
ISOLATION = os.environ.get("ANNSLAM_TEST_ISOLATION",
                           "auto" if bwrap_available() is not None else "none")
FULL = sum(gs.POINTS.values())
GUARDED = [ROOT / "annslam_lib", ROOT / "notebooks"]


def _fingerprint() -> dict:
    folders = GUARDED + [fetch.data_dir()]
    out = {}
    for folder in folders:
        for p in sorted(Path(folder).rglob("*")):
            if p.is_file() and "__pycache__" not in p.parts:
                out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@pytest.fixture(scope="module")
def instructor(tmp_path_factory):
    path = tmp_path_factory.mktemp("instructor") / "chapter.ipynb"
    gs.write(gs.instructor(), path)
    return path


@pytest.fixture(scope="module")
def course_files():
    before = _fingerprint()
    yield before
    assert _fingerprint() == before, "a submission changed a course file"


def grade(nb, instructor, tmp_path, *, name="chapter.ipynb", limits=LIMITS, isolation=ISOLATION,
          guard=GUARDED):
    path = tmp_path / "submitted" / "student" / "chapter" / name
    if isinstance(nb, bytes):
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(nb)
    else:
        gs.write(nb, path)
    t0 = time.monotonic()
    g = grade_submission(path, instructor, limits=limits, isolation=isolation,
                         hide=[instructor.parent], guard=guard)
    g.wall = time.monotonic() - t0
    assert g.wall <= limits.deadline + 15, f"grading took {g.wall:.0f} s"
    return g


def by_id(g) -> dict:
    return {r.grade_id: r for r in g.exercises}


# ------------------------------------------------------------------ honest and empty work

def test_honest_full_marks_empty_zero_partial_partial(instructor, tmp_path, course_files):
    g = grade(gs.honest(), instructor, tmp_path)
    assert (g.score, g.max_score) == (FULL, FULL), g.report()
    assert g.notes == [] and g.errors == []
    empty = grade(gs.submission(), instructor, tmp_path / "e")
    assert empty.score == 0 and empty.max_score == FULL
    assert {r.status for r in empty.exercises} == {"not written"}
    half = grade(gs.submission(gs.OBSERVE_BODY), instructor, tmp_path / "h")
    assert half.score == gs.POINTS["ex-observe-tests"]
    assert by_id(half)["ex-speed-tests"].status == "not written"


def test_hidden_tests_run_and_a_wrong_answer_gets_the_checks_message(instructor, tmp_path,
                                                                     course_files):
    wrong = gs.OBSERVE_BODY.replace("np.arctan2(dy, dx) - pose[2] + np.pi / 2",
                                    "np.arctan2(dy, dx) - pose[2]")
    g = grade(gs.submission(wrong, gs.SPEED_BODY), instructor, tmp_path)
    r = by_id(g)["ex-observe-tests"]
    assert r.points == 0 and r.status == "failed"
    assert "off by a constant -90.0°" in r.message
    assert g.score == gs.POINTS["ex-speed-tests"]


# ------------------------------------------------------------------ time-outs and deaths

def test_a_cell_that_never_finishes_scores_zero_with_its_reason(instructor, tmp_path,
                                                                course_files):
    spin = "while True:\n    pass\n" + gs.OBSERVE_BODY
    g = grade(gs.submission(spin, gs.SPEED_BODY), instructor, tmp_path)
    r = by_id(g)["ex-observe-tests"]
    assert r.points == 0 and r.status == "solution error"
    assert "did not finish within its time-out" in r.message
    assert g.score == gs.POINTS["ex-speed-tests"]            # the other exercise is graded
    assert g.wall < 25


def test_an_honest_but_slow_cell_times_out_instead_of_passing(instructor, tmp_path,
                                                             course_files):
    slow = "import time\ntime.sleep(6)\n" + gs.OBSERVE_BODY
    g = grade(gs.submission(slow, gs.SPEED_BODY), instructor, tmp_path)
    assert by_id(g)["ex-observe-tests"].status == "solution error"
    assert "time-out" in by_id(g)["ex-observe-tests"].message


def test_a_cell_ignoring_sigint_is_killed_and_the_rest_still_graded(instructor, tmp_path,
                                                                   course_files):
    stubborn = ("import signal\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n"
                "while True:\n    pass\n")
    g = grade(gs.submission(stubborn, gs.SPEED_BODY), instructor, tmp_path)
    r = by_id(g)["ex-observe-tests"]
    assert r.status == "solution error" and "ignored the interrupt and was killed" in r.message
    assert by_id(g)["ex-speed-tests"].points == gs.POINTS["ex-speed-tests"]
    assert any("restarted 1 time" in n for n in g.notes)
    assert g.wall < 30                # one time-out (4 s) plus 5 s for the interrupt


def test_os_exit_is_reported_as_a_kernel_death_at_once(instructor, tmp_path, course_files):
    g = grade(gs.submission("import os\nos._exit(0)", gs.SPEED_BODY), instructor, tmp_path)
    r = by_id(g)["ex-observe-tests"]
    assert r.status == "solution error" and "the kernel died" in r.message
    assert "exited with code 0" in r.message
    assert by_id(g)["ex-speed-tests"].points == gs.POINTS["ex-speed-tests"]
    assert g.wall < 15                # noticed at once, not after the 4 s time-out each time


def test_a_function_that_kills_the_kernel_when_called(instructor, tmp_path, course_files):
    killer = "def my_observe(pose, landmark):\n    import os\n    os._exit(3)"
    g = grade(gs.submission(killer, gs.SPEED_BODY), instructor, tmp_path)
    assert by_id(g)["ex-observe-tests"].status == "kernel died"
    assert "exited with code 3" in by_id(g)["ex-observe-tests"].message
    assert by_id(g)["ex-speed-tests"].points == gs.POINTS["ex-speed-tests"]


def test_cpu_and_memory_limits(instructor, tmp_path, course_files):
    spin = "while True:\n    pass"
    g = grade(gs.submission(spin, gs.SPEED_BODY), instructor, tmp_path,
              limits=Limits(cpu_seconds=2, cell_timeout=20, call_timeout=4, deadline=60))
    assert "SIGXCPU" in by_id(g)["ex-observe-tests"].message
    hog = "x = bytearray(6 << 30)\n" + gs.OBSERVE_BODY
    g = grade(gs.submission(hog, gs.SPEED_BODY), instructor, tmp_path / "m")
    assert by_id(g)["ex-observe-tests"].status == "solution error"
    assert "MemoryError" in by_id(g)["ex-observe-tests"].message


def test_the_file_size_limit_binds_where_the_kernel_may_write(instructor, tmp_path,
                                                             course_files):
    """Its working directory, home and /tmp: a file past the limit fails (EFBIG, or the
    memory folder's own size, ENOSPC, whichever comes first)."""
    big = ("import errno, os, tempfile\nSEEN = []\n"
           "for d in ('.', os.path.expanduser('~'), tempfile.gettempdir()):\n"
           "    try:\n"
           "        with open(os.path.join(d, 'big.bin'), 'wb') as f:\n"
           "            f.write(b'x' * (3 << 20))\n"
           "        SEEN.append('written')\n"
           "    except OSError as e:\n"
           "        SEEN.append(errno.errorcode[e.errno])\n"
           "raise AssertionError('SIZES %s' % SEEN)\n")
    g = grade(gs.submission(big, gs.SPEED_BODY), instructor, tmp_path,
              limits=Limits(file_bytes=2 << 20, cell_timeout=20, call_timeout=4, deadline=60))
    r = by_id(g)["ex-observe-tests"]
    seen = eval(r.message.split("SIZES ")[1])
    assert len(seen) == 3 and set(seen) <= {"EFBIG", "ENOSPC"} and "EFBIG" in seen, seen
    assert by_id(g)["ex-speed-tests"].points == gs.POINTS["ex-speed-tests"]


# ------------------------------------------------------------------ the submission's metadata

def _points(nb, gid, pts):
    nb.cells[gs.solution_index(nb, gid)].metadata["nbgrader"]["points"] = pts


def test_points_come_from_the_instructor_notebook(instructor, tmp_path, course_files):
    g = grade(gs.submission(edit=lambda nb: _points(nb, "ex-observe-tests", 1000)), instructor,
              tmp_path)
    assert g.max_score == FULL and g.score == 0
    assert any("changed to 1000" in n for n in g.notes)
    g = grade(gs.submission(gs.OBSERVE_BODY, edit=lambda nb: _points(nb, "ex-observe-tests", -5)),
              instructor, tmp_path / "n")
    assert g.score == gs.POINTS["ex-observe-tests"] and g.max_score == FULL


def test_an_appended_bonus_cell_is_ignored(instructor, tmp_path, course_files):
    bonus = nbformat.v4.new_code_cell("pass")
    bonus.metadata["nbgrader"] = {"grade": True, "grade_id": "bonus", "points": 100,
                                  "solution": False, "locked": True, "schema_version": 3}
    g = grade(gs.submission(extra_cells=[bonus]), instructor, tmp_path)
    assert g.score == 0 and g.max_score == FULL
    assert any("'bonus'" in n and "ignored" in n for n in g.notes)


def test_deleted_retyped_and_edited_test_cells_are_restored(instructor, tmp_path, course_files):
    def damage(nb):
        k = gs.solution_index(nb, "ex-observe-tests")
        nb.cells[k].source = "pass  # edited to pass"
        j = gs.solution_index(nb, "ex-speed-tests")
        nb.cells[j] = nbformat.v4.new_markdown_cell("gone")
    g = grade(gs.submission(edit=damage), instructor, tmp_path)
    assert g.score == 0 and g.max_score == FULL
    assert any("'ex-observe-tests' was edited" in n for n in g.notes)
    assert any("'ex-speed-tests' is missing" in n for n in g.notes)
    g = grade(gs.submission(gs.OBSERVE_BODY, gs.SPEED_BODY, edit=damage), instructor,
              tmp_path / "h")
    assert g.score == FULL                      # honest work still counts in full


def test_a_renamed_solution_grade_id_is_found_by_its_function(instructor, tmp_path,
                                                             course_files):
    def rename(nb):
        nb.cells[gs.solution_index(nb, "ex-observe")].metadata["nbgrader"]["grade_id"] = "mine"
    g = grade(gs.submission(gs.OBSERVE_BODY, edit=rename), instructor, tmp_path)
    assert by_id(g)["ex-observe-tests"].points == gs.POINTS["ex-observe-tests"]
    assert any("not found by its grade id" in n for n in g.notes)


# ------------------------------------------------------------------ disarming the checks

# attack -> (code put before the function, whether honest work beside it still counts)
DISARM = {
    "rebind the check module": ("gk = type('Fake', (), {'check_observe': staticmethod("
                                "lambda *a, **k: None)})()\n", True),
    "setattr on the check": ("import annslam_lib.grading.observation as m\n"
                             "m.check_observe = lambda *a, **k: None\n"
                             "import annslam_lib.grading.core as c\n"
                             "c.check_function = lambda *a, **k: None\n", True),
    "input transformer blanks tests": (
        "get_ipython().input_transformers_post.append(\n"
        "    lambda lines: [] if any('check_' in l for l in lines) else lines)\n", True),
    "input transformer blanks the grader": (
        "get_ipython().input_transformers_post.append(\n"
        "    lambda lines: [] if any('__annslam' in l for l in lines) else lines)\n", False),
    "fake grader helper": (
        "import sys, types, json\n"
        "fake = types.ModuleType('annslam_lib.course.kernel_side')\n"
        "fake.call = lambda *a: json.dumps({'value': [1.0, 0.0], 'hits': [], 'states': []})\n"
        "fake.call_many = lambda n, ps, f='[]': '[' + ','.join(fake.call() for _ in ps) + ']'\n"
        "sys.modules['annslam_lib.course.kernel_side'] = fake\n"
        "__annslam_kernel__ = fake\n", False),
}


@pytest.mark.parametrize("attack", list(DISARM), ids=lambda a: a.replace(" ", "-"))
def test_disarming_the_checks_from_the_kernel_earns_nothing(attack, instructor, tmp_path,
                                                           course_files):
    code, honest_counts = DISARM[attack]
    g = grade(gs.submission(code + "def my_observe(pose, landmark):\n    return 1.0, 0.0"),
              instructor, tmp_path)
    assert g.score == 0, g.report()
    if honest_counts:     # the attack does not stop honest work beside it from counting
        g = grade(gs.submission(code + gs.OBSERVE_BODY, gs.SPEED_BODY), instructor,
                  tmp_path / "h")
        assert g.score == FULL, g.report()


# ------------------------------------------------------------------ the course's files

WRITE = (
    "import pathlib\n"
    "p = pathlib.Path({target!r})\n"
    "p.write_text(p.read_text() + '\\ncheck_observe = lambda *a, **k: None\\n')\n")


PLANT = (
    "import pathlib\n"
    "d = pathlib.Path({folder!r})\n"
    "d.mkdir(exist_ok=True)\n"
    "(d / 'compiled.gate_loop-43.py311.nbi').write_bytes(b'planted index')\n"
    "(d / 'compiled.gate_loop-43.py311.1.nbc').write_bytes(b'planted code')\n")


@pytest.fixture
def course_copy(tmp_path):
    """A copy of the course's library for the attacks that succeed without a sandbox
    (isolation 'none'): they write there, never into the checkout that the other tests,
    graders included, read meanwhile."""
    lib = tmp_path / "course" / "annslam_lib"
    import shutil
    shutil.copytree(ROOT / "annslam_lib", lib)
    return lib


def test_a_planted_numba_cache_is_deleted_after_the_submission(instructor, tmp_path,
                                                              course_files, course_copy):
    """Without a sandbox (isolation 'none') a submission can write next to the library; numba
    would unpickle a cache file planted there in the instructor's next long run
    (slam.compiled). New or changed cache files are deleted after the submission; one
    that was there before and did not change stays."""
    cache = course_copy / "slam" / "__pycache__"
    cache.mkdir(exist_ok=True)
    kept = cache / "compiled.kept_by_the_instructor.nbi"
    kept.write_bytes(b"the instructor's own")
    attack = PLANT.format(folder=str(cache)) + gs.OBSERVE_BODY
    g = grade(gs.submission(attack, gs.SPEED_BODY), instructor, tmp_path, isolation="none",
              guard=[course_copy])
    assert g.score == FULL, g.report()               # not held against the student
    assert not list(cache.glob("compiled.gate_loop-43.py311*")), "a planted file is left"
    assert kept.read_bytes() == b"the instructor's own"


@pytest.mark.parametrize("isolation", ["bwrap", "none"])
def test_writing_to_the_course_library_changes_nothing_for_the_next_student(
        isolation, instructor, tmp_path, course_files, course_copy):
    if isolation == "bwrap" and bwrap_available() is None:
        pytest.skip("bubblewrap is not installed here (apt-get install bubblewrap)")
    lib = course_copy if isolation == "none" else ROOT / "annslam_lib"
    target = str(lib / "grading" / "observation.py")
    before = Path(target).read_bytes()
    attack = WRITE.format(target=target) + "def my_observe(pose, landmark):\n    return 1.0, 0.0"
    if isolation == "none":          # the write went through: undone, and grading stops
        with pytest.raises(GradingEnvironmentError, match="course files changed") as e:
            grade(gs.submission(attack), instructor, tmp_path, isolation=isolation,
                  guard=[lib])
        g = e.value.grade
        assert any("restored" in n for n in g.notes), g.notes
        assert {r.status for r in g.exercises} == {"tampered"}
    else:                            # the write itself failed: the library is not there
        g = grade(gs.submission(attack), instructor, tmp_path, isolation=isolation)
        assert "Error" in by_id(g)["ex-observe-tests"].message
    assert g.score == 0
    assert Path(target).read_bytes() == before, "the library file was left changed"
    nxt = grade(gs.submission(), instructor, tmp_path / "next", isolation=isolation, guard=[lib])
    assert nxt.score == 0 and {r.status for r in nxt.exercises} == {"not written"}


def test_the_sandbox_hides_the_instructor_notebook_and_has_no_network(instructor, tmp_path,
                                                                     course_files):
    if bwrap_available() is None:
        pytest.skip("bubblewrap is not installed here (apt-get install bubblewrap)")
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    port = server.getsockname()[1]
    threading.Thread(target=lambda: server.accept(), daemon=True).start()
    probe = (f"import pathlib, socket\n"
             f"assert not pathlib.Path({str(instructor)!r}).exists(), 'instructor visible'\n"
             f"s = socket.socket()\n"
             f"try:\n    s.connect(('127.0.0.1', {port}))\n    NET = True\n"
             f"except OSError:\n    NET = False\n"
             f"assert not NET, 'network reachable'\n"
             f"import os\nassert os.environ.get('ANNSLAM_CACHE') == 'off', 'study cache on'\n"
             f"from annslam_lib.slam import compiled\n"
             f"assert compiled.gating_kernel() is None, 'compiled gating on'\n"
             f"assert os.environ['NUMBA_CACHE_DIR'].startswith(os.environ['HOME']), 'numba cache'\n"
             + gs.OBSERVE_BODY)
    g = grade(gs.submission(probe, gs.SPEED_BODY), instructor, tmp_path, isolation="bwrap")
    server.close()
    assert g.score == FULL, g.report()         # the asserts held inside the sandbox


# ------------------------------------------------------------------ shortcuts

SHORTCUTS = {
    "attribute call": "def my_observe(pose, landmark):\n    return observation.observe(pose, landmark)[0]",
    "imported alias": ("from annslam_lib.models.observation import observe as o\n"
                       "def my_observe(pose, landmark):\n    return o(pose, landmark)[0]"),
    "hidden by getattr": ("def my_observe(pose, landmark):\n"
                          "    m = __import__('annslam_lib.models.observation', fromlist=['x'])\n"
                          "    return getattr(m, 'obs' + 'erve')(pose, landmark)[0]"),
}


@pytest.mark.parametrize("how", list(SHORTCUTS), ids=lambda a: a.replace(" ", "-"))
def test_calling_the_library_instead_of_writing_it_scores_zero(how, instructor, tmp_path,
                                                              course_files):
    g = grade(gs.submission(SHORTCUTS[how], gs.SPEED_BODY), instructor, tmp_path)
    r = by_id(g)["ex-observe-tests"]
    assert r.points == 0 and r.status in ("forbidden", "failed")
    said = ("my_observe uses __import__(), getattr() with a computed name" if how ==
            "hidden by getattr" else
            "my_observe calls annslam_lib.models.observation.observe: write it yourself")
    assert said in r.message, r.message
    assert by_id(g)["ex-speed-tests"].points == gs.POINTS["ex-speed-tests"]


def test_odd_return_values_fail_cleanly(instructor, tmp_path, course_files):
    odd = ("class Weird:\n    def __float__(self):\n        return 5.0\n"
           "def my_observe(pose, landmark):\n    return Weird(), Weird()")
    g = grade(gs.submission(odd, "def my_axle_speed(v_e, alpha, H, L):\n"
                                 "    return np.zeros(300_000)"), instructor, tmp_path)
    assert g.score == 0 and all(r.status == "failed" for r in g.exercises), g.report()


# ------------------------------------------------------------------ batches

def test_a_batch_grades_everything_it_can_and_reports_the_rest(instructor, tmp_path,
                                                              course_files):
    sub = tmp_path / "submitted"
    gs.write(gs.honest(), sub / "alice" / "chapter" / "chapter.ipynb")
    gs.write(gs.submission(), sub / "bob" / "chapter" / "chapter.ipynb")
    (sub / "carol" / "chapter").mkdir(parents=True)
    (sub / "carol" / "chapter" / "chapter.ipynb").write_text("this is not a notebook")
    gs.write(gs.submission(edit=lambda nb: nb.cells.clear()), sub / "dave" / "chapter" /
             "chapter.ipynb")
    gs.write(gs.submission(gs.OBSERVE_BODY), sub / "erin" / "chapter" / "chapter.ipynb")
    gs.write(gs.honest(), sub / "frank" / "chapter" / "other.ipynb")     # no such chapter
    out = tmp_path / "grades.json"
    results = grade_batch([sub], instructor_dir=instructor.parent, json_path=out,
                          limits=LIMITS, log=lambda s: None)
    rows = {r["student"]: r for r in json.loads(out.read_text())}
    assert sorted(rows) == ["alice", "bob", "carol", "dave", "erin", "frank"]
    assert rows["alice"]["score"] == FULL and rows["bob"]["score"] == 0
    assert rows["erin"]["score"] == gs.POINTS["ex-observe-tests"]
    assert rows["dave"]["graded"] and rows["dave"]["score"] == 0     # every cell restored
    assert not rows["carol"]["graded"] and "not a valid notebook" in rows["carol"]["reason"]
    assert not rows["frank"]["graded"] and "no instructor notebook" in rows["frank"]["reason"]
    for r in rows.values():
        assert Path(r["submission"]).is_absolute() and r["assignment"] == "chapter"
        assert r["max_score"] in (FULL, 0)
    assert len(results) == 6


@pytest.mark.needs_sandbox
def test_the_grade_command_exit_code_and_json(instructor, tmp_path, course_files):
    from annslam_lib.course.cli import main

    gs.write(gs.honest(), tmp_path / "a" / "chapter.ipynb")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "chapter.ipynb").write_bytes(b"\x00\x01")
    out = tmp_path / "g.json"
    code = main(["grade", str(tmp_path / "a"), str(tmp_path / "b"), "--instructor",
                 str(instructor.parent), "--json", str(out), "--timeout", "4", "--deadline", "45"])
    assert code == 1
    rows = json.loads(out.read_text())
    assert [r["graded"] for r in rows] == [True, False] and rows[0]["score"] == FULL
    assert "not UTF-8" in rows[1]["reason"] or "not a valid notebook" in rows[1]["reason"]
