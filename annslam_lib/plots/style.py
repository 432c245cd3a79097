"""The course's one plotting style: the notebook set-up, the axes helper, the widget
figures, and the shared marker styles.

``notebook_setup()`` is the first line of every chapter (NumPy print options, figure size,
resolution and fonts), so figures look the same everywhere and use the notebook's width.
Every plotting function of :mod:`annslam_lib.plots` draws on an ``ax`` it is given (or a new
one from :func:`axes`) and returns it, so a notebook cell stays one line.
"""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

__all__ = ["notebook_setup", "axes", "figure", "widget_figure", "show_widget_figure",
           "BEACON_STYLE", "FIG_WIDTH", "DPI"]

#: Width of a full-width figure (inches) and the resolution of the notebook's images: a
#: figure FIG_WIDTH wide at DPI fills about 1000 px, the text column of JupyterLab at
#: 1400 px browser width.
FIG_WIDTH = 11.0
DPI = 90

BEACON_STYLE = dict(marker="*", s=140, color="tab:red", edgecolor="k", linewidth=0.5, zorder=5)


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
    """Display a :func:`widget_figure` in the callback's Output (instead of ``plt.show()``).

    Explicit display, because no pyplot flush knows about the figure; nothing else can show
    it early from another thread, which is the point (see :func:`widget_figure`)."""
    from IPython.display import display  # only widgets need IPython

    display(fig)



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
    })


def axes(ax=None, figsize=(6, 6)):
    """``ax``, or the axes of a new figure of ``figsize`` (inches)."""
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def figure(nrows: int = 1, ncols: int = 1, *, height: float = 4.5, **subplots_kw):
    """A full-width pyplot figure (:data:`FIG_WIDTH` wide, ``height`` inches tall) and its
    axes: every chapter figure starts here, so all use the notebook's width."""
    return plt.subplots(nrows, ncols, figsize=(FIG_WIDTH, height), **subplots_kw)

