"""When things happen in the simulator's loop: the timing models the twin offers.

``unity`` (the default) is the real simulator's loop (`CommandServer.cs`, see
docs/twin-timing.md): physics free-runs at PHYSICS_DT whatever the client does;
the screen renders at ``fps``; a command waits until the first render frame after
it arrives, where it sets the (sticky) inputs and one telemetry is captured; the
client's reply reaches the simulator ``compute_ms + latency_ms`` after the capture
it answers.  No clock is sent: the client only has its own wall clock.

``lockstep`` is the twin's old debugging loop: every command advances exactly one
0.04 s frame at once and the twin sends its ``sim_time`` clock.  It is EASIER than
the real simulator (no latency, the client never acts on a stale frame).

In-process missions run the unity model on a virtual clock (`VirtualClock`), so
they are deterministic per seed and timing parameters and much faster than real
time; the client's compute time is modelled as the fixed ``compute_ms``, never
measured, because a measured wall time would make every run different.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from sim.physics import PHYSICS_DT

TIMING_MODELS = ("unity", "lockstep")  # the loops the twin can run
DEFAULT_TIMING = "unity"  # every mission and evaluation runs the real simulator's loop unless told otherwise
UNITY_FPS = 30.0  # render frames/s of the simulator at quality Fastest..Beautiful (vSync 2); 60 = Fantastic
# Round trip of one telemetry (a real twin frame, 5.4 KB of JSON) out and the real client's
# command (with insets) back over a real websocket on this machine: the twin's websocket-client
# against drive_rover.py's python-socketio 4 / eventlet server replying at once, loopback.
# `python -m benchmarks.wire_latency` on 2026-11-25, 2 cores shared (load 5-6): median 5.42 and
# 4.52 ms over 2,000 round trips each (p95 8-12 ms), ms.
WIRE_LATENCY_MS = 5.0
# The client's compute time per telemetry in the in-process model: the median total of
# `python -m benchmarks.frame` (decode + perception + decision + insets) on this machine on
# 2026-11-25 was 1.78 ms; modelled as a constant so a seed reproduces exactly, ms.
CLIENT_COMPUTE_MS = 2.0
LOCKSTEP_FRAME_S = 2 * PHYSICS_DT  # lockstep: one command advances this much simulated time, s
TIME_EPS = 1e-9  # s, tolerance when a time falls exactly on a frame or physics step boundary
MAX_FPS = 240.0  # render rates above this are not a simulator setting, frames/s
MAX_DELAY_MS = 10_000.0  # latency or compute beyond this is a misconfiguration, ms


@dataclass(frozen=True)
class Timing:
    """One timing model and its parameters (what every result names)."""

    model: str = DEFAULT_TIMING
    fps: float = UNITY_FPS  # render frames per second (unity)
    latency_ms: float = WIRE_LATENCY_MS  # transport round trip, telemetry out + command back (unity)
    compute_ms: float = CLIENT_COMPUTE_MS  # the client's modelled compute time per telemetry (unity, in-process)

    def __post_init__(self):
        if self.model not in TIMING_MODELS:
            raise ValueError(f"timing model must be one of {TIMING_MODELS}, not {self.model!r}")
        if not (math.isfinite(self.fps) and 0 < self.fps <= MAX_FPS):
            raise ValueError(f"fps must be in (0, {MAX_FPS:.0f}], got {self.fps!r}")
        for name in ("latency_ms", "compute_ms"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 <= v <= MAX_DELAY_MS):
                raise ValueError(f"{name} must be in [0, {MAX_DELAY_MS:.0f}] ms, got {v!r}")

    @property
    def unity(self) -> bool:
        return self.model == "unity"

    @property
    def sends_sim_time(self) -> bool:
        """Only the lockstep debugging loop sends the twin-only clock."""
        return self.model == "lockstep"

    @property
    def frame_s(self) -> float:
        return 1.0 / self.fps

    @property
    def reply_delay_s(self) -> float:
        """Capture of a telemetry -> its command reaches the simulator."""
        return (self.latency_ms + self.compute_ms) / 1e3

    def describe(self) -> dict:
        """The fields every JSON result carries (lockstep has no fps or latency)."""
        if not self.unity:
            return {"timing": "lockstep", "fps": None, "latency_ms": None, "compute_ms": None}
        d = asdict(self)
        d["timing"] = d.pop("model")
        return d

    def label(self) -> str:
        if not self.unity:
            return "lockstep (EASIER than the real simulator: no latency, twin sim_time clock)"
        return (f"Unity timing, {self.fps:g} fps, {self.latency_ms:g} ms latency + "
                f"{self.compute_ms:g} ms client compute")


def frame_after(t: float, fps: float) -> int:
    """Index of the first render frame strictly after time t (frame k is at k / fps)."""
    return int(math.floor(t * fps + TIME_EPS)) + 1


def frame_time(k: int, fps: float) -> float:
    return k / fps


def physics_steps_at(t: float) -> int:
    """Physics steps Unity has run by time t (FixedUpdate catches up before each frame)."""
    return int(math.floor(t / PHYSICS_DT + TIME_EPS))


class VirtualClock:
    """A settable clock the in-process client reads as its wall clock (AutonomyClient(clock=...))."""

    def __init__(self, t: float = 0.0):
        self.t = float(t)

    def __call__(self) -> float:
        return self.t


class TwinLoop:
    """Drives a RoverTwin through one timing model on a virtual clock (in-process missions, envs).

    ``clock`` is what the client must read as its wall clock.  ``step`` raises
    sim.twin.CommandError (the real simulator would send no reply) and returns the next
    telemetry and the simulated seconds it took.
    """

    def __init__(self, twin, timing: Timing | None = None):
        self.twin = twin
        self.timing = timing or Timing()
        twin.sim_time_field = self.timing.sends_sim_time
        self.clock = VirtualClock()
        self.captured_at = 0.0  # time of the render frame that captured the last telemetry, s
        self.delays = []  # per command: capture it answered -> the frame it acted at, s

    def reset(self, seed=None, start_yaw=None) -> dict:
        tel = self.twin.reset(seed, start_yaw=start_yaw)
        self.captured_at = 0.0
        self._set_clock()
        return tel

    def _set_clock(self):
        # the client reads its clock when the telemetry reaches it: half the round trip after capture
        t = self.captured_at
        self.clock.t = t + self.timing.latency_ms / 2e3 if self.timing.unity else t

    def step(self, event, payload=None):
        """The client's reply to the last telemetry -> (next telemetry, simulated seconds elapsed)."""
        if self.timing.unity:
            tel, dt, acted_at = self._unity(event, payload)
        else:
            tel = self.twin.step(event, payload)
            dt = self.twin.frame_dt
            acted_at = self.captured_at + dt
        self.delays.append(acted_at - self.captured_at)
        self.captured_at = acted_at
        self._set_clock()
        return tel, dt

    def _unity(self, event, payload):
        """Physics runs on while the reply travels; it acts, and is answered, at the next render frame."""
        t = self.timing
        act_at = frame_time(frame_after(self.captured_at + t.reply_delay_s, t.fps), t.fps)
        dt = self.twin.advance_to(act_at)
        self.twin.apply(event, payload)  # CommandError: no reply, the chain stalls for good
        return self.twin.capture(), dt, act_at


def add_timing_options(parser) -> None:
    """--timing, --fps, --latency-ms, --compute-ms: the same on every tool."""
    parser.add_argument("--timing", choices=TIMING_MODELS, default=DEFAULT_TIMING,
                        help="unity (default): the real simulator's loop - free-running physics, commands act "
                             "at the next render frame, no clock sent; lockstep: the twin's old loop, one "
                             "frame per command with a sim_time clock, EASIER than the real simulator")
    parser.add_argument("--fps", type=float, default=UNITY_FPS,
                        help=f"render frames/s under unity timing (default {UNITY_FPS:g}; 60 = Fantastic, "
                             "15 = a slow machine)")
    parser.add_argument("--latency-ms", type=float, default=WIRE_LATENCY_MS,
                        help=f"transport round trip under unity timing, ms (default {WIRE_LATENCY_MS:g}, "
                             "measured over a real websocket on the development machine)")
    parser.add_argument("--compute-ms", type=float, default=CLIENT_COMPUTE_MS,
                        help=f"the client's modelled compute time per telemetry in-process, ms (default "
                             f"{CLIENT_COMPUTE_MS:g}; fixed, not measured, so a seed reproduces exactly)")


def timing_from_args(args) -> Timing:
    """Timing from parsed add_timing_options arguments; ValueError on bad values."""
    return Timing(args.timing, float(args.fps), float(args.latency_ms), float(args.compute_ms))
