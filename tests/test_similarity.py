"""Copied-code detection (annslam_lib.course.similarity): a renamed or reformatted
copy of the library's function, and two students sharing code, are flagged; honest
solutions of the same exercise are not."""
import inspect
import re

import pytest

from annslam_lib.course import similarity as sim
from annslam_lib.evaluation import map as map_eval

LIBRARY = inspect.getsource(map_eval.rigid_align)

HONEST_A = '''
def my_rigid_align(a, b):
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    a_bar = a.mean(axis=0)
    b_bar = b.mean(axis=0)
    C = (a - a_bar).T @ (b - b_bar)
    U, S, Vt = np.linalg.svd(C)
    V = Vt.T
    d = np.linalg.det(V @ U.T)
    R = V @ np.diag([1, d]) @ U.T
    t = b_bar - R @ a_bar
    return R, t
'''

HONEST_B = '''
def my_rigid_align(a, b):
    # centre both point sets, then the SVD of the cross-covariance
    ma, mb = np.mean(a, 0), np.mean(b, 0)
    H = np.zeros((2, 2))
    for p, q in zip(a, b):
        H += np.outer(p - ma, q - mb)
    u, s, vt = np.linalg.svd(H)
    rot = vt.T @ u.T
    if np.linalg.det(rot) < 0:
        vt[1, :] *= -1
        rot = vt.T @ u.T
    return rot, mb - rot @ ma
'''


def _renamed(src):
    """Every name the function chooses, renamed (whole words only)."""
    for old, new in (("rigid_align", "my_rigid_align"), ("ca", "centre_a"), ("cb", "centre_b"),
                     ("da", "xa"), ("db", "xb"), ("dd", "diff"), ("Vt", "W"), ("U", "Q"),
                     ("R", "rot"), ("d", "sgn")):
        src = re.sub(rf"\b{old}\b", new, src)
    return src


def _reformatted(src):
    body = src.replace('"""', "'''").replace("    ", "        ")        # other quotes, indent
    body = body.replace("ca, cb = a.mean(axis=0), b.mean(axis=0)",
                        "ca = a.mean(axis=0)   # centroid of a\n        cb = (b.mean(axis=0))")
    return "# my answer\n\n" + body.replace("\n", "\n\n")


def test_copies_of_the_library_score_high_and_honest_solutions_do_not():
    renamed, reformatted = _renamed(LIBRARY), _reformatted(LIBRARY)
    assert "ca" not in renamed.split("(")[0] and renamed != LIBRARY
    assert sim.similarity(renamed, LIBRARY) == pytest.approx(1.0)
    assert sim.similarity(reformatted, LIBRARY) > 0.95          # one statement split in two
    for honest in (HONEST_A, HONEST_B):
        assert sim.similarity(honest, LIBRARY) < sim.THRESHOLD - 0.1
    assert sim.similarity(HONEST_A, HONEST_B) < sim.THRESHOLD


def test_flags_name_the_copy_its_source_and_the_students_sharing_code():
    shared = HONEST_A.replace("a_bar", "abar").replace("b_bar", "bbar") + "# checked it\n"
    solutions = {"ann": HONEST_A, "bob": shared, "cy": HONEST_B, "dee": _renamed(LIBRARY),
                 "eve": "def my_rigid_align(a, b):\n    return (\n"}          # does not parse
    flags = sim.flag_copies(solutions, {"rigid_align": LIBRARY})
    pairs = {(f.student, f.other) for f in flags}
    assert pairs == {("dee", "library: rigid_align"), ("ann", "bob")}
    lib = next(f for f in flags if f.student == "dee")
    assert lib.other_source == LIBRARY and lib.similarity == pytest.approx(1.0)
    assert set(lib.as_json()) == {"student", "other", "similarity", "other_source"}


def test_normalisation_ignores_names_constants_layout_and_docstrings():
    a = 'def f(x, y=2):\n    """doc"""\n    z = x + y * 3.5  # c\n    return np.sqrt(z)\n'
    b = "def g(p, q=7):\n    r = p + q * 1.0\n\n    return np.sqrt(r)\n"
    c = "def g(p, q=7):\n    r = p + q * 1.0\n    return np.cbrt(r)\n"          # another API
    assert sim.normalised(a) == sim.normalised(b)
    assert sim.normalised(b) != sim.normalised(c)
    assert sim.normalised("x = 1\ndef h(u):\n    return u\n", function="h") == \
        sim.normalised("def k(w):\n    return w\n", function="k")


@pytest.mark.parametrize("bad, err, match", [
    ("def f(:\n", ValueError, "not valid Python"), (b"x = 1", TypeError, "str"),
])
def test_bad_solutions_get_a_clear_error(bad, err, match):
    with pytest.raises(err, match=match):
        sim.normalised(bad)
    with pytest.raises(ValueError, match="no function"):
        sim.normalised("x = 1\n", function="f")
    with pytest.raises(ValueError, match="threshold"):
        sim.flag_copies({"a": "x = 1"}, threshold=0)
