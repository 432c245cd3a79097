"""plots.blit: a blitted picture equals the same figure drawn in full, a step replaces the
moving artists, drawn_by names what a draw added."""
import io

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from PIL import Image

from annslam_lib.plots.blit import Blit, drawn_by


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))


def _full(make) -> np.ndarray:
    fig = make()
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba()).copy()


def _figure(y):
    fig = Figure(figsize=(3, 2), dpi=50)
    ax = fig.subplots()
    ax.plot([0, 1], [0, 1], color="0.5")                      # kept
    ax.set(xlim=(0, 1), ylim=(0, 1))
    return fig, ax


def test_a_step_draws_the_new_marker_over_the_kept_picture():
    fig, ax = _figure(0.2)
    (_, moving) = drawn_by([ax], lambda: ax.plot([0.5], [0.2], "s", color="k"))
    assert len(moving) == 1 and moving[0] in ax.lines
    view = Blit(fig, moving)
    view.png()
    view.clear()
    view.set_moving(drawn_by([ax], lambda: ax.plot([0.5], [0.8], "s", color="k"))[1])
    assert len(ax.lines) == 2                                # the old marker was removed

    def expected():
        f, a = _figure(0.8)
        a.plot([0.5], [0.8], "s", color="k")
        return f

    # the blitted picture and a fresh figure in that state, drawn in full: the same pixels
    # (the marker is drawn last in both)
    np.testing.assert_array_equal(_pixels(view.png()), _full(expected))


def test_a_moving_artist_is_left_out_of_the_kept_picture():
    fig, ax = _figure(0.2)
    marker, = ax.plot([0.5], [0.2], "s", color="k")
    view = Blit(fig, [marker])
    marker.set_visible(False)
    shown = _pixels(view.png())                              # the kept picture alone
    f, _ = _figure(0.2)
    np.testing.assert_array_equal(shown, _full(lambda: f))
