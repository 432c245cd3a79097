"""The grader's batch of a check's inputs (``RemoteFunction.__annslam_prefetch__``): each
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
