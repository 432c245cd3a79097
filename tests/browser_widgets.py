"""Every widget of chapters 01-08 in a real browser: JupyterLab + headless Chromium (chapter
00's scan scrubber has its own, deeper test: tests/test_browser.py). The tests are
tests/test_browser_widgets_0104.py and tests/test_browser_widgets_0508.py (two files, so that
the two test workers share them); this module holds what they run.

For each chapter, JupyterLab opens a small notebook made here: the code that builds the
widget's inputs as the chapter does (:data:`SETUP`: the data, the chapter's style, and for
06-08 the filter run, network grid or R sweep, read from the study cache), then each widget
call exactly as the chapter's cell has it (checked: the call is in exactly one cell of the
chapter). Run All, then for each widget: press ArrowRight on its first slider, as a student
would, and check that

- the readout text and the figure both change, within STEP_TIMEOUT, and how long it took
  (printed; the course's target is 0.25 s, a measurement here, not an assertion: software
  rendering on a loaded CI machine is not a student's laptop);
- the text the browser shows is exactly what the same widget, built in this process by the
  same set-up code and call and moved by the same step, prints for that control value;

- the keyboard reaches every control of the widget by Tab, in order, each with a visible
  focus outline, and operates the check boxes and drop-downs (:func:`check_keyboard`);

and keep a screenshot of each moved widget in test-artifacts/browser/. Skipped, saying why,
without Playwright or Chromium (as tests/test_browser.py).

The whole student version's Run All (only the exercises raise) is checked with nbclient by
tests/test_student_run.py: JupyterLab's Run All executes the same cells in the same kernel,
and rendering a whole chapter in Chromium costs several times nbclient's CPU (tens of
seconds per chapter beyond the kernel's).
"""
import contextlib
import io
import re
import time

import matplotlib
import pytest
from browser_support import (ARTIFACTS, REPO, chromium_path, launch_chromium, start_lab,
                             wait_run_all, why_no_browser)


matplotlib.use("Agg")

PAGE_TIMEOUT, RUN_ALL_TIMEOUT, STEP_TIMEOUT = 60, 240, 30


_CAR = "from annslam_lib.data import loaders\ncar = loaders.load_car_park()\n"

#: Per chapter: the code that builds its widgets' inputs as the chapter does.
SETUP = {
    "01_kinematics": "from annslam_lib.chapters import ch01_kinematics as chapter\n"
                     "from annslam_lib.models.vehicle import ACFR_UTE\n"
                     "chapter.setup()\nV = ACFR_UTE\n",
    "01a_kalman_filter": "from annslam_lib.chapters import ch01a_kalman_filter as chapter\n"
                         "chapter.setup(precision=4)\n",
    "02_laser_offset": "from annslam_lib.chapters import ch02_laser_offset as chapter\n"
                       "chapter.setup()\n" + _CAR,
    "03_observation": "from annslam_lib.chapters import ch03_observation as chapter\n"
                      "chapter.setup(precision=4)\n",
    "04_landmarks_association": "from annslam_lib.chapters import ch04_landmarks as chapter\n"
                                "chapter.setup()\n" + _CAR,
    "04a_ekf_localisation": "from annslam_lib.chapters import ch04a_localisation as chapter\n"
                            "chapter.setup(precision=4)\n" + _CAR,
    "05_ekf_slam": "from annslam_lib.chapters import ch05_ekf_slam as chapter\n"
                   "chapter.setup()\n" + _CAR,
    "06_victoria_park": "from annslam_lib.chapters import ch06_victoria_park as chapter\n"
                        "from annslam_lib.data import loaders\n"
                        "from annslam_lib.evaluation.trajectory import gps_outliers\n"
                        "from annslam_lib.slam import config as slam_config\n"
                        "from annslam_lib.slam import runner\n"
                        "chapter.setup()\n"
                        "vp = loaders.load_victoria_park()\n"
                        "cfg = slam_config.SlamConfig.for_dataset('victoria_park')\n"
                        "r = runner.run_cached(vp, cfg)\n"
                        "out = gps_outliers(vp.gps)\n",
    "07_ann_training": "from annslam_lib.chapters import ch07_ann_training as chapter\n"
                       "from annslam_lib import ann\n"
                       "from annslam_lib.ann.evaluation import hidden_size_grid\n"
                       "from annslam_lib.slam import config as slam_config\n"
                       "from annslam_lib.slam import runner\n"
                       "chapter.setup(precision=4)\n" + _CAR +
                       "result = runner.run(car, slam_config.SlamConfig.for_dataset('car_park'),\n"
                       "                    progress=False)\n"
                       "ts = ann.training_set(result, car)\n"
                       "grid = hidden_size_grid(ts, hidden=(1, 2, 5, 10, 20), seeds=range(5))\n",
    "08_ann_slam_verdict": "from annslam_lib.chapters import ch08_verdict as chapter\n"
                           "from annslam_lib.paper import study\n"
                           "chapter.setup()\n" + _CAR +
                           "st = study.study(car, seeds=5)\n"
                           "sweep = study.r_scale_sweep(car, t_heldout=st.t_heldout)\n"
                           "ref = study.reference_from_study(st, 0)\n",
    "10_beyond_the_ekf": "from annslam_lib.chapters import ch10_beyond_ekf as chapter\n"
                         "chapter.setup(precision=4)\n" + _CAR +
                         "p = chapter.car_park_graph(car)['problem']\n",
}

# (notebook, the widget call exactly as its cell has it)
WIDGETS = [
    ("01_kinematics", "chapter.kinematics_explorer(V, speed=2.0, steering=0.3, dt=0.2)"),
    ("01a_kalman_filter", "chapter.update_explorer(mu=12.0, var=0.34, z=12.4, r=0.16)"),
    ("02_laser_offset", "chapter.offset_explorer(car)"),
    ("03_observation", "chapter.measurement_explorer(landmark=(10.0, 3.0), sigma_xy=0.3, "
     "sigma_phi_deg=5.0)"),
    ("04_landmarks_association", "chapter.beacon_scrubber(car, start=92, max_range=16)"),
    ("04_landmarks_association", "chapter.gate_explorer()"),
    ("04a_ekf_localisation", "chapter.map_error_explorer(car, beacon=12, shift=0.0)"),
    ("05_ekf_slam", "chapter.slam_explorer(car, t_end=40.0)"),
    ("06_victoria_park", "chapter.run_scrubber(r, vp.gps, start=1100, outliers=out)"),
    ("07_ann_training", "chapter.hidden_size_explorer(grid, hidden=10, seed=0)"),
    ("08_ann_slam_verdict", "chapter.r_scale_explorer(sweep=sweep, reference=ref, scale=1.0)"),
    ("10_beyond_the_ekf", "chapter.loop_closure_explorer(car, p, drop=0.0)"),
]

# The widget's state in cell `i`: slider readouts, its text (printed lines or the HTML
# widget's <pre>), its image. Resolves once text and a loaded image are there and, with
# `old`, once both differ from it.
WIDGET_STATE_JS = """([i, old]) => {
  const cell = document.querySelectorAll('.jp-Notebook .jp-Cell')[i];
  if (!cell) return null;
  const out = cell.querySelector('.jp-OutputArea');
  if (!out) return null;
  const readouts = [...out.querySelectorAll('.widget-readout')].map(e => e.textContent.trim());
  const pres = [...out.querySelectorAll('pre')].map(e => e.textContent.trim()).filter(t => t);
  const img = out.querySelector('img');
  if (!pres.length || !img || !img.complete || img.naturalWidth === 0 || !readouts.length) return null;
  const s = {readouts, text: pres.join('\\n'), img: img.src, width: img.getBoundingClientRect().width};
  if (old && (s.text === old.text || s.img === old.img)) return null;
  return s;
}"""


# Every control of the widget in cell `i` the keyboard can reach (tabindex >= 0 or editable
# text such as a slider's readout, shown), in
# page order, each marked with its place (data-annslam-key) and described.
CONTROLS_JS = """(i) => {
  const out = document.querySelectorAll('.jp-Notebook .jp-Cell')[i].querySelector('.jp-OutputArea');
  const els = [...out.querySelectorAll('*')].filter(e => (e.tabIndex >= 0 || e.isContentEditable)
                                                       && !e.disabled && e.getClientRects().length);
  return els.map((e, k) => { e.dataset.annslamKey = String(k);
    return {tag: e.tagName, role: e.getAttribute('role'), type: e.type || null,
            cls: e.className.toString()}; });
}"""

# The focused element: its place among CONTROLS_JS's, its outline and the colour behind it.
FOCUSED_JS = """() => {
  const e = document.activeElement;
  const s = getComputedStyle(e);
  let b = e.parentElement, bg = 'rgba(0, 0, 0, 0)';     // the outline lies outside e
  while (b && (bg = getComputedStyle(b).backgroundColor) === 'rgba(0, 0, 0, 0)') b = b.parentElement;
  return {key: e.dataset.annslamKey ?? null, tag: e.tagName, cls: e.className.toString(), style: s.outlineStyle,
          width: parseFloat(s.outlineWidth), color: s.outlineColor, behind: bg,
          visible: e.matches(':focus-visible'), checked: e.checked ?? null,
          value: e.getAttribute('aria-valuenow') ?? e.value ?? null};
}"""


def _rgb(css: str) -> tuple:
    return tuple(float(v) for v in re.findall(r"[\d.]+", css)[:3])


def contrast(a: str, b: str) -> float:
    """WCAG 2.1's contrast ratio of two CSS rgb() colours."""
    def lum(rgb):
        c = [v / 255 for v in rgb]
        c = [v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4 for v in c]
        return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
    hi, lo = sorted((lum(_rgb(a)), lum(_rgb(b))), reverse=True)
    return (hi + 0.05) / (lo + 0.05)


def check_keyboard(page, cell: int, where: str) -> list[dict]:
    """Tab through the widget of ``cell`` from its first label: the keyboard reaches every
    control in page order, one Tab each, and then leaves the widget; each shows a focus
    outline at least 2 px wide with a contrast of 3:1 or more against what is behind it
    (WCAG 2.4.7, and 1.4.11's figure for a focus indicator); a check box toggles with Space
    and a drop-down moves with the arrow keys, each put back. Returns the controls."""
    controls = page.evaluate(CONTROLS_JS, cell)
    assert controls, f"{where}: no control the keyboard can reach"
    page.locator(".jp-Notebook .jp-Cell").nth(cell).locator(".widget-label").first.click()
    for _ in range(6):                       # past the cell's own toolbar to the first control
        page.keyboard.press("Tab")
        if page.evaluate(FOCUSED_JS)["key"] == "0":
            break
    for k, c in enumerate(controls):
        if k:
            page.keyboard.press("Tab")
        f = page.evaluate(FOCUSED_JS)
        what = f"{where}: control {k} ({c['tag']} {c['role'] or c['type'] or ''})"
        assert f["key"] == str(k), f"{what}: Tab went to control {f['key']} instead"
        assert f["visible"] and f["style"] not in ("none", "hidden") and f["width"] >= 2, (
            f"{what}: no visible focus outline ({f['style']} {f['width']} px)")
        ratio = contrast(f["color"], f["behind"])
        assert ratio >= 3, f"{what}: focus outline {f['color']} on {f['behind']}: {ratio:.2f}:1"
        if c["type"] == "checkbox":
            page.keyboard.press("Space")
            assert page.evaluate(FOCUSED_JS)["checked"] is (not f["checked"]), f"{what}: Space"
            page.keyboard.press("Space")
        elif c["tag"] == "SELECT":
            for key, back in (("ArrowDown", "ArrowUp"), ("ArrowUp", "ArrowDown")):
                page.keyboard.press(key)
                moved = page.evaluate(FOCUSED_JS)
                if moved["value"] != f["value"]:
                    page.keyboard.press(back)
                    break
            assert moved["value"] != f["value"], f"{what}: the arrow keys did not change the choice"
        g = page.evaluate(FOCUSED_JS)
        assert g["key"] == str(k), f"{what}: the keys moved the focus to {g}"
    page.keyboard.press("Tab")
    assert page.evaluate(FOCUSED_JS)["key"] is None, f"{where}: Tab stayed in the widget"
    return controls


def notebooks(first: int, last: int) -> list[str]:
    """The notebooks with widgets among chapters first..last."""
    return list(dict.fromkeys(w[0] for w in WIDGETS if first <= int(w[0][:2]) <= last))


@pytest.fixture(scope="module")
def chromium():
    reason = why_no_browser()
    if reason:
        pytest.skip(f"browser widget tests skipped: {reason}")
    return chromium_path()


def widget_notebook(stem: str):
    """The small notebook JupyterLab opens for chapter ``stem``: its :data:`SETUP`, then one
    cell per widget call. Each call must be in exactly one code cell of the chapter."""
    import nbformat

    chapter = nbformat.read(REPO / "notebooks" / f"{stem}.ipynb", as_version=4)
    calls = [call for s, call in WIDGETS if s == stem]
    for call in calls:
        hits = [c for c in chapter.cells if c.cell_type == "code" and call in c.source]
        assert len(hits) == 1, f"{stem}: the widget call {call!r} is not in exactly one cell"
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(SETUP[stem])] + [nbformat.v4.new_code_cell(c) for c in calls]
    nb.metadata["kernelspec"] = chapter.metadata.get("kernelspec", {})
    return nb


@pytest.fixture(scope="module")
def lab(chromium, tmp_path_factory, request):
    import nbformat

    work = tmp_path_factory.mktemp("lab-widgets")
    folder = work / "notebooks"
    folder.mkdir()
    for stem in request.module.NOTEBOOKS:
        nbformat.write(widget_notebook(stem), folder / f"{stem}-widgets.ipynb")
    server = start_lab(folder, work)
    server.folder = folder
    yield server
    server.stop()


@pytest.fixture(scope="module")
def browser(chromium):
    pw, b = launch_chromium()
    yield b
    b.close()
    pw.stop()


def _wait(page, lab, js, arg, timeout, what, shot):
    from playwright.sync_api import TimeoutError as PlaywrightTimeout
    try:
        return page.wait_for_function(js, arg=arg, timeout=timeout * 1000, polling=50).json_value()
    except PlaywrightTimeout:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(shot))
        pytest.fail(f"timed out after {timeout} s waiting for {what}; screenshot {shot}; "
                    f"JupyterLab log tail:\n{lab.log_tail(1500)}", pytrace=False)


def _step_here(widget, readout: str):
    """Move this process's copy of the widget as one ArrowRight of its first slider moved
    the browser's: a selection slider one option on, a numeric one to the value the browser's
    readout shows (the browser snaps to min + k * step, which ``value + step`` need not be);
    return the text it prints (interactive widgets) or shows (holder['text'])."""
    from ipywidgets import SelectionSlider
    sliders = [c for c in widget.children if hasattr(c, "value") and
               (isinstance(c, SelectionSlider) or hasattr(c, "step"))]
    s = sliders[0]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        if isinstance(s, SelectionSlider):
            s.index = min(s.index + 1, len(s.options) - 1)
        else:
            value = type(s.value)(float(readout))
            assert s.value < value <= min(s.value + 2 * s.step, s.max), (
                f"ArrowRight moved the browser's slider from {s.value} to {readout}")
            s.value = value
    holder = getattr(widget, "holder", {})
    return holder.get("text", buf.getvalue()).strip()


_NOT_TEXT = re.compile(r"^(Figure\(\d+x\d+\)|<Figure size .*>|<IPython\.core\.display\.Image object>)$")


def _pre_texts(text: str) -> str:
    """The printed lines, without what only a terminal sees: clear_output's escape codes and
    the repr a figure (or its PNG) prints where it cannot be displayed."""
    text = text.replace("\x1b[2K", "").replace("\r", "")
    return "\n".join(line.strip() for line in text.strip().split("\n")
                     if line.strip() and not _NOT_TEXT.match(line.strip()))


def check_widgets(stem, lab, browser):
    """Run All of chapter ``stem``'s widget notebook in the browser, then move and check each
    of its widgets (module docstring)."""
    calls = [call for s, call in WIDGETS if s == stem]
    here = _built_here(stem)
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    shot = ARTIFACTS / f"{stem}-failure.png"
    try:
        t0 = time.monotonic()
        page.goto(f"{lab.url}/lab/tree/{stem}-widgets.ipynb?token={lab.token}&reset")
        _wait(page, lab, "() => [...document.querySelectorAll('.jp-StatusBar-Item')]"
              ".some(e => e.textContent.includes('| Idle'))", None, PAGE_TIMEOUT,
              "the notebook to open with an idle kernel", shot)
        page.locator(".lm-MenuBar-item", has_text="Run").click()
        page.get_by_role("menuitem", name="Run All Cells", exact=True).click()
        state, _ = wait_run_all(page, RUN_ALL_TIMEOUT)
        t_run = time.monotonic() - t0
        if state == "timeout":
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(shot))
            pytest.fail(f"{stem}: Run All did not finish within {RUN_ALL_TIMEOUT} s; "
                        f"screenshot {shot}; JupyterLab log tail:\n{lab.log_tail(1500)}",
                        pytrace=False)
        if state != "done":
            errors = page.locator('[data-mime-type="application/vnd.jupyter.stderr"]').all_inner_texts()
            pytest.fail(f"{stem}: Run All stopped before the last cell; stderr:\n"
                        + "\n".join(e[-600:] for e in errors), pytrace=False)
        for i, call in enumerate(calls, start=1):
            before = _wait(page, lab, WIDGET_STATE_JS, [i, None], STEP_TIMEOUT,
                           f"the widget of cell {i} to render", shot)
            handle = page.locator(".jp-Notebook .jp-Cell").nth(i).locator(".noUi-handle").first
            handle.scroll_into_view_if_needed()
            t_press = time.monotonic()
            handle.press("ArrowRight")
            after = _wait(page, lab, WIDGET_STATE_JS, [i, before], STEP_TIMEOUT,
                          f"the widget of cell {i} to redraw after ArrowRight", shot)
            took = time.monotonic() - t_press
            assert after["readouts"] != before["readouts"], "the slider did not move"
            assert len(after["text"].split("\n")) == len(before["text"].split("\n"))
            assert after["width"] >= 400, f"the widget's figure is {after['width']:.0f} px wide"
            expected = _step_here(here(call), after["readouts"][0])
            assert _pre_texts(after["text"]) == _pre_texts(expected), (
                f"{stem} {call}: the browser shows\n{after['text']}\nthe library, for the same "
                f"control values:\n{expected}")
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            page.locator(".jp-Notebook .jp-Cell").nth(i).screenshot(
                path=str(ARTIFACTS / f"{stem}-cell{i}.png"))
            keys = check_keyboard(page, i, f"{stem} {call}")
            print(f"{stem} {call}: Run All of the widget notebook {t_run:.1f} s; ArrowRight "
                  f"answered in {took:.2f} s (polled every 50 ms); readouts "
                  f"{before['readouts']} -> {after['readouts']}; {len(keys)} controls by Tab")
    finally:
        page.close()


def _built_here(stem):
    """A function building, in this process, the widget of a call after running the
    chapter's :data:`SETUP` (its printed output discarded)."""
    import matplotlib.pyplot as plt

    ns: dict = {}
    with contextlib.redirect_stdout(io.StringIO()):
        exec(SETUP[stem], ns)                      # the test's own code, not a submission

    def build(call):
        with contextlib.redirect_stdout(io.StringIO()):
            w = eval(call, ns)
        plt.close("all")
        return w
    return build
