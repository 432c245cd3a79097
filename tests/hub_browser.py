"""A student at the class hub in headless Chromium, as a person uses it: the hub's login
form, JupyterLab, nbgrader's Assignments panel (Nbgrader > Assignment List), a notebook's
cells typed into and saved. Used by tests/test_hub.py; not a test module."""
from __future__ import annotations

import nbformat
from browser_support import ARTIFACTS

PANEL = "#nbgrader-assignment-list, .nbgrader-AssignmentList, #released_assignments_list"


class Student:
    """One student's browser session at the hub ``url``."""

    def __init__(self, browser, url: str, name: str):
        self.url, self.name = url, name
        self.context = browser.new_context(viewport={"width": 1400, "height": 1000})
        self.page = self.context.new_page()
        self.page.set_default_timeout(60_000)

    def shot(self, what: str) -> str:
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        path = ARTIFACTS / f"hub-{self.name}-{what}.png"
        try:
            self.page.screenshot(path=str(path))
        except Exception as e:                       # noqa: BLE001 (the picture is a courtesy)
            return f"(no screenshot: {e})"
        return str(path)

    def log_in(self, password: str) -> None:
        """The hub's login form; then JupyterLab, once the student's server has started."""
        p = self.page
        p.goto(f"{self.url}/hub/login")
        p.fill("#username_input", self.name)
        p.fill("#password_input", password)
        p.click("#login_submit")
        p.wait_for_url(f"**/user/{self.name}/lab**", timeout=120_000)
        p.wait_for_selector(".jp-DirListing-item", timeout=60_000)

    def assignments(self) -> None:
        """Open nbgrader's Assignments panel from the menu bar."""
        p = self.page
        p.click(".lm-MenuBar-itemLabel:text-is('Nbgrader')")
        p.click(".lm-Menu-itemLabel:text-is('Assignment List')")
        p.wait_for_selector("#released_assignments_list", state="attached")

    def refresh_assignments(self) -> None:
        """The panel's refresh button: it lists the exchange again, now with feedback."""
        p = self.page
        p.click("#refresh_assignments_list")
        p.wait_for_selector("#submitted_assignments_list :text('feedback available to fetch')")

    def press(self, listing: str, button: str, then: str, timeout: float = 60_000) -> None:
        """Click ``button`` in the panel's ``listing`` (released, fetched, submitted) and
        wait until ``then`` (a selector) is attached."""
        p = self.page
        p.click(f"#{listing}_assignments_list button:text-is('{button}')")
        p.wait_for_selector(then, state="attached", timeout=timeout)

    def open_notebook(self, path: str) -> None:
        p = self.page
        p.goto(f"{self.url}/user/{self.name}/lab/tree/{path}")
        p.wait_for_selector(".jp-Notebook .jp-Cell", timeout=60_000)
        # the kernel's status on the toolbar: the notebook is fully opened
        p.wait_for_selector(".jp-Notebook-ExecutionIndicator, .jp-Toolbar-kernelStatus",
                            state="attached")

    def type_cell(self, index: int, source: str) -> None:
        """Replace the text of the notebook's cell ``index`` as typed in its editor."""
        p = self.page
        editor = p.locator(".jp-Notebook .jp-Cell").nth(index).locator(".cm-content")
        editor.scroll_into_view_if_needed()
        editor.click()
        p.keyboard.press("Control+A")
        p.keyboard.press("Delete")
        p.keyboard.insert_text(source)

    def save(self) -> None:
        p = self.page
        p.keyboard.press("Control+S")
        # JupyterLab marks an unsaved notebook's tab with jp-mod-dirty
        p.wait_for_selector(".lm-TabBar-tab.jp-mod-current:not(.jp-mod-dirty)",
                            state="attached", timeout=30_000)

    def fetch_text(self, path: str) -> tuple[int, str]:
        """(status, text) of ``path`` (below the hub's address) fetched by this page, with
        the student's own cookies: what their browser gets."""
        # JupyterHub wants the _xsrf cookie echoed by every cookie-authenticated API call
        return tuple(self.page.evaluate(
            """async (u) => {
                 const m = document.cookie.match(/(?:^|; )_xsrf=([^;]*)/);
                 const r = await fetch(u, {headers: m ? {'X-XSRFToken': m[1]} : {}});
                 return [r.status, await r.text()]; }""", f"{self.url}{path}"))

    def view_feedback(self, filename: str) -> str:
        """Click the panel's "(view feedback)" (the file browser goes to the feedback
        folder), open ``filename`` there with a double click: the text JupyterLab's HTML
        viewer shows."""
        p = self.page
        p.click("#submitted_assignments_list a:text-is(' (view feedback)')")
        item = p.locator(f".jp-DirListing-item:has-text('{filename}')")
        item.dblclick()
        body = p.frame_locator(".jp-HTMLViewer iframe").locator("body")
        body.locator("h1").wait_for()
        return body.inner_text()

    def close(self) -> None:
        self.context.close()


def solution_source(notebook, grade_id: str) -> str:
    """The instructor notebook's solution cell ``grade_id``, without its markers."""
    nb = nbformat.read(notebook, as_version=4)
    cell = next(c for c in nb.cells
                if c.metadata.get("nbgrader", {}).get("grade_id") == grade_id)
    return "\n".join(line for line in cell.source.splitlines()
                     if "### BEGIN SOLUTION" not in line and "### END SOLUTION" not in line)


def cell_index(notebook, grade_id: str) -> int:
    nb = nbformat.read(notebook, as_version=4)
    return next(i for i, c in enumerate(nb.cells)
                if c.metadata.get("nbgrader", {}).get("grade_id") == grade_id)
