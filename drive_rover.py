"""The socket edge: a Socket.IO server the Unity rover simulator connects to.

Why these exact libraries: the simulator opens
``ws://127.0.0.1:4567/socket.io/?EIO=4&transport=websocket`` but speaks
Engine.IO 3 (it pings ``2`` every 25 s) and never sends the namespace CONNECT
``40``.  python-engineio 3.14+ rejects that handshake and python-socketio 5
drops every event of a client that never sent ``40``; python-socketio 4.x with
python-engineio <= 3.13.2 accepts it.  So the versions are checked at start-up
and a wrong install exits with the fix spelled out.

Each ``telemetry`` gets exactly one reply from ``AutonomyClient`` (``data``,
``pickup`` or ``manual``): the simulator answers every command with one new
telemetry, so more than one reply would multiply the chains and none would
stall it.  Recording (optional folder argument) writes a simulator-format
``robot_log.csv`` + ``IMG/`` from a background thread and never deletes
anything.

Usage: ``python drive_rover.py [image_folder] [--host 127.0.0.1] [--port 4567]
[--ground-truth PATH|none] [--save-map PATH.npy] [--log-level INFO]``
"""
from __future__ import annotations

import argparse
import datetime as _dt
import logging
import math
import os
import queue
import re
import signal
import sys
import threading
import warnings
from importlib import metadata
from pathlib import Path
from typing import Optional, Tuple

log = logging.getLogger("drive_rover")

DEFAULT_HOST = "127.0.0.1"  # loopback: the simulator runs on the same machine
DEFAULT_PORT = 4567  # the port hard-coded in the simulator
SOCKETIO_RANGE = ((4, 0, 0), (4, 99, 99))  # accepted python-socketio versions, inclusive
ENGINEIO_RANGE = ((3, 9, 0), (3, 13, 2))  # accepted python-engineio: >= 3.9.0 (CVE-2019-13611 fix), <= 3.13.2 (3.14 rejects the sim)
FIX_COMMAND = 'pip install "python-socketio==4.6.1" "python-engineio==3.13.2"'  # the fix we print
PING_INTERVAL_S = 25  # Engine.IO ping interval announced in the handshake, s
PING_TIMEOUT_S = 60  # Engine.IO ping timeout, s
RECORD_QUEUE_FRAMES = 256  # frames buffered for the recorder thread before dropping, frames
RECORD_JOIN_TIMEOUT_S = 10.0  # time allowed to flush the recorder at exit, s
LIB_LOG_LEVEL = logging.WARNING  # socketio/engineio loggers (INFO logs every packet)
SAVE_MAP_EVERY_FRAMES = 100  # --save-map: telemetry frames between worldmap dumps (plus one at exit), frames


# --------------------------------------------------------------------------- versions
def _version_tuple(text: str) -> Tuple[int, ...]:
    parts = re.findall(r"\d+", text or "")[:3]
    return tuple(int(p) for p in parts) + (0,) * (3 - len(parts))


def check_versions(socketio_version: Optional[str], engineio_version: Optional[str]) -> Optional[str]:
    """None when the installed Socket.IO stack works with the simulator, else a
    message that says what is wrong and how to fix it."""
    problems = []
    for name, version, (low, high), why in (
            ("python-socketio", socketio_version, SOCKETIO_RANGE,
             "5.x drops every event because the simulator never sends the namespace CONNECT '40'"),
            ("python-engineio", engineio_version, ENGINEIO_RANGE,
             "3.14+ rejects the simulator's EIO=4 handshake and 4.x speaks a newer protocol")):
        if not version:
            problems.append(f"{name} is not installed")
        elif not low <= _version_tuple(version) <= high:
            problems.append(f"{name} {version} is installed but "
                            f"{'.'.join(map(str, low))}..{'.'.join(map(str, high))} is needed ({why})")
    if not problems:
        return None
    return ("The Unity rover simulator cannot talk to this Socket.IO install: "
            + "; ".join(problems) + f". Fix: {FIX_COMMAND}")


def installed_version(dist: str) -> Optional[str]:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def require_compatible_versions(socketio_version=None, engineio_version=None):
    """Exit (status 1) with the fix when the installed versions are wrong."""
    socketio_version = socketio_version or installed_version("python-socketio")
    engineio_version = engineio_version or installed_version("python-engineio")
    message = check_versions(socketio_version, engineio_version)
    if message:
        log.error("%s", message)
        sys.exit(message)


# --------------------------------------------------------------------------- recording
class Recorder:
    """Writes valid frames into a simulator-format log on a background thread,
    so disk latency never delays the reply.  Drops (and counts) frames when the
    queue is full rather than blocking the frame loop."""

    def __init__(self, folder, max_queue: int = RECORD_QUEUE_FRAMES):
        from replay.log_format import LogWriter

        self.writer = LogWriter(folder)
        self.folder = self.writer.folder
        self.dropped = 0
        self.errors = 0
        self._queue: "queue.Queue" = queue.Queue(maxsize=max_queue)
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()

    def submit(self, tel) -> bool:
        if tel is None or not tel.ok or not tel.image_jpeg:
            return False
        row = (tel.image_jpeg, tel.steer, tel.throttle, tel.brake, tel.speed,
               tel.pos[0], tel.pos[1], tel.pitch, tel.yaw, tel.roll, _dt.datetime.now())
        try:
            self._queue.put_nowait(row)
            return True
        except queue.Full:
            self.dropped += 1
            if self.dropped in (1, 10, 100) or self.dropped % 1000 == 0:
                log.warning("recorder falling behind: %d frames dropped", self.dropped)
            return False

    def _run(self):
        while True:
            row = self._queue.get()
            if row is None:
                return
            try:
                self.writer.write(*row[:-1], when=row[-1])
            except Exception:
                self.errors += 1
                if self.errors <= 3:
                    log.exception("recording a frame failed")

    def close(self):
        self._queue.put(None)
        self._thread.join(RECORD_JOIN_TIMEOUT_S)
        self.writer.close()
        log.info("recorded %d frames into %s (%d dropped)", self.writer.frames,
                 self.folder, self.dropped)


class MapSaver:
    """``--save-map``: dumps ``rover.worldmap`` as .npy every few frames and at exit,
    so a mission scorer (or a user) can read the map of a live run; each write is
    atomic (temp file + rename), so a reader never sees half a file."""

    def __init__(self, path, every: int = SAVE_MAP_EVERY_FRAMES):
        self.path = Path(path).expanduser()
        self.every = max(1, int(every))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._failed = False

    def maybe_save(self, rover) -> None:
        if rover.frame_count % self.every == 0:
            self.save(rover)

    def save(self, rover) -> None:
        import numpy as np

        tmp = self.path.with_name(f".{self.path.name}.tmp")
        try:
            with open(tmp, "wb") as fh:
                np.save(fh, np.asarray(rover.worldmap))
            os.replace(tmp, self.path)
        except OSError as exc:  # a full disk must not stop the rover
            if not self._failed:
                log.warning("cannot write the worldmap to %s: %s", self.path, exc)
            self._failed = True


# --------------------------------------------------------------------------- server
def build_server(client, recorder: Optional[Recorder] = None, map_saver: Optional[MapSaver] = None,
                 dashboard=None):
    """The Socket.IO server and WSGI app around ``client`` (an AutonomyClient);
    ``dashboard`` (optional) gets ``observe(client, event)`` after every reply."""
    import flask
    import socketio

    from autonomy import SAFE_STOP, RateLimitedLog, command_payload

    warn = RateLimitedLog(log)
    lib_logger = logging.getLogger("drive_rover.socketio")
    lib_logger.setLevel(logging.DEBUG if log.getEffectiveLevel() <= logging.DEBUG else LIB_LOG_LEVEL)

    class SimulatorServer(socketio.Server):
        """Socket.IO 4.x server that survives malformed packets and logs unknown
        events (the simulator only ever sends ``telemetry``)."""

        def _handle_eio_message(self, sid, data):
            try:
                return super()._handle_eio_message(sid, data)
            except Exception as exc:
                warn("garbage", "ignored malformed Socket.IO packet %r (%s)", str(data)[:80], exc)

        def _trigger_event(self, event, namespace, *args):
            if event not in ("connect", "disconnect") and \
                    event not in self.handlers.get(namespace, {}):
                warn("unknown-" + str(event)[:40], "ignored unknown event %r (no reply)",
                     str(event)[:80])
                return None
            return super()._trigger_event(event, namespace, *args)

    sio = SimulatorServer(async_mode="eventlet", async_handlers=False, logger=lib_logger,
                          engineio_logger=lib_logger, ping_interval=PING_INTERVAL_S,
                          ping_timeout=PING_TIMEOUT_S)

    @sio.on("connect")
    def on_connect(sid, environ):
        log.info("simulator connected (%s, %s)", sid, environ.get("QUERY_STRING", ""))

    @sio.on("disconnect")
    def on_disconnect(sid):
        log.info("simulator disconnected (%s)", sid)

    @sio.on("telemetry")
    def on_telemetry(sid, data=None, *extra):
        try:
            event, payload = client.handle_telemetry(data)
        except Exception:  # handle_telemetry never raises; keep the lockstep anyway
            log.exception("autonomy client raised")
            stop = SAFE_STOP
            event, payload = "data", command_payload(stop["throttle"], stop["brake"], stop["steer"])
        if recorder is not None and event != "manual":
            recorder.submit(client.last_telemetry)
        if map_saver is not None and event != "manual":
            map_saver.maybe_save(client.rover)
        sio.emit(event, payload, room=sid)
        if dashboard is not None:
            dashboard.observe(client, event)

    app = flask.Flask(__name__)

    @app.route("/")
    def index():
        return "drive_rover: RoboND rover autonomy client. Start the simulator in Autonomous mode.\n"

    return sio, socketio.WSGIApp(sio, app)


def load_ground_truth_arg(value):
    """``--ground-truth``: a path, 'none', or None for the shared default."""
    from evaluation.metrics import load_ground_truth
    import shared_data

    if value is not None and value.lower() == "none":
        return None
    if value is None:
        path = shared_data.ground_truth_map_path()
        if not path.exists():
            log.info("no ground-truth map at %s: Mapped/Fidelity show n/a", path)
            return None
    else:
        path = Path(value).expanduser()
    try:
        truth = load_ground_truth(path)
    except ValueError as exc:
        sys.exit(f"--ground-truth: {exc}")
    log.info("ground truth: %s (%d navigable cells)", path, int((truth > 0).sum()))
    return truth


def parse_args(argv=None):
    p = argparse.ArgumentParser(description="Autonomy client for the Udacity RoboND rover simulator "
                                            "(start this first, then the simulator in Autonomous mode).")
    p.add_argument("image_folder", nargs="?", default=None,
                   help="record a simulator-format log (robot_log.csv + IMG/) here; "
                        "a non-empty folder gets a new timestamped subfolder")
    p.add_argument("--host", default=DEFAULT_HOST, help="address to bind (default %(default)s)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help="port to bind (default %(default)s, the simulator's; 0 = any free port)")
    p.add_argument("--ground-truth", default=None,
                   help="map_bw.png for the Mapped/Fidelity inset (default: the shared one if present; 'none' to disable)")
    p.add_argument("--save-map", default=None, metavar="PATH.npy",
                   help="write the worldmap (200x200x3 uint8, [y, x]) here every "
                        f"{SAVE_MAP_EVERY_FRAMES} frames and at exit")
    add_home_by_option(p)
    from dashboard import add_dashboard_options

    add_dashboard_options(p)
    p.add_argument("--log-level", default="INFO", help="DEBUG, INFO, WARNING, ... (default %(default)s)")
    return p.parse_args(argv)


def add_home_by_option(parser: argparse.ArgumentParser):
    """--home-by SECONDS, the client's return deadline; the twin's tools offer the same option."""
    from decision import HOME_BY_S, SEARCH_HOME_BY_S

    parser.add_argument("--home-by", type=positive_seconds, default=None, metavar="SECONDS",
                        help=f"head home so as to arrive by this mission time (default {HOME_BY_S:.0f} s, "
                             f"tuned for a 600 s mission, stretched to {SEARCH_HOME_BY_S:.0f} s while the map is "
                             "incomplete or samples are missing and the search has places left; a value given "
                             "here is never stretched)")


def positive_seconds(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a positive number of seconds, got {text!r}")
    return v


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=getattr(logging, str(args.log_level).upper(), logging.INFO),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    require_compatible_versions()
    warnings.filterwarnings("ignore", message=r"\s*Eventlet is deprecated")  # documented in README
    import eventlet
    import eventlet.wsgi

    from autonomy import AutonomyClient

    client = AutonomyClient(ground_truth=load_ground_truth_arg(args.ground_truth), home_by_s=args.home_by)
    try:
        listener = eventlet.listen((args.host, args.port))
    except OSError as exc:
        sys.exit(f"cannot listen on {args.host}:{args.port}: {exc} "
                 f"(is another drive_rover.py running? pick another --port)")
    recorder = Recorder(args.image_folder) if args.image_folder else None
    if recorder is not None:
        log.info("recording into %s", recorder.folder)
    map_saver = MapSaver(args.save_map) if args.save_map else None
    dashboard = None
    if args.dashboard:
        from dashboard import LiveDashboard

        try:
            dashboard = LiveDashboard(args.dashboard_port, title="drive_rover").start()
        except OSError as exc:
            sys.exit(f"--dashboard-port: {exc}")
    _, wsgi_app = build_server(client, recorder, map_saver, dashboard)
    host, port = listener.getsockname()[:2]
    log.info("listening on %s:%d; now start the simulator and choose Autonomous mode", host, port)

    def _shutdown(signum, frame):
        # eventlet's server waits for open websockets to end, which the simulator
        # never does; so flush what matters (the recording, the logs) and leave.
        log.info("signal %d: stopping after %d frames (%d bad, %d step errors)", signum,
                 client.rover.frame_count, client.bad_frames, client.step_errors)
        if recorder is not None:
            recorder.close()
        if map_saver is not None:
            map_saver.save(client.rover)
        logging.shutdown()
        os._exit(0)

    signal.signal(signal.SIGTERM, _shutdown)
    signal.signal(signal.SIGINT, _shutdown)
    eventlet.wsgi.server(listener, wsgi_app, log=logging.getLogger("drive_rover.wsgi"),
                         log_output=False)
    if recorder is not None:
        recorder.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
