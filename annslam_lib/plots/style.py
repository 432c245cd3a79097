"""The course's one plotting style: the notebook set-up, the axes helper, the widget
figures, and the shared marker styles.

``notebook_setup()`` is the first line of every chapter (NumPy print options, figure size,
resolution and fonts), so figures look the same everywhere and use the notebook's width.
Every plotting function of :mod:`annslam_lib.plots` draws on an ``ax`` it is given (or a new
one from :func:`axes`) and returns it, so a notebook cell stays one line.
"""
from __future__ import annotations

import functools
import io

import matplotlib.pyplot as plt
from cycler import cycler
import numpy as np
from matplotlib.figure import Figure

from . import alt

__all__ = ["notebook_setup", "axes", "figure", "widget_figure", "show_widget_figure", "show_png",
           "show_in_image", "render_png", "keyboard_ready", "FOCUS_CLASS",
           "layout_signature",
           "BEACON_STYLE", "FIG_WIDTH", "DPI", "PALETTE", "BLUE", "ORANGE", "GREEN", "RED",
           "PURPLE", "SKY", "BLACK", "GREY"]

#: Width of a full-width figure (inches) and the resolution of the notebook's images: a
#: figure FIG_WIDTH wide at DPI fills about 1000 px, the text column of JupyterLab at
#: 1400 px browser width.
FIG_WIDTH = 11.0
DPI = 90

#: The course's colours: Okabe and Ito's palette ("Color Universal Design", 2008), whose
#: colours stay apart for readers with any common colour-vision deficiency. RED and GREEN
#: are its vermillion and bluish green, which differ in lightness as well as hue.
BLUE, ORANGE, GREEN, RED = "#0072B2", "#E69F00", "#009E73", "#D55E00"
PURPLE, SKY, BLACK, GREY = "#CC79A7", "#56B4E9", "#000000", "#666666"
#: The colour cycle of every figure (``notebook_setup``).
PALETTE = (BLUE, ORANGE, GREEN, RED, PURPLE, SKY, BLACK, GREY)

BEACON_STYLE = dict(marker="*", s=140, color=RED, edgecolor="k", linewidth=0.5, zorder=5)


def widget_figure(nrows: int = 1, ncols: int = 1, *, figsize, layout=None, **subplots_kw):
    """A Figure made outside pyplot and its axes (``Figure.subplots(nrows, ncols, **subplots_kw)``),
    for a widget callback to draw on; show it with :func:`show_widget_figure`. ``layout``:
    the Figure's layout engine (None: the course style's, constrained).

    With JupyterLab 4.6 and ipykernel 7 a kernel subshell thread runs matplotlib-inline's
    ``flush_figures`` while a callback is still drawing, showing and closing every open pyplot
    figure (blank or half-drawn plots, found by tests/test_browser.py); pyplot never sees this one."""
    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(nrows, ncols, **subplots_kw)



def show_widget_figure(fig: Figure) -> None:
    """Display a :func:`widget_figure` in the callback's Output (instead of ``plt.show()``),
    as the PNG of :func:`render_png`.

    Explicit display, because no pyplot flush knows about the figure; nothing else can show
    it early from another thread, which is the point (see :func:`widget_figure`)."""
    show_png(render_png(fig), alt.alt_text(fig))


def show_png(png: bytes, alt_text: str) -> None:
    """Display PNG bytes in the callback's Output (a :class:`plots.blit.Blit` picture, or
    :func:`render_png`'s) with their alt text (:func:`plots.alt.alt_text` of the figure
    drawn), which the output's metadata carries."""
    from IPython.display import Image, display  # only widgets need IPython

    if not isinstance(alt_text, str) or len(alt_text) < alt.MIN_LENGTH:
        raise ValueError(f"show_png needs the picture's alt text (at least {alt.MIN_LENGTH} "
                         f"characters: what it shows), got {alt_text!r}")
    display(Image(data=png, format="png", alt=alt_text))


def show_in_image(image, png: bytes, alt_text: str) -> None:
    """Show PNG bytes in an ipywidgets ``Image`` (a widget that redraws in place, as chapter
    05's and 08's explorers do) and keep their alt text on the widget object
    (``image.alt_text``), where the website's animation frames read it. Not as the Image's
    ``tooltip``: with one, ipywidgets 8.1's Image did not render in JupyterLab 4.6 (a
    JavaScript error in its place)."""
    if not isinstance(alt_text, str) or len(alt_text) < alt.MIN_LENGTH:
        raise ValueError(f"show_in_image needs the picture's alt text (at least "
                         f"{alt.MIN_LENGTH} characters: what it shows), got {alt_text!r}")
    image.alt_text = alt_text
    image.value = png


#: The class :func:`keyboard_ready` gives a widget's box, which its focus style selects.
FOCUS_CLASS = "annslam-keys"
# ipywidgets 8.1 draws no focus indicator on its slider handles ("outline: none") nor on its
# drop-downs ("outline: none !important"), so a keyboard user cannot see where they are
# (WCAG 2.4.7). One outline for every focusable part of a course widget, in JupyterLab's own
# accent colour (3:1 or more against its light and dark backgrounds), outside the control.
_FOCUS_CSS = (f".{FOCUS_CLASS} :focus-visible {{outline: 2px solid var(--jp-brand-color1, "
              f"#1976d2) !important; outline-offset: 2px !important}}")


def keyboard_ready(widget):
    """Give a chapter's widget a visible keyboard focus: every control of it (slider handles,
    readouts, drop-downs, check boxes) shows an outline while the keyboard is on it. A style
    sheet travels with the widget as a hidden ``HTML`` child, so it works wherever the widget
    is shown live (JupyterLab, Notebook 7, VS Code), before ``widget.out`` for an
    ``interactive`` (whose output stays the last child). Returns ``widget``."""
    from ipywidgets import HTML, Layout

    sheet = HTML(f"<style>{_FOCUS_CSS}</style>", layout=Layout(display="none"))
    kids = list(widget.children)
    out = getattr(widget, "out", None)
    at = next((i for i, k in enumerate(kids) if k is out), len(kids))
    widget.children = tuple(kids[:at] + [sheet] + kids[at:])
    widget.add_class(FOCUS_CLASS)
    return widget


#: Axes positions of the widget figures laid out so far, by :func:`layout_signature`.
_LAYOUTS: dict[tuple, list] = {}
_LAYOUTS_MAX = 64


def _lines(text) -> int:
    """How many lines a Text artist takes (0 when empty): what its height depends on."""
    t = text.get_text() if text is not None else ""
    return t.count("\n") + 1 if t else 0


def layout_signature(fig: Figure) -> tuple:
    """What a figure's constrained layout depends on, short of its tick labels: its size, and
    per axes the grid cell, the title, axis-label and legend line counts, scales and aspect
    (with a fixed aspect that shapes the box, the shape of the data box to two digits).
    Two figures with the same signature get the same layout (up to their tick labels' widths,
    which the layout's padding absorbs: tested for every widget at its sliders' ends)."""
    def grid(ax):
        ss = ax.get_subplotspec()
        if ss is None:
            return None
        gs = ss.get_gridspec()
        return (ss.rowspan.start, ss.rowspan.stop, ss.colspan.start, ss.colspan.stop,
                gs.get_geometry(), tuple(gs.get_width_ratios() or ()),
                tuple(gs.get_height_ratios() or ()))

    def legend(ax):
        lg = ax.get_legend()
        return None if lg is None else (len(lg.get_texts()), lg._loc, lg._bbox_to_anchor is not None)

    def shape(ax):
        # an axes of fixed aspect takes the shape of its data box (part of the layout),
        # unless it widens its data limits instead ("datalim")
        if ax.get_aspect() == "auto" or ax.get_adjustable() == "datalim":
            return None
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        return float(f"{abs((y1 - y0) / (x1 - x0)) if x1 != x0 else 0.0:.2g}")

    axes = tuple((type(ax).__name__, grid(ax), ax.axison, ax.get_aspect(), shape(ax), ax.get_xscale(),
                  ax.get_yscale(), _lines(ax.title), _lines(ax._left_title), _lines(ax._right_title),
                  _lines(ax.xaxis.label), _lines(ax.yaxis.label), ax.xaxis.get_label_position(),
                  ax.yaxis.get_label_position(), ax.xaxis.get_ticks_position(),
                  ax.yaxis.get_ticks_position(), legend(ax)) for ax in fig.axes)
    return (tuple(fig.get_size_inches()), fig.dpi, _lines(fig._suptitle), _lines(fig._supxlabel),
            _lines(fig._supylabel), axes)


@functools.lru_cache(maxsize=1)
def mathtext_parser():
    from matplotlib.mathtext import MathTextParser

    return MathTextParser("path")            # what the Agg renderer makes for itself


def render_png(fig: Figure) -> bytes:
    """``fig`` as PNG bytes at its own size and resolution, drawn once.

    A widget draws a figure of the same make at every step. The course style's constrained
    layout takes about half of a step's drawing time (it measures every label before the
    draw), so the first figure of a :func:`layout_signature` is laid out by it and the
    positions of its axes are kept; a later figure with the same signature is drawn at those
    positions, without the layout pass (tests/layout_support.py measures the result at every
    widget's control ends). Drawn by the Agg canvas directly: ``savefig`` would draw a
    figure with a layout engine twice (once to measure, once to render), and so would the
    inline backend's ``bbox_inches='tight'``; the layout already keeps labels inside."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    key = kept = None
    if isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine):
        key = layout_signature(fig)
        kept = _LAYOUTS.get(key)
        if kept is not None:
            fig.set_layout_engine("none")
            for ax, (pos, title_at_top) in zip(fig.axes, kept):
                ax.set_position(pos)
                if title_at_top:
                    # The first figure's titles sat on the frame: place these there too,
                    # instead of measuring the ticks again to see whether they must move
                    # (a third of a step on a figure with log axes).
                    for t in (ax.title, ax._left_title, ax._right_title):
                        t.set_y(1.0)
                    ax._autotitlepos = False
    canvas = FigureCanvasAgg(fig)
    # One mathtext parser for every figure: each new renderer makes its own, whose parse
    # cache starts empty, and parsing a log axis's "10^k" labels took a third of a step.
    canvas.get_renderer().mathtext_parser = mathtext_parser()
    buf = io.BytesIO()
    canvas.print_png(buf)
    if key is not None and kept is None:
        if len(_LAYOUTS) >= _LAYOUTS_MAX:
            _LAYOUTS.pop(next(iter(_LAYOUTS)))
        _LAYOUTS[key] = [(ax.get_position(original=True).frozen(),
                          ax.xaxis.get_ticks_position() == "bottom"
                          and ax.xaxis.get_label_position() == "bottom"
                          and all(t.get_position()[1] == 1.0
                                  for t in (ax.title, ax._left_title, ax._right_title)))
                         for ax in fig.axes]
    return buf.getvalue()


def notebook_setup(*, precision: int = 3, linewidth: int = 110) -> None:
    """The set-up line of every chapter: NumPy prints ``precision`` digits (no scientific
    notation for small numbers), and matplotlib draws figures :data:`FIG_WIDTH` wide at
    :data:`DPI` with readable fonts and layouts that keep labels clear of the data."""
    np.set_printoptions(precision=precision, suppress=True, linewidth=linewidth)
    plt.rcParams.update({
        "figure.dpi": DPI, "savefig.dpi": DPI, "figure.figsize": (FIG_WIDTH, 4.5),
        "figure.constrained_layout.use": True, "font.size": 10, "axes.titlesize": 11,
        "axes.labelsize": 10, "legend.fontsize": 9, "xtick.labelsize": 9,
        "ytick.labelsize": 9, "legend.framealpha": 0.85, "axes.grid": False,
        "axes.prop_cycle": cycler(color=PALETTE),
    })
    alt.install()             # every figure shown carries its alt text (plots.alt)


def axes(ax=None, figsize=(6, 6)):
    """``ax``, or the axes of a new figure of ``figsize`` (inches)."""
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def figure(nrows: int = 1, ncols: int = 1, *, height: float = 4.5, **subplots_kw):
    """A full-width pyplot figure (:data:`FIG_WIDTH` wide, ``height`` inches tall) and its
    axes: every chapter figure starts here, so all use the notebook's width."""
    return plt.subplots(nrows, ncols, figsize=(FIG_WIDTH, height), **subplots_kw)

