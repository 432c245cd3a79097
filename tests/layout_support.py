"""A widget's kept layout stays clear: plots.style.render_png lays out the first figure of a
make with constrained layout and draws the later ones at the positions it kept. That skips
the measuring of the later figures' tick labels, so here every control of a widget is moved
to its ends (where the limits, and so the tick labels, differ most from the first figure's)
and each figure drawn at a kept layout is measured after all: every axes' tight box (ticks,
labels, title, legend) inside the figure, no two axes' boxes overlapping when their
frames do not, and no title over its axes' y offset text (kept figures place titles on the
frame without measuring)."""
import contextlib
import io

import matplotlib
import numpy as np

from ipywidgets import Checkbox, SelectionSlider
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.layout_engine import ConstrainedLayoutEngine

from annslam_lib.plots import blit, style

TOL_PX = 1.0


def _clear(fig, renderer=None) -> list[str]:
    """What of ``fig`` (drawn at a kept layout) is not clear, as sentences."""
    renderer = renderer or FigureCanvasAgg(fig).get_renderer()
    page = fig.bbox
    boxes, problems = [], []
    for i, ax in enumerate(fig.axes):
        if not ax.get_visible():
            continue
        bb = ax.get_tightbbox(renderer)
        if (bb.x0 < page.x0 - TOL_PX or bb.y0 < page.y0 - TOL_PX or bb.x1 > page.x1 + TOL_PX
                or bb.y1 > page.y1 + TOL_PX):
            problems.append(f"axes {i} ({ax.get_title()!r}) reaches outside the figure: "
                            f"{bb.bounds} in {page.bounds}")
        boxes.append((i, ax, bb))
        off = ax.yaxis.offsetText          # e.g. "1e-3" above the y axis: clear of the title
        if off.get_visible() and off.get_text():
            ob = off.get_window_extent(renderer)
            for t in (ax.title, ax._left_title, ax._right_title):
                if t.get_text() and ob.overlaps(t.get_window_extent(renderer)):
                    problems.append(f"axes {i}: the y offset text {off.get_text()!r} runs into "
                                    f"the title {t.get_text()!r}")
    for a in range(len(boxes)):
        for b in range(a + 1, len(boxes)):
            (i, ax_i, bi), (j, ax_j, bj) = boxes[a], boxes[b]
            if ax_i.get_position().overlaps(ax_j.get_position()):
                continue                     # twins, insets: meant to share room
            w = min(bi.x1, bj.x1) - max(bi.x0, bj.x0)
            h = min(bi.y1, bj.y1) - max(bi.y0, bj.y0)
            if w > TOL_PX and h > TOL_PX:
                problems.append(f"axes {i} ({ax_i.get_title()!r}) and {j} ({ax_j.get_title()!r}) "
                                f"overlap by {w:.0f} x {h:.0f} px")
    return problems


def _ends(control):
    if isinstance(control, SelectionSlider):
        n = len(control.options)
        return [("index", 0), ("index", n - 1)]
    if isinstance(control, Checkbox):
        return [("value", not control.value), ("value", control.value)]
    if hasattr(control, "min") and hasattr(control, "max"):
        return [("value", control.min), ("value", control.max)]
    return []


def controls(widget) -> list:
    return [c for c in widget.children if _ends(c)]


def assert_kept_layouts_clear(make_widget, *, min_checked: int = 2, only=None) -> int:
    """Build a widget with ``make_widget()`` (on an empty layout memo), move each control to
    its ends and back, and assert that every figure drawn at a kept layout is clear. Returns
    how many were checked (at least ``min_checked``: the mechanism was really used). ``only``:
    the indices (among the controls) to move, for a widget whose every step re-runs a filter."""
    drawn = []
    real = FigureCanvasAgg.print_png

    def print_png(canvas, *args, **kwargs):       # what render_png draws with
        fig = canvas.figure
        kept = (not isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine)
                and style.layout_signature(fig) in style._LAYOUTS)
        out = real(canvas, *args, **kwargs)
        if kept:
            drawn.append(fig)
        return out

    real_png = blit.Blit.png
    blitted = []

    def blit_png(view):
        out = real_png(view)
        problems = _clear(view.fig, view.canvas.get_renderer())
        shown = np.asarray(view.canvas.buffer_rgba()).copy()
        # The same state drawn from scratch: the figure without its moving artists, then
        # those drawn over it, as Blit does. Equal to the pixel unless the kept picture is stale.
        full = FigureCanvasAgg(view.fig)
        full.draw()
        for a in view.moving:
            if a.get_visible():
                view.fig.draw_artist(a)
        whole = np.asarray(full.buffer_rgba())
        view.fig.set_canvas(view.canvas)
        differ = int(np.count_nonzero(np.any(shown != whole, axis=-1)))
        if differ:
            problems.append(f"the blitted picture differs from the same state drawn from scratch "
                            f"in {differ} pixels (a changed artist not declared moving?)")
        # The kept picture itself: the figure with every moving artist hidden. A moving artist
        # that its parent draws anyway (an axis label: the axis draws it) shows here.
        view.canvas.restore_region(view._background)
        kept = np.asarray(view.canvas.buffer_rgba()).copy()
        visible = [a.get_visible() for a in view.moving]
        for a in view.moving:
            a.set_visible(False)
        bare = FigureCanvasAgg(view.fig)
        bare.draw()
        differ = int(np.count_nonzero(np.any(kept != np.asarray(bare.buffer_rgba()), axis=-1)))
        for a, v in zip(view.moving, visible):
            a.set_visible(v)
        view.fig.set_canvas(view.canvas)
        if differ:
            problems.append(f"the kept picture differs from the figure drawn without its moving "
                            f"artists in {differ} pixels (a moving artist drawn by its parent?)")
        blitted.append(problems)
        return out

    style._LAYOUTS.clear()
    FigureCanvasAgg.print_png = print_png
    blit.Blit.png = blit_png
    printing = np.get_printoptions()
    try:
        with matplotlib.rc_context(), contextlib.redirect_stdout(io.StringIO()):
            style.notebook_setup()                  # the chapters' style: constrained layout
            widget = make_widget()
            moved = controls(widget)
            for c in moved if only is None else [moved[i] for i in only]:
                start = c.index if isinstance(c, SelectionSlider) else c.value
                for attr, v in _ends(c):
                    setattr(c, attr, v)
                setattr(c, "index" if isinstance(c, SelectionSlider) else "value", start)
    finally:
        FigureCanvasAgg.print_png = real
        blit.Blit.png = real_png
        np.set_printoptions(**printing)
    kept = drawn
    problems = [f"figure {n}: {p}" for n, f in enumerate(kept) for p in _clear(f)]
    problems += [f"blitted step {n}: {p}" for n, ps in enumerate(blitted) for p in ps]
    assert not problems, "\n".join(problems)
    checked = len(kept) + len(blitted)
    assert checked >= min_checked, f"only {checked} figure(s) drawn at a kept layout or blitted"
    return checked
