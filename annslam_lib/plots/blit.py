"""A widget figure whose steps redraw only what moves (matplotlib's blitting).

A slider that moves a marker over fixed axes need not draw the axes again: the figure is
drawn in full once (laid out, ticks, labels, the lines that never change), that picture is
kept, and each step puts it back and draws the moving artists over it - the technique of
matplotlib's own animations (``FuncAnimation(blit=True)``). In chapter 08's explorer a step
costs a fraction of a whole redraw (a three-panel figure with log axes drawn again), and
most of what is left is the PNG encoding (``benchmarks/bench_notebooks.py`` measures steps
in the kernel).

The caller promises what blitting needs: nothing but the moving artists changes between
steps, and the moving artists stay within views that do not change (fixed limits), so the
kept picture stays true. ``tests/layout_support.py`` checks every blitted step of every
such widget at its controls' ends, as it does render_png's kept layouts.
"""
from __future__ import annotations

import io

import matplotlib.image
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg

from .style import mathtext_parser

__all__ = ["Blit", "drawn_by", "log_limits"]


class Blit:
    """``fig`` drawn once without its ``moving`` artists, then :meth:`png` at each step.

    fig: a matplotlib Figure (not pyplot's); moving: the artists a step changes (lines,
    markers, texts, a legend), marked animated so the full draw leaves them out. Change
    them (``set_data``, ``set_text``, :meth:`replace`), then call :meth:`png`."""

    def __init__(self, fig, moving) -> None:
        self.fig = fig
        self.moving = list(moving)
        for a in self.moving:
            a.set_animated(True)
        self.canvas = FigureCanvasAgg(fig)
        self.canvas.get_renderer().mathtext_parser = mathtext_parser()
        self.canvas.draw()                       # layout and the kept picture
        self.fig.set_layout_engine("none")       # the positions stay where they were drawn
        self._background = self.canvas.copy_from_bbox(fig.bbox)

    def set_moving(self, artists) -> None:
        """The artists the next steps draw (e.g. the new lines a step plotted, after the
        previous step's were removed)."""
        self.moving = list(artists)
        for a in self.moving:
            a.set_animated(True)

    def clear(self, keep=()) -> None:
        """Remove the moving artists from the figure (but those in ``keep``, e.g. titles a
        step only re-texts), before a step draws new ones (:meth:`set_moving`)."""
        for a in self.moving:
            if not any(a is k for k in keep):
                a.remove()
        self.moving = [a for a in self.moving if any(a is k for k in keep)]

    def replace(self, old, new) -> None:
        """Swap a moving artist for a new one (e.g. a legend made again with new labels)."""
        i = self.moving.index(old)
        new.set_animated(True)
        self.moving[i] = new

    def png(self) -> bytes:
        """The kept picture with the moving artists drawn over it, as PNG bytes at the
        figure's size and resolution."""
        self.canvas.restore_region(self._background)
        for a in self.moving:
            if a.get_visible():
                self.fig.draw_artist(a)
        buf = io.BytesIO()
        # zlib level 1: 0.022 s against the default level's 0.033 s for chapter 08's picture,
        # the file 4 % larger (the kernel sends it to a browser on the same machine or hub)
        matplotlib.image.imsave(buf, self.canvas.buffer_rgba(), format="png", origin="upper",
                                dpi=self.fig.dpi, pil_kwargs={"compress_level": 1})
        return buf.getvalue()


def drawn_by(axes, draw):
    """Call ``draw()`` and return (its result, the artists it added to ``axes``, a list of
    Axes): what a blitted step must draw again and later remove."""
    before = [set(ax.get_children()) for ax in axes]
    out = draw()
    return out, [c for ax, b in zip(axes, before) for c in ax.get_children() if c not in b]


def log_limits(arrays, what: str = "no positive, finite value") -> tuple[float, float]:
    """Log-axis limits that hold every positive, finite value of ``arrays`` with a margin of
    5 % of the decades (at least 0.005 decade): one fixed view for a widget's every step.
    Raises ValueError naming ``what`` when there is nothing to show."""
    v = np.concatenate([np.ravel(np.asarray(a, dtype=float)) for a in arrays]) if arrays else \
        np.empty(0)
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        raise ValueError(f"{what} to show")
    lo, hi = np.log10(v.min()), np.log10(v.max())
    pad = 0.05 * max(hi - lo, 0.1)
    return 10.0 ** (lo - pad), 10.0 ** (hi + pad)
