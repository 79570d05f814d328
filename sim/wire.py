"""Headless simulator process that talks to a client exactly like the Unity program.

    python -m sim.wire [--host 127.0.0.1] [--port 4567] [--seed N] [--world SPEC]
                       [--mode realtime|lockstep] [--fps 30] [--extra-latency-ms MS]
                       [--time-limit S] [--record DIR]

Like the real simulator it is the websocket *client*: it opens
``ws://HOST:PORT/socket.io/?EIO=4&transport=websocket`` directly (no polling, no
upgrade), never sends ``40``, pings ``2`` every 25 s, answers ``3`` to ``2``,
reconnects while disconnected, emits ``42["telemetry",{...}]`` (string values)
when the socket opens and then exactly one telemetry per handled command
(``data``, ``manual``, ``pickup``, ``fixed_turn``), and says ``41`` + ``1`` on quit.

Modes:
* ``realtime`` (default, the real simulator's loop, sim/timing.py "unity"): physics
  free-runs on the wall clock; the screen renders at ``--fps``; a command waits in a
  queue until the first render frame after it arrives (plus ``--extra-latency-ms``
  if asked), where it sets the inputs and one telemetry is captured at that frame
  and sent.  With the single reply chain a client keeps, that is at most one
  telemetry per render frame.  No ``sim_time`` is sent.
* ``lockstep`` (EASIER than the real simulator, for debugging): every command
  advances the twin one frame (0.04 s) and the reply carries the new state and the
  twin-only ``sim_time`` clock - runs as fast as the client answers.

A command the real simulator cannot parse (JSON numbers, garbage, NaN, missing
fields, unknown events) gets *no reply*, as in the real one (its float.Parse
throws and the chain stalls); the twin logs it and keeps running.
"""
from __future__ import annotations

import json
import logging
import math
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

from dashboard import add_dashboard_options
from interrupts import reraise_interrupt
from sim.cli import check_paths, non_negative_int, parse_with_logging, port_number, seed_number, tool_parser
from sim.mission_parts import TruthTrack, all_collected_and_home, open_recorder, progress_bar
from sim.timing import UNITY_FPS, WIRE_LATENCY_MS, Timing

log = logging.getLogger(__name__)

URL_TEMPLATE = "ws://{host}:{port}/socket.io/?EIO=4&transport=websocket"  # the simulator's URL
PING_INTERVAL_S = 25.0  # s between the client's "2" pings (Engine.IO v3 rule)
RECONNECT_DELAY_S = 0.005  # s between reconnect attempts (the simulator's 5 ms)
RECV_POLL_S = 0.05  # s, longest receive wait so pings keep flowing
MIN_RECV_WAIT_S = 0.0005  # s, shortest receive wait before a due render frame
OPEN_TELEMETRY_COUNT = 1  # telemetry messages sent unprompted when the socket opens
DEFAULT_FPS = UNITY_FPS  # render frames per second in real-time mode
MODES = ("realtime", "lockstep")  # sim.timing models "unity" and "lockstep" on the wire
STALL_TIMEOUT_S = 30.0  # wall s without a command before a wire mission gives up
SERVER_START_TIMEOUT_S = 60.0  # wall s to wait for drive_rover.py to accept connections
CLIENT_MAP_OPTION = "--save-map"  # drive_rover.py option (if it has one) to dump rover.worldmap as .npy
HOME_STILL_S = 2.0  # s stopped within the home radius after collecting all = done (wire missions)
PROJECT_DIR = Path(__file__).resolve().parent.parent


def encode_event(event: str, payload) -> str:
    """Socket.IO EVENT packet as a text frame: 42["name",{...}]."""
    return "42" + json.dumps([event, payload], separators=(",", ":"))


def decode_event(frame: str):
    """(event, payload) of a 42 frame; raises ValueError for anything else."""
    body = frame[2:]
    if body.startswith("/"):  # namespaced packet "42/ns,[...]": the sim only knows "/"
        body = body.split(",", 1)[1] if "," in body else ""
    while body and body[0].isdigit():  # ack id
        body = body[1:]
    msg = json.loads(body)
    if not isinstance(msg, list) or not msg or not isinstance(msg[0], str):
        raise ValueError(f"not an event packet: {frame[:80]!r}")
    return msg[0], (msg[1] if len(msg) > 1 else None)


class WireSimulator:
    """One simulated rover on the wire. `run()` blocks until `stop()` or `should_stop()`.

    on_frame(twin, dt) is called after every advance of the twin (dt simulated seconds).
    """

    def __init__(self, twin, host="127.0.0.1", port=4567, mode="realtime", fps=DEFAULT_FPS,
                 recorder=None, on_frame=None, should_stop=None, open_telemetry=OPEN_TELEMETRY_COUNT,
                 extra_latency_s=0.0, clock=time.monotonic):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, not {mode!r}")
        self.twin = twin
        self.url = URL_TEMPLATE.format(host=host, port=int(port))
        self.mode = mode
        self.fps = float(fps) if fps and fps > 0 else DEFAULT_FPS
        self.extra_latency_s = max(0.0, float(extra_latency_s))  # held back before a command is seen
        self.recorder = recorder
        self.on_frame = on_frame
        self.should_stop = should_stop or (lambda: False)
        self.open_telemetry = max(0, int(open_telemetry))
        self.clock = clock
        self._stop = threading.Event()
        self.ws = None
        self.connections = 0
        self.commands = 0
        self.rejected = 0
        self.replies = 0
        self.render_frames = 0  # real-time render frames run
        self.last_command_wall = clock()
        self._t0 = None  # wall time of the scene's t = 0 (first connection), real-time mode
        self._pending = []  # (due wall time, event, payload) commands waiting for a render frame
        self._last_capture = None  # (frame time, wall time the telemetry left) of the last capture
        self.reply_delays_s = []  # frame time a command acted at - frame time of the capture before it
        self.round_trips_s = []  # wall: render frame of a capture -> the next command received

    def stop(self):
        self._stop.set()

    def _stopping(self):
        return self._stop.is_set() or self.should_stop()

    # ---------------------------------------------------------------- connection
    def _connect(self):
        import websocket

        warned = False
        while not self._stopping():
            try:
                ws = websocket.create_connection(self.url, timeout=5)
                ws.settimeout(RECV_POLL_S)
                self.connections += 1
                log.info("connected to %s", self.url)
                return ws
            except Exception as exc:  # refused, reset, timeout: the sim keeps trying
                if not warned:
                    log.info("waiting for a server at %s (%s)", self.url, exc)
                    warned = True
                time.sleep(RECONNECT_DELAY_S)
        return None

    def _send(self, text):
        self.ws.send(text)

    def _send_telemetry(self, tel):
        self._send(encode_event("telemetry", tel))
        self.replies += 1

    # ---------------------------------------------------------------- frames
    def _frame_done(self, dt):
        if self.recorder is not None:
            self.recorder.write_twin(self.twin)
        if self.on_frame is not None:
            self.on_frame(self.twin, dt)

    def _handle_event(self, event, payload):
        """A decoded command: lockstep answers at once; real time queues it for the next frame."""
        self.commands += 1
        now = self.clock()
        self.last_command_wall = now
        if self.mode == "realtime":
            if self._last_capture is not None:
                self.round_trips_s.append(now - self._last_capture[1])
            self._pending.append((now + self.extra_latency_s, event, payload))
            return
        tel = self._apply(event, payload, advance=True)
        if tel is not None:
            self._send_telemetry(tel)

    def _apply(self, event, payload, advance):
        """Apply one command to the twin; the lockstep telemetry, True (real time) or None if rejected."""
        from sim.twin import CommandError

        try:
            if advance:
                tel = self.twin.step(event, payload)
                self._frame_done(self.twin.frame_dt)
                return tel
            self.twin.apply(event, payload)
            return True
        except CommandError as exc:
            self.rejected += 1
            log.warning("no telemetry reply (the real simulator would stall): %s", exc)
        except Exception as exc:  # a twin bug must not kill the simulator: Unity logs and carries on
            reraise_interrupt(exc)  # ...but a Ctrl-C a numba kernel wrapped still stops the run
            self.rejected += 1
            log.exception("error handling %r; no telemetry reply", event)
        return None

    def render_frame(self, now=None):
        """One real-time render frame: physics catches up to the wall clock, due commands set
        the inputs, and one telemetry captured now answers each of them."""
        now = self.clock() if now is None else now
        if self._t0 is None:
            self._t0 = now
        frame_t = now - self._t0
        dt = self.twin.advance_to(frame_t)
        self.render_frames += 1
        due = [c for c in self._pending if c[0] <= now]
        self._pending = [c for c in self._pending if c[0] > now]
        answered = sum(1 for _, event, payload in due if self._apply(event, payload, advance=False))
        if answered:
            if self._last_capture is not None:
                self.reply_delays_s.append(frame_t - self._last_capture[0])
            tel = self.twin.capture()
            self._frame_done(dt)
            for _ in range(answered):  # Unity queues one telemetry per handled command
                self._send_telemetry(tel)
            self._last_capture = (frame_t, now)
        elif self.on_frame is not None:
            self.on_frame(self.twin, dt)

    def _handle_frame(self, frame):
        if not isinstance(frame, str) or not frame:
            return
        kind = frame[0]
        if frame == "2" or frame.startswith("2probe"):
            self._send("3" + frame[1:])
        elif kind == "0":
            log.debug("handshake %s", frame[:120])
        elif frame.startswith("42"):
            try:
                event, payload = decode_event(frame)
            except (ValueError, json.JSONDecodeError) as exc:
                self.rejected += 1
                log.warning("undecodable event frame ignored: %s", exc)
                return
            self._handle_event(event, payload)
        elif frame.startswith("41") or kind == "1":
            raise ConnectionResetError("server closed the session")
        # "3" (pong), "40" (namespace connect, ignored by the sim), others: nothing to do

    # ---------------------------------------------------------------- main loop
    def _open(self):
        """The socket just opened: the simulator sends its current telemetry unprompted."""
        if self.mode == "realtime" and self._t0 is None:
            self._t0 = self.clock()
        for _ in range(self.open_telemetry):
            self._send_telemetry(self.twin.telemetry())
        if self.mode == "realtime":
            self._last_capture = (self.twin.sim_time, self.clock())

    def run(self):
        import websocket

        period = 1.0 / self.fps
        while not self._stopping():
            self.ws = self._connect()
            if self.ws is None:
                break
            next_ping = self.clock() + PING_INTERVAL_S
            next_frame = self.clock() + period
            try:
                self._open()
                while not self._stopping():
                    now = self.clock()
                    if now >= next_ping:
                        self._send("2")
                        next_ping = now + PING_INTERVAL_S
                    wait = RECV_POLL_S
                    if self.mode == "realtime":
                        if now >= next_frame:
                            self.render_frame(now)
                            # a frame that overran drops the missed ones, as a slow machine's frame rate falls
                            next_frame = max(next_frame + period, self.clock())
                        wait = min(RECV_POLL_S, max(MIN_RECV_WAIT_S, next_frame - self.clock()))
                    self.ws.settimeout(wait)
                    try:
                        frame = self.ws.recv()
                    except websocket.WebSocketTimeoutException:
                        continue
                    self._handle_frame(frame)
            except (websocket.WebSocketException, OSError, ConnectionError) as exc:
                log.info("disconnected (%s); reconnecting", exc)
            finally:
                try:
                    if self._stopping() and self.ws.connected:
                        self._send("41")  # leave the namespace, then close the Engine.IO session
                        self._send("1")
                    self.ws.close()
                except Exception:  # the peer may already be gone
                    pass
        log.info("wire simulator stopped: %d commands, %d rejected, %d replies, %d render frames",
                 self.commands, self.rejected, self.replies, self.render_frames)


# ------------------------------------------------------------------------ wire missions
def free_port(host="127.0.0.1") -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def start_client_server(port, log_path=None, extra_args=()):
    """Start drive_rover.py on `port` as a subprocess; returns the Popen."""
    cmd = [sys.executable, str(PROJECT_DIR / "drive_rover.py"), "--port", str(port),
           "--log-level", "WARNING", *extra_args]
    out = open(log_path, "ab") if log_path else subprocess.DEVNULL
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(cmd, cwd=str(PROJECT_DIR), stdout=out, stderr=subprocess.STDOUT, env=env)
    if log_path:
        out.close()
    return proc


def wait_for_port(port, proc=None, timeout=SERVER_START_TIMEOUT_S, host="127.0.0.1") -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc is not None and proc.poll() is not None:
            return False
        try:
            with socket.create_connection((host, port), timeout=0.5):
                return True
        except OSError:
            time.sleep(0.1)
    return False


def stop_process(proc, timeout=10.0):
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=timeout)


def client_supports_map_dump() -> bool:
    """True when drive_rover.py accepts CLIENT_MAP_OPTION (checked without starting it)."""
    import contextlib
    import io

    try:
        sys.path.insert(0, str(PROJECT_DIR))
        import drive_rover

        with contextlib.redirect_stderr(io.StringIO()):
            drive_rover.parse_args(["--port", "1", CLIENT_MAP_OPTION, "x.npy"])
        return True
    except (SystemExit, Exception):
        return False


def _load_client_map(path):
    import numpy as np

    try:
        m = np.load(path)
    except (OSError, ValueError):
        return None
    return m if m.shape == (200, 200, 3) else None


class WireMissionWatch:
    """Truth tracking, progress and the stop rules every wire mission shares (drive_rover.py or any client).

    Ends at the time limit, after home_still_s stopped at home with every sample, when the client
    exits, or when it sends no command for stall_timeout_s wall seconds. Set .proc and .wire once they exist.
    """

    def __init__(self, twin, time_limit, progress, desc, home_still_s=HOME_STILL_S, stall_timeout_s=STALL_TIMEOUT_S):
        self.twin, self.time_limit = twin, time_limit
        self.home_still_s, self.stall_timeout_s = home_still_s, stall_timeout_s
        self.end, self.completed, self.still_home_s = "time limit", False, 0.0
        self.track = TruthTrack(twin)
        self.bar = progress_bar(time_limit, progress, desc)
        self.proc = None  # the client process
        self.wire = None  # the WireSimulator (its last_command_wall)

    def on_frame(self, tw, dt):
        self.track.update(tw, dt)
        self.bar.update(dt)
        done = all_collected_and_home(tw.truth) and abs(tw.truth.v) < 0.01
        self.still_home_s = self.still_home_s + dt if done else 0.0

    def should_stop(self):
        if self.twin.sim_time >= self.time_limit:
            return True
        if self.still_home_s >= self.home_still_s:
            self.end, self.completed = "all collected and home", True
            return True
        if self.proc.poll() is not None:
            self.end = f"client exited with {self.proc.returncode}"
            return True
        if time.monotonic() - self.wire.last_command_wall > self.stall_timeout_s:
            self.end = "stalled: no command from the client"
            return True
        return False


def run_wire_mission(world, seed, time_limit=900.0, record=None, progress=True, render=True,
                     server_log=None, home_by=None, timing: Timing | None = None,
                     client_args=()):
    """Twin over the real protocol against drive_rover.py in a subprocess.

    timing: unity (default) runs the real simulator's loop in real time at timing.fps, holding
    each command back by latency_ms minus the transport's own WIRE_LATENCY_MS (the wire has its
    real latency; compute_ms does not apply: the client's compute is real too); lockstep runs the
    old easier loop with the twin's sim_time.
    The client's worldmap lives in the other process: it is scored only when
    drive_rover.py can dump it (CLIENT_MAP_OPTION); otherwise mapped/fidelity/located
    are None and only the truth-based figures are available.
    """
    import shutil
    import statistics
    import tempfile

    from sim.twin import RoverTwin

    timing = timing or Timing()
    mode = "realtime" if timing.unity else "lockstep"
    twin = RoverTwin(world, seed=seed, render=render, sim_time_field=timing.sends_sim_time)
    port = free_port()
    map_dir = tempfile.mkdtemp(prefix="twin-wire-map-")
    map_path = os.path.join(map_dir, "worldmap.npy")
    extra = [CLIENT_MAP_OPTION, map_path] if client_supports_map_dump() else []
    if home_by is not None:
        extra += ["--home-by", repr(float(home_by))]
    extra += list(client_args)  # e.g. --dashboard
    proc = start_client_server(port, server_log, extra)
    watch = WireMissionWatch(twin, time_limit, progress, f"seed {seed} (wire, {mode})")
    watch.proc = proc
    track, bar = watch.track, watch.bar
    recorder = open_recorder(record)

    extra_latency_s = max(0.0, timing.latency_ms - WIRE_LATENCY_MS) / 1e3 if timing.unity else 0.0
    sim = WireSimulator(twin, port=port, mode=mode, fps=timing.fps, recorder=recorder, on_frame=watch.on_frame,
                        should_stop=watch.should_stop, extra_latency_s=extra_latency_s)
    watch.wire = sim
    t0 = time.perf_counter()
    try:
        if not wait_for_port(port, proc):
            raise RuntimeError(f"drive_rover.py did not start on port {port} (exit {proc.poll()})")
        sim.last_command_wall = time.monotonic()
        sim.run()
    except KeyboardInterrupt:  # Ctrl-C: the caller writes the partial mission
        watch.end = "interrupted"
        log.warning("Ctrl-C at %.0f s simulated: writing the partial mission", twin.sim_time)
    finally:
        bar.close()
        stop_process(proc)
        if recorder is not None:
            recorder.close()
    worldmap = _load_client_map(map_path) if CLIENT_MAP_OPTION in extra else None
    shutil.rmtree(map_dir, ignore_errors=True)  # our own temp folder
    if CLIENT_MAP_OPTION in extra and worldmap is None:
        log.warning("drive_rover.py did not leave a readable worldmap at %s", map_path)

    def median_ms(values):
        return round(1e3 * statistics.median(values), 1) if values else None

    if timing.unity:
        log.info("wire: %d render frames, %d telemetries; capture -> command received %s ms median, "
                 "capture -> command acted %s ms median", sim.render_frames, sim.replies,
                 median_ms(sim.round_trips_s), median_ms(sim.reply_delays_s))
    return dict(twin=twin, stuck=track.stuck, traj=track.traj, distance=track.distance,
                wall=time.perf_counter() - t0, end_reason=watch.end, completed=watch.completed,
                worldmap=worldmap, rejected=sim.rejected, timing=timing,
                reply_delay_ms=median_ms(sim.reply_delays_s) if timing.unity else None,
                round_trip_ms=median_ms(sim.round_trips_s) if timing.unity else None,
                render_frames=sim.render_frames)


# ------------------------------------------------------------------------ CLI
def main(argv=None) -> int:
    p = tool_parser("python -m sim.wire", "Headless RoboND rover simulator on the real wire protocol: connects "
                    "to a client (python drive_rover.py) like the Unity program does.")
    p.add_argument("--host", default="127.0.0.1", help="client address (default %(default)s)")
    p.add_argument("--port", type=port_number, default=4567, help="client port (default %(default)s)")
    p.add_argument("--seed", type=seed_number, default=0, help="scene seed >= 0 (default 0)")
    p.add_argument("--world", default="default", help="real | procedural:K | PATH.png")
    p.add_argument("--mode", choices=MODES, default="realtime",
                   help="realtime (default): the real simulator's loop on the wall clock, no sim_time; "
                        "lockstep: one frame per command with the twin's sim_time, EASIER than the real simulator")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS, help="render frames/s in realtime mode")
    p.add_argument("--extra-latency-ms", type=float, default=0.0,
                   help="realtime: hold each command back this long on top of the real transport, ms")
    p.add_argument("--time-limit", type=float, default=0.0, help="stop after this many simulated s (0 = never)")
    p.add_argument("--record", default=None, help="record a simulator-format log into this folder")
    p.add_argument("--open-telemetry", type=non_negative_int, default=OPEN_TELEMETRY_COUNT,
                   help="telemetry messages sent when the socket opens (the real sim: ~2)")
    add_dashboard_options(p)
    a = parse_with_logging(p, argv)
    if not (math.isfinite(a.time_limit) and a.time_limit >= 0):
        p.error(f"--time-limit: must be >= 0 seconds, got {a.time_limit}")
    check_paths(p, a, folders=("--record",))
    from sim.twin import RoverTwin
    from sim.world import load_world

    try:
        world = load_world(a.world)
    except (ValueError, FileNotFoundError) as exc:
        p.error(f"--world: {exc}")
    if not (math.isfinite(a.fps) and a.fps > 0) or not (math.isfinite(a.extra_latency_ms) and a.extra_latency_ms >= 0):
        p.error("--fps must be positive and --extra-latency-ms non-negative")
    twin = RoverTwin(world, seed=a.seed, sim_time_field=a.mode == "lockstep")
    on_frame = dash = None
    if a.dashboard:  # the simulator's side: camera, true pose, commands, samples (dashboard/twin_view.py)
        from dashboard import LiveDashboard
        from dashboard.twin_view import TwinView

        try:
            dash = LiveDashboard(a.dashboard_port, title=f"sim.wire seed {a.seed} (simulator side)").start()
        except OSError as exc:
            p.error(f"--dashboard-port: {exc}")
        view = TwinView(twin)

        def publish(tw, dt):
            dash.observe(view.update())
        on_frame = publish
    recorder = open_recorder(a.record)
    limit = a.time_limit if a.time_limit and a.time_limit > 0 else math.inf
    log.info("mode %s%s", a.mode, f" at {a.fps:g} fps" if a.mode == "realtime"
             else " (EASIER than the real simulator: no latency, sim_time clock)")
    sim = WireSimulator(twin, a.host, a.port, a.mode, a.fps, recorder=recorder,
                        should_stop=lambda: twin.sim_time >= limit, open_telemetry=a.open_telemetry, on_frame=on_frame,
                        extra_latency_s=a.extra_latency_ms / 1e3)
    try:
        sim.run()
    except KeyboardInterrupt:
        log.info("interrupted")
    finally:
        if recorder is not None:
            recorder.close()
        if dash is not None:
            dash.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
