"""The dashboard's web server: a Flask app on its own threads, beside the control loop.

Why a separate threaded server (werkzeug) rather than the rover's Socket.IO
server: the simulator's server is pinned to an old Socket.IO stack and runs
one eventlet loop; a browser that stalls must not share it.  Each page gets a
thread that waits on the ``LatestSlot`` and streams server-sent events; a slow
or closed page only ever blocks its own thread.
"""
from __future__ import annotations

import errno
import logging
import socket
import threading
import time
from pathlib import Path

from wire_guard import HostCheck, allowed_host_names

log = logging.getLogger(__name__)

DEFAULT_HOST = "127.0.0.1"  # only this machine can open the page
DEFAULT_PORT = 4568  # beside the simulator's 4567
STREAM_HZ = 10.0  # server-sent events per second per page, at most
KEEPALIVE_S = 10.0  # a comment line this often keeps idle streams open, s
STATIC_DIR = Path(__file__).resolve().parent / "static"


def port_problem(host: str, port: int):
    """None when ``host:port`` can be listened on by us alone, else why not (text).

    Binds without SO_REUSEPORT, so a port another server holds (even one that
    set SO_REUSEPORT, as eventlet does) is reported busy instead of shared."""
    if not 0 <= int(port) <= 65535:
        return f"{port} is not a port number (0-65535)"
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        return f"cannot resolve host {host!r}: {exc}"
    family, _, _, _, addr = infos[0]
    s = socket.socket(family, socket.SOCK_STREAM)
    try:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # ignore TIME_WAIT leftovers only
        s.bind(addr)
        s.listen(1)
    except OSError as exc:
        reason = "is already in use by another server" if exc.errno == errno.EADDRINUSE else f"cannot be used: {exc.strerror}"
        return f"{host}:{port} {reason}"
    finally:
        s.close()
    return None


def create_app(holder):
    """Flask app serving the page and ``holder.source`` (a LiveSource or MissionSource;
    the holder lets a finished live mission hand the same page over to the viewer)."""
    import flask

    app = flask.Flask(__name__, static_folder=str(STATIC_DIR), static_url_path="/static")
    legend_png = []

    @app.route("/legend.png")
    def legend():
        if not legend_png:
            import cv2

            from dashboard import mapview
            from dashboard.view import MAP_SCALE

            legend_png.append(cv2.imencode(".png", mapview.legend(200 * MAP_SCALE))[1].tobytes())
        return flask.Response(legend_png[0], mimetype="image/png")

    @app.route("/")
    def index():
        return flask.send_from_directory(STATIC_DIR, "index.html")

    @app.route("/api/info")
    def info():
        return flask.jsonify(holder.source.info())

    @app.route("/api/state")
    def state():
        text = holder.source.state_json()
        if text is None:
            return flask.Response('{"version": 0}', mimetype="application/json")
        return flask.Response(text, mimetype="application/json", headers={"Cache-Control": "no-store"})

    @app.route("/api/frame/<int:index>")
    def frame(index):
        source = holder.source
        text = source.frame_json(index) if hasattr(source, "frame_json") else None
        if text is None:
            flask.abort(404)
        return flask.Response(text, mimetype="application/json")

    @app.route("/api/stream")
    def stream():
        source = holder.source
        if not hasattr(source, "stream"):
            flask.abort(404)
        return flask.Response(source.stream(), mimetype="text/event-stream",
                              headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    return app


class LiveSource:
    """The live view: renders whatever the control loop last published."""

    def __init__(self, slot, renderer, title="rover"):
        self.slot, self.renderer, self.title = slot, renderer, title
        self.stopping = threading.Event()

    def info(self):
        return {"kind": "live", "title": self.title}

    def state_json(self):
        version, snap = self.slot.latest()
        return None if snap is None else self.renderer.render(version, snap)

    def stream(self):
        version = 0
        period = 1.0 / STREAM_HZ
        yield "retry: 1000\n\n"
        while not self.stopping.is_set():
            got = self.slot.wait_newer(version, KEEPALIVE_S)
            if got is None:
                if self.slot.closed:
                    return
                yield ": keepalive\n\n"
                continue
            version, snap = got
            sent = time.monotonic()
            yield f"id: {version}\ndata: {self.renderer.render(version, snap)}\n\n"
            pause = period - (time.monotonic() - sent)
            if pause > 0:
                time.sleep(pause)


class DashboardServer:
    """Binds at construction (so a bad port fails before any work), serves on ``start()``."""

    def __init__(self, source, host=DEFAULT_HOST, port=DEFAULT_PORT):
        from werkzeug.serving import make_server

        problem = port_problem(host, port)
        if problem:
            raise OSError(problem)
        self.source = source
        # Loopback Host names only (and the bound one): a DNS-rebinding page cannot read the view.
        app = HostCheck(create_app(self), allowed_host_names([host]))
        self.server = make_server(host, port, app, threaded=True)
        self.server.daemon_threads = True
        self.host, self.port = self.server.server_address[:2]
        self._thread = None
        logging.getLogger("werkzeug").setLevel(logging.WARNING)  # no line per request

    @property
    def url(self):
        return f"http://{self.host}:{self.port}/"

    def start(self):
        self._thread = threading.Thread(target=self.server.serve_forever, name="dashboard", daemon=True)
        self._thread.start()
        log.info("dashboard: open %s in a browser", self.url)
        return self

    def show(self, source):
        """Serve another source from now on (open pages reload it: live streams end)."""
        old, self.source = self.source, source
        self._end(old)

    @staticmethod
    def _end(source):
        if hasattr(source, "stopping"):
            source.stopping.set()
        slot = getattr(source, "slot", None)
        if slot is not None:
            slot.close()

    def stop(self):
        self._end(self.source)
        if self._thread is not None:
            self.server.shutdown()
            self._thread.join(5)
        self.server.server_close()
