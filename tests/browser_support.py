"""Helpers for the browser end-to-end test (tests/test_browser.py): find the browser, start a
throw-away JupyterLab on 127.0.0.1, stop it again. Not a test module (no ``test_`` prefix)."""
from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import nbformat

REPO = Path(__file__).resolve().parents[1]
ARTIFACTS = REPO / "test-artifacts" / "browser"

# Flags measured to be needed for the Debian Chromium in a container (NOTEBOOK_TESTING.md).
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--disable-dev-shm-usage"]

# nbgrader (an instructor tool, installed for its own tests) adds four server extensions, a lab
# extension and a menu to every JupyterLab in the venv; the browser test does not need them, and
# they add about a second to the server start and a warning about the course directory.
NBGRADER_SERVER_EXTENSIONS = ["nbgrader.server_extensions.formgrader",
                              "nbgrader.server_extensions.validate_assignment",
                              "nbgrader.server_extensions.assignment_list",
                              "nbgrader.server_extensions.course_list"]

# User settings for the test's JupyterLab: no news/update-check popup; every cell in the DOM
# (the default 'contentVisibility' windowing may leave off-screen cells unattached).
LAB_SETTINGS = {
    "@jupyterlab/apputils-extension/notification": {"checkForUpdates": False, "fetchNews": "false"},
    "@jupyterlab/notebook-extension/tracker": {"windowingMode": "none"},
}


def why_no_browser() -> str | None:
    """Why the browser test cannot run here (None when it can): playwright and Chromium."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError as e:
        return (f"the Python package playwright cannot be imported ({e}); "
                "install it with: pip install -r environment-instructor.txt "
                "(./course.sh test does this)")
    if chromium_path() is None:
        return ("Chromium is not installed (no /usr/bin/chromium, no `chromium` on PATH); "
                "install it with: apt-get install chromium (.ci/run does this when it runs as root "
                "with apt-get available)")
    return None


def chromium_path() -> str | None:
    """The system (Debian package) Chromium: playwright launches it, nothing is downloaded."""
    return "/usr/bin/chromium" if os.access("/usr/bin/chromium", os.X_OK) else shutil.which("chromium")


def launch_chromium():
    """(playwright, browser): the system Chromium, started by playwright with CHROMIUM_ARGS;
    stop both with ``browser.close(); playwright.stop()``."""
    from playwright.sync_api import sync_playwright

    pw = sync_playwright().start()
    return pw, pw.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)


def serve_copy(notebook: Path, folder: Path) -> Path:
    """Copy ``notebook`` into ``folder`` without outputs, execution counts or saved widget state.

    The server works on the copy (JupyterLab autosaves; the committed notebook is compared by
    nbval at the same time), and every output the test sees must come from the live kernel."""
    nb = nbformat.read(notebook, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs, cell.execution_count = [], None
    nb.metadata.pop("widgets", None)
    folder.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, folder / notebook.name)
    return folder / notebook.name


_NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # 127.0.0.1 is local


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class LabServer:
    proc: subprocess.Popen
    port: int
    token: str
    log: Path

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def log_tail(self, n: int = 3000) -> str:
        return self.log.read_text(errors="replace")[-n:] if self.log.exists() else "(no log)"

    def status(self) -> dict:
        req = urllib.request.Request(f"{self.url}/api/status",
                                     headers={"Authorization": f"token {self.token}"})
        with _NO_PROXY.open(req, timeout=2) as r:
            return json.load(r)

    def stop(self) -> None:
        """SIGTERM to the server's process group (the server shuts its kernels down), then
        SIGKILL if it is still there after 15 s."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=5)


def start_lab(root_dir: Path, work: Path, *, timeout: float = 60.0) -> LabServer:
    """Start JupyterLab on 127.0.0.1 serving ``root_dir``, with a random token, its own config,
    data, runtime and settings folders under ``work``, and the caller's environment (so
    ``ANNSLAM_DATA`` reaches the kernel). Returns once ``/api/status`` answers."""
    settings, config = work / "lab-settings", work / "jupyter-config"
    for name, values in LAB_SETTINGS.items():
        f = settings / f"{name}.jupyterlab-settings"
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(json.dumps(values))
    (config / "labconfig").mkdir(parents=True, exist_ok=True)
    (config / "jupyter_server_config.json").write_text(json.dumps(
        {"ServerApp": {"jpserver_extensions": {e: False for e in NBGRADER_SERVER_EXTENSIONS}}}))
    (config / "labconfig" / "page_config.json").write_text(json.dumps(
        {"disabledExtensions": {"@jupyter/nbgrader": True}}))
    env = dict(os.environ, JUPYTERLAB_SETTINGS_DIR=str(settings),
               JUPYTERLAB_WORKSPACES_DIR=str(work / "lab-workspaces"),
               JUPYTER_CONFIG_DIR=str(config), JUPYTER_DATA_DIR=str(work / "jupyter-data"),
               JUPYTER_RUNTIME_DIR=str(work / "jupyter-runtime"), IPYTHONDIR=str(work / "ipython"))
    port, token = _free_port(), secrets.token_hex(16)
    cmd = [sys.executable, "-m", "jupyter", "lab", "--no-browser", "--ip=127.0.0.1",
           f"--port={port}", "--ServerApp.port_retries=0",  # fail loudly, never move to another port
           f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={root_dir}"]
    if os.geteuid() == 0:
        cmd.append("--allow-root")  # Jupyter refuses to run as root without it (containers)
    log = work / "jupyterlab.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen(cmd, env=env, cwd=work, stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
    server = LabServer(proc, port, token, log)
    deadline = time.monotonic() + timeout
    while True:
        if proc.poll() is not None:
            raise RuntimeError(f"JupyterLab exited with code {proc.returncode} before it was "
                               f"ready; its log:\n{server.log_tail()}")
        try:
            server.status()
            return server
        except OSError:
            pass
        if time.monotonic() > deadline:
            server.stop()
            raise RuntimeError(f"JupyterLab did not answer /api/status within {timeout:.0f} s; "
                               f"its log:\n{server.log_tail()}")
        time.sleep(0.2)


# Code-cell prompts: "[ ]:" never run, "[*]:" queued or running, "[12]:" done.
# Resolves to "done" when every cell ran, "stopped" when execution ended with cells left over
# (an error aborts the queue), so a broken notebook fails at once instead of at the time limit.
RUN_STATE_JS = """() => {
  const p = [...document.querySelectorAll('.jp-Notebook .jp-CodeCell .jp-InputPrompt')]
    .map(e => e.textContent.trim());
  const done = p.filter(t => /^\\[\\d+\\]:$/.test(t)).length;
  if (p.length > 0 && done === p.length) return 'done';
  if (done > 0 && !p.some(t => t === '[*]:')) return 'stopped';
  return false;
}"""

# How far a Run All got: [cells with an execution number, code cells, cells queued or
# running ([*]), the kernel idle]. A cell that raises with the `raises-exception` tag (the
# student versions' autograded checks) does not stop the kernel's queue, but JupyterLab
# 4.6 clears the [*] of the cells still queued: the run goes on without them showing it.
RUN_PROGRESS_JS = """() => {
  const p = [...document.querySelectorAll('.jp-Notebook .jp-CodeCell .jp-InputPrompt')]
    .map(e => e.textContent.trim());
  const idle = [...document.querySelectorAll('.jp-StatusBar-Item')]
    .some(e => e.textContent.includes('| Idle'));
  return [p.filter(t => /^\\[\\d+\\]:$/.test(t)).length, p.length,
          p.filter(t => t === '[*]:').length, idle];
}"""


def wait_run_all(page, timeout: float, settle: float = 5.0) -> tuple[str, float]:
    """('done', s) once every code cell has its execution number, or ('stopped', s) once the
    count has not moved for ``settle`` seconds with the kernel idle and nothing shown
    queued; ('timeout', s) after ``timeout`` seconds."""
    t0 = time.monotonic()
    last, since = None, t0
    while time.monotonic() - t0 < timeout:
        done, total, queued, idle = page.evaluate(RUN_PROGRESS_JS)
        now = time.monotonic()
        if total and done == total:
            return "done", now - t0
        if done != last or queued or not idle:
            last, since = done, now
        elif done and now - since >= settle:
            return "stopped", now - t0
        time.sleep(0.2)
    return "timeout", time.monotonic() - t0
