"""annslam_lib.plots.frames: the values an animation visits and the control it moves (the
capture itself runs in a kernel at refresh; tests/test_site.py checks what it stored)."""
import pytest
from ipywidgets import FloatSlider, HBox, Image, IntSlider, SelectionSlider, VBox

from annslam_lib.plots import frames, style


def test_positions_spread_over_the_range_on_the_step_and_keep_the_current_value():
    s = IntSlider(value=150, min=0, max=585)
    assert frames.positions(s, 5) == [0, 146, 150, 292, 439, 585]
    f = FloatSlider(value=0.3, min=-0.6, max=0.6, step=0.05)
    got = frames.positions(f, 5)
    assert got == pytest.approx([-0.6, -0.3, 0.0, 0.3, 0.6])          # 0.3 is one of them
    assert all(abs(v / 0.05 - round(v / 0.05)) < 1e-9 for v in got)
    sel = SelectionSlider(options=[("1", 1), ("2", 2), ("5", 5), ("10", 10), ("20", 20)], value=10)
    assert frames.positions(sel, 10) == [1, 2, 5, 10, 20]
    assert frames.positions(sel, 3) == [1, 5, 10, 20]                    # the current one added


def test_a_control_is_found_by_its_description_anywhere_in_the_widget():
    inner = FloatSlider(description="t [s]")
    w = VBox([HBox([IntSlider(description="scan"), inner]), Image()])
    assert frames.find_control(w, "t [s]") is inner
    with pytest.raises(ValueError, match=r"no control 'gate'.*'scan', 't \[s\]'"):
        frames.find_control(w, "gate")


def test_printed_text_is_kept_as_a_terminal_shows_it():
    assert frames._plain("\x1b[2K\r\x1b[2Kscan 150  t = 32.12 s\nnext\rlast\n") == \
        "scan 150  t = 32.12 s\nlast"


def test_an_image_widget_gets_its_picture_and_its_alt_text_together():
    img = Image(format="png")
    with pytest.raises(ValueError, match="alt text"):
        style.show_in_image(img, b"\x89PNG", "a plot")
    words = "Figure: the EKF's path and map at t = 40 s, against the surveyed beacons."
    style.show_in_image(img, b"\x89PNG", words)
    assert (img.value, img.alt_text, img.tooltip) == (b"\x89PNG", words, None)
