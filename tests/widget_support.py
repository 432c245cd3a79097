"""Helpers the widget tests share (tests/test_widgets_*.py, tests/test_ann_plots.py).

``close_figures`` is an autouse fixture: a test module that imports it
(``from widget_support import close_figures  # noqa: F401``) has every figure closed after
each of its tests. ``move`` sets a widget's controls by their descriptions and redraws it.
"""
import pytest


@pytest.fixture(autouse=True)
def close_figures():
    yield
    import matplotlib.pyplot as plt   # here, not at import: the test module picks the backend
    plt.close("all")


def move(widget, **values):
    for c in widget.children:
        if getattr(c, "description", None) in values:
            c.value = values[c.description]
    widget.update()
    return widget.holder["summary"]
