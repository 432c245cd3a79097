"""The widgets of chapters 05-10 driven in JupyterLab + headless Chromium: see
tests/browser_widgets.py for what is checked."""
import pytest
from browser_widgets import browser, check_widgets, chromium, lab, notebooks  # noqa: F401

NOTEBOOKS = notebooks(5, 10)


@pytest.mark.parametrize("stem", NOTEBOOKS)
def test_every_widget_answers_its_slider_in_jupyterlab(stem, lab, browser):  # noqa: F811
    check_widgets(stem, lab, browser)
