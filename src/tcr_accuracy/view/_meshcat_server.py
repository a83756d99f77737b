"""meshcat's server bridge, listening on 127.0.0.1 only (run by ``meshcat_page.LiveView``).

meshcat's ``meshcat-server`` binds its ZeroMQ socket to 127.0.0.1 but its web server
(tornado ``Application.listen(port)``) to every interface; this subclass passes
``address="127.0.0.1"`` so the scene is never reachable from another machine. It also
serves the page of :mod:`tcr_accuracy.view.meshcat_page` (meshcat's viewer plus the legend) at
``/view``. The page's HTML is read from stdin; ``zmq_url=`` and ``web_url=`` lines on
stdout tell the parent where to connect, as meshcat's own server does. The server stops
when its parent process is gone.
"""

from __future__ import annotations

import os
import sys

HOST = "127.0.0.1"


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
                (r"/static/(.*)", StaticFileHandlerNoCache,
                 {"path": VIEWER_ROOT, "default_filename": VIEWER_HTML}),
                (r"/view", PageHandler),
                (r"/", WebSocketHandler, {"bridge": self}),
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
