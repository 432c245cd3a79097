"""The grader's economy of round trips: its batch of a check's inputs (``RemoteFunction.__annslam_prefetch__``): each
distinct input goes to the kernel once, a prefetched reply is used once, and a second
prefetch of the same inputs sends nothing new."""
import json
from types import SimpleNamespace

from annslam_lib.course import codec
from annslam_lib.course.grader import RemoteFunction


def _remote(calls):
    session = SimpleNamespace(sandbox=SimpleNamespace(limits=SimpleNamespace(call_timeout=1.0)))
    f = RemoteFunction(session, "square")

    def round_trip(method, payload, timeout):        # stands for the kernel: squares x
        calls.append((method, payload))
        def reply(p):
            (x,) = codec.decode(json.loads(p))
            return {"value": codec.encode(x * x, [])}
        return [reply(p) for p in payload] if method == "call_many" else reply(payload)

    f._round_trip = round_trip
    return f


def test_each_distinct_input_is_sent_once_and_a_repeat_prefetch_sends_nothing():
    calls = []
    f = _remote(calls)
    f.__annslam_prefetch__([(2,), (3,), (2,)])
    assert [(m, len(p)) for m, p in calls] == [("call_many", 2)]
    f.__annslam_prefetch__([(2,), (3,)])            # already held: no second round trip
    assert len(calls) == 1
    assert f(3) == 9 and f(2) == 4 and len(calls) == 1    # answered from the batch
    assert f(2) == 4                                       # used once: asked again
    assert [m for m, _ in calls] == ["call_many", "call"]


# -- one run of a student's whole loop per hidden run, for every test cell ----------------

def test_a_session_keeps_one_proxy_per_name_until_its_kernel_restarts():
    from annslam_lib.course.grader import _Session

    session = _Session(SimpleNamespace(), SimpleNamespace())
    first = session.proxy("my_localise")
    assert session.proxy("my_localise") is first           # the next test cell: same proxy
    assert session.proxy("my_slam") is not first
    session.restarts += 1                                  # a new kernel: a new proxy
    again = session.proxy("my_localise")
    assert again is not first and session.proxy("my_localise") is again


def test_a_loop_result_is_kept_per_function_run_and_rule_and_forgotten_after_a_submission():
    import numpy as np

    from annslam_lib.grading import _tracks, forget_results
    from annslam_lib.grading.core import forbids

    calls = []

    def loop(run):
        calls.append(run)
        K = 4
        return {"t": np.arange(K, dtype=float), "pose": np.zeros((K, 3)),
                "pose_cov": np.tile(np.eye(3), (K, 1, 1)), "landmarks": np.zeros(0),
                "landmark_cov": np.zeros((0, 0))}

    def other_library_function():
        pass

    @forbids(np.linalg.inv)
    def check(fn, run):
        return _tracks.result_of(fn, run, "my_localise")

    @forbids(other_library_function)
    def other_check(fn, run):
        return _tracks.result_of(fn, run, "my_localise")

    kept = dict(_tracks.CACHE)                      # other tests' entries, put back after
    _tracks.CACHE.clear()
    _tracks.CACHE[("reference", "sim:1:1")] = (None, {"nees_mean": 1.0})
    try:
        check(loop, "sim:1:1")
        check(loop, "sim:1:1")                      # a second test cell: read back
        assert calls == ["sim:1:1"]
        check(loop, "sim:2:1")
        assert calls == ["sim:1:1", "sim:2:1"]
        other_check(loop, "sim:1:1")                # another rule: computed under it
        assert calls == ["sim:1:1", "sim:2:1", "sim:1:1"]
        forget_results()
        assert list(_tracks.CACHE) == [("reference", "sim:1:1")]   # the reference stays
        check(loop, "sim:1:1")
        assert len(calls) == 4
    finally:
        _tracks.CACHE.clear()
        _tracks.CACHE.update(kept)
