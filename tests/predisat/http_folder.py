"""A folder served over HTTP on the loopback interface, for the tests of URL inputs."""

from __future__ import annotations

import functools
import http.server
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["serve_folder"]


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    token: str | None = None  # when set, requests without "Authorization: Bearer TOKEN": 401

    def log_message(self, format: str, *args: Any) -> None:
        pass

    def _allowed(self) -> bool:
        if self.token is None or self.headers.get("Authorization") == f"Bearer {self.token}":
            return True
        self.send_error(401, "no or wrong token")
        return False

    def do_GET(self) -> None:
        if self._allowed():
            super().do_GET()

    def do_HEAD(self) -> None:
        if self._allowed():
            super().do_HEAD()


@contextmanager
def serve_folder(folder: Path, token: str | None = None) -> Iterator[str]:
    """``http://127.0.0.1:PORT`` serving ``folder`` (read only) while the block runs; with a
    ``token``, only to requests with the header ``Authorization: Bearer TOKEN``."""
    handler = functools.partial(type("Handler", (_QuietHandler,), {"token": token}),
                                directory=str(folder))  # fmt: skip
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, name="http-folder", daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5.0)
