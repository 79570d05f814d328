"""One telemetry frame end to end: parse -> rover state -> perception ->
decision -> command (with the pickup safety gate) -> insets.

Why one class: ``drive_rover.py`` (the socket edge) and the twin's mission
runner drive the same code, so what the twin measures is what the simulator
gets.  ``handle_telemetry`` never raises: a bad frame or a crash inside
perception/decision is logged (rate-limited) and answered with a safe stop,
because the simulator waits for exactly one reply per telemetry and an
exception would stall it for good.
"""
from __future__ import annotations

import logging
import math
import time
from typing import Callable, Dict, Optional, Tuple

import numpy as np

from interrupts import reraise_interrupt
from rover_state import RoverState
import supporting_functions as sf

log = logging.getLogger(__name__)

PICKUP_MAX_SPEED = 0.05  # |speed| below this counts as stopped for a pickup, m/s (sim reports 0 below 0.01)
PICKUP_RETRY_S = 1.0  # no second pickup request within this time of the last, s
MAX_STEER_DEG = 15.0  # simulator steering clamp, degrees
MAX_THROTTLE = 1.0  # |throttle| clamp (simulator does not clamp; 1 is full torque)
MAX_BRAKE = 10.0  # brake clamp (simulator does not clamp), brake units
SAFE_STOP = {"throttle": 0.0, "brake": 1.0, "steer": 0.0}  # command for bad frames
LOG_EVERY_S = 5.0  # the same warning is logged at most once per this many seconds
RESET_JUMP_M = 20.0  # a position jump this large between frames means the simulator restarted, m
TELEPORT_SPEED_M_S = 5.0  # fastest the rover moves (the simulator clamps at 5 m/s), m/s
TELEPORT_SLACK_M = 2.0  # jump allowed on top of speed x elapsed time (queueing jitter between frames), m
SAMPLE_MATCH_M = 0.1  # a reported sample farther than this from every known one is new, m
NUMBER_FORMAT = "{:.4f}"  # plain decimal with '.', as the simulator's float.Parse expects

STAGES = ("decode", "perception", "decision", "insets", "total")  # timing hook keys


class RateLimitedLog:
    """Log a message kind at most once per ``every`` seconds, counting the rest."""

    def __init__(self, logger: logging.Logger, every: float = LOG_EVERY_S,
                 clock: Callable[[], float] = time.monotonic):
        self.logger, self.every, self.clock = logger, every, clock
        self._last: Dict[str, float] = {}
        self._suppressed: Dict[str, int] = {}

    def __call__(self, kind: str, msg: str, *args, level=logging.WARNING, exc_info=False):
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.every:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return
        skipped = self._suppressed.pop(kind, 0)
        if skipped:
            msg = msg + f" ({skipped} similar suppressed)"
        self._last[kind] = now
        self.logger.log(level, msg, *args, exc_info=exc_info)


def format_number(value: float) -> str:
    """A command number for the wire: '.' decimal, 4 places, never '-0.0000'."""
    return NUMBER_FORMAT.format(float(value) + 0.0).replace("-0.0000", "0.0000")


def pickup_allowed(rover) -> bool:
    """The safety gate: a pickup with no sample near freezes the real simulator,
    so only ask when near a sample, stopped, not already picking up, and not
    right after the previous request."""
    if not rover.near_sample or rover.picking_up:
        return False
    if not math.isfinite(rover.vel) or abs(rover.vel) >= PICKUP_MAX_SPEED:
        return False
    last = rover.pickup_sent_at
    return last is None or rover.total_time - last >= PICKUP_RETRY_S or rover.total_time < last


def sanitize_command(throttle, brake, steer) -> Optional[Tuple[float, float, float]]:
    """Clamp a command; None if any part is not a finite number (then stop)."""
    try:
        t, b, s = float(throttle), float(brake), float(steer)
    except (TypeError, ValueError):
        return None
    if not (math.isfinite(t) and math.isfinite(b) and math.isfinite(s)):
        return None
    t = min(max(t, -MAX_THROTTLE), MAX_THROTTLE)
    b = min(max(b, 0.0), MAX_BRAKE)
    s = min(max(s, -MAX_STEER_DEG), MAX_STEER_DEG)
    return t, b, s


def command_payload(throttle: float, brake: float, steer: float) -> Dict[str, str]:
    return {"throttle": format_number(throttle), "brake": format_number(brake),
            "steering_angle": format_number(steer)}


def fixed_turn_reply(rover, enabled: bool):
    """("fixed_turn", payload) when decision asked for one this frame (rover.fixed_turn: degrees CCW, deg/s),
    else None; the request is consumed either way.  Not sent with fixed turns off (the decision then
    sees the yaw not move and steers the turn) or for an angle that cannot be sent."""
    from navigation import fixed_turn

    turn, rover.fixed_turn = getattr(rover, "fixed_turn", None), None
    if turn is None or not enabled:
        return None
    try:
        angle, rate = turn
        return "fixed_turn", fixed_turn.payload(angle, rate)
    except (TypeError, ValueError):
        log.warning("fixed turn of %r deg cannot be sent; data instead", turn)
        return None


def _default_steps():
    """The real perception and decision modules (imported late so that a
    missing module surfaces as one clear import error at client start)."""
    import decision
    import perception

    return perception.perception_step, decision.decision_step


class AutonomyClient:
    """Turns each telemetry dict into exactly one ``(event, payload)`` reply.

    ``clock`` is the client's wall clock (seconds, any origin): drive_rover.py
    uses ``time.monotonic`` because the real simulator sends no clock; the twin's
    in-process runner injects its virtual clock (sim.timing.VirtualClock) so a
    mission runs faster than real time and reproduces exactly.  Only the twin's
    lockstep debugging loop sends ``sim_time``, which then overrides the clock.
    ``perception_step``/``decision_step`` default to the real modules; tests
    pass doubles.  ``last_timings`` holds the last frame's stage durations in
    milliseconds (keys in ``STAGES``) for the benchmark; ``last_telemetry`` the
    last parsed frame (the recorder stores its JPEG bytes).
    """

    def __init__(self, ground_truth=None, clock: Callable[[], float] = time.monotonic,
                 insets: bool = True, perception_step=None, decision_step=None, home_by_s=None,
                 fixed_turns: bool = True):
        if perception_step is None or decision_step is None:
            real_perception, real_decision = _default_steps()
            perception_step = perception_step or real_perception
            decision_step = decision_step or real_decision
        self.home_by_s = home_by_s  # return deadline handed to every mission's RoverState, s or None
        self.fixed_turns = bool(fixed_turns)  # turn in place with the simulator's fixed_turn (False: steer, e.g. the gym)
        self.rover = self._fresh_rover(ground_truth)
        self.clock = clock
        self.insets = insets
        self.perception_step = perception_step
        self.decision_step = decision_step
        self.warn = RateLimitedLog(log)
        self.last_timings: Dict[str, float] = {}
        self.last_telemetry: Optional[sf.Telemetry] = None
        self.bad_frames = 0  # telemetry frames answered with a safe stop
        self.episodes = 1  # missions seen (a simulator restart starts a new one)
        self._last_sim_time: Optional[float] = None
        self._last_frame_time: Optional[float] = None  # _now() of the last handled frame, s
        self.step_errors = 0  # exceptions caught from perception/decision/insets

    def warm_up(self) -> float:
        """Run perception and decision once on a throwaway rover and a synthetic frame, so the numba
        kernels are compiled (first run, seconds) or loaded from their cache (~0.5 s) before the
        simulator's first telemetry instead of during it.  Leaves this client's state untouched;
        never raises.  Returns the seconds it took."""
        t0 = time.perf_counter()
        rover = RoverState()
        rover.img = np.zeros((160, 320, 3), np.uint8)
        rover.img[100:] = (200, 185, 170)  # floor below a dark wall: every mask has pixels
        rover.pos, rover.yaw, rover.total_time = (100.0, 100.0), 0.0, 0.0
        try:
            self.perception_step(rover)
            self.decision_step(rover)
        except Exception:  # a warm-up failure is only a slower first frame
            log.debug("warm-up frame failed", exc_info=True)
        return time.perf_counter() - t0

    # -- helpers --------------------------------------------------------------
    def _fresh_rover(self, ground_truth):
        rover = RoverState(ground_truth=ground_truth)
        rover.home_by_s = self.home_by_s
        rover.fixed_turns = self.fixed_turns
        return rover

    def _safe_stop(self):
        s = SAFE_STOP
        return "data", command_payload(s["throttle"], s["brake"], s["steer"])

    def _now(self, tel: sf.Telemetry) -> float:
        """The mission clock for this frame: the lockstep twin's sim_time, else our own clock."""
        if tel.sim_time is not None:
            return tel.sim_time
        return self.clock()

    def _restart_reason(self, tel: sf.Telemetry) -> Optional[str]:
        """Why this frame belongs to a new mission (the user reloaded the
        simulator while we kept running), or None.  Samples only ever
        disappear, the rover cannot teleport and the twin's clock only runs
        forward, so any of those going the other way means a restart."""
        r = self.rover
        if r.start_time is None:
            return None
        if tel.sim_time is not None and self._last_sim_time is not None \
                and tel.sim_time < self._last_sim_time:
            return f"sim_time went back to {tel.sim_time:.2f} s"
        if tel.sample_count is not None and r.samples_remaining is not None \
                and tel.sample_count > r.samples_remaining:
            return f"sample_count rose from {r.samples_remaining} to {tel.sample_count}"
        x, y = r.pos
        if math.isfinite(x) and math.isfinite(y):
            jump = math.hypot(tel.pos[0] - x, tel.pos[1] - y)
            if jump > RESET_JUMP_M or jump > self._teleport_limit(tel):
                return f"position jumped from ({x:.1f}, {y:.1f}) to ({tel.pos[0]:.1f}, {tel.pos[1]:.1f})"
        known_x, known_y = np.asarray(r.samples_pos[0]), np.asarray(r.samples_pos[1])
        if len(known_x) and len(tel.samples_xy):
            if tel.samples_xy[:, 0].tolist() == known_x.tolist() and tel.samples_xy[:, 1].tolist() == known_y.tolist():
                return None  # the same samples as last frame (nearly every frame): each matches itself at 0 m
            dx = tel.samples_xy[:, 0:1] - known_x[None, :]
            dy = tel.samples_xy[:, 1:2] - known_y[None, :]
            if (np.hypot(dx, dy).min(axis=1) > SAMPLE_MATCH_M).any():
                return "a sample appeared where none was"
        return None

    def _teleport_limit(self, tel: sf.Telemetry) -> float:
        """The farthest the rover can have driven since the last frame: a restart
        near the start (same samples, under RESET_JUMP_M away) still jumps
        farther than that, because the rover is put back at once."""
        if self._last_frame_time is None:
            return math.inf
        elapsed = self._now(tel) - self._last_frame_time
        if not math.isfinite(elapsed) or elapsed < 0:
            return math.inf
        return TELEPORT_SLACK_M + TELEPORT_SPEED_M_S * elapsed

    def _new_mission(self, reason: str):
        log.warning("simulator restarted (%s): starting a new mission", reason)
        self.rover = self._fresh_rover(self.rover.ground_truth)
        self.episodes += 1

    # -- the frame ------------------------------------------------------------
    def handle_telemetry(self, data) -> Tuple[str, Dict[str, str]]:
        """One reply: ("data", command+insets), ("pickup", {}), ("fixed_turn", {"angle", "time"}) or ("manual", {})."""
        t0 = time.perf_counter()
        timings = {k: 0.0 for k in STAGES}
        self.last_timings = timings
        try:
            reply = self._handle(data, timings)
        except Exception as exc:  # last line of defence; _handle already guards its steps
            reraise_interrupt(exc)
            self.step_errors += 1
            self.warn("frame", "unexpected error handling telemetry; safe stop", exc_info=True)
            reply = self._safe_stop()
        timings["total"] = (time.perf_counter() - t0) * 1e3
        return reply

    def _handle(self, data, timings):
        if data is None or (isinstance(data, (dict, str, list)) and len(data) == 0):
            self.last_telemetry = None
            return "manual", {}
        t = time.perf_counter()
        tel = sf.parse_telemetry(data)
        timings["decode"] = (time.perf_counter() - t) * 1e3
        self.last_telemetry = tel
        if tel.warnings:
            self.warn("telemetry", "telemetry: %s", "; ".join(tel.warnings))
        rover = self.rover
        if not tel.ok:
            self.bad_frames += 1
            sf.update_rover(rover, tel, 0.0)
            self.warn("bad-frame", "bad telemetry frame answered with a safe stop")
            return self._safe_stop()
        reason = self._restart_reason(tel)
        if reason:
            self._new_mission(reason)
            rover = self.rover
        now = self._now(tel)
        sf.update_rover(rover, tel, now)
        self._last_sim_time = tel.sim_time
        self._last_frame_time = now

        t = time.perf_counter()
        try:
            rover.send_pickup = False
            rover.fixed_turn = None
            self.perception_step(rover)
            timings["perception"] = (time.perf_counter() - t) * 1e3
            t = time.perf_counter()
            self.decision_step(rover)
            timings["decision"] = (time.perf_counter() - t) * 1e3
        except Exception as exc:
            reraise_interrupt(exc)
            self.step_errors += 1
            self.warn("step", "perception/decision raised; safe stop", exc_info=True)
            rover.send_pickup = False
            rover.fixed_turn = None
            return self._safe_stop()

        want_pickup = bool(rover.send_pickup)
        rover.send_pickup = False
        if want_pickup and pickup_allowed(rover):
            rover.pickup_sent_at = rover.total_time
            return "pickup", {}
        turn = fixed_turn_reply(rover, self.fixed_turns)
        if turn is not None:
            return turn
        if want_pickup:
            self.warn("pickup-gate", "pickup vetoed (near=%s, speed=%.3f, picking_up=%s)",
                      rover.near_sample, rover.vel, rover.picking_up, level=logging.INFO)

        cmd = sanitize_command(rover.throttle, rover.brake, rover.steer)
        if cmd is None:
            self.warn("nan", "decision produced a non-finite command (%r, %r, %r); safe stop",
                      rover.throttle, rover.brake, rover.steer)
            return self._safe_stop()
        payload = command_payload(*cmd)
        if self.insets:
            t = time.perf_counter()
            try:
                payload["inset_image1"], payload["inset_image2"] = sf.create_output_images(rover)
            except Exception as exc:
                reraise_interrupt(exc)
                self.step_errors += 1
                self.warn("insets", "inset rendering failed; command sent without insets",
                          exc_info=True)
            timings["insets"] = (time.perf_counter() - t) * 1e3
        return "data", payload
