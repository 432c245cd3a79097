"""A widget's pictures at several positions of one of its controls, captured in the kernel
that runs it: what the course's website plays where no kernel can move the widget.

:func:`capture` moves the control through :func:`positions` (evenly spread over its range,
and the position the widget was left at), lets the widget draw each one as it does for a
student, and keeps the picture with its alt text and the line it printed, without showing
anything: every output is captured, and the control is put back where it was. The refresh of
the stored outputs calls :func:`emit` in the notebook's own kernel, after Run All, for each
widget cell marked ``{"annslam": {"animate": {"control": DESCRIPTION}}}`` in its metadata.
"""
from __future__ import annotations

import base64
import html
import json
import math
import re

__all__ = ["capture", "positions", "find_control", "emit", "MARKER", "FRAMES"]

#: How many positions an animation shows (besides the widget's own).
FRAMES = 10
#: The line :func:`emit` prints before its JSON, so the refresh finds it among other output.
MARKER = "annslam-frames:"


def _parts(widget):
    """``widget`` and every widget inside it, breadth first."""
    queue = [widget]
    while queue:
        w = queue.pop(0)
        yield w
        queue.extend(getattr(w, "children", ()) or ())


def find_control(widget, description: str):
    """The control of ``widget`` (searched through its children) whose description is
    ``description``; ValueError naming the descriptions there are when none is."""
    seen = []
    for w in _parts(widget):
        if getattr(w, "description", None) == description and hasattr(w, "value"):
            return w
        if getattr(w, "description", None):
            seen.append(w.description)
    raise ValueError(f"no control {description!r} in the widget (it has {seen})")


def positions(control, count: int = FRAMES) -> list:
    """``count`` values evenly spread over ``control``'s range (a slider's min to max, on its
    step; a selection's options), with its current value, in order, without repeats."""
    if hasattr(control, "options") and not hasattr(control, "min"):
        options = [o[1] if isinstance(o, tuple) else o for o in control.options]
        idx = sorted({round(i * (len(options) - 1) / max(count - 1, 1)) for i in range(count)})
        values = [options[i] for i in idx]
    else:
        lo, hi = float(control.min), float(control.max)
        step = float(getattr(control, "step", 0) or 0)
        values = []
        for i in range(count):
            v = lo + (hi - lo) * i / max(count - 1, 1)
            if step > 0:
                v = lo + round((v - lo) / step) * step
            v = min(max(v, lo), hi)
            values.append(int(round(v)) if isinstance(control.value, int) else round(v, 10))
    values.append(control.value)
    out = []
    for v in values:
        if not any(_same(v, w) for w in out):
            out.append(v)
    if all(isinstance(v, (int, float)) for v in out):
        out.sort()
    return out


def _same(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        try:
            return math.isclose(float(a), float(b), rel_tol=0, abs_tol=1e-9)
        except (TypeError, ValueError):
            return False
    return a == b


def _picture(widget, outputs):
    """(png bytes, alt) the widget shows now: the last PNG it displayed (an Output's), or its
    Image widget's picture and title."""
    for out in reversed(outputs):
        data = getattr(out, "data", {}) or {}
        if "image/png" in data:
            png = data["image/png"]
            alt = (getattr(out, "metadata", {}) or {}).get("image/png", {}).get("alt", "")
            return (base64.b64decode(png) if isinstance(png, str) else png), alt
    for w in _parts(widget):
        if type(w).__name__ == "Image" and getattr(w, "format", "") == "png" and w.value:
            return bytes(w.value), getattr(w, "alt_text", "") or w.tooltip or ""
    raise ValueError("the widget showed no PNG picture")


def _label(control, value) -> str:
    if hasattr(control, "options") and not hasattr(control, "min"):
        for o in control.options:
            if isinstance(o, tuple) and _same(o[1], value):
                return str(o[0])
        return str(value)
    fmt = getattr(control, "readout_format", None) or ("d" if isinstance(value, int) else ".2f")
    try:
        return format(value, fmt)
    except (TypeError, ValueError):
        return str(value)


def capture(widget, description: str, count: int = FRAMES) -> list[dict]:
    """The widget's pictures at :func:`positions` of its control ``description``: one dict
    per position with ``value`` (the control's readout), ``png`` (base64), ``alt`` and
    ``text`` (what the widget printed or wrote there). Nothing is shown; the control ends
    where it was."""
    control = find_control(widget, description)
    start = control.value
    frames = []
    values = positions(control, count)
    # a control set to the value it holds does not redraw: begin elsewhere
    order = values[1:] + values[:1] if _same(values[0], start) else values
    try:
        for v in order:
            with _captured() as cap:
                control.value = v
            png, alt = _picture(widget, cap.outputs)
            text = _plain(cap.stdout)
            if not text:       # an HTML widget's <pre> line (chapters 05, 08)
                text = _html_text(widget)
            frames.append({"value": _label(control, v), "png": base64.b64encode(png).decode(),
                           "alt": alt, "text": text})
    finally:
        with _captured():
            control.value = start
    return [frames[order.index(v)] for v in values]


class _captured:
    """IPython's ``capture_output``, which an Output widget can write into: in a kernel, the
    widget first points the display publisher at its message (``set_parent``), which the
    capturing publisher does not have."""

    def __enter__(self):
        from IPython.utils.capture import capture_output

        self._cap = capture_output()
        cap = self._cap.__enter__()
        pub = getattr(self._cap, "shell", None) and self._cap.shell.display_pub
        if pub is not None and not hasattr(pub, "set_parent"):
            pub.set_parent = lambda parent: None
        return cap

    def __exit__(self, *exc):
        return self._cap.__exit__(*exc)


def _plain(text: str) -> str:
    """Printed text as a terminal shows it: escape sequences dropped, each line what follows
    its last carriage return (clear_output writes both)."""
    text = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", text)
    return "\n".join(line.split("\r")[-1] for line in text.split("\n")).strip()


def _html_text(widget) -> str:
    stack = [widget]
    while stack:
        w = stack.pop(0)
        if type(w).__name__ == "HTML" and w.value:
            return html.unescape(re.sub(r"<[^>]+>", "", w.value)).strip()
        stack.extend(getattr(w, "children", ()) or ())
    return ""


def emit(history_in, history_out, source: str, description: str, count: int = FRAMES) -> None:
    """Print :data:`MARKER` and the JSON of :func:`capture` for the widget that the last
    run of the cell ``source`` returned (IPython's ``In`` and ``Out``)."""
    runs = [k for k, s in enumerate(history_in) if s.strip() == source.strip()]
    if not runs or runs[-1] not in history_out:
        raise ValueError("the widget's cell has not returned a widget in this kernel")
    frames = capture(history_out[runs[-1]], description, count)
    print(MARKER + json.dumps({"control": description, "frames": frames}))
