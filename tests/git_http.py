"""Git repositories served over git's smart HTTP protocol on 127.0.0.1, by ``git
http-backend`` run per request as its CGI interface asks (nbgitpuller clones with ``--depth
1``, which the plain-file "dumb" protocol cannot serve). For the hub's tests; not a test
module."""
from __future__ import annotations

import os
import subprocess
import urllib.parse
from http.server import BaseHTTPRequestHandler
from pathlib import Path

from loopback import Loopback


class GitServer(Loopback):
    """``with GitServer(folder) as g``: every repository in ``folder`` at ``g.url/NAME``."""

    def __init__(self, folder: Path):
        root = str(folder)

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def _cgi(self):
                url = urllib.parse.urlsplit(self.path)
                body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
                env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"),
                       "GIT_PROJECT_ROOT": root, "GIT_HTTP_EXPORT_ALL": "1",
                       "PATH_INFO": urllib.parse.unquote(url.path), "QUERY_STRING": url.query,
                       "REQUEST_METHOD": self.command, "REMOTE_ADDR": "127.0.0.1",
                       "CONTENT_TYPE": self.headers.get("Content-Type", ""),
                       "CONTENT_LENGTH": str(len(body)),
                       "HTTP_GIT_PROTOCOL": self.headers.get("Git-Protocol", "")}
                out = subprocess.run(["git", "http-backend"], input=body, env=env,
                                     capture_output=True, timeout=120).stdout
                head, _, payload = out.partition(b"\r\n\r\n")
                status, headers = 200, []
                for line in head.decode("latin-1").split("\r\n"):
                    key, _, value = line.partition(":")
                    if key.lower() == "status":
                        status = int(value.split()[0])
                    elif key:
                        headers.append((key, value.strip()))
                self.send_response(status)
                for key, value in headers:
                    self.send_header(key, value)
                self.send_header("Content-Length", str(len(payload)))
                self.end_headers()
                self.wfile.write(payload)

            do_GET = do_POST = _cgi

        super().__init__(Handler)
