"""The Socket.IO server the simulator connects to, and one session per websocket.

Why a session with a mailbox: the simulator sends its next telemetry only in
answer to a command, so every telemetry needs exactly one reply - but when
frames arrive faster than the autonomy stack handles them, answering each in
full builds a backlog (seconds of lag, unbounded memory) and the rover acts on
the past.  So the reader only files each telemetry in the session's mailbox
(the newest body and a count); the session's worker answers the ones that
were overtaken at once with the last command (cheap: no decode, no
perception, no insets) and runs the full pipeline only on the newest.
Memory is one frame per session whatever the rate.

Why one simulator at a time: the rover state belongs to one mission.  A
second websocket while one is live is refused (HTTP 401, one log line every
few seconds); the simulator's own reconnect (every 5 ms) gets in as soon as
the first one closes, and a reconnecting simulator continues the same
``AutonomyClient`` (its restart detection decides whether it is a new
mission).  Polling clients (not the simulator) may connect but are never
answered.

Packet-level rules (which frames count, which are ignored): ``wire_guard.py``.
"""
from __future__ import annotations

import collections
import logging
import threading
import time
import urllib.parse
from typing import Callable, Dict, Optional, Tuple

import wire_guard

log = logging.getLogger("drive_rover")

LIB_LOG_LEVEL = logging.WARNING  # socketio/engineio loggers (INFO logs every packet)
PING_INTERVAL_S = 25  # Engine.IO ping interval announced in the handshake, s
PING_TIMEOUT_S = 60  # Engine.IO ping timeout, s
SIMULATOR_TRANSPORT = "websocket"  # the simulator opens a websocket directly (no polling)
COMMAND_KEYS = ("throttle", "brake", "steering_angle")  # the part of a data reply repeated for stale frames
READER_SLICE_S = 0.1  # during a flood the reader reads at most this long before the worker runs, s

Reply = Tuple[str, Dict[str, str]]


def _quiet_refusals(record: logging.LogRecord) -> bool:
    """engineio logs every refused connection; the simulator retries every 5 ms,
    so our own rate-limited line replaces it."""
    return record.getMessage() != "Application rejected connection"


class Mailbox:
    """The newest unanswered telemetry body and how many arrived in all.
    ``put`` is what the reader does per frame; ``take`` empties it."""

    def __init__(self):
        self._lock = threading.Lock()
        self.newest: Optional[str] = None
        self.pending = 0
        self.peak = 0  # largest backlog seen, frames

    def put(self, body: str) -> None:
        with self._lock:
            self.newest = body
            self.pending += 1
            self.peak = max(self.peak, self.pending)

    def take(self) -> Optional[Tuple[str, int]]:
        """(newest body, number of older unanswered frames) or None when empty."""
        with self._lock:
            if not self.pending:
                return None
            taken = (self.newest, self.pending - 1)
            self.newest, self.pending = None, 0
            return taken


class Driver:
    """The autonomy side of every session: a full reply for a telemetry body,
    a cheap one for a stale frame, and the side effects of a handled frame
    (recorder, --save-map).  Never raises: the simulator stalls without a reply."""

    def __init__(self, client, recorder=None, map_saver=None, dashboard=None):
        from autonomy import RateLimitedLog

        self.client = client
        self.recorder = recorder
        self.map_saver = map_saver
        self.dashboard = dashboard  # gets observe(client, event) after every handled frame
        self.warn = RateLimitedLog(log)
        self.last_command: Optional[Dict[str, str]] = None  # command part of the last data reply

    def _safe_stop(self) -> Reply:
        from autonomy import SAFE_STOP, command_payload

        return "data", command_payload(SAFE_STOP["throttle"], SAFE_STOP["brake"], SAFE_STOP["steer"])

    def full_reply(self, body: str) -> Reply:
        try:
            data = wire_guard.telemetry_argument(body)
        except wire_guard.BadTelemetry as exc:
            self.client.bad_frames += 1
            self.warn("bad-json", "%s; safe stop", exc)
            return self._safe_stop()
        try:
            event, payload = self.client.handle_telemetry(data)
        except Exception:  # handle_telemetry never raises; keep the lockstep anyway
            self.warn("client", "autonomy client raised; safe stop", exc_info=True)
            return self._safe_stop()
        if event == "data":
            self.last_command = {k: payload[k] for k in COMMAND_KEYS if k in payload}
        if event != "manual":
            self._side_effects()
        return event, payload

    def stale_reply(self) -> Reply:
        """The last command again (commands are sticky in the simulator, so this
        changes nothing); never a pickup, which must come from a fresh frame."""
        if self.last_command is None:
            return self._safe_stop()
        return "data", dict(self.last_command)

    def observe(self, event: str) -> None:
        """Tell the dashboard (if any) about a handled frame, after its reply is queued."""
        if self.dashboard is None:
            return
        try:
            self.dashboard.observe(self.client, event)
        except Exception:
            self.warn("dashboard", "dashboard update failed", exc_info=True)

    def _side_effects(self) -> None:
        try:
            if self.recorder is not None:
                self.recorder.submit(self.client.last_telemetry)
            if self.map_saver is not None:
                self.map_saver.maybe_save(self.client.rover)
        except Exception:
            self.warn("side-effects", "recording or map dump failed", exc_info=True)


class Session:
    """One simulator websocket: counts what came in, answers every telemetry once."""

    def __init__(self, sid: str, driver: Driver, send: Callable[[str, Dict[str, str]], None],
                 wake_event, pause: Callable[[], None] = lambda: None,
                 clock: Callable[[], float] = time.monotonic):
        self.sid = sid
        self.driver = driver
        self.send = send
        self.mailbox = Mailbox()
        self._wake = wake_event
        self._pause = pause  # yields the reader to the worker (eventlet: sleep(0))
        self._clock = clock
        self._last_pause = clock()
        self.closed = False
        self.messages = 0  # Socket.IO messages received
        self.telemetry = 0  # telemetry frames received
        self.full = 0  # telemetry answered by the full pipeline
        self.stale = 0  # telemetry answered with the last command
        self.ignored: collections.Counter = collections.Counter()  # reason -> messages/frames

    # -- reader side (engineio's websocket loop) -----------------------------------
    def on_message(self, text) -> None:
        self.messages += 1
        kind, detail = wire_guard.classify_message(text)
        if kind == wire_guard.TELEMETRY:
            self.telemetry += 1
            self.mailbox.put(detail)
            self._wake.set()
            # a sender that never pauses would keep this (green) reader busy and
            # starve the worker: step aside now and then, so the newest frame is
            # acted on during a flood, not after it
            now = self._clock()
            if now - self._last_pause >= READER_SLICE_S:
                self._last_pause = now
                self._pause()
        else:
            self.ignore(detail, text)

    def ignore(self, reason: str, text=None) -> None:
        self.ignored[reason] += 1
        excerpt = "" if text is None else f" {str(text)[:wire_guard.REASON_TEXT_CHARS]!r}"
        self.driver.warn("ignored-" + reason, "ignored %s%s (no reply)", reason, excerpt)

    # -- worker side ------------------------------------------------------------------
    def serve_once(self) -> int:
        """Answer what the mailbox holds; returns the number of replies sent."""
        taken = self.mailbox.take()
        if taken is None:
            return 0
        body, stale = taken
        if stale:
            reply = self.driver.stale_reply()
            for _ in range(stale):
                self.send(*reply)
            self.stale += stale
            self.driver.warn("stale", "%d telemetry frames overtaken by newer ones: answered "
                                      "with the last command (backlog peak %d)", stale,
                             self.mailbox.peak, level=logging.INFO)
        event, payload = self.driver.full_reply(body)
        self.send(event, payload)
        self.full += 1
        self.driver.observe(event)
        return stale + 1

    def run(self) -> None:
        while not self.closed:
            self._wake.wait()
            self._wake.clear()
            if self.closed:
                break
            try:
                self.serve_once()
            except Exception:  # a dead worker would leave every later telemetry unanswered
                self.driver.warn("worker", "session worker error (continuing)", exc_info=True)

    def close(self) -> None:
        self.closed = True
        self._wake.set()

    def summary(self) -> str:
        reasons = ", ".join(f"{n} {reason}" for reason, n in self.ignored.most_common()) or "-"
        return (f"{self.messages} messages, {self.telemetry} telemetry ({self.full} handled, "
                f"{self.stale} answered with the last command, {self.mailbox.pending} unanswered "
                f"at close), ignored {sum(self.ignored.values())}: {reasons}")


def build_server(client, recorder=None, map_saver=None, hosts=(), dashboard=None, link=None):
    """(sio, wsgi_app): the Socket.IO server around ``client`` (an AutonomyClient),
    wrapped in the Host check; ``hosts`` are extra Host names to serve (``--host``);
    ``link`` (link_status.LinkStatus) hears when a simulator connects and leaves."""
    import flask
    import socketio

    driver = Driver(client, recorder, map_saver, dashboard)
    lib_logger = logging.getLogger("drive_rover.socketio")
    lib_logger.setLevel(logging.DEBUG if log.getEffectiveLevel() <= logging.DEBUG else LIB_LOG_LEVEL)
    lib_logger.addFilter(_quiet_refusals)

    class SimulatorServer(socketio.Server):
        """Socket.IO 4.x server whose packet handling is ours (see wire_guard):
        no stray packet can disconnect the namespace or wait for attachments."""

        sessions: Dict[str, Session] = {}
        active: Optional[str] = None  # sid of the simulator being driven
        dropped_frames: collections.Counter = collections.Counter()  # engine.io frames dropped, by reason

        def _handle_eio_connect(self, sid, environ):
            query = urllib.parse.parse_qs(environ.get("QUERY_STRING", ""))
            transport = query.get("transport", ["polling"])[0]
            if transport == SIMULATOR_TRANSPORT:
                if self.active is not None:
                    driver.warn("second-simulator",
                                "refused a second simulator connection: %s is being driven "
                                "(one simulator at a time; close the other one)", self.active)
                    return False
                self.active = sid
                self.sessions[sid] = Session(sid, driver, self._sender(sid), self.eio.create_event(),
                                             pause=lambda: self.sleep(0))
                self.start_background_task(self.sessions[sid].run)
                log.info("simulator connected (%s, %s)", sid, environ.get("QUERY_STRING", ""))
                if link is not None:
                    link.on_connect(time.monotonic())
            else:
                log.info("non-simulator client connected over %s (%s): it will not be answered",
                         transport, sid)
            return super()._handle_eio_connect(sid, environ)

        def _sender(self, sid):
            def send(event, payload):
                try:
                    self.emit(event, payload, room=sid)
                except Exception:
                    driver.warn("emit", "could not send %s to %s", event, sid, exc_info=True)
            return send

        def _handle_eio_message(self, sid, data):
            session = self.sessions.get(sid)
            if session is None:
                driver.warn("not-simulator", "ignored a message from a non-simulator client %s", sid)
                return
            session.on_message(data)

        def _handle_eio_disconnect(self, sid):
            session = self.sessions.pop(sid, None)
            if session is not None:
                session.close()
                log.info("simulator disconnected (%s): %s", sid, session.summary())
                if link is not None:
                    link.on_disconnect(time.monotonic())
            if self.active == sid:
                self.active = None
            super()._handle_eio_disconnect(sid)

    sio = SimulatorServer(async_mode="eventlet", logger=lib_logger, engineio_logger=lib_logger,
                          ping_interval=PING_INTERVAL_S, ping_timeout=PING_TIMEOUT_S)
    sio.sessions, sio.dropped_frames = {}, collections.Counter()

    def on_drop(sid, reason):
        sio.dropped_frames[reason] += 1
        session = sio.sessions.get(sid)
        if session is not None:
            session.ignore(reason)
        else:
            driver.warn("dropped-" + reason, "dropped a %s (no reply)", reason)

    wire_guard.install_fast_websocket_mask()
    # engineio builds one websocket wrapper per connection from this table; ours
    # filters frames before engineio decodes them (engineio 3.13.2 pinned)
    sio.eio._async = dict(sio.eio._async, websocket=wire_guard.guarded_websocket_class(
        sio.eio._async["websocket"], on_drop))

    app = flask.Flask(__name__)

    @app.route("/")
    def index():
        return "drive_rover: RoboND rover autonomy client. Start the simulator in Autonomous mode.\n"

    allowed = wire_guard.allowed_host_names(hosts)
    return sio, wire_guard.HostCheck(socketio.WSGIApp(sio, app), allowed,
                                     on_refuse=lambda host: driver.warn(
                                         "host", "refused a request for Host %r: only %s are served "
                                                 "(DNS-rebinding guard)", host,
                                         ", ".join(sorted(allowed))))
