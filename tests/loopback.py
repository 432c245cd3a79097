"""An HTTP server on a free port of 127.0.0.1, serving from a thread while in a ``with``
block: the base of the tests' stand-ins (an LMS, a git server, a proxy's API). Not a test
module."""
from __future__ import annotations

import threading
from http.server import ThreadingHTTPServer


class Loopback:
    """``with Loopback(Handler) as s``: ``Handler`` answering at ``s.url``."""

    def __init__(self, handler):
        self.server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"

    def __enter__(self):
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        return self

    def __exit__(self, *exc):
        self.server.shutdown()
        self.server.server_close()
