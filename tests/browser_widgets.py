"""Every widget of chapters 01-08 in a real browser: JupyterLab + headless Chromium (chapter
00's scan scrubber has its own, deeper test: tests/test_browser.py). The tests are
tests/test_browser_widgets_0104.py and tests/test_browser_widgets_0508.py (two files, so that
the two test workers share them); this module holds what they run.

Each file's JupyterLab serves the student versions of its notebooks (the course's release, no
outputs), as a student opens them. For each notebook: Run All Cells (it must reach the last
cell), then for each of its widgets: press ArrowRight on its first slider, as a student
would, and check that

- the readout text and the figure both change, within STEP_TIMEOUT, and how long it took
  (printed; the course's target is 0.5 s, a measurement here, not an assertion: software
  rendering on a loaded CI machine is not a student's laptop);
- where the widget's inputs are cheap to rebuild here (chapters 00-05), the text the browser
  shows is exactly what the same widget, built in this process from the library with the
  notebook's arguments and moved by the same step, prints for that control value;
- otherwise (06-08, whose inputs are whole filter runs or trained network grids) the text
  changed and still has the widget's shape (same number of lines);

and keep a screenshot of each moved widget in test-artifacts/browser/. Then save the notebook
from JupyterLab and check what the Run All left: only the exercises raised, each saying
"not written yet" in a few lines (tests/student_run_checks.py; tests/test_student_run.py
checks the same with nbclient where there is no browser). Skipped, saying why,
without Playwright or Chromium (as tests/test_browser.py).
"""
import contextlib
import io
import re
import time

import matplotlib
import pytest
from browser_support import (ARTIFACTS, REPO, chromium_path, launch_chromium, start_lab,
                             wait_run_all, why_no_browser)
from student_run_checks import check_student_run

from annslam_lib.models.vehicle import ACFR_UTE

matplotlib.use("Agg")

PAGE_TIMEOUT, RUN_ALL_TIMEOUT, STEP_TIMEOUT = 60, 240, 30


def _ch(n):
    import importlib
    names = {0: "ch00_course_map", 1: "ch01_kinematics", 2: "ch02_laser_offset",
             3: "ch03_observation", 4: "ch04_landmarks", 5: "ch05_ekf_slam"}
    return importlib.import_module(f"annslam_lib.chapters.{names[n]}")


# (notebook, the widget call exactly as its cell has it, the same widget built here or None)
WIDGETS = [
    ("01_kinematics", "chapter.kinematics_explorer(V, speed=2.0, steering=0.3, dt=0.2)",
     lambda car: _ch(1).kinematics_explorer(ACFR_UTE, speed=2.0, steering=0.3, dt=0.2)),
    ("02_laser_offset", "chapter.offset_explorer(car)", lambda car: _ch(2).offset_explorer(car)),
    ("03_observation", "chapter.measurement_explorer(landmark=(10.0, 3.0), sigma_xy=0.3, "
     "sigma_phi_deg=5.0)", lambda car: _ch(3).measurement_explorer(
         landmark=(10.0, 3.0), sigma_xy=0.3, sigma_phi_deg=5.0)),
    ("04_landmarks_association", "chapter.beacon_scrubber(car, start=92, max_range=16)",
     lambda car: _ch(4).beacon_scrubber(car, start=92, max_range=16)),
    ("04_landmarks_association", "chapter.gate_explorer()", lambda car: _ch(4).gate_explorer()),
    ("05_ekf_slam", "chapter.slam_explorer(car, t_end=40.0)",
     lambda car: _ch(5).slam_explorer(car, t_end=40.0)),
    ("06_victoria_park", "chapter.run_scrubber(r, vp.gps, start=1100, outliers=out)", None),
    ("07_ann_training", "chapter.hidden_size_explorer(grid, hidden=10, seed=0)", None),
    ("08_ann_slam_verdict", "chapter.r_scale_explorer(sweep=sweep, reference=ref, scale=1.0)",
     None),
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


def notebooks(first: int, last: int) -> list[str]:
    """The notebooks with widgets among chapters first..last."""
    return list(dict.fromkeys(w[0] for w in WIDGETS if first <= int(w[0][:2]) <= last))


@pytest.fixture(scope="module")
def chromium():
    reason = why_no_browser()
    if reason:
        pytest.skip(f"browser widget tests skipped: {reason}")
    return chromium_path()


@pytest.fixture(scope="module")
def lab(chromium, car_park, victoria_park, tmp_path_factory, request):
    from annslam_lib.course import release

    work = tmp_path_factory.mktemp("lab-widgets")
    release.release([REPO / "notebooks" / f"{stem}.ipynb" for stem in request.module.NOTEBOOKS],
                    work / "notebooks")                 # what students open: no outputs
    server = start_lab(work / "notebooks", work)
    server.folder = work / "notebooks"
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


def _step_here(widget):
    """Move this process's copy of the widget by one ArrowRight of its first slider; return
    the text it prints (interactive widgets) or shows (holder['text'])."""
    from ipywidgets import SelectionSlider
    sliders = [c for c in widget.children if hasattr(c, "value") and
               (isinstance(c, SelectionSlider) or hasattr(c, "step"))]
    s = sliders[0]
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        if isinstance(s, SelectionSlider):
            s.index = min(s.index + 1, len(s.options) - 1)
        else:
            s.value = min(s.value + s.step, s.max)
    holder = getattr(widget, "holder", {})
    return holder.get("text", buf.getvalue()).strip()


_NOT_TEXT = re.compile(r"^(Figure\(\d+x\d+\)|<Figure size .*>)$")


def _pre_texts(text: str) -> str:
    """The printed lines, without what only a terminal sees: clear_output's escape codes and
    the repr a figure prints where it cannot be displayed."""
    text = text.replace("\x1b[2K", "").replace("\r", "")
    return "\n".join(line.strip() for line in text.strip().split("\n")
                     if line.strip() and not _NOT_TEXT.match(line.strip()))


def check_widgets(stem, lab, browser, car_park):
    """Run All of notebook ``stem`` in the browser, then move and check each of its widgets
    (module docstring)."""
    import nbformat

    path = lab.folder / f"{stem}.ipynb"
    nb = nbformat.read(path, as_version=4)
    mine = [w for w in WIDGETS if w[0] == stem]
    cells = {}
    for _, call, _ in mine:
        hits = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and call in c.source]
        assert len(hits) == 1, f"{stem}: the widget call {call!r} is not in exactly one cell"
        cells[call] = hits[0]
    page = browser.new_page(viewport={"width": 1400, "height": 900})
    shot = ARTIFACTS / f"{stem}-failure.png"
    try:
        t0 = time.monotonic()
        page.goto(f"{lab.url}/lab/tree/{stem}.ipynb?token={lab.token}&reset")
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
        for _, call, factory in mine:
            i = cells[call]
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
            if factory is not None:
                expected = _moved_text(factory, car_park)
                assert _pre_texts(after["text"]) == _pre_texts(expected), (
                    f"{stem} cell {i}: the browser shows\n{after['text']}\nthe library, for "
                    f"the same control values:\n{expected}")
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            page.locator(".jp-Notebook .jp-Cell").nth(i).screenshot(
                path=str(ARTIFACTS / f"{stem}-cell{i}.png"))
            print(f"{stem} cell {i}: Run All {t_run:.1f} s; ArrowRight answered in {took:.2f} s "
                  f"(polled every 50 ms); readouts {before['readouts']} -> {after['readouts']}")
        check_student_run(_saved(page, lab, path, shot))
    finally:
        page.close()


def _saved(page, lab, path, shot):
    """File -> Save Notebook, then the notebook as JupyterLab wrote it, with every code cell
    executed (what the student's Run All left)."""
    import nbformat

    page.locator(".lm-MenuBar-item", has_text="File").click()
    page.get_by_role("menuitem", name=re.compile(r"^Save Notebook(?! As)")).click()
    end = time.monotonic() + PAGE_TIMEOUT
    while time.monotonic() < end:
        try:
            nb = nbformat.read(path, as_version=4)
        except Exception:              # being written
            nb = None
        if nb is not None and all(c.get("execution_count") is not None for c in nb.cells
                                  if c.cell_type == "code"):
            return nb
        time.sleep(0.2)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(shot))
    pytest.fail(f"JupyterLab did not save {path.name} with every cell executed within "
                f"{PAGE_TIMEOUT} s; screenshot {shot}", pytrace=False)


def _moved_text(factory, car):
    """The text of a freshly built widget after one ArrowRight of its first slider."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        w = factory(car)
    return _step_here(w)
