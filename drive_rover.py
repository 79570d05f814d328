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
stall it.  The sessions (one simulator at a time, the newest frame handled
during a flood) are in ``wire_server.py``, the per-frame rules (what is
ignored, the Host check) in ``wire_guard.py``; docs/wire-hardening.md.
Recording (optional folder argument) writes a simulator-format
``robot_log.csv`` + ``IMG/`` from a background thread, never deletes
anything, and leaves no temp file when a write fails (``safe_write.py``).

Usage: ``python drive_rover.py [image_folder] [--host 127.0.0.1] [--port 4567]
[--ground-truth PATH|none] [--save-map PATH.npy] [--log-level INFO]``
"""
from __future__ import annotations

import argparse
import datetime as _dt
import logging
import os
import queue
import re
import signal
import sys
import threading
import time
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
RECORD_QUEUE_FRAMES = 256  # frames buffered for the recorder thread before dropping, frames
RECORD_JOIN_TIMEOUT_S = 10.0  # time allowed to flush the recorder at exit, s
RECORD_ERRORS_LOGGED = 3  # recorder write errors logged in full before only every RECORD_ERROR_LOG_EVERY-th
RECORD_ERROR_LOG_EVERY = 1000  # then one log line per this many failed frames, frames
STATUS_TICK_S = 1.0  # s between checks of the link status (lines are rarer: link_status.py)
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
            except Exception as exc:  # a full disk: the frame is lost, no litter is left (safe_write)
                self.errors += 1
                if self.errors <= RECORD_ERRORS_LOGGED or self.errors % RECORD_ERROR_LOG_EVERY == 0:
                    log.warning("recording a frame failed (%d so far): %s", self.errors, exc)

    def close(self):
        self._queue.put(None)
        self._thread.join(RECORD_JOIN_TIMEOUT_S)
        self.writer.close()
        log.info("recorded %d frames into %s (%d dropped, %d failed to write)", self.writer.frames,
                 self.folder, self.dropped, self.errors)


class MapSaver:
    """``--save-map``: dumps ``rover.worldmap`` as .npy every few frames and at exit,
    so a mission scorer (or a user) can read the map of a live run.  Each write
    is atomic and leaves no temp file when it fails (safe_write), and the
    target is checked up front (``check_map_target``): a folder, or a file that
    is not a NumPy .npy file, is refused rather than replaced."""

    def __init__(self, path, every: int = SAVE_MAP_EVERY_FRAMES):
        self.path = check_map_target(path)
        self.every = max(1, int(every))
        self._failing = False

    def maybe_save(self, rover) -> None:
        if rover.frame_count % self.every == 0:
            self.save(rover)

    def save(self, rover) -> None:
        import io

        import numpy as np
        from safe_write import atomic_write

        buf = io.BytesIO()
        np.save(buf, np.asarray(rover.worldmap))
        try:
            atomic_write(self.path, buf.getvalue())
        except OSError as exc:  # a full disk must not stop the rover
            if not self._failing:
                log.warning("cannot write the worldmap to %s: %s (will keep trying)", self.path, exc)
            self._failing = True
            return
        if self._failing:
            log.info("worldmap written to %s again", self.path)
        self._failing = False


NPY_MAGIC = b"\x93NUMPY"  # first bytes of every .npy file


def check_map_target(path) -> Path:
    """The ``--save-map`` path, or ValueError saying why it may not be written:
    it must end in .npy, must not be a folder, and an existing file there must
    be a .npy file (we replace our own dumps, never anything else)."""
    path = Path(path).expanduser()
    if path.is_dir():
        raise ValueError(f"{path} is a folder; give a file name such as {path / 'worldmap.npy'}")
    if path.suffix.lower() != ".npy":
        raise ValueError(f"{path} does not end in .npy (the map is written with numpy.save)")
    if path.exists() or path.is_symlink():
        if not path.is_file():
            raise ValueError(f"{path} exists and is not a regular file; refusing to replace it")
        try:
            with open(path, "rb") as fh:
                head = fh.read(len(NPY_MAGIC))
        except OSError as exc:
            raise ValueError(f"{path} exists and cannot be read ({exc}); refusing to replace it") from None
        if head != NPY_MAGIC and path.stat().st_size > 0:
            raise ValueError(f"{path} exists and is not a NumPy .npy file; refusing to replace it")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"cannot create the folder {path.parent}: {exc}") from None
    return path


# --------------------------------------------------------------------------- server
def build_server(client, recorder: Optional[Recorder] = None, map_saver: Optional[MapSaver] = None,
                 dashboard=None, hosts=()):
    """The Socket.IO server and WSGI app around ``client`` (an AutonomyClient);
    ``dashboard`` (optional) gets ``observe(client, event)`` after every handled
    frame.  Sessions, packet guards and the Host check live in wire_server/wire_guard."""
    import wire_server

    return wire_server.build_server(client, recorder, map_saver, hosts=hosts, dashboard=dashboard)


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
        _usage_error(f"--ground-truth: {exc}")
    log.info("ground truth: %s (%d navigable cells)", path, int((truth > 0).sum()))
    return truth


PROG = "python drive_rover.py"  # how help and errors name this tool


def _usage_error(message: str):
    """One line naming the option, exit status 2 (as argparse does for a bad option)."""
    from sim.cli import USAGE_EXIT

    sys.stderr.write(f"{PROG}: error: {message}\n")
    sys.exit(USAGE_EXIT)


def build_parser():
    from sim.cli import port_number, tool_parser

    p = tool_parser(PROG, "Autonomy client for the Udacity RoboND rover simulator "
                          "(start this first, then the simulator in Autonomous mode).")
    p.add_argument("image_folder", nargs="?", default=None,
                   help="record a simulator-format log (robot_log.csv + IMG/) here; "
                        "a non-empty folder gets a new timestamped subfolder")
    p.add_argument("--host", default=DEFAULT_HOST, help="address to bind (default %(default)s)")
    p.add_argument("--port", type=port_number, default=DEFAULT_PORT,
                   help="port to bind (default %(default)s, the simulator's; 0 = any free port)")
    p.add_argument("--ground-truth", default=None,
                   help="map_bw.png for the Mapped/Fidelity inset (default: the shared one if present; 'none' to disable)")
    p.add_argument("--save-map", default=None, metavar="PATH.npy",
                   help="write the worldmap (200x200x3 uint8, [y, x]) here every "
                        f"{SAVE_MAP_EVERY_FRAMES} frames and at exit")
    add_home_by_option(p)
    from dashboard import add_dashboard_options

    add_dashboard_options(p)
    from sim.cli import add_log_level_option

    add_log_level_option(p)
    return p


def parse_args(argv=None):
    return build_parser().parse_args(argv)


def check_args(args):
    """Every option that can be wrong, checked before any work starts: one line, exit 2.
    Returns the MapSaver for --save-map (or None)."""
    from dashboard.server import port_problem
    from sim.cli import file_problem, folder_problem

    if args.image_folder:
        problem = folder_problem(args.image_folder)
        if problem:
            _usage_error(f"image_folder: {problem}")
    map_saver = None
    if args.save_map:
        try:
            map_saver = MapSaver(args.save_map)
        except ValueError as exc:
            _usage_error(f"--save-map: {exc}")
        problem = file_problem(args.save_map)
        if problem:
            _usage_error(f"--save-map: {problem}")
    if args.port:
        problem = port_problem(args.host, args.port)
        if problem:
            _usage_error(f"--port: {problem} (another drive_rover.py? stop it or pick another --port)")
    if args.dashboard and args.dashboard_port:
        if args.dashboard_port == args.port:
            _usage_error(f"--dashboard-port: {args.dashboard_port} is the simulator's --port")
        problem = port_problem(DEFAULT_HOST, args.dashboard_port)
        if problem:
            _usage_error(f"--dashboard-port: {problem}")
    return map_saver


class FrameObservers:
    """Everything that hears of a handled frame: the link status (always) and the dashboard (optional)."""

    def __init__(self, status, dashboard=None):
        self.status, self.dashboard = status, dashboard

    def observe(self, client, event=None, force=False):
        self.status.on_telemetry(time.monotonic(), client.last_timings.get("total", float("nan")))
        if self.dashboard is not None:
            self.dashboard.observe(client, event, force)


def _report_status(status, client):
    """Green thread: log the link's status lines (see link_status.py) about once a second."""
    import eventlet

    while True:
        eventlet.sleep(STATUS_TICK_S)
        try:
            for level, message in status.tick(time.monotonic(), client.rover):
                log.log(level, "%s", message)
        except Exception:  # the status line must never take the server down
            log.exception("status line failed")


def add_home_by_option(parser: argparse.ArgumentParser):
    """--home-by SECONDS, the client's return deadline; the twin's tools offer the same option."""
    from decision import HOME_BY_S, SEARCH_HOME_BY_S

    parser.add_argument("--home-by", type=positive_seconds, default=None, metavar="SECONDS",
                        help=f"head home so as to arrive by this mission time (default {HOME_BY_S:.0f} s, "
                             f"tuned for a 600 s mission, stretched to {SEARCH_HOME_BY_S:.0f} s while the map is "
                             "incomplete or samples are missing and the search has places left; a value given "
                             "here is never stretched)")


def positive_seconds(text):
    from sim.cli import positive_number

    return positive_number(text, "a positive number of seconds")


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level, logging.INFO),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    require_compatible_versions()
    map_saver = check_args(args)
    warnings.filterwarnings("ignore", message=r"\s*Eventlet is deprecated")  # documented in README
    import eventlet
    import eventlet.wsgi

    from autonomy import AutonomyClient

    client = AutonomyClient(ground_truth=load_ground_truth_arg(args.ground_truth), home_by_s=args.home_by)
    try:  # no SO_REUSEPORT: a second server on the port must fail, not share the simulator's connections
        listener = eventlet.listen((args.host, args.port), reuse_port=False)
    except OSError as exc:
        _usage_error(f"--port: cannot listen on {args.host}:{args.port}: {exc} "
                     f"(another drive_rover.py? stop it or pick another --port)")
    try:
        recorder = Recorder(args.image_folder) if args.image_folder else None
    except (OSError, ValueError) as exc:
        _usage_error(f"image_folder: cannot record into {args.image_folder}: {exc}")
    if recorder is not None:
        log.info("recording into %s", recorder.folder)
    dashboard = None
    if args.dashboard:
        from dashboard import LiveDashboard

        try:
            dashboard = LiveDashboard(args.dashboard_port, title="drive_rover").start()
        except OSError as exc:
            _usage_error(f"--dashboard-port: {exc}")
    host, port = listener.getsockname()[:2]
    from link_status import LinkStatus

    status = LinkStatus(time.monotonic(), f"{host}:{port}",
                        f"python-socketio {installed_version('python-socketio')}, "
                        f"python-engineio {installed_version('python-engineio')}")
    import wire_server

    _, wsgi_app = wire_server.build_server(client, recorder, map_saver, hosts=(args.host,),
                                           dashboard=FrameObservers(status, dashboard), link=status)
    eventlet.spawn(_report_status, status, client)
    log.info("compiled kernels ready in %.1f s", client.warm_up())  # not during the first telemetry
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
