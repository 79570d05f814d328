"""First contact with the real simulator: a status line while driving, plain words when the link is wrong.

Why: the commonest problem is "the simulator connects but the rover never
moves" (wrong Socket.IO versions, a second server on the port, the simulator in
Training mode or paused).  ``drive_rover.py`` feeds this monitor from its
socket handlers and calls ``tick()`` about once a second; it returns the lines
to log: a status line every ``STATUS_EVERY_S`` while telemetry flows, and one
warning (per episode) when a websocket opens but no telemetry follows, when
telemetry stops, or when nothing connects at all.
"""
from __future__ import annotations

import logging
import math
from collections import deque
from typing import List, Optional, Tuple

STATUS_EVERY_S = 5.0  # s between status lines while telemetry flows
NO_TELEMETRY_S = 5.0  # s after a connection without any telemetry before we say what to check
TELEMETRY_GAP_S = 3.0  # s without telemetry (after some arrived) before we say it stopped
NO_CONNECTION_S = 30.0  # s after start without any connection before we say how the simulator connects
LATENCY_WINDOW = 1000  # reply latencies kept between two status lines (median and max), count

Line = Tuple[int, str]  # (logging level, message)


class LinkStatus:
    def __init__(self, now: float, address: str = "127.0.0.1:4567", versions: str = ""):
        self.started = now
        self.address = address
        self.versions = versions  # e.g. "python-socketio 4.6.1, python-engineio 3.13.2"
        self.connections = 0
        self.open_sockets = 0
        self.connected_at: Optional[float] = None
        self.frames = 0
        self.frames_this_connection = 0
        self.last_telemetry: Optional[float] = None
        self.latencies: deque = deque(maxlen=LATENCY_WINDOW)
        self._last_status = now
        self._frames_at_status = 0
        self._warned_silent = self._warned_gap = self._warned_unconnected = False

    # ---------------------------------------------------------------- events
    def on_connect(self, now: float):
        self.connections += 1
        self.open_sockets += 1
        self.connected_at = now
        self.frames_this_connection = 0
        self._warned_silent = False

    def on_disconnect(self, now: float):
        self.open_sockets = max(0, self.open_sockets - 1)

    def on_telemetry(self, now: float, reply_ms: float):
        if self._warned_gap:
            self._warned_gap = False
        if self.frames_this_connection == 0:  # status rates count from the first frame of a connection
            self._last_status, self._frames_at_status = now, self.frames
        self.frames += 1
        self.frames_this_connection += 1
        self.last_telemetry = now
        if math.isfinite(reply_ms):
            self.latencies.append(reply_ms)

    # ---------------------------------------------------------------- lines
    def tick(self, now: float, rover=None) -> List[Line]:
        lines: List[Line] = []
        if self.connections == 0:
            if not self._warned_unconnected and now - self.started >= NO_CONNECTION_S:
                self._warned_unconnected = True
                lines.append((logging.WARNING, self.no_connection_text(now)))
            return lines
        if self.open_sockets and self.frames_this_connection == 0:
            if not self._warned_silent and self.connected_at is not None \
                    and now - self.connected_at >= NO_TELEMETRY_S:
                self._warned_silent = True
                lines.append((logging.WARNING, self.silent_text(now)))
            return lines
        if not self.open_sockets:  # the simulator left (its disconnect is logged); it reconnects by itself
            return lines
        if self.last_telemetry is not None and now - self.last_telemetry >= TELEMETRY_GAP_S:
            if not self._warned_gap:
                self._warned_gap = True
                lines.append((logging.WARNING, self.gap_text(now)))
            self._last_status, self._frames_at_status = now, self.frames
            return lines
        if now - self._last_status >= STATUS_EVERY_S and self.frames > self._frames_at_status:
            lines.append((logging.INFO, self.status_text(now, rover)))
            self._last_status, self._frames_at_status = now, self.frames
            self.latencies.clear()  # each line reports its own window
        return lines

    def status_text(self, now, rover=None) -> str:
        rate = (self.frames - self._frames_at_status) / max(1e-9, now - self._last_status)
        lat = sorted(self.latencies)
        latency = f"reply {lat[len(lat) // 2]:.1f} ms median, {lat[-1]:.1f} max" if lat else "reply n/a"
        text = f"driving: {rate:.1f} telemetry/s, {latency}"
        if rover is not None:
            text += f", mode {rover.mode}, {scores_text(rover)}"
        return text

    def silent_text(self, now) -> str:
        return (f"the simulator connected {now - self.connected_at:.0f} s ago but has sent no telemetry, so the "
                "rover cannot move. Check: (1) the simulator is in Autonomous Mode, not Training; (2) only one "
                f"drive_rover.py is running (another one on {self.address} takes the telemetry); (3) the "
                f"Socket.IO versions are python-socketio 4.6.1 + python-engineio 3.13.2 (installed: "
                f"{self.versions or 'unknown'}).")

    def gap_text(self, now) -> str:
        return (f"no telemetry for {now - self.last_telemetry:.0f} s after {self.frames} frames: the simulator is "
                "paused, minimised, frozen or closed (a pickup request with no sample in reach freezes it). "
                "Driving resumes by itself when telemetry returns.")

    def no_connection_text(self, now) -> str:
        return (f"nothing has connected in {now - self.started:.0f} s. Start the simulator, pick a screen size, "
                f"then Autonomous Mode: it connects to {self.address}. If it is running already, check that no "
                "firewall blocks local connections and that nothing else answers on that port.")


def scores_text(rover) -> str:
    """'mapped 34.2 %, fidelity 91.0 %, collected 2/6' from the client's own map (n/a without ground truth)."""
    from evaluation.metrics import score_map

    mem = getattr(rover, "inset_memory", None)
    samples = getattr(mem, "samples_all", ()) if mem is not None else ()
    try:
        s = score_map(rover.worldmap, rover.ground_truth, [tuple(p) for p in samples])
        mapped = "n/a" if not math.isfinite(s.mapped_pct) else f"{s.mapped_pct:.1f} %"
        fidelity = "n/a" if not math.isfinite(s.fidelity_pct) else f"{s.fidelity_pct:.1f} %"
    except Exception:  # a status line must never break the server
        mapped = fidelity = "n/a"
    collected = "n/a"
    if rover.samples_initial is not None and rover.samples_remaining is not None:
        collected = f"{rover.samples_initial - rover.samples_remaining}/{rover.samples_initial}"
    return f"mapped {mapped}, fidelity {fidelity}, collected {collected}"
