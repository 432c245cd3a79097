"""The grader's end inside the sandboxed kernel: call one of the student's functions.

The grader (:mod:`annslam_lib.course.grader`) imports this module in the kernel after the
submission's notebook has run, then, for every call a check makes, executes
``__annslam_kernel__.call(name, args_json, forbidden_json)`` and reads the returned JSON.
Everything here runs next to the student's code and can be changed by it; that is fine,
because nothing here decides a score: at most it changes what the student's own function
appears to return, which the grader compares with its own reference in its own process.
"""
from __future__ import annotations

import json

from ..grading.core import watch_calls
from .codec import MAX_BYTES, CodecError, module_spec, decode, encode

__all__ = ["call", "call_many", "REPLY_BYTES"]

#: Largest reply sent back in one message (the grader refuses larger ones).
REPLY_BYTES = MAX_BYTES // 4


def call(name: str, payload: str, forbidden: str = "[]") -> str:
    """Run the user namespace's ``name(*args)`` and return a JSON reply: the encoded value
    or exception, the weights of any torch module argument after the call (training
    exercises change them in place), and the forbidden library functions it called."""
    ip = get_ipython()  # noqa: F821 - defined in an IPython kernel
    fn = ip.user_ns.get(name)
    if not callable(fn):
        err = NameError(f"name {name!r} is not defined (or not a function): keep the "
                        "function's name as the exercise gives it")
        return json.dumps({"error": encode(err), "hits": [], "states": []})
    modules: list = []
    try:
        args = decode(json.loads(payload), modules)
    except (CodecError, ValueError) as e:
        return json.dumps({"error": encode(e), "hits": [], "states": []})
    value = error = None
    with watch_calls(json.loads(forbidden)) as hits:
        try:
            value = fn(*args)
        except Exception as e:                # KeyboardInterrupt (a time-out) propagates
            error = e
    reply = {"hits": sorted(set(hits)), "states": []}
    try:
        reply["states"] = [module_spec(m)["state"] for m in modules]
        reply["value" if error is None else "error"] = encode(value if error is None else error)
        text = json.dumps(reply, allow_nan=False)
        if len(text) > REPLY_BYTES:
            raise CodecError(f"it is {len(text) / 1e6:.0f} MB encoded, more than the "
                             f"{REPLY_BYTES / 1e6:.0f} MB a result may be")
        return text
    except Exception as e:
        reply = {"error": encode(CodecError(f"the result cannot be sent back: {e}")),
                 "hits": reply["hits"], "states": []}
    return json.dumps(reply, allow_nan=False)


def call_many(name: str, payloads: list, forbidden: str = "[]") -> str:
    """:func:`call` for each payload; one JSON list of replies (a check's batch of inputs
    in one round trip). A batch that would outgrow one message stops early: the grader then
    asks for the calls one by one."""
    out, size = [], 0
    for p in payloads:
        out.append(call(name, p, forbidden))
        size += len(out[-1])
        if size > REPLY_BYTES:
            break
    return "[" + ",".join(out) + "]"
