"""``tlt-live-viewer``: serves the project's three.js live viewer to a browser (docs/live-view.md).

The page (``web/index.html``) connects to ``tlt-live-bridge`` itself, over Foxglove's WebSocket
protocol, at ``ws://<the page's host>:<bridge port>`` (``?ws=ws://host:port`` in the address picks
another bridge); this server only hands out its files, three.js from ``web/node_modules`` (which
``scripts/setup.sh`` installs there with ``npm ci`` from ``web/package-lock.json``), and
``config.json`` with the bridge's port.

    tlt-live-viewer --port 8766 --bridge-port 8765    # then open http://127.0.0.1:8766/
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

WEB_DIR = Path(__file__).resolve().parent / "web"
THREE_MODULE = WEB_DIR / "node_modules" / "three" / "build" / "three.module.js"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8766
DEFAULT_BRIDGE_PORT = 8765


class MissingThreeJs(RuntimeError):
    """three.js is not installed beside the page."""


class _Handler(SimpleHTTPRequestHandler):
    """The page's files; ``/config.json`` from the server's settings; no request log on stderr."""

    def __init__(self, *args: Any, config: bytes, **kwargs: Any) -> None:
        self._config = config
        super().__init__(*args, directory=str(WEB_DIR), **kwargs)

    def do_GET(self) -> None:
        if self.path.split("?")[0] != "/config.json":
            super().do_GET()
            return
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(self._config)))
        self.end_headers()
        self.wfile.write(self._config)

    def log_message(self, format: str, *args: object) -> None:
        pass


class LiveViewerServer(ThreadingHTTPServer):
    """Serves the viewer on ``host``:``port`` (0: any free port), pointing it at the bridge's port."""

    daemon_threads = True

    def __init__(
        self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, bridge_port: int = DEFAULT_BRIDGE_PORT
    ) -> None:
        if not THREE_MODULE.is_file():
            raise MissingThreeJs(
                f"three.js is not installed beside the viewer ({THREE_MODULE} is missing): run "
                "scripts/setup.sh, which installs it with npm"
            )
        config = json.dumps({"bridgePort": bridge_port}).encode()
        super().__init__((host, port), partial(_Handler, config=config))
        self.host = host

    @property
    def address(self) -> str:
        """The address a browser opens: ``http://host:port/``."""
        return f"http://{self.host}:{self.server_port}/"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="tlt-live-viewer", description=__doc__.splitlines()[0])
    p.add_argument("--host", default=DEFAULT_HOST, help="address to serve on (0.0.0.0: every interface)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help="port to serve the page on")
    p.add_argument(
        "--bridge-port",
        type=int,
        default=DEFAULT_BRIDGE_PORT,
        help="tlt-live-bridge's port on the page's host",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    """Serve until SIGINT/SIGTERM. Exit status 0, 2 for bad arguments, 1 if it cannot serve."""
    args = _parser().parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda _signum, _frame: stop.set())
    try:
        server = LiveViewerServer(args.host, args.port, args.bridge_port)
    except (MissingThreeJs, OSError) as exc:
        print(f"tlt-live-viewer: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 1
    print(
        f"live view in a browser: open {server.address} (the EDU in 3D from the bridge on port "
        f"{args.bridge_port})",
        flush=True,
    )
    serving = threading.Thread(target=server.serve_forever, daemon=True)
    serving.start()
    try:
        while not stop.wait(0.5):
            pass
    finally:
        server.shutdown()
        server.server_close()
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["DEFAULT_BRIDGE_PORT", "DEFAULT_PORT", "WEB_DIR", "LiveViewerServer", "MissingThreeJs", "main"]
