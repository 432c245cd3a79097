"""Alt text: what every figure of the course says to a reader who cannot see it.

A figure shown in a notebook is a PNG; a screen reader reads its ``alt`` attribute, which
an HTML export takes from the output's metadata (``{"image/png": {"alt": ...}}``, the
convention of IPython's ``Image(alt=...)``; nbconvert's classic template writes it). Every
figure gets one from :func:`alt_text`: the figure's message when its maker stated one with
:func:`describe` (what the reader should see in it), followed by what the figure holds, read
from the figure itself (title, panels, axes and their scales, the legend's series), so the
description cannot drift from the drawing. :func:`install` makes the notebook's figure
display carry it (``style.notebook_setup`` calls it); widgets pass it to ``style.show_png``.
"""
from __future__ import annotations

import re

from matplotlib.figure import Figure, SubFigure

__all__ = ["describe", "alt_text", "install", "MIN_LENGTH"]

#: A description shorter than this says nothing a reader could use ("a plot").
MIN_LENGTH = 40

_MESSAGE = "annslam_alt_message"     # the attribute holding describe()'s message


def describe(fig: Figure, message: str) -> Figure:
    """State ``fig``'s message, the first sentence of its alt text (chapter figures: what a
    reader should take from it). Returns ``fig``.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    message : str
        One or two plain sentences, no markup.

    Returns
    -------
    matplotlib.figure.Figure
        ``fig`` itself, so a figure function can end with ``return describe(fig, ...)``.
    """
    if not isinstance(fig, (Figure, SubFigure)):
        raise TypeError(f"describe needs a matplotlib Figure, got {type(fig).__name__}")
    if not isinstance(message, str) or not message.strip():
        raise ValueError("describe needs a non-empty message")
    setattr(fig, _MESSAGE, _plain(message))
    return fig


def _plain(text: str) -> str:
    """Mathtext and line breaks made readable: '$\\sigma_r$' -> 'sigma_r'."""
    text = re.sub(r"\\(mathrm|mathbf|mathit|text)\{([^}]*)\}", r"\2", text)
    text = text.replace("$", "").replace("\\", "").replace("{", "").replace("}", "")
    return " ".join(text.split())


def _sentence(text: str) -> str:
    text = text.strip()
    return text if not text or text[-1] in ".!?" else text + "."


def _axis(ax, which: str) -> str:
    axis = ax.xaxis if which == "x" else ax.yaxis
    label = _plain(axis.get_label().get_text())
    if not label:                  # a shared axis is often labelled on one panel only
        shared = ax.get_shared_x_axes() if which == "x" else ax.get_shared_y_axes()
        for other in shared.get_siblings(ax):
            other_axis = other.xaxis if which == "x" else other.yaxis
            label = _plain(other_axis.get_label().get_text())
            if label:
                break
    scale = ax.get_xscale() if which == "x" else ax.get_yscale()
    if label and scale != "linear":
        label += f" ({scale} scale)"
    return label


def _series(ax) -> list[str]:
    legend = ax.get_legend()
    if legend is not None:
        names = [_plain(t.get_text()) for t in legend.get_texts()]
    else:
        names = [_plain(h) for h in ax.get_legend_handles_labels()[1]]
    return [n for n in dict.fromkeys(names) if n]


def _title(ax) -> str:
    return " ".join(_plain(t.get_text()) for t in (ax._left_title, ax.title, ax._right_title)
                    if t.get_text())


def _content(ax) -> str:
    """What a panel holds, without its title: 'y against x; showing A, B'."""
    x, y = _axis(ax, "x"), _axis(ax, "y")
    bits = []
    if ax.images:
        bits.append("an image" + (f" over {y} and {x}" if x and y else ""))
    elif x and y:
        bits.append(f"{y} against {x}")
    elif x or y:
        bits.append(x or y)
    names = _series(ax)
    if names:
        bits.append("showing " + ", ".join(names))
    return "; ".join(bits)


def _panel(title: str, body: str) -> str:
    """A panel in words from its title and :func:`_content`."""
    if title and body:
        return f'"{title}": {body}'
    return f'"{title}"' if title else body


def _drawn_axes(fig) -> list:
    # colour bars and empty axes carry no panel of their own
    return [ax for ax in fig.axes if ax.get_visible() and ax.axison
            and not hasattr(ax, "_colorbar")
            and (ax.lines or ax.collections or ax.images or ax.patches or ax.texts
                 or ax.get_title())]


def alt_text(fig: Figure) -> str:
    """The figure's alt text: its :func:`describe` message (if any), then what it holds,
    read from the figure (suptitle; per panel its title, y against x with non-linear scales
    named, the legend's series; panels that differ only in their titles described once).

    Parameters
    ----------
    fig : matplotlib.figure.Figure

    Returns
    -------
    str
        Plain text, one paragraph.
    """
    if not isinstance(fig, (Figure, SubFigure)):
        raise TypeError(f"alt_text needs a matplotlib Figure, got {type(fig).__name__}")
    message = getattr(fig, _MESSAGE, "")
    sup = _plain(fig._suptitle.get_text()) if fig._suptitle is not None else ""
    named = f' "{sup}"' if sup else ""
    axes = _drawn_axes(fig)
    contents = [_content(ax) for ax in axes]
    titles = [_title(ax) for ax in axes]
    panels = [p for p in map(_panel, titles, contents) if p]
    if len(axes) > 2 and contents[0] and len(set(contents)) == 1 and all(titles):
        # small multiples: the same axes and series, one panel per case
        what = (f"Figure of {len(axes)} panels{named}, each {contents[0]}, titled "
                + ", ".join(f'"{t}"' for t in titles))
    elif len(panels) == 1:
        what = f"Figure{named}: {panels[0]}"
    elif panels:
        what = (f"Figure of {len(panels)} panels{named}. "
                + " ".join(f"Panel {k}, {p}." for k, p in enumerate(panels, 1)))
    else:
        what = f"Figure{named}"
    return " ".join(s for s in (_sentence(message), _sentence(what)) if s)


def _png_with_alt(png_formatter):
    def png_and_alt(fig):
        data = png_formatter(fig)
        if data is None:
            return None
        return data, {"alt": alt_text(fig)}
    png_and_alt.annslam_alt = True
    return png_and_alt


def _wrap(shell) -> None:
    formatter = shell.display_formatter.formatters["image/png"]
    try:
        current = formatter.lookup_by_type(Figure)
    except KeyError:                       # no PNG display of figures: nothing to label
        return
    if not getattr(current, "annslam_alt", False):
        formatter.for_type(Figure, _png_with_alt(current))


def install() -> bool:
    """Make every matplotlib figure the running IPython kernel displays carry its
    :func:`alt_text` in the output's metadata. Kept in place before each cell (the inline
    backend replaces the figure formatter when it is configured again). Returns False
    outside IPython (nothing to do)."""
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    if shell is None or not hasattr(shell, "display_formatter"):
        return False
    import matplotlib.pyplot as plt

    if not plt.get_fignums():
        # load the backend now (switching closes figures: there are none), so the inline
        # backend's own figure formatter is in place before the first figure is drawn
        plt.switch_backend(plt.get_backend())
    _wrap(shell)
    callbacks = shell.events.callbacks.get("pre_run_cell", [])
    if not any(getattr(c, "annslam_alt", False) for c in callbacks):
        def keep(*_args):
            _wrap(shell)
        keep.annslam_alt = True
        shell.events.register("pre_run_cell", keep)
    return True
