"""What may reach the Socket.IO stack from the wire, decided per frame.

Why this exists: python-socketio 4.6.1 + python-engineio 3.13.2 are pinned
because the Unity simulator needs them (docs/wire-hardening.md), but their
packet handling lets one stray frame wedge or close a session: a ``45``/``46``
makes socketio wait for binary attachments forever, a ``41`` disconnects the
namespace the simulator never re-connects (it never sends ``40``), and a ``b``
frame that is not valid base64 raises outside engineio's receive guard and
closes the socket.  The simulator itself only ever sends ``2`` (ping), ``3``
(pong), ``42["telemetry",{...}]``, and ``41`` + ``1`` when it quits.  So:

* engine.io level (``engineio_frame_verdict``): only close ``1``, ping ``2``,
  pong ``3`` and message ``4`` text frames go on to engineio; every other
  frame (binary, ``b…``, empty, ``0``/``5``/``6``/other types) is dropped and
  counted.  Frames over eventlet's 8 MiB frame limit and text that is not
  UTF-8 are closed by eventlet before we see them (close-and-reconnect).
* Socket.IO level (``classify_message``): an EVENT on ``/`` whose name is
  ``telemetry`` is telemetry - even when its JSON does not decode (too deep,
  truncated), because the simulator waits for a reply to every telemetry;
  everything else (CONNECT, DISCONNECT, ACK, ERROR, BINARY_*, unknown events,
  other namespaces, undecodable non-telemetry) is ignored and counted.
* HTTP level (``HostCheck``): only loopback Host names (and the ``--host``
  name) are served, which closes the DNS-rebinding hole a same-origin check
  leaves open.

* websocket level (``fast_apply_mask``): eventlet unmasks every incoming
  frame with a Python loop per byte (measured 14.3 ms for a median 8.6 KB
  test_dataset telemetry on the shared 2-core box, seconds for an 8 MiB
  frame, all of it blocking the server); the same XOR as one big-integer
  operation (0.024 ms) is byte-for-byte identical.

Pure functions here; the server wiring is in ``wire_server.py``.
"""
from __future__ import annotations

import json
import logging
import re
from typing import Callable, Iterable, Optional, Tuple

log = logging.getLogger("drive_rover.wire")

ENGINEIO_TYPES_PASSED = "1234"  # engine.io packet types a websocket client may send: close, ping, pong, message
LOOPBACK_HOST_NAMES = ("127.0.0.1", "localhost", "::1")  # Host names always served
MAX_ACK_ID_DIGITS = 12  # a Socket.IO ack id longer than this is garbage, digits
REASON_TEXT_CHARS = 40  # characters of an unknown event name quoted in a reason, chars

TELEMETRY = "telemetry"  # classify_message kinds
IGNORE = "ignore"

_SOCKETIO_TYPE_NAMES = {"0": "CONNECT", "1": "DISCONNECT", "3": "ACK", "4": "ERROR",
                        "5": "BINARY_EVENT", "6": "BINARY_ACK"}
# the event name at the start of an EVENT body: '["telemetry",' or '["telemetry"]' (spaces allowed)
_TELEMETRY_HEAD = re.compile(r'\[\s*"telemetry"\s*[,\]]')


# --------------------------------------------------------------------------- engine.io frames
def engineio_frame_verdict(frame) -> Optional[str]:
    """None when engineio may see this websocket frame, else why it is dropped."""
    if not isinstance(frame, str):
        return "binary frame"
    if not frame:
        return "empty frame"
    if frame[0] not in ENGINEIO_TYPES_PASSED:
        return "base64 binary frame" if frame[0] == "b" else "engine.io packet of another type"
    return None


class GuardedWebSocket:
    """A websocket whose ``wait()`` skips the frames ``engineio_frame_verdict``
    refuses (reporting each to ``on_drop(reason)``); everything else is the
    wrapped eventlet websocket."""

    def __init__(self, ws, on_drop: Callable[[str], None]):
        self._ws = ws
        self._on_drop = on_drop

    def wait(self):
        while True:
            frame = self._ws.wait()
            if frame is None:  # closed
                return None
            reason = engineio_frame_verdict(frame)
            if reason is None:
                return frame
            self._on_drop(reason)

    def __getattr__(self, name):
        return getattr(self._ws, name)


def guarded_websocket_class(base, on_drop: Callable[[Optional[str], str], None]):
    """A subclass of engineio's websocket WSGI wrapper (``base``) that hands
    engineio a ``GuardedWebSocket``; ``on_drop(sid, reason)`` counts drops."""

    class GuardedWebSocketWSGI(base):
        def __init__(self, handler, *args, **kwargs):
            sid = getattr(getattr(handler, "__self__", None), "sid", None)

            def guarded_handler(ws):
                return handler(GuardedWebSocket(ws, lambda reason: on_drop(sid, reason)))

            super().__init__(guarded_handler, *args, **kwargs)

    return GuardedWebSocketWSGI


def fast_apply_mask(data, mask, length=None, offset=0) -> bytes:
    """Drop-in for eventlet's ``RFC6455WebSocket._apply_mask``: the first
    ``length`` bytes of ``data`` XOR the 4-byte ``mask`` starting at mask
    position ``offset``, computed as one integer XOR instead of per byte."""
    if length is None:
        length = len(data)
    if length <= 0:
        return b""
    key = bytes(mask[(offset + i) % 4] for i in range(4))
    key = (key * (length // 4 + 1))[:length]
    value = int.from_bytes(bytes(data[:length]), "big") ^ int.from_bytes(key, "big")
    return value.to_bytes(length, "big")


def install_fast_websocket_mask() -> None:
    """Make eventlet's websocket use ``fast_apply_mask`` (process-wide; idempotent)."""
    from eventlet.websocket import RFC6455WebSocket

    RFC6455WebSocket._apply_mask = staticmethod(fast_apply_mask)


# --------------------------------------------------------------------------- Socket.IO messages
def classify_message(text) -> Tuple[str, str]:
    """(TELEMETRY, json_body) or (IGNORE, reason) for one engine.io message.

    The body of a telemetry event is returned undecoded: only the newest
    telemetry is ever decoded (``telemetry_argument``), so a backlog costs a
    regex per frame.  Reasons come from a small fixed set (they key counters
    and rate-limited logs, which must not grow with what a client invents)."""
    if not isinstance(text, str):
        return IGNORE, "binary Socket.IO message"
    if not text:
        return IGNORE, "empty Socket.IO message"
    kind, body = text[0], text[1:]
    if kind != "2":
        name = _SOCKETIO_TYPE_NAMES.get(kind)
        return IGNORE, (f"Socket.IO {name} packet" if name else "Socket.IO packet of unknown type")
    if body.startswith("/"):
        namespace, _, body = body.partition(",")
        if namespace != "/":
            return IGNORE, "event on another namespace"
    digits = 0
    while digits < len(body) and body[digits].isdigit():
        digits += 1
    if digits > MAX_ACK_ID_DIGITS:
        return IGNORE, "malformed event (ack id)"
    body = body[digits:]
    if _TELEMETRY_HEAD.match(body):
        return TELEMETRY, body
    try:
        message = json.loads(body)
    except (ValueError, RecursionError):
        return IGNORE, "malformed event"
    if not isinstance(message, list) or not message or not isinstance(message[0], str):
        return IGNORE, "malformed event"
    if message[0] == "telemetry":  # spelled with escapes: still the simulator's event
        return TELEMETRY, body
    return IGNORE, "unknown event"


class BadTelemetry(ValueError):
    """A telemetry event whose JSON does not decode (answered with a safe stop)."""


def telemetry_argument(body: str):
    """The telemetry dict (or whatever the first argument is; None when there
    is none) of a body ``classify_message`` called telemetry."""
    try:
        message = json.loads(body)
    except (ValueError, RecursionError) as exc:
        raise BadTelemetry(f"telemetry JSON does not decode ({type(exc).__name__})") from None
    if not isinstance(message, list) or not message:
        raise BadTelemetry("telemetry event is not a JSON list")
    return message[1] if len(message) > 1 else None


# --------------------------------------------------------------------------- HTTP Host names
def host_name(header: Optional[str]) -> Optional[str]:
    """The name part of a Host header, lower-case, without port or trailing dot
    (``[::1]:4567`` -> ``::1``); None when absent or malformed."""
    if not header:
        return None
    header = header.strip().lower()
    if header.startswith("["):
        end = header.find("]")
        if end < 0 or header[end + 1:] and not re.fullmatch(r":\d{1,5}", header[end + 1:]):
            return None
        return header[1:end]
    if header.count(":") == 1:
        header, _, port = header.partition(":")
        if not re.fullmatch(r"\d{1,5}", port):
            return None
    elif ":" in header:
        return None
    return header.rstrip(".") or None


def allowed_host_names(extra: Iterable[str] = ()) -> frozenset:
    """Loopback names plus the names we were asked to bind (``--host``)."""
    names = set(LOOPBACK_HOST_NAMES)
    for name in extra:
        parsed = host_name(f"[{name}]" if ":" in name and not name.startswith("[") else name)
        if parsed:
            names.add(parsed)
    return frozenset(names)


class HostCheck:
    """WSGI middleware: 403 for any request (HTTP or websocket upgrade) whose
    Host header names anything but an allowed host.  A web page that rebinds
    its own DNS name to 127.0.0.1 still sends its own name as Host, so it can
    neither read our pages nor open the websocket."""

    def __init__(self, app, allowed: frozenset, on_refuse: Callable[[str], None] = None):
        self.app = app
        self.allowed = allowed
        self.on_refuse = on_refuse or (lambda host: log.warning(
            "refused a request for Host %r: only %s are served", host, ", ".join(sorted(allowed))))

    def __call__(self, environ, start_response):
        header = environ.get("HTTP_HOST")
        if host_name(header) not in self.allowed:
            self.on_refuse(str(header)[:REASON_TEXT_CHARS * 2])
            start_response("403 Forbidden", [("Content-Type", "text/plain")])
            return [b"Host not allowed: drive_rover serves loopback names only\n"]
        return self.app(environ, start_response)
