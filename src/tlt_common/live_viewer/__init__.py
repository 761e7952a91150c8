"""The project's own live viewer: a three.js page (``web/``) that talks Foxglove's WebSocket
protocol to ``tlt-live-bridge`` and draws the EDU, the tower and the arms as they move, and the
small HTTP server that serves it (``tlt-live-viewer``, :mod:`tlt_common.live_viewer.server`).
docs/live-view.md."""
