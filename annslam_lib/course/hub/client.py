"""Driving a class hub over its REST API, as an admin service (``ANNSLAM_HUB_ADMIN_TOKEN``):
start a student's server, run code in a kernel of it over the server's websocket, log in as
a browser does; and :func:`launch`, a hub started on free loopback ports from a prepared
folder. Used by the hub's tests and its load benchmark; every wait has a deadline.
"""
from __future__ import annotations

import json
import os
import secrets
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from ... import _settings
from . import HubError, HubLayout, account_status

__all__ = ["HubClient", "Kernel", "Execution", "RunningHub", "launch", "free_ports",
           "remove_accounts"]


@dataclass
class Execution:
    """What one ``execute_request`` gave: its stdout, its error (``"Name: value"``) if any."""
    stdout: str
    error: str | None
    seconds: float


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    def http_error_302(self, req, fp, code, msg, headers):
        return fp

    http_error_301 = http_error_303 = http_error_307 = http_error_302


class HubClient:
    """The hub at ``url`` (``http://127.0.0.1:PORT``) with an admin API ``token``."""

    def __init__(self, url: str, token: str, *, log_tail=lambda: ""):
        self.url, self.token, self.log_tail = url.rstrip("/"), token, log_tail

    def request(self, method: str, path: str, body=None, *, timeout: float = 30):
        """``(status, decoded JSON or text)`` of one API call."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, method=method, headers={
            "Authorization": f"token {self.token}", "Content-Type": "application/json"})
        try:
            with urllib.request.urlopen(req, timeout=timeout) as r:
                raw = r.read()
                return r.status, (json.loads(raw) if raw.strip() else None)
        except urllib.error.HTTPError as e:
            raw = e.read()
            try:
                return e.code, json.loads(raw)
            except ValueError:
                return e.code, raw.decode(errors="replace")

    def start_server(self, name: str, *, wait: bool = True, deadline: float = 150) -> None:
        status, body = self.request("POST", f"/hub/api/users/{name}/server")
        if status not in (201, 202, 400):       # 400: already running
            raise RuntimeError(f"starting {name}'s server: {status} {body}\n{self.log_tail()}")
        if wait:
            self.wait_ready(name, deadline)

    def wait_ready(self, name: str, deadline: float = 150) -> None:
        end = time.monotonic() + deadline
        while time.monotonic() < end:
            status, user = self.request("GET", f"/hub/api/users/{name}")
            server = (user or {}).get("servers", {}).get("", {}) if status == 200 else {}
            if server.get("ready"):
                return
            if status == 200 and not server:
                raise RuntimeError(f"{name}'s server stopped while starting:\n{self.log_tail()}")
            time.sleep(0.5)
        raise TimeoutError(f"{name}'s server was not ready in {deadline:.0f} s:\n"
                           f"{self.log_tail()}")

    def stop_server(self, name: str) -> None:
        self.request("DELETE", f"/hub/api/users/{name}/server")

    def kernel(self, name: str) -> "Kernel":
        status, body = self.request("POST", f"/user/{name}/api/kernels", {"name": "python3"})
        if status != 201:
            raise RuntimeError(f"no kernel for {name}: {status} {body}")
        return Kernel(self, name, body["id"])

    def run(self, name: str, code: str, deadline: float = 60) -> Execution:
        """``code`` in a new kernel of ``name``'s server, which is then shut down."""
        with self.kernel(name) as k:
            return k.execute(code, deadline)

    def login(self, name: str, password: str) -> int:
        """POST the login form as a browser does; the status of the answer (302 to the
        user's server when let in; 403 with the form again when not)."""
        import http.cookiejar

        jar = http.cookiejar.CookieJar()
        opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(jar),
                                             _NoRedirect())
        try:
            opener.open(self.url + "/hub/login", timeout=30).read()
        except urllib.error.HTTPError as e:
            e.read()
        xsrf = next((c.value for c in jar if c.name == "_xsrf"), "")
        form = urllib.parse.urlencode({"username": name, "password": password,
                                       "_xsrf": xsrf}).encode()
        try:
            with opener.open(self.url + "/hub/login", data=form, timeout=30) as r:
                return r.status
        except urllib.error.HTTPError as e:
            return e.code


class Kernel:
    """One kernel of a user's server, reached over its websocket."""

    def __init__(self, hub: HubClient, user: str, kernel_id: str):
        import websocket

        self.hub, self.user, self.id = hub, user, kernel_id
        ws_url = hub.url.replace("http", "ws", 1)
        self.ws = websocket.create_connection(
            f"{ws_url}/user/{user}/api/kernels/{kernel_id}/channels",
            header=[f"Authorization: token {hub.token}"], timeout=120)
        self.session = uuid.uuid4().hex

    def execute(self, code: str, deadline: float = 60) -> Execution:
        msg_id, t0 = uuid.uuid4().hex, time.monotonic()
        self.ws.send(json.dumps({
            "header": {"msg_id": msg_id, "username": self.user, "session": self.session,
                       "msg_type": "execute_request", "version": "5.3"},
            "parent_header": {}, "metadata": {}, "channel": "shell", "buffers": [],
            "content": {"code": code, "silent": False, "store_history": False,
                        "user_expressions": {}, "allow_stdin": False,
                        "stop_on_error": False}}))
        out, error = [], None
        replied = idle = False
        self.ws.settimeout(deadline)
        # The shell reply and the iopub output reach the websocket by different sockets, in
        # no fixed order: the execution is over when both the reply and iopub's "idle" came.
        while time.monotonic() - t0 < deadline:
            frame = self.ws.recv()
            if isinstance(frame, bytes):
                # a message with binary buffers (a widget's or a comm's): never one of the
                # execution's reply, status, stream or error messages read here
                continue
            msg = json.loads(frame)
            if msg.get("parent_header", {}).get("msg_id") != msg_id:
                continue
            kind = msg["msg_type"]
            if kind == "stream":
                out.append(msg["content"]["text"])
            elif kind == "error":
                error = f"{msg['content']['ename']}: {msg['content']['evalue']}"
            elif kind == "execute_reply":
                replied = True
            elif kind == "status" and msg["content"].get("execution_state") == "idle":
                idle = True
            if replied and idle:
                return Execution("".join(out), error, time.monotonic() - t0)
        raise TimeoutError(f"no reply from {self.user}'s kernel in {deadline:.0f} s")

    def close(self) -> None:
        try:
            self.ws.close()
        finally:
            self.hub.request("DELETE", f"/user/{self.user}/api/kernels/{self.id}")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def free_ports(n: int = 3) -> int:
    """A port p with p .. p+n-1 free on 127.0.0.1 (the hub, its API, the proxy's API)."""
    for _ in range(200):
        p = 20000 + secrets.randbelow(30000)
        socks = []
        try:
            for k in range(n):
                s = socket.socket()
                s.bind(("127.0.0.1", p + k))
                socks.append(s)
            return p
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free ports")


@dataclass
class RunningHub:
    """A running class hub: its folder, port, admin token, passwords and process."""
    layout: HubLayout
    port: int
    token: str
    passwords: dict
    proc: subprocess.Popen
    log: Path
    users: list = field(default_factory=list)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def api(self) -> HubClient:
        return HubClient(self.url, self.token, log_tail=self.log_tail)

    def log_tail(self, n: int = 60) -> str:
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return "(no log)"

    def stop(self) -> None:
        for name in self.users:
            self.api.stop_server(name)
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)


def launch(layout: HubLayout, students: list[str], folder: Path, *,
           deadline: float = 90) -> RunningHub:
    """``python -m annslam_lib hub --no-studies`` for ``students`` from the prepared folder
    ``layout``, on free loopback ports, with a fresh admin token and passwords; its log in
    ``folder``. Returns once the hub's API answers. The class's studies are whatever
    ``layout.studies`` holds (:func:`.setup.warm_class_studies` fills it, outside the
    deadline)."""
    class_file = folder / "class.txt"
    class_file.write_text("".join(f"{s}\n" for s in students))
    port = free_ports()
    token = secrets.token_hex(24)
    passwords = {_settings.HUB_PASSWORD: secrets.token_urlsafe(12),
                 _settings.HUB_INSTRUCTOR_PASSWORD: secrets.token_urlsafe(36)}
    env = {**os.environ, _settings.HUB_DIR: str(layout.root), _settings.HUB_ADMIN_TOKEN: token,
           **passwords}
    log = folder / "hub.log"
    with open(log, "wb") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "annslam_lib", "hub", "--no-studies",
                                 "--class", str(class_file), "--port", str(port)], env=env,
                                stdout=fh, stderr=subprocess.STDOUT, start_new_session=True)
    h = RunningHub(layout, port, token, passwords, proc, log)
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise RuntimeError(f"the hub exited with {proc.returncode}:\n{h.log_tail()}")
        try:
            with urllib.request.urlopen(h.url + "/hub/api", timeout=3) as r:
                if r.status == 200:
                    return h
        except OSError:
            pass
        time.sleep(0.5)
    h.stop()
    raise RuntimeError(f"the hub did not answer in {deadline:.0f} s:\n{h.log_tail()}")


def remove_accounts(names) -> None:
    """Delete the course's accounts among ``names`` with their homes (never another's)."""
    for n in names:
        try:
            if account_status(n) == "course":
                subprocess.run(["userdel", "--remove", n], capture_output=True, timeout=30)
        except HubError:
            pass
