"""The course as a static website: every chapter read from its stored outputs (nothing is
executed), the guides, the errata and the data's notes, with a search box and the math
rendered, built by Sphinx with myst-nb and the Book theme.

    python -m annslam_lib site --out site/ [--hub URL] [--release-repo URL --release-ref REF]
                                            [--course-repo URL --course-ref REF]

What a chapter's page shows is the student's version (:func:`release.student_version`: no
solution, no hidden test, no written answer) with the instructor notebook's stored outputs
on every cell the release leaves unchanged; the exercise cells show their stubs and no
output. A widget cannot run without a kernel: its page shows the picture it stored, with its
alt text, and a line naming its controls, then (for a chapter's main widget) an animation
of the frames the refresh stored (:mod:`annslam_lib.plots.frames`), played by a small
script of the site's own. Everything a page loads (scripts, styles, fonts,
MathJax, pictures) is served by the site itself; the only links to other hosts are the
launch links (:mod:`launch`) a reader follows on purpose.

The site's tools (Sphinx, myst-nb, the theme, MathJax) are in the instructor's environment
(``environment-instructor.txt``), not the students'.
"""
from __future__ import annotations

import copy
import html
import json
import posixpath
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import nbformat

from .launch import LaunchTargets, links
from .plan import cell_meta
from .release import read_notebook, student_version

__all__ = ["SiteReport", "build", "site_notebook", "widget_pictures", "player", "frame_files",
           "html_pages", "mathjax_folder", "PAGES", "WIDGET_NOTE_CLASS", "PLAYER_CLASS"]

_REPO = Path(__file__).resolve().parents[2]
#: The guides and notes published beside the chapters: (file in the repository, page title).
PAGES = [("INSTRUCTOR.md", "Instructor's guide"), ("MAINTAINING.md", "Maintainer's guide"),
         ("docs/errata.md", "The paper's errata"), ("data/README.md", "The data"),
         ("LICENSE-CONTENT.md", "Licence of the course's text and figures"),
         ("CHANGELOG.md", "Changes")]
WIDGET_NOTE_CLASS = "annslam-widget-note"
PLAYER_CLASS = "annslam-player"
_WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"
_WIDGET_STATE = "application/vnd.jupyter.widget-state+json"
_CONTROLS = {"IntSliderModel", "FloatSliderModel", "FloatLogSliderModel", "IntRangeSliderModel",
             "FloatRangeSliderModel", "SelectionSliderModel", "DropdownModel",
             "ToggleButtonsModel", "RadioButtonsModel", "CheckboxModel", "ToggleButtonModel",
             "PlayModel", "SelectionRangeSliderModel"}


@dataclass(frozen=True)
class SiteReport:
    """What :func:`build` wrote: the folder, its pages, its size and the build's time."""
    out: Path
    chapters: list
    pages: int
    size_mb: float
    seconds: float

    def summary(self) -> str:
        return (f"{len(self.chapters)} chapters and {self.pages - len(self.chapters)} other "
                f"pages in {self.out} ({self.size_mb:.1f} MB), built in {self.seconds:.0f} s")


def _state(nb) -> dict:
    return nb.metadata.get("widgets", {}).get(_WIDGET_STATE, {}).get("state", {})


def _models(state: dict, model_id: str):
    """(model name, state, model) of ``model_id`` and every widget inside it, each once,
    parents before their children in the order they show."""
    seen, stack = set(), [model_id]
    while stack:
        mid = stack.pop()
        if mid in seen or mid not in state:
            continue
        seen.add(mid)
        model = state[mid]
        st = model.get("state", {})
        yield model.get("model_name", ""), st, model
        stack += [str(c).removeprefix("IPY_MODEL_") for c in reversed(st.get("children", []))]


def widget_pictures(state: dict, model_id: str, image_alt: str | None = None, *,
                    pictures: bool = True) -> list:
    """The outputs that stand for the widget ``model_id`` on a page without a kernel: the
    pictures its Output widgets hold (with their metadata: the alt text), its Image widgets'
    pictures (alt text: their title, else ``image_alt``: the alt text of the animation's frame
    at the stored value) and its shown HTML widgets' text, then one HTML line naming its
    controls and where they stand. With ``pictures=False`` only that line (a page that plays
    the widget's frames shows its picture and text there). Raises ValueError for a widget
    whose state was not saved (its page would show nothing)."""
    if model_id not in state:
        raise ValueError(f"widget {model_id[:8]} has no saved state: save the notebook with "
                         "its widget state (the refresh does)")
    shown, controls = [], []
    for name, st, model in _models(state, model_id):
        if name in ("OutputModel", "ImageModel", "HTMLModel") and (
                not pictures or _hidden(state, st)):
            continue
        if name == "OutputModel":
            for o in st.get("outputs", []):
                if "image/png" in o.get("data", {}):
                    shown.append(nbformat.v4.new_output(
                        "display_data", data={"image/png": o["data"]["image/png"],
                                              "text/plain": "<Figure>"},
                        metadata=copy.deepcopy(o.get("metadata", {}))))
        elif name == "ImageModel" and st.get("format") == "png":
            data = next((b["data"] for b in model.get("buffers", [])
                         if b.get("path") == ["value"] and b.get("encoding") == "base64"), None)
            if data:                           # a picture redrawn in place, its title its alt
                shown.append(nbformat.v4.new_output(
                    "display_data", data={"image/png": data, "text/plain": "<Figure>"},
                    metadata={"image/png": {"alt": st.get("tooltip") or image_alt or ""}}))
        elif name == "HTMLModel" and st.get("value"):
            shown.append(nbformat.v4.new_output(   # the widget's own text (escaped there)
                "display_data", data={"text/html": st["value"], "text/plain": st["value"]}))
        elif name in _CONTROLS:
            label = st.get("description") or name.removesuffix("Model").lower()
            value = st.get("value")
            if "options" in st or "_options_labels" in st:
                labels = st.get("_options_labels") or st.get("options")
                index = st.get("index")
                value = labels[index] if isinstance(index, int) and 0 <= index < len(labels) else value
            span = f" (from {st['min']} to {st['max']})" if "min" in st and "max" in st else ""
            controls.append(f"{label} = {value}{span}")
    words = "; ".join(controls) if controls else "no control"
    note = (f'<p class="{WIDGET_NOTE_CLASS}">In JupyterLab this picture is interactive '
            f"({html.escape(words)}). Open the chapter to move its controls.</p>")
    return shown + [nbformat.v4.new_output(
        "display_data", data={"text/html": note, "text/plain": note})]


def _hidden(state: dict, st: dict) -> bool:
    """Whether a widget is laid out hidden (``display: none``, e.g. the style sheet of
    ``plots.style.keyboard_ready``): shown nowhere, so not on the page either."""
    layout = state.get(str(st.get("layout", "")).removeprefix("IPY_MODEL_"), {})
    return layout.get("state", {}).get("display") == "none"


def player(frames: list, control: str, stem: str, start: str | None = None) -> str:
    """The HTML of an animation over a widget's stored ``frames`` (:mod:`plots.frames`): the
    picture with its alt text, a Play button, a range control named after the widget's
    ``control`` and the frame's readout, played by the site's ``annslam-player.js``. The
    pictures are files ``../frames/{stem}/{k}.png`` beside the page's folder."""
    if not frames:
        raise ValueError(f"{stem}: an animation needs frames")
    k0 = next((k for k, f in enumerate(frames) if f["value"] == start), 0)
    data = [{"src": f"../frames/{stem}/{k}.png", "alt": f["alt"], "label": f["value"],
             "text": f.get("text", "")} for k, f in enumerate(frames)]
    e = html.escape
    f0 = data[k0]
    return (f'<figure class="{PLAYER_CLASS}" role="group" aria-label="Animation: the widget '
            f'at {len(data)} values of {e(control)}" data-frames="{e(json.dumps(data))}">'
            f'<img src="{e(f0["src"])}" alt="{e(f0["alt"])}">'
            f'<figcaption><button type="button" class="annslam-play">Play</button> '
            f'<label>{e(control)} <input type="range" min="0" max="{len(data) - 1}" '
            f'step="1" value="{k0}" aria-valuetext="{e(f0["label"])}"></label> '
            f'<output aria-live="polite">{e(f0["label"])}</output>'
            f'<pre class="annslam-frame-text">{e(f0["text"])}</pre></figcaption></figure>')


#: The cell tag sphinx-book-theme widens a cell by (over the page's contents column).
FULL_WIDTH = "full-width"


def site_notebook(instructor, name: str = "notebook"):
    """The page version of an instructor notebook: the student version's cells (its
    metadata kept to the release's keys), with the instructor notebook's stored outputs on
    every code cell the release leaves unchanged, and each widget replaced by
    :func:`widget_pictures`, or, when its frames are stored, by its :func:`player` (which
    starts on the stored picture) and the line naming its controls."""
    page = student_version(instructor, name)
    stem = Path(name).stem
    state = _state(instructor)
    for src, cell in zip(instructor.cells, page.cells):
        if cell.cell_type != "code" or cell.source != src.source:
            continue
        meta = cell_meta(src)
        if meta.get("solution") or meta.get("grade"):
            continue
        anim = src.metadata.get("annslam", {})
        start = (_control_value(state, src, anim["animate"]["control"])
                 if anim.get("frames") else None)
        image_alt = next((f["alt"] for f in anim.get("frames", []) if f["value"] == start), None)
        outs = []
        for o in src.get("outputs", []):
            view = o.get("data", {}).get(_WIDGET_VIEW) if o.get("output_type") in (
                "display_data", "execute_result") else None
            outs += (widget_pictures(state, view["model_id"], image_alt,
                                     pictures=not anim.get("frames")) if view
                     else [copy.deepcopy(o)])
        if anim.get("frames"):
            note = player(anim["frames"], anim["animate"]["control"], stem, start)
            outs.append(nbformat.v4.new_output("display_data", data={
                "text/html": note, "text/plain": "an animation of the widget"}))
        cell.outputs, cell.execution_count = outs, src.get("execution_count")
        if any("image/png" in o.get("data", {}) or "text/html" in o.get("data", {}) and
               PLAYER_CLASS in o["data"]["text/html"] for o in outs):
            # a figure is drawn for the notebook's ~1000 px: the theme's full-width cell
            # gives it the page's contents column too, near its own size
            cell.metadata.setdefault("tags", []).append(FULL_WIDTH)
    return page


def _control_value(state: dict, cell, description: str) -> str | None:
    """The readout the widget of ``cell`` was stored at, for its control ``description``
    (the frame the animation starts on)."""
    for o in cell.get("outputs", []):
        view = o.get("data", {}).get(_WIDGET_VIEW)
        if not view:
            continue
        for name, st, _ in _models(state, view["model_id"]):
            if st.get("description") == description:
                if "_options_labels" in st and isinstance(st.get("index"), int):
                    return st["_options_labels"][st["index"]]
                fmt = st.get("readout_format") or (".2f" if "Float" in name else "d")
                try:
                    return format(st.get("value"), fmt)
                except (TypeError, ValueError):
                    return str(st.get("value"))
    return None


def frame_files(instructor, stem: str) -> dict:
    """{relative path: PNG bytes} of every stored frame of ``instructor``'s animations."""
    import base64

    files = {}
    for c in instructor.cells:
        for k, f in enumerate(c.get("metadata", {}).get("annslam", {}).get("frames", []) or []):
            files[f"frames/{stem}/{k}.png"] = base64.b64decode(f["png"])
    return files


def _title(nb) -> str:
    for c in nb.cells:
        if c.cell_type == "markdown":
            m = re.search(r"^#\s+(.+)$", c.source, re.M)
            if m:
                return m.group(1).strip()
    raise ValueError("a chapter needs a '# title' in a markdown cell")


_LINK = re.compile(r"(?<!!)\[([^\]]+)\]\(([^)\s]+)\)")


def _relink(text: str, here: str, staged: set, targets: LaunchTargets) -> str:
    """Markdown links to files the site does not hold (code, licences, configuration) lead to
    the course repository's copy when one is configured (GitHub's ``/blob/REF/PATH``
    layout); otherwise only their text stays."""
    def fix(m):
        label, target = m.group(1), m.group(2)
        if re.match(r"^[a-z]+:", target) or target.startswith("#"):
            return m.group(0)
        norm = posixpath.normpath(posixpath.join(posixpath.dirname(here),
                                                  target.split("#")[0]))
        if norm in staged or (norm.rstrip("/") + "/README.md") in staged:
            return m.group(0)
        if targets.course_repo:
            return f"[{label}]({targets.course_repo}/blob/{targets.course_ref}/{norm})"
        return label
    return _LINK.sub(fix, text)


def _launch_cell(targets: LaunchTargets, notebook: str):
    rows = links(targets, notebook)
    if not rows:
        return None
    items = []
    for label, link, note in rows:
        if link:
            items.append(f"- [{label}]({link})" + (f": {note}" if note else ""))
        else:
            items.append(f"- {note[:1].upper()}{note[1:]}")
    return nbformat.v4.new_markdown_cell("**Run this chapter.**\n\n" + "\n".join(items))


_CONF = '''\
project = "annslam"
author = "the course's contributors"
language = "en"
extensions = ["myst_nb"]
mathjax_path = "mathjax/tex-chtml.js"
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3
nb_execution_mode = "off"
nb_render_plugin = "annslam"
nb_ipywidgets_js = {{}}
nb_output_stderr = "remove"
exclude_patterns = ["_build", "_extra"]
suppress_warnings = ["myst.header", "mystnb.unknown_mime_type", "misc.highlighting_failure"]
html_theme = "sphinx_book_theme"
html_title = "annslam: EKF-SLAM for a car"
html_static_path = ["_static"]
html_css_files = ["annslam.css"]
html_js_files = ["annslam-player.js"]
html_extra_path = ["_extra"]
html_theme_options = {{
    "use_download_button": True,
    "use_fullscreen_button": False,
    "use_repository_button": False,
    "home_page_in_toc": True,
    "show_toc_level": 2,
}}
html_show_sourcelink = False
html_favicon = "_static/favicon.svg"
html_context = {{"default_mode": "auto"}}
'''

# A focus ring on every control reached by keyboard (the theme's own ring is transparent on
# some buttons): 3 px of the course's blue, at least 3:1 against both of the theme's
# backgrounds (WCAG 2.1's 1.4.11). While a full-width figure is in view the theme folds the
# page's contents into a bar that opens on hover: it opens for the keyboard too (a link
# with the focus is never hidden), and its sign is a character (the theme's is an icon-font
# glyph the site does not load).
_CSS = """\
.annslam-widget-note { font-style: italic; }
.annslam-player img { max-width: 100%; height: auto; }
.annslam-player figcaption { display: flex; flex-wrap: wrap; gap: 0.5em 1em; align-items: center; }
.annslam-player input[type=range] { width: 14em; max-width: 60vw; }
.annslam-frame-text { flex-basis: 100%; white-space: pre-wrap; margin: 0; text-align: left; }
:focus-visible { outline: 3px solid #0072B2 !important; outline-offset: 2px; }
.bd-sidebar-secondary.hide:not(:hover) .onthispage:after { content: "\\25BE"; font-family: inherit; }
.bd-sidebar-secondary.hide:focus-within { max-height: none !important; overflow-y: auto !important; }
.bd-sidebar-secondary.hide:focus-within nav.page-toc { opacity: 1 !important; }
"""


#: The parts of MathJax 3 a page uses: TeX in, HTML-CSS out with its fonts, the extensions
#: TeX loads on demand, and the accessibility parts (assistive MathML, the explorer, speech).
_MATHJAX_PARTS = ["tex-chtml.js", "input/tex/extensions", "output/chtml", "a11y", "sre",
                  "ui"]


def mathjax_folder() -> Path:
    """MathJax 3 as the pinned ``sphinx-mathjax-offline`` package holds it."""
    import importlib.util

    spec = importlib.util.find_spec("sphinx-mathjax-offline")
    if spec is None or spec.origin is None:
        raise RuntimeError("MathJax is not installed: the site needs environment-instructor.txt "
                           "(./course.sh site installs it)")
    return Path(spec.origin).parent / "static" / "mathjax"


def _copy_mathjax(dest: Path) -> None:
    src = mathjax_folder()
    for part in _MATHJAX_PARTS:
        if not (src / part).exists():
            continue
        if (src / part).is_dir():
            shutil.copytree(src / part, dest / part)
        else:
            dest.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src / part, dest / part)


# The animations' player: a range control and a Play button over the frames listed in the
# figure's data-frames; the picture's alt text and the readout follow the frame. Playing
# steps once a second and stops at the last frame; nothing moves unless the reader asks.
_PLAYER_JS = """\
document.addEventListener("DOMContentLoaded", () => {
  for (const fig of document.querySelectorAll("figure.annslam-player")) {
    const frames = JSON.parse(fig.dataset.frames);
    const img = fig.querySelector("img"), range = fig.querySelector("input[type=range]");
    const out = fig.querySelector("output"), text = fig.querySelector(".annslam-frame-text");
    const play = fig.querySelector("button.annslam-play");
    for (const f of frames) { const i = new Image(); i.src = f.src; }
    let timer = null;
    const show = (k) => {
      const f = frames[k];
      range.value = k; img.src = f.src; img.alt = f.alt;
      range.setAttribute("aria-valuetext", f.label); out.textContent = f.label;
      text.textContent = f.text;
    };
    const stop = () => {
      clearInterval(timer); timer = null; play.textContent = "Play";
      out.setAttribute("aria-live", "polite");
    };
    range.addEventListener("input", () => { stop(); show(Number(range.value)); });
    play.addEventListener("click", () => {
      if (timer) { stop(); return; }
      out.setAttribute("aria-live", "off");
      let k = Number(range.value) >= frames.length - 1 ? 0 : Number(range.value);
      show(k); play.textContent = "Pause";
      timer = setInterval(() => {
        k += 1; show(k);
        if (k >= frames.length - 1) stop();
      }, 1000);
    });
  }
});
"""

# A car's path around a landmark, in the course's blue and orange.
_FAVICON = ('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 16 16">'
            '<path d="M2 13 C4 3, 12 3, 14 13" fill="none" stroke="#0072B2" stroke-width="2"/>'
            '<circle cx="8" cy="9" r="2" fill="#E69F00"/></svg>')


#: The file that marks a folder as a site build, which a new build may replace.
MARKER = ".annslam-site"


def _clear(out: Path, check_only: bool = False) -> None:
    """Remove an earlier build at ``out``; refuse a folder that holds anything else."""
    if not out.exists():
        return
    if not out.is_dir() or (any(out.iterdir()) and not (out / MARKER).is_file()):
        raise ValueError(f"{out} exists and is not a site built here: choose another --out "
                         "(a build replaces its folder)")
    if not check_only:
        shutil.rmtree(out)


def build(out, *, targets: LaunchTargets | None = None, notebooks=None, quiet: bool = True,
          jobs: int = 1) -> SiteReport:
    """Build the website into ``out`` (an earlier build there is replaced; a folder holding
    anything else is refused) and return what was written. ``notebooks``: the chapters (default: the course's). Raises
    RuntimeError with Sphinx's messages when the build fails or warns (a broken link, a
    missing picture)."""
    t0 = time.perf_counter()
    targets = targets or LaunchTargets()
    out = Path(out).resolve()
    _clear(out, check_only=True)
    paths = sorted(Path(p) for p in ((_REPO / "notebooks").glob("*.ipynb") if notebooks is None
                                     else notebooks))
    if not paths:
        raise ValueError("no chapter to publish")
    stage = out.parent / f".{out.name}-source"
    if stage.exists():
        shutil.rmtree(stage)
    (stage / "_static").mkdir(parents=True)
    (stage / "notebooks").mkdir()
    (stage / "_extra").mkdir()
    (stage / "_static" / "annslam-player.js").write_text(_PLAYER_JS)
    (stage / "_static" / "annslam.css").write_text(_CSS)
    (stage / "_static" / "favicon.svg").write_text(_FAVICON)
    staged = {"index.md"} | {f"notebooks/{p.name}" for p in paths} | {p for p, _ in PAGES}
    chapters = []
    for p in paths:
        nb = read_notebook(p)
        page = site_notebook(nb, p.name)
        cell = _launch_cell(targets, p.name)
        if cell is not None:
            page.cells.insert(1, cell)
        for c in page.cells:
            if c.cell_type == "markdown":
                c.source = _relink(c.source, f"notebooks/{p.name}", staged, targets)
        nbformat.write(page, stage / "notebooks" / p.name)
        for rel, data in frame_files(nb, p.stem).items():
            (stage / "_extra" / rel).parent.mkdir(parents=True, exist_ok=True)
            (stage / "_extra" / rel).write_bytes(data)
        chapters.append((p.stem, _title(nb)))
    for rel, _title_ in PAGES:
        dest = stage / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(_relink((_REPO / rel).read_text(), rel, staged, targets))
    readme = _relink((_REPO / "README.md").read_text(), "README.md", staged, targets)
    toc = ["", "```{toctree}", ":caption: Chapters", ":maxdepth: 1", ""]
    toc += [f"notebooks/{stem}" for stem, _ in chapters]
    toc += ["```", "", "```{toctree}", ":caption: Guides and notes", ":maxdepth: 1", ""]
    toc += [f"{title} <{rel.removesuffix('.md')}>" for rel, title in PAGES] + ["```", ""]
    (stage / "index.md").write_text(readme + "\n".join(toc))
    (stage / "conf.py").write_text(_CONF.format())
    # built inside the staging folder, then moved: myst-nb writes a folder of its own
    # beside the build's output folder
    html_dir = stage / "_build" / "html"
    cmd = [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-E",
           "-j", str(jobs), "-d", str(stage / "_build" / "doctrees"), str(stage), str(html_dir)]
    if quiet:
        cmd.insert(5, "-q")
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError("the site's build failed:\n" + (proc.stderr or proc.stdout)[-4000:])
    _clear(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(html_dir, out)
    _copy_mathjax(out / "_static" / "mathjax")
    (out / MARKER).write_text("a website built by python -m annslam_lib site; a new build "
                              "replaces this folder\n")
    shutil.rmtree(stage)
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file()) / 1e6
    pages = len([f for f in html_pages(out) if f.name not in ("genindex.html", "search.html")])
    return SiteReport(out=out, chapters=chapters, pages=pages, size_mb=size,
                      seconds=time.perf_counter() - t0)


def html_pages(out) -> list[Path]:
    """The built site's pages (not the theme's template fragments in ``_static``, nor the
    chapters' downloadable sources in ``_sources``)."""
    out = Path(out)
    return sorted(f for f in out.rglob("*.html")
                  if f.relative_to(out).parts[0] not in ("_static", "_sources"))
