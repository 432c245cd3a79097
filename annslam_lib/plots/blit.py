"""A widget figure whose steps redraw only what moves (matplotlib's blitting).

A slider that moves a marker over fixed axes need not draw the axes again: the figure is
drawn in full once (laid out, ticks, labels, the lines that never change), that picture is
kept, and each step puts it back and draws the moving artists over it - the technique of
matplotlib's own animations (``FuncAnimation(blit=True)``). In chapter 08's explorer a step
fell from 0.49 s (a whole three-panel figure with log axes drawn again) to 0.035 s, of which
the PNG encoding is 0.022 s (one process, this machine; ``benchmarks/bench_notebooks.py``
measures steps in the kernel).

The caller promises what blitting needs: nothing but the moving artists changes between
steps, and the moving artists stay within views that do not change (fixed limits), so the
kept picture stays true. ``tests/layout_support.py`` checks every blitted step of every
such widget at its controls' ends, as it does render_png's kept layouts.
"""
from __future__ import annotations

import io

import matplotlib.image
from matplotlib.backends.backend_agg import FigureCanvasAgg

from .style import _mathtext_parser

__all__ = ["Blit", "drawn_by"]


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
        self.canvas.get_renderer().mathtext_parser = _mathtext_parser()
        self.canvas.draw()                       # layout and the kept picture
        self.fig.set_layout_engine("none")       # the positions stay where they were drawn
        self._background = self.canvas.copy_from_bbox(fig.bbox)

    def set_moving(self, artists) -> None:
        """The artists the next steps draw (e.g. the new lines a step plotted, after the
        previous step's were removed)."""
        self.moving = list(artists)
        for a in self.moving:
            a.set_animated(True)

    def step(self, draw, keep=()) -> None:
        """Replace the moving artists: remove them from the figure (but those in ``keep``,
        e.g. titles a step only re-texts), then ``draw()``, which returns the new ones."""
        for a in self.moving:
            if not any(a is k for k in keep):
                a.remove()
        self.set_moving(draw())

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
