"""Figures every reader can read: the course's colours stay apart under colour-vision
deficiencies (simulated with the published matrices of Machado, Oliveira and Fernandes, IEEE
TVCG 15(6), 2009, severity 1), no figure relies on matplotlib's red and green, and legend
text is not set below the course's 9 pt."""
import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from annslam_lib.plots import style

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = sorted((ROOT / "annslam_lib").rglob("*.py"))

MACHADO = {
    "protanopia": [[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216],
                   [-0.003882, -0.048116, 1.051998]],
    "deuteranopia": [[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413],
                     [-0.011820, 0.042940, 0.968881]],
    "tritanopia": [[1.255528, -0.076749, -0.178779], [-0.078411, 0.930809, 0.147602],
                   [0.004733, 0.691367, 0.303900]],
}
#: sRGB (linear) to CIE XYZ, D65.
XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
#: Smallest CIE76 colour difference two palette colours keep under every deficiency, and
#: the one the red/green pair (good/bad in the course's figures) keeps. Chosen before
#: measuring the palette: about 2.3 is a just-noticeable difference, 10 is "clearly".
MIN_PAIR, MIN_RED_GREEN = 12.0, 30.0


def _linear(hex_colour):
    c = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _lab(rgb):
    t = XYZ @ np.clip(rgb, 0.0, 1.0) / (XYZ @ np.ones(3))
    d = 6 / 29
    f = np.where(t > d**3, np.cbrt(t), t / (3 * d**2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def difference(a, b, deficiency=None):
    """CIE76 difference of two '#rrggbb' colours as seen with ``deficiency``."""
    A, B = _linear(a), _linear(b)
    if deficiency:
        A, B = np.array(MACHADO[deficiency]) @ A, np.array(MACHADO[deficiency]) @ B
    return float(np.linalg.norm(_lab(A) - _lab(B)))


def worst(a, b):
    return min(difference(a, b, d) for d in MACHADO)


def test_the_simulation_keeps_greys_grey_and_loses_tableau_red_from_green():
    for m in MACHADO.values():
        np.testing.assert_allclose(np.sum(m, axis=1), 1.0, atol=2e-5)   # white stays white
    assert difference("#808080", "#808080", "deuteranopia") == pytest.approx(0.0, abs=1e-3)
    # matplotlib's tab:red and tab:green: 120 apart to normal vision, 7 for a deuteranope
    assert difference("#d62728", "#2ca02c") > 100
    assert difference("#d62728", "#2ca02c", "deuteranopia") < MIN_PAIR


def test_every_pair_of_the_course_colours_stays_apart_under_every_deficiency():
    pairs = {(a, b): worst(a, b) for a, b in itertools.combinations(style.PALETTE, 2)}
    close = {k: round(v, 1) for k, v in pairs.items() if v < MIN_PAIR}
    assert not close, f"palette colours too close for some readers: {close}"
    assert worst(style.RED, style.GREEN) >= MIN_RED_GREEN


def test_no_plotting_code_names_matplotlibs_own_red_or_green():
    found = []
    for path in LIBRARY:
        text = path.read_text()
        for m in re.finditer(r"tab:(?:red|green)|\"[rg][-.:o^sx*+v<>dD]{0,2}\"(?=,\s*(?:ms|lw|"
                             r"label|markersize|color)\b)|color=\"(?:red|green|r|g)\"", text):
            found.append(f"{path.relative_to(ROOT)}:{text[:m.start()].count(chr(10)) + 1}: "
                         f"{m.group(0)}")
    assert not found, "\n".join(found)


def test_legend_text_is_never_below_the_course_size_and_no_text_below_8_pt():
    found = []
    for path in LIBRARY:
        text = path.read_text()
        for m in re.finditer(r"\.legend\((?:[^()]|\([^()]*\))*\)", text):
            size = re.search(r"fontsize=(\d+)", m.group(0))
            if size and int(size.group(1)) < 9:
                found.append(f"{path.relative_to(ROOT)}: {m.group(0)[:60]}")
        for m in re.finditer(r"fontsize=(\d+)\b", text):
            if int(m.group(1)) < 8:
                found.append(f"{path.relative_to(ROOT)}: fontsize={m.group(1)}")
    assert not found, "\n".join(found)


def test_keyboard_ready_gives_a_widget_its_focus_outline_and_keeps_the_output_last():
    from ipywidgets import FloatSlider, VBox, interactive

    w = style.keyboard_ready(interactive(lambda a: None, a=FloatSlider()))
    sheets = [c for c in w.children if type(c).__name__ == "HTML"]
    assert len(sheets) == 1 and w.children[-1] is w.out and w.children[-2] is sheets[0]
    assert style.FOCUS_CLASS in w._dom_classes and sheets[0].layout.display == "none"
    css = sheets[0].value
    assert css.startswith("<style>") and f".{style.FOCUS_CLASS} :focus-visible" in css
    width = re.search(r"outline: (\d+)px solid", css)
    assert width and int(width.group(1)) >= 2
    box = style.keyboard_ready(VBox([FloatSlider()]))
    assert [type(c).__name__ for c in box.children] == ["FloatSlider", "HTML"]


def test_every_chapter_widget_is_returned_keyboard_ready():
    """Each chapter function that builds a widget (``interactive(`` or ``VBox(``) returns it
    through ``keyboard_ready``; the browser tests check the outline itself."""
    import ast

    chapters = Path(style.__file__).parents[1] / "chapters"
    builders, missing = 0, []
    for f in sorted(chapters.glob("ch*.py")):
        for fn in ast.walk(ast.parse(f.read_text())):
            if not isinstance(fn, ast.FunctionDef):
                continue
            calls = {getattr(n.func, "id", None) for n in ast.walk(fn) if isinstance(n, ast.Call)}
            if not calls & {"interactive", "VBox"}:
                continue
            builders += 1
            returns, todo = [], list(ast.iter_child_nodes(fn))
            while todo:                     # its own returns, not those of its callbacks
                n = todo.pop()
                if isinstance(n, ast.Return):
                    returns.append(n)
                elif not isinstance(n, (ast.FunctionDef, ast.Lambda)):
                    todo.extend(ast.iter_child_nodes(n))
            if not returns or not all(isinstance(r.value, ast.Call) and
                                      getattr(r.value.func, "id", None) == "keyboard_ready"
                                      for r in returns):
                missing.append(f"{f.name}:{fn.name}")
    assert builders == 13 and missing == []
