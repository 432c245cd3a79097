"""The grader's codec carries SciPy sparse matrices as data (chapter 11's Gauss-Newton
step is passed one): a round trip keeps every entry, and a hostile message (an index out of
bounds, a row pointer that runs backwards, object data, a bad shape) is refused before any
matrix is used."""
import json

import numpy as np
import pytest
import scipy.sparse as sp

from annslam_lib.course import codec


def test_a_sparse_matrix_crosses_whole():
    m = sp.random(30, 12, density=0.2, random_state=1, format="csc")
    back = codec.loads(codec.dumps(m))
    assert sp.issparse(back) and back.shape == (30, 12)
    np.testing.assert_array_equal(back.toarray(), m.toarray())


def _tampered(change):
    tree = codec.encode(sp.identity(4, format="csr"))
    change(tree)
    return json.dumps(tree)


@pytest.mark.parametrize("change", [
    lambda t: t.update(indices=codec.encode(np.array([0, 1, 2, 9]))),         # column 9 of 4
    lambda t: t.update(indptr=codec.encode(np.array([0, 2, 1, 3, 4]))),       # runs backwards
    lambda t: t.update(shape=[4, -1]),
    lambda t: t.update(shape=[4, True]),
    lambda t: t.update(data=codec.encode(np.array(["a", "b", "c", "d"]))),
    lambda t: t.update(indices=codec.encode(np.array([0.0, 1.0, 2.0, 3.0]))),
], ids=["index-out-of-bounds", "pointer-backwards", "negative-shape", "bool-shape",
        "string-data", "float-indices"])
def test_a_malformed_sparse_matrix_is_refused(change):
    with pytest.raises(codec.CodecError):
        codec.loads(_tampered(change))


@pytest.mark.parametrize("parts", [
    {"indptr": np.array([0, 400000, -1]), "indices": np.array([0]), "data": np.array([1.0]),
     "shape": [2, 2]},                                         # SciPy's full check skips this
    {"indptr": np.array([0, 2**64 - 1], dtype=np.uint64), "indices": np.array([0]),
     "data": np.array([1.0]), "shape": [1, 2]},                # wraps to -1 as int64
    {"indptr": np.array([0, 1]), "indices": np.array([0]), "data": np.array([1.0]),
     "shape": [1, 2**31 - 1]},                                 # 16 GB when made dense
    {"indptr": np.array([0, 1, 2]), "indices": np.array([0, 1]), "data": np.array([1.0, 2.0]),
     "shape": [3, 2]},                                         # one row pointer short
], ids=["negative-last-pointer", "uint64-wrap", "huge-shape", "short-pointers"])
def test_a_sparse_matrix_that_would_crash_or_exhaust_the_grader_is_refused(parts):
    tree = {"t": "csr", "shape": parts["shape"],
            **{k: codec.encode(parts[k]) for k in ("indptr", "indices", "data")}}
    with pytest.raises(codec.CodecError):
        codec.loads(json.dumps(tree))


def test_duplicate_entries_arrive_summed():
    tree = {"t": "csr", "shape": [1, 3], "indptr": codec.encode(np.array([0, 2])),
            "indices": codec.encode(np.array([1, 1])), "data": codec.encode(np.array([2.0, 3.0]))}
    m = codec.loads(json.dumps(tree))
    assert m.nnz == 1 and m.toarray().tolist() == [[0.0, 5.0, 0.0]]
