"""The course website (annslam_lib.course.site): built for real from the stored notebooks,
read as HTML, then served on 127.0.0.1 and opened page by page in headless Chromium with
every request to another host aborted, and checked by axe-core against WCAG 2.1 A and AA."""
from __future__ import annotations

import functools
import json
import html.parser
import http.server
import re
import threading
from pathlib import Path
from types import SimpleNamespace
from urllib.parse import parse_qs, unquote, urlsplit

import nbformat
import pytest

from annslam_lib.course import launch, site
from annslam_lib.course.release import hidden_test_lines, solution_lines, ANSWER_TAG
from annslam_lib.plots import alt

pytest.importorskip("sphinx", reason="the site's tools are not installed: pip install -r "
                    "environment-instructor.txt (./course.sh test does)")
pytest.importorskip("myst_nb", reason="myst-nb is not installed (environment-instructor.txt)")

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((REPO / "notebooks").glob("*.ipynb"))
TARGETS = launch.LaunchTargets(
    release_repo="https://github.com/example-course/annslam-release", release_ref="fall-2027",
    hub="https://hub.example.edu", course_repo="https://github.com/example-course/annslam",
    course_ref="v0.1.0")
SERIOUS = ("serious", "critical")
WCAG_TAGS = ["wcag2a", "wcag2aa", "wcag21a", "wcag21aa"]


class _Page(html.parser.HTMLParser):
    """What a page holds: its tags' attributes by tag, its ids, its text, and the text of its
    code blocks (``<pre>``)."""

    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.ids: set[str] = set()
        self.text: list[str] = []
        self.code: list[str] = []
        self._pre = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append((tag, a))
        if a.get("id"):
            self.ids.add(a["id"])
        self._pre += tag == "pre"

    def handle_endtag(self, tag):
        if tag == "pre":
            self._pre -= 1
            self.code.append("\n")

    def handle_data(self, data):
        self.text.append(data)
        if self._pre:
            self.code.append(data)


@functools.lru_cache(maxsize=None)
def _parse(path: Path) -> _Page:
    p = _Page()
    p.feed(path.read_text())
    return p


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("site") / "html"
    report = site.build(out, targets=TARGETS)
    return report


def _pages(root: Path) -> list[Path]:
    return site.html_pages(root)


def test_the_site_holds_every_chapter_and_guide(built):
    root = built.out
    assert [stem for stem, _ in built.chapters] == [p.stem for p in NOTEBOOKS]
    for p in NOTEBOOKS:
        page = root / "notebooks" / f"{p.stem}.html"
        assert page.is_file(), f"{p.name}: no page"
        title = dict(built.chapters)[p.stem]
        assert title in "".join(_parse(page).text), f"{p.name}: its title {title!r} is not shown"
    for rel, _ in site.PAGES:
        assert (root / rel.replace(".md", ".html")).is_file(), f"{rel}: no page"
    assert (root / "search.html").is_file() and (root / "searchindex.js").is_file()
    assert (root / "_static" / "mathjax" / "tex-chtml.js").is_file()
    index = "".join(_parse(root / "index.html").text)
    assert "The two commands" in index                # the README is the front page
    assert built.pages == len(_pages(root)) - 2       # genindex and search are not pages
    assert 0 < built.size_mb < 40


def test_a_build_leaves_only_its_folder_and_never_replaces_one_it_did_not_make(built, tmp_path):
    assert sorted(p.name for p in built.out.parent.iterdir()) == ["html"]   # no staging left
    assert (built.out / site.MARKER).is_file()
    mine = tmp_path / "notes"
    mine.mkdir()
    (mine / "lecture.txt").write_text("my notes")
    with pytest.raises(ValueError, match="not a site built here"):
        site.build(mine, notebooks=NOTEBOOKS[:1])
    assert (mine / "lecture.txt").read_text() == "my notes"
    with pytest.raises(ValueError, match="no chapter"):
        site.build(tmp_path / "empty", notebooks=[])


def _is_local(url: str) -> bool:
    s = urlsplit(url)
    return not s.scheme and not s.netloc or s.scheme == "data"


def test_no_page_loads_anything_from_another_host(built):
    """Scripts, styles, fonts, pictures and frames: every one is the site's own. Links a
    reader follows (launch buttons, references) may lead elsewhere; nothing is loaded."""
    loads = []
    for page in _pages(built.out):
        for tag, a in _parse(page).tags:
            for key in ("src", "srcset", "data-src", "poster"):
                if a.get(key) and not _is_local(a[key]):
                    loads.append((page.name, tag, a[key]))
            if tag == "link" and a.get("href") and not _is_local(a["href"]) and \
                    a.get("rel", "") not in ("canonical",):
                loads.append((page.name, tag, a["href"]))
    for css in built.out.rglob("*.css"):
        for url in re.findall(r"url\(\s*['\"]?([^'\")]+)", css.read_text(errors="replace")):
            if not _is_local(url):
                loads.append((css.name, "css", url))
    assert loads == []


def _figures(nb) -> list[str]:
    """The alt text of every picture a page of ``nb`` shows, in order."""
    return [o["metadata"]["image/png"]["alt"] for c in nb.cells if c.cell_type == "code"
            for o in c.get("outputs", []) if "image/png" in o.get("data", {})]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_stored_figure_is_on_its_page_with_its_alt_text(built, path):
    nb = nbformat.read(path, as_version=4)
    expected = _figures(site.site_notebook(nb, path.name))
    # independently of the page version: the instructor's figures, but those of the
    # exercises' cells, and each widget's saved picture in place of the widget, or, for a
    # widget with an animation, the animation starting on the frame at the stored value
    own, players = [], []
    for c in nb.cells:
        meta = c.get("metadata", {}).get("nbgrader", {})
        if c.cell_type != "code" or meta.get("solution") or meta.get("grade"):
            continue
        for o in c.get("outputs", []):
            view = o.get("data", {}).get("application/vnd.jupyter.widget-view+json")
            if view:
                anim = c.metadata.get("annslam", {})
                start = site._control_value(site._state(nb), c, anim["animate"]["control"]) \
                    if anim.get("frames") else None
                frame_alt = next((f["alt"] for f in anim.get("frames", [])
                                  if f["value"] == start), None)
                if anim.get("frames"):
                    players.append(frame_alt)
                    continue
                own += _figures(nbformat.from_dict({"cells": [{"cell_type": "code", "outputs":
                                site.widget_pictures(site._state(nb), view["model_id"],
                                                     frame_alt)}]}))
            elif "image/png" in o.get("data", {}):
                own.append(o["metadata"]["image/png"]["alt"])
    assert expected == own
    page = _parse(built.out / "notebooks" / f"{path.stem}.html")
    shown = [a.get("alt") for tag, a in page.tags
             if tag == "img" and "_images/" in a.get("src", "")]
    assert shown == expected, f"{path.name}: {len(shown)} pictures shown, {len(expected)} stored"
    assert all(len(a) >= alt.MIN_LENGTH for a in shown)
    starts = [a.get("alt") for tag, a in page.tags
              if tag == "img" and "/frames/" in a.get("src", "")]
    assert starts == players and all(players)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_no_solution_hidden_test_or_written_answer_reaches_a_page(built, path):
    nb = nbformat.read(path, as_version=4)
    parsed = _parse(built.out / "notebooks" / f"{path.stem}.html")
    text = "".join(parsed.text)
    shown = {line.strip() for line in "".join(parsed.code).split("\n")}   # the code cells
    leaked = (solution_lines(nb) | hidden_test_lines(nb)) & shown
    assert not leaked, f"{path.name}: {sorted(leaked)[:5]}"
    assert "BEGIN SOLUTION" not in text and "BEGIN HIDDEN TESTS" not in text
    for c in nb.cells:
        if c.cell_type == "markdown" and ANSWER_TAG in c.metadata.get("tags", []):
            words = " ".join(c.source.split())[:80]
            assert words not in " ".join(text.split()), f"{path.name}: a written answer shows"


def test_every_internal_link_leads_to_a_page_and_its_anchor(built):
    broken = []
    for page in _pages(built.out):
        for tag, a in _parse(page).tags:
            href = a.get("href")
            if tag != "a" or not href or urlsplit(href).scheme or href.startswith("//"):
                continue
            path, _, anchor = href.partition("#")
            target = (page.parent / unquote(path)).resolve() if path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                broken.append((page.relative_to(built.out).as_posix(), href))
            elif anchor and target.suffix == ".html" and unquote(anchor) not in _parse(target).ids:
                broken.append((page.relative_to(built.out).as_posix(), href))
    assert broken == []


def test_a_widget_shows_its_saved_picture_and_names_its_controls(built):
    page = _parse(built.out / "notebooks" / "00_course_map.html")
    notes = [t for t in page.text if "interactive" in t and "scan = 150" in t]
    assert notes and "(from 0 to 585)" in notes[0]


def _query(url: str) -> dict:
    return {k: v[0] for k, v in parse_qs(urlsplit(url).query).items()}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_each_chapter_has_its_launch_links(built, path):
    page = _parse(built.out / "notebooks" / f"{path.stem}.html")
    hrefs = [a["href"] for tag, a in page.tags if tag == "a" and a.get("href", "").startswith("https://")]
    hub = [h for h in hrefs if h.startswith("https://hub.example.edu/")]
    assert len(hub) == 1
    assert urlsplit(hub[0]).path == "/hub/user-redirect/git-pull"
    assert _query(hub[0]) == {"repo": TARGETS.release_repo, "branch": "fall-2027",
                              "urlpath": f"lab/tree/annslam/{path.name}", "targetpath": "annslam"}
    binder = [h for h in hrefs if h.startswith("https://mybinder.org/")]
    assert len(binder) == 1
    assert urlsplit(binder[0]).path == "/v2/gh/example-course/annslam/v0.1.0"
    pull = _query(binder[0])["urlpath"]
    assert pull.startswith("git-pull?") and _query("x:/?" + pull.split("?", 1)[1]) == \
        _query(hub[0])
    colab = [h for h in hrefs if h.startswith("https://colab.research.google.com/")]
    text = " ".join("".join(page.text).split()).replace("\u2019", "'")   # Sphinx's smart quotes
    if path.stem in launch.NOT_ON_COLAB:
        assert colab == [] and f"Not on Colab: {launch.NOT_ON_COLAB[path.stem]}" in text
    else:
        assert colab == [f"https://colab.research.google.com/github/example-course/"
                         f"annslam-release/blob/fall-2027/{path.name}"]
        assert "the chapter's first cell installs the course's library there" in text


def test_launch_links_refuse_what_is_not_an_address_a_ref_or_a_chapter():
    ok = ("https://hub.example.edu", "https://github.com/a/b", "main", "05_ekf_slam.ipynb")
    assert launch.nbgitpuller_link(*ok).startswith("https://hub.example.edu/hub/user-redirect/")
    for hub in ("javascript:alert(1)", "hub.example.edu", "https://hub.example.edu/?x=1",
                "ftp://hub.example.edu"):
        with pytest.raises(ValueError, match="address"):
            launch.nbgitpuller_link(hub, *ok[1:])
    for ref in ("main branch", "../main", "main;rm", ""):
        with pytest.raises(ValueError, match="branch or tag"):
            launch.nbgitpuller_link(ok[0], ok[1], ref, ok[3])
    for nb in ("../secret.ipynb", "a/b.ipynb", "notes.txt"):
        with pytest.raises(ValueError, match="file name"):
            launch.nbgitpuller_link(*ok[:3], nb)
    # Colab opens GitHub only; Binder takes any git host by its encoded address
    assert launch.colab_link("https://git.example.edu/a/b", "main", "05_ekf_slam.ipynb") is None
    b = launch.binder_link("https://git.example.edu/a/b", "v1", "https://git.example.edu/a/r",
                           "main", "05_ekf_slam.ipynb")
    assert urlsplit(b).path == "/v2/git/https%3A%2F%2Fgit.example.edu%2Fa%2Fb/v1"
    assert launch.links(launch.LaunchTargets(), "05_ekf_slam.ipynb") == []
    with pytest.raises(ValueError):
        launch.LaunchTargets(release_repo="file:///srv/release")


# --- in the browser --------------------------------------------------------------------

@pytest.fixture(scope="module")
def served(built):
    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), functools.partial(Quiet, directory=str(built.out)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


@pytest.fixture(scope="module")
def page():
    from browser_support import why_no_browser

    reason = why_no_browser()
    if reason:
        pytest.skip(reason)
    from browser_support import CHROMIUM_ARGS, chromium_path
    from playwright.sync_api import sync_playwright

    pw = sync_playwright().start()
    browser = pw.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS + [
        "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1"])
    ctx = browser.new_context(viewport={"width": 1280, "height": 900})
    yield ctx.new_page()
    ctx.close()
    browser.close()
    pw.stop()


#: The code cells' highlighted text: half of axe's time on a chapter's page (every token a
#: node whose contrast it computes). Their colours are one palette, checked whole by
#: test_the_code_highlighting_palette_has_aa_contrast_in_both_modes, and axe checks them on
#: the pages of FULL_AXE.
CODE = ".highlight"
FULL_AXE = ["notebooks/05a_diagnose_the_filter.html", "notebooks/09_capstone.html"]


def _axe(page, exclude=()) -> list[dict]:
    import axe_playwright_python

    # colours still changing (the theme's 0.15 s transitions as the mode applies) are no
    # page's colours: wait for every transition to end
    page.wait_for_function("document.getAnimations().every(a => a.playState !== 'running')")
    if not page.evaluate("typeof axe !== 'undefined'"):
        page.evaluate((Path(axe_playwright_python.__file__).parent / "axe.min.js").read_text())
    res = page.evaluate("([tags, exclude]) => axe.run(exclude.length ? {exclude: exclude.map(s => [s])}"
                        " : document, {runOnly: {type: 'tag', values: tags}, resultTypes: "
                        "['violations']})", [WCAG_TAGS, list(exclude)])
    return res["violations"]


def _serious(violations) -> list[str]:
    return [f"{v['id']} ({v['impact']}, {len(v['nodes'])}x): {v['nodes'][0]['target']}"
            for v in violations if v["impact"] in SERIOUS]


def test_every_page_opens_offline_renders_its_math_and_passes_wcag_21_aa(built, served, page):
    """Every page: nothing requested from another host (the browser resolves none; each
    such request would be counted), no failed request, no console error, every formula
    typeset by the site's own MathJax, and no serious or critical axe-core violation of
    WCAG 2.1 A/AA."""
    elsewhere, failed, errors, loading = [], [], [], [True]

    def note(bucket, item):
        if loading[0]:            # axe fetches the stylesheets again itself, resolving the
            bucket.append(item)   # theme's @import against the page: not the page's requests
    page.on("request", lambda r: None if r.url.startswith((served, "data:"))
            else elsewhere.append(r.url))
    page.on("requestfailed", lambda r: note(failed, r.url))
    page.on("response", lambda r: note(failed, f"{r.status} {r.url}") if r.status >= 400 else None)
    page.on("console", lambda m: note(errors, m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: note(errors, str(e)))
    report = {}
    for path in _pages(built.out):
        rel = path.relative_to(built.out).as_posix()
        loading[0] = True
        page.goto(f"{served}/{rel}", wait_until="load")
        maths = page.evaluate("document.querySelectorAll('.math').length")
        if maths:
            page.wait_for_function("n => document.querySelectorAll('.math mjx-container')"
                                   ".length >= n", arg=maths, timeout=60_000)
        loading[0] = False
        report[rel] = _serious(_axe(page, () if rel in FULL_AXE else (CODE,)))
    assert elsewhere == [] and failed == [] and errors == []
    assert {k: v for k, v in report.items() if v} == {}


def test_the_dark_mode_passes_wcag_21_aa_too(served, page):
    """The theme follows the reader's colour scheme: the front page and a chapter in dark."""
    page.emulate_media(color_scheme="dark")
    try:
        for rel in ["index.html", FULL_AXE[0]]:
            page.goto(f"{served}/{rel}", wait_until="load")
            assert page.evaluate("document.documentElement.dataset.theme") == "dark"
            assert _serious(_axe(page)) == [], rel
    finally:
        page.emulate_media(color_scheme="light")


def _luminance(hex_colour: str) -> float:
    rgb = [int(hex_colour[i:i + 2], 16) / 255 for i in (1, 3, 5)]
    lin = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in rgb]
    return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]


def contrast(a: str, b: str) -> float:
    """WCAG 2.1's contrast ratio of two #rrggbb colours."""
    la, lb = sorted((_luminance(a), _luminance(b)), reverse=True)
    return (la + 0.05) / (lb + 0.05)


def test_the_code_highlighting_palette_has_aa_contrast_in_both_modes(built):
    """Every token colour of the code cells against the code background, in the light and
    the dark theme: at least 4.5:1 (WCAG 2.1 AA for text)."""
    assert round(contrast("#777777", "#ffffff"), 2) == 4.48      # the formula, on a known pair
    css = (built.out / "_static" / "pygments.css").read_text()
    low = {}
    for mode in ("light", "dark"):
        rules = re.findall(rf'html\[data-theme="{mode}"\] \.highlight( \.[\w-]+)? \{{([^}}]*)\}}', css)
        background = [re.search(r"background(?:-color)?:\s*(#[0-9a-fA-F]{6})", body).group(1)
                      for cls, body in rules if not cls and "background" in body]
        assert len(background) == 1, mode
        colours = {cls.strip(): m.group(1) for cls, body in rules
                   if (m := re.search(r"(?<!-)color:\s*(#[0-9a-fA-F]{6})", body))}
        assert len(colours) > 20, f"{mode}: {len(colours)} token colours found"
        low |= {f"{mode} {cls}": round(contrast(c, background[0]), 2)
                for cls, c in colours.items() if contrast(c, background[0]) < 4.5}
    assert low == {}


def test_the_wcag_gate_fails_a_page_with_planted_defects(served, page):
    """The gate can fail: a picture without alt text, grey text on white at 1.6:1, a control
    without a name, each reported serious or critical on a page of the site."""
    page.goto(f"{served}/index.html", wait_until="load")
    page.evaluate("""() => {
        const m = document.querySelector('main') || document.body;
        m.insertAdjacentHTML('beforeend', '<img src="_static/annslam.css">'
          + '<p style="color:#ccc;background:#fff">faint words</p><button></button>');
    }""")
    found = {v["id"] for v in _axe(page) if v["impact"] in SERIOUS}
    assert {"image-alt", "color-contrast", "button-name"} <= found


def test_a_feedback_page_passes_wcag_21_aa(page):
    from annslam_lib.course.hub.classroom import feedback_page

    g = SimpleNamespace(
        graded=True, score=4, max_score=6, reason="", assignment="05_ekf_slam", student="ada",
        notes=["exercise 5.3 was graded on hidden runs"], errors=[],
        exercises=[SimpleNamespace(grade_id="ex5_1", points=2, max_points=2, status="passed",
                                   message="ok"),
                   SimpleNamespace(grade_id="ex5_3", points=2, max_points=4, status="failed",
                                   message="the gain ignores the landmark's covariance")])
    page.set_content(feedback_page(g))
    assert _serious(_axe(page)) == []


# The focused element: its focus ring (an outline or a box shadow) and whether it can be
# seen (a box, no ancestor transparent, inside every ancestor that clips its overflow).
FOCUS_JS = """() => {
    const e = document.activeElement;
    if (!e || e === document.body) return null;
    const s = getComputedStyle(e);
    const r = e.getBoundingClientRect();
    let shown = r.width > 0 && r.height > 0;
    for (let a = e; a && a !== document.body && shown; a = a.parentElement) {
        const t = getComputedStyle(a);
        if (parseFloat(t.opacity) === 0 || t.visibility === 'hidden') shown = false;
        if (a !== e && t.overflowY !== 'visible') {
            const c = a.getBoundingClientRect();
            if (r.bottom <= c.top || r.top >= c.bottom) shown = false;
        }
    }
    return {tag: e.tagName, text: (e.innerText || e.getAttribute('aria-label') || '').slice(0, 40),
            ring: (s.outlineStyle !== 'none' && parseFloat(s.outlineWidth) > 0)
                  || (s.boxShadow && s.boxShadow !== 'none'),
            shown, toc: !!e.closest('.bd-sidebar-secondary')};
}"""


def _tab_stops(page, count: int) -> list[dict]:
    page.evaluate("document.activeElement && document.activeElement.blur()")
    stops = []
    for _ in range(count):
        page.keyboard.press("Tab")
        info = page.evaluate(FOCUS_JS)
        if info is not None:
            stops.append(info)
    return stops


def test_keyboard_focus_is_visible_on_every_control_of_a_chapter(served, page):
    """Tab through the first 40 stops of a chapter page, and into the page's contents with
    a full-width figure in view (the theme then folds them into a bar): each focused element
    shows a focus ring and none is hidden, the folded contents' links included."""
    page.goto(f"{served}/notebooks/05_ekf_slam.html", wait_until="load")
    stops = _tab_stops(page, 40)
    assert len(stops) >= 20 and [i for i in stops if not (i["ring"] and i["shown"])] == []
    page.locator(f"figure.{site.PLAYER_CLASS}").scroll_into_view_if_needed()
    page.wait_for_function("document.querySelector('.bd-sidebar-secondary.hide') !== null")
    # from the link before the contents (the figure stays in view), Tab on into them
    page.evaluate("""() => { const all = [...document.querySelectorAll('.prev-next-area a')];
                             all[all.length - 1].focus({preventScroll: true}); }""")
    stops = []
    for _ in range(6):
        page.keyboard.press("Tab")
        stops.append(page.evaluate(FOCUS_JS))
    assert page.locator(".bd-sidebar-secondary.hide").count() == 1      # still folded
    assert sum(i["toc"] for i in stops) >= 5
    assert [i for i in stops if not (i["ring"] and i["shown"])] == []


# --- the widgets' animations -------------------------------------------------------------

ANIMATED = [p for p in NOTEBOOKS if any(
    "animate" in c.get("metadata", {}).get("annslam", {})
    for c in nbformat.read(p, as_version=4).cells)]
#: What one page's animation frames may weigh.
FRAMES_BUDGET_MB = 2.5
#: The widgets that draw a new view only when a step leaves the one they hold (MAINTAINING.md,
#: Widgets): the picture at a value depends on the values visited before it.
VIEW_REFIT = {"01_kinematics", "02_laser_offset", "03_observation", "05_ekf_slam"}


def _png_size(png: bytes) -> tuple[int, int]:
    import struct

    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", png[16:24])


def test_every_chapter_with_a_widget_has_an_animation():
    widgets = [p for p in NOTEBOOKS if "application/vnd.jupyter.widget-view+json" in p.read_text()]
    assert ANIMATED == widgets and len(ANIMATED) >= 10


@pytest.mark.parametrize("path", ANIMATED, ids=lambda p: p.stem)
def test_an_animation_is_the_widget_itself_at_other_values(built, path):
    """The stored frames: enough of them, each with alt text and its readout; the frame at the
    widget's stored value is, byte for byte, the picture the widget stored; their files are
    on the site within the page's budget, and the page has the player."""
    import base64

    nb = nbformat.read(path, as_version=4)
    cell = next(c for c in nb.cells if "animate" in c.metadata.get("annslam", {}))
    frames = cell.metadata["annslam"]["frames"]
    assert len(frames) >= 5
    assert all(len(f["alt"]) >= alt.MIN_LENGTH and f["value"] for f in frames)
    assert len({f["png"] for f in frames}) == len(frames), "two frames are the same picture"
    stored = [o for o in site.widget_pictures(site._state(nb), next(
        o["data"]["application/vnd.jupyter.widget-view+json"]["model_id"] for o in cell.outputs
        if "application/vnd.jupyter.widget-view+json" in o.get("data", {})))
        if "image/png" in o.get("data", {})]
    start = site._control_value(site._state(nb), cell, cell.metadata["annslam"]["animate"]["control"])
    at_start = [f for f in frames if f["value"] == start]
    assert len(at_start) == 1, f"no frame at the stored value {start!r}"
    got, want = (base64.b64decode(x) for x in (at_start[0]["png"], stored[-1]["data"]["image/png"]))
    if path.stem in VIEW_REFIT:
        # drawn after the other values, within the view they left: the same state and words,
        # the axes' ranges may differ (an Image widget stores no alt text of its own)
        assert stored[-1]["metadata"]["image/png"]["alt"] in ("", at_start[0]["alt"])
        assert _png_size(got) == _png_size(want)
    else:
        assert got == want
    files = sorted((built.out / "frames" / path.stem).glob("*.png"))
    assert len(files) == len(frames)
    assert sum(f.stat().st_size for f in files) / 1e6 <= FRAMES_BUDGET_MB
    page = _parse(built.out / "notebooks" / f"{path.stem}.html")
    players = [a for tag, a in page.tags if tag == "figure" and site.PLAYER_CLASS in a.get("class", "")]
    assert len(players) == 1 and players[0]["aria-label"].startswith("Animation")


def test_every_animation_plays_and_answers_the_keyboard(built, served, page):
    """On each page: Play changes the picture (two screenshots differ) and its alt text; the
    range control, reached by Tab, steps the frames with the arrow keys."""
    for path in ANIMATED:
        page.goto(f"{served}/notebooks/{path.stem}.html", wait_until="load")
        fig = page.locator(f"figure.{site.PLAYER_CLASS}")
        fig.scroll_into_view_if_needed()
        img = fig.locator("img")
        page.wait_for_function("i => i.complete && i.naturalWidth > 0", arg=img.element_handle())
        shot0, src0 = img.screenshot(), img.get_attribute("src")
        fig.get_by_role("button", name="Play").click()
        page.wait_for_function("([i, s]) => i.getAttribute('src') !== s && i.complete "
                               "&& i.naturalWidth > 0", arg=[img.element_handle(), src0],
                               timeout=5000)
        fig.get_by_role("button").click()                       # pause
        assert img.screenshot() != shot0, f"{path.stem}: the picture did not change"
        frames = json.loads(fig.get_attribute("data-frames"))
        shown = [f["alt"] for f in frames if f["src"] == img.get_attribute("src")]
        assert shown == [img.get_attribute("alt")]               # the alt text follows
        rng = fig.get_by_role("slider")
        rng.focus()
        before = rng.get_attribute("aria-valuetext")
        page.keyboard.press("Home")
        page.keyboard.press("ArrowRight")
        assert rng.get_attribute("aria-valuetext") != before or rng.input_value() == "1"
        assert fig.locator("output").inner_text() == rng.get_attribute("aria-valuetext")
