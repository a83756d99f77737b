"""meshcat's server bridge, listening on 127.0.0.1 only (run by ``meshcat_page.LiveView``).

meshcat's ``meshcat-server`` binds its ZeroMQ socket to 127.0.0.1 but its web server
(tornado ``Application.listen(port)``) to every interface; this subclass passes
``address="127.0.0.1"`` so the scene is never reachable from another machine. It also
serves the page of :mod:`tcr_accuracy.view.meshcat_page` (meshcat's viewer plus the legend) at
``/view``. The page's HTML is read from stdin; ``zmq_url=`` and ``web_url=`` lines on
stdout tell the parent where to connect, as meshcat's own server does. The server stops
when its parent process is gone.

Listening on 127.0.0.1 is not enough against DNS rebinding: a page of ``evil.example`` whose
name is made to resolve to 127.0.0.1 talks to this server from the user's own browser. So
every request (page, static files, the WebSocket that carries the scene) must name this host
as ``127.0.0.1`` or ``localhost`` in its ``Host`` header, and a WebSocket opened by a page
must come from such an origin; anything else is answered 403.
"""

from __future__ import annotations

import os
import sys

HOST = "127.0.0.1"
#: The host names a request may give in its Host header or its Origin.
ALLOWED_HOSTS = ("127.0.0.1", "localhost")


def allowed_host(host: str | None) -> bool:
    """Whether a ``Host`` header value (``name[:port]``) names this machine by an allowed name."""
    if not host:
        return False
    name = host.rsplit(":", 1)[0] if host.count(":") == 1 else host
    return name.lower() in ALLOWED_HOSTS


def allowed_origin(origin: str) -> bool:
    """Whether a browser's ``Origin`` (``http://name:port``) is a page served from this machine."""
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(origin)
    except ValueError:
        return False
    return parts.scheme in ("http", "https") and (parts.hostname or "").lower() in ALLOWED_HOSTS


def _guarded(handler_class):
    """``handler_class`` answering 403 to a request whose Host (or WebSocket Origin) is not allowed."""
    import tornado.web

    class Guarded(handler_class):
        def prepare(self):
            if not allowed_host(self.request.headers.get("Host")):
                raise tornado.web.HTTPError(403)
            return super().prepare()

        def check_origin(self, origin):  # WebSocket handlers only: a page of another site may not connect
            return allowed_origin(origin)

    Guarded.__name__ = f"Guarded{handler_class.__name__}"
    return Guarded


def main() -> int:
    import tornado.ioloop
    import tornado.web
    from meshcat.servers.zmqserver import (
        VIEWER_HTML,
        VIEWER_ROOT,
        StaticFileHandlerNoCache,
        WebSocketHandler,
        ZMQWebSocketBridge,
    )

    page = sys.stdin.read()

    class PageHandler(tornado.web.RequestHandler):
        def get(self) -> None:
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.set_header("Cache-Control", "no-store")
            self.write(page)

    class LocalApplication(tornado.web.Application):
        def listen(self, port, address="", **kwargs):  # noqa: ARG002 - address forced
            return super().listen(port, address=HOST, **kwargs)

    class LocalBridge(ZMQWebSocketBridge):
        def make_app(self):
            return LocalApplication([
                (r"/static/(.*)", _guarded(StaticFileHandlerNoCache),
                 {"path": VIEWER_ROOT, "default_filename": VIEWER_HTML}),
                (r"/view", _guarded(PageHandler)),
                (r"/", _guarded(WebSocketHandler), {"bridge": self}),
            ])

    bridge = LocalBridge(host=HOST)
    parent = os.getppid()

    def stop_when_orphaned() -> None:  # the parent died without stopping us
        if os.getppid() != parent:
            bridge.ioloop.stop()

    tornado.ioloop.PeriodicCallback(stop_when_orphaned, 1000).start()
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url=http://{HOST}:{bridge.fileserver_port}/view", flush=True)
    bridge.run()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
