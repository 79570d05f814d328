"""`RoverTwin`: the simulator in one object, with a Gymnasium-like reset/step.

`reset(seed)` and `telemetry()` return exactly the telemetry dict the Unity
simulator would send (every value a string, .NET N4 formatting, raw 0-360
pitch/roll, ...).  Only when built with ``sim_time_field=True`` (the lockstep
debugging loop) does it add the twin-only `sim_time` (simulated seconds as a
string); the real simulator sends no clock.

Two ways to move time (sim/timing.py says which loop uses which):
* the real simulator's loop: `advance_to(t)` runs the free-running 0.02 s physics
  up to time t, `apply(...)` sets the inputs at a render frame and `capture()`
  takes that frame's telemetry;
* lockstep: `step(event, payload)` applies a command, advances one frame of
  PHYSICS_STEPS_PER_FRAME physics steps (0.04 s) and returns the telemetry.

Commands are parsed as the real CommandServer does (values must be JSON strings;
`float.Parse` on anything else throws and the real simulator sends no reply).
The in-process API raises `CommandError` for such a command and leaves the state
untouched (no time passes); the wire front end logs it and sends no reply, as the
real one.  Strings that parse to NaN/Infinity are rejected the same way (the real
simulator would feed NaN into its physics; the twin refuses instead).
"""
from __future__ import annotations

import base64
import logging
import math
from dataclasses import dataclass

import numpy as np

from sim.physics import MAX_STEER_DEG, PHYSICS_DT, Controls, RoverPhysics, delta_angle
from sim.samples import PickupArm, near_index, spawn_samples

log = logging.getLogger(__name__)

PHYSICS_STEPS_PER_FRAME = 2  # physics steps per telemetry frame (2 x 0.02 s = 25 Hz)
JPEG_QUALITY = 75  # Unity EncodeToJPG default quality
SPEED_ZERO_BELOW = 0.01  # m/s, telemetry speed reads 0 below this
FIXED_TURN_STILL_SPEED = 0.01  # m/s, fixed_turn accepted only below this speed
SIM_TIME_DECIMALS = 4  # decimals of the twin-only sim_time field
EVENTS = ("data", "manual", "pickup", "fixed_turn")  # events the simulator handles
STILL_POSITION_M = 1e-4  # a frame whose rover moved less than this (x and y) since the last render reuses its image, m
STILL_ANGLE_DEG = 1e-3  # ... and whose yaw, pitch and roll each moved less than this, deg


class CommandError(ValueError):
    """A command the real simulator would choke on (it sends no telemetry reply)."""


# --------------------------------------------------------------------- formatting
def format_n(value: float, decimals: int = 4) -> str:
    """.NET `N<decimals>` in en-US: group separator at >= 1000, no "-0.0000"."""
    v = float(value)
    if not math.isfinite(v):
        return "NaN" if math.isnan(v) else ("Infinity" if v > 0 else "-Infinity")
    text = f"{v:,.{decimals}f}"
    if text.startswith("-") and not any(ch in "123456789" for ch in text):
        text = text[1:]  # the Mono runtime of Unity 5.6 prints rounded negative zero as 0
    return text


def format_angle_0_360(deg: float) -> str:
    """Unity localEulerAngles: raw 0..360, small negatives appear as 359.x."""
    return format_n(float(deg) % 360.0)


def parse_sim_float(value, name: str) -> float:
    """float.Parse(field.str): only JSON strings holding finite numbers are accepted."""
    if not isinstance(value, str):
        raise CommandError(f"{name}: expected a JSON string, got {type(value).__name__} {value!r}")
    text = value.strip()
    if not text.isascii():  # .NET only reads ASCII digits; Python would accept e.g. Arabic-Indic
        raise CommandError(f"{name}: not a number: {value!r}")
    try:
        number = float(text.replace(",", "")) if text else float("nan")
    except ValueError:
        raise CommandError(f"{name}: not a number: {value!r}") from None
    if not math.isfinite(number) or "_" in text:
        raise CommandError(f"{name}: not a finite number: {value!r}")
    return number


def parse_command(event, payload):
    """Validate one client event; returns (event, parsed dict) or raises CommandError."""
    if event not in EVENTS:
        raise CommandError(f"unknown event {event!r} (the simulator has no handler)")
    if payload is None:
        payload = {}
    if not isinstance(payload, dict):
        raise CommandError(f"{event}: payload must be a JSON object, got {type(payload).__name__}")
    if event == "data":
        for key in ("steering_angle", "throttle"):
            if key not in payload:
                raise CommandError(f"data: missing required field {key!r}")
        parsed = {"steer": parse_sim_float(payload["steering_angle"], "steering_angle"),
                  "throttle": parse_sim_float(payload["throttle"], "throttle"),
                  "brake": parse_sim_float(payload["brake"], "brake") if "brake" in payload else 0.0}
        return event, parsed
    if event == "fixed_turn":
        if "angle" not in payload:
            raise CommandError("fixed_turn: missing required field 'angle'")
        angle = parse_sim_float(payload["angle"], "angle")
        t = payload.get("time")
        duration = parse_sim_float(t, "time") if t not in (None, "") else 0.0  # 0: the default angle / 45 s
        return event, {"angle": angle, "time": duration}
    return event, {}


# --------------------------------------------------------------------- truth
@dataclass
class TwinTruth:
    """What really happened (for scoring), never sent to the client."""

    x: float
    y: float
    yaw: float
    pitch: float
    roll: float
    v: float
    sim_time: float
    frame: int  # telemetry frames produced since reset
    samples: list  # remaining Sample objects
    collected: list  # collected Sample objects
    initial_samples: list
    picking_up: bool
    pickup_stuck: bool
    collided: bool
    start_xy: tuple


class RoverTwin:
    """Headless simulator: physics, samples, rendering and telemetry for one rover."""

    def __init__(self, world=None, seed: int = 0, steps_per_frame: int = PHYSICS_STEPS_PER_FRAME,
                 render: bool = True, renderer=None, jpeg_quality: int = JPEG_QUALITY,
                 sim_time_field: bool = False):
        if world is None:
            from sim.world import default_world

            world = default_world()
        self.world = world
        self.steps_per_frame = max(1, int(steps_per_frame))
        self.frame_dt = self.steps_per_frame * PHYSICS_DT
        self.render_enabled = bool(render)
        self._renderer = renderer
        self.jpeg_quality = int(jpeg_quality)
        self.sim_time_field = bool(sim_time_field)  # add the twin-only clock (lockstep debugging only)
        self._blank_jpeg_b64 = None
        self._sample_key = None  # the sample positions the cached samples_x/_y strings were built from
        self._sample_text = {}
        self.last_rgb = None  # last rendered camera frame (RGB) or None
        self.last_jpeg = None  # its JPEG bytes
        self.reuse_still_frames = True  # False: every frame rendered afresh (see _still_frame)
        self.reset(seed)

    # ------------------------------------------------------------------ lifecycle
    def reset(self, seed: int | None = None, start_yaw: float | None = None) -> dict:
        """New scene: start pose at world.start_xy, random yaw and samples from `seed`."""
        if seed is not None:
            self.seed = int(seed)
        rng = np.random.default_rng(self.seed)
        yaw = float(rng.uniform(0.0, 360.0)) if start_yaw is None else float(start_yaw) % 360.0
        self.initial_yaw = yaw
        self.samples = spawn_samples(self.world.sample_spots, rng)
        self.initial_samples = list(self.samples)
        self.physics = RoverPhysics(self.world, *self.world.start_xy, yaw)
        self.controls = Controls()
        self.arm = PickupArm()
        self.physics_steps = 0
        self.frame = 0
        self.rejected_commands = 0
        self._still = None  # (pose, scene key, base64 image) of the last rendered frame
        self.reused_frames = 0  # frames since reset that reused the last image (the rover still)
        return self.telemetry()

    # ------------------------------------------------------------------ commands
    def step(self, event: str, payload=None) -> dict:
        """Handle one client event like the simulator, advance one frame, return telemetry.

        Raises CommandError (state unchanged) for a command the real simulator would
        not answer.
        """
        self.apply(event, payload)
        self.advance_frame()
        return self.telemetry()

    def apply(self, event: str, payload=None) -> None:
        """Apply one client event without advancing time (real-time wire mode)."""
        try:
            event, cmd = parse_command(event, payload)
        except CommandError:
            self.rejected_commands += 1
            raise
        if event == "data":
            self.controls = Controls(cmd["throttle"], cmd["brake"], cmd["steer"])
        elif event == "pickup":
            if not self.arm.active:
                self.arm.start(self._near())
                self.physics.freeze()
        elif event == "fixed_turn":
            s = self.physics.state
            c = self.controls
            if abs(s.v) < FIXED_TURN_STILL_SPEED and c.throttle == 0 and c.brake == 0 and c.steer == 0:
                self.physics.start_fixed_turn(cmd["angle"], cmd["time"])
            else:
                log.debug("fixed_turn ignored: rover moving, or throttle/brake/steer nonzero")

    def advance_frame(self):
        """One lockstep frame of game time: physics steps, pickup arm, clock."""
        self.advance_steps(self.steps_per_frame)
        self.frame += 1

    def advance_steps(self, n: int) -> None:
        """Run n physics steps on the current (sticky) inputs, the pickup arm alongside."""
        for _ in range(max(0, int(n))):
            self.physics.step(self.controls, frozen=self.arm.freezes_rover)
            self.arm.advance(PHYSICS_DT, self.samples)
        self.physics_steps += max(0, int(n))

    def advance_to(self, t: float) -> float:
        """Free-running physics up to time t (Unity's FixedUpdate catch-up); returns seconds advanced."""
        from sim.timing import physics_steps_at

        n = physics_steps_at(t) - self.physics_steps
        self.advance_steps(n)
        return max(0, n) * PHYSICS_DT

    def capture(self) -> dict:
        """One telemetry captured at this render frame (the real loop's reply to a command)."""
        self.frame += 1
        return self.telemetry()

    @property
    def sim_time(self) -> float:
        """Simulated seconds since reset (whole physics steps, no float drift)."""
        return self.physics_steps * PHYSICS_DT

    def _near(self):
        s = self.physics.state
        return near_index(self.samples, s.x, s.y, s.yaw)

    # ------------------------------------------------------------------ output
    def pose(self):
        s = self.physics.state
        return (s.x, s.y, s.yaw, s.pitch, s.roll)

    def renderer(self):
        """The twin's renderer, built on first use (a twin made with render=False never bakes one)."""
        if self._renderer is None:
            from sim.render import Renderer

            self._renderer = Renderer(self.world)
        return self._renderer

    def _render_samples(self) -> tuple:
        return tuple(smp.render_tuple() for smp in self.samples)

    def render_rgb(self):
        from sim.tracks import tyre_tracks
        return self.renderer().render(self.pose(), self._render_samples(), tyre_tracks(self))

    def _image_b64(self) -> str:
        if not self.render_enabled:
            if self._blank_jpeg_b64 is None:
                import cv2

                ok, buf = cv2.imencode(".jpg", np.zeros((160, 320, 3), np.uint8))
                self._blank_jpeg_b64 = base64.b64encode(buf.tobytes()).decode("ascii")
            self.last_rgb, self.last_jpeg = None, None
            return self._blank_jpeg_b64
        from sim.render import encode_jpeg
        from sim.tracks import tyre_tracks

        tracks = tyre_tracks(self)  # laid every frame, reused or not, so the tracks never depend on the cache
        pose = self.pose()
        scene = self._scene_key(tracks)
        if self._still_frame(pose, scene):
            self.reused_frames += 1
            return self._still[2]
        rgb = self._renderer.render(pose, scene[-1], tracks)
        self.last_rgb = rgb
        self.last_jpeg = encode_jpeg(rgb, quality=self.jpeg_quality)
        b64 = base64.b64encode(self.last_jpeg).decode("ascii")
        self._still = (pose, scene, b64)
        return b64

    def _scene_key(self, tracks) -> tuple:
        """Everything besides the pose that a render depends on and that can change during a run
        (the samples last: `_image_b64` draws them from here)."""
        r = self.renderer()
        settings = tuple(v for v in vars(r).values() if isinstance(v, (bool, int, float, str)))
        return (id(r), settings, self.jpeg_quality, tracks.laid, self._render_samples())

    def _still_frame(self, pose, scene) -> bool:
        """True when the rover has not moved since the last rendered frame (the pickup arm's 10 s, a
        braked standstill): ~12 % of a mission's frames. Rendering them again would give the same
        image to within ~0.02 levels (a 0.1 mm / 0.001 deg pose change), at ~2 ms a frame."""
        if not self.reuse_still_frames or self._still is None:
            return False
        last, last_scene, _ = self._still
        if scene != last_scene:
            return False
        if abs(pose[0] - last[0]) >= STILL_POSITION_M or abs(pose[1] - last[1]) >= STILL_POSITION_M:
            return False
        return all(abs(delta_angle(b, a)) < STILL_ANGLE_DEG for a, b in zip(pose[2:], last[2:]))

    def telemetry(self) -> dict:
        """The simulator's telemetry for the current state (field order as the real one)."""
        s = self.physics.state
        c = self.controls
        picking = self.arm.active
        speed = 0.0 if (picking or abs(s.v) < SPEED_ZERO_BELOW) else s.v
        near = (not self.arm.release_pending) and self._near() is not None
        out = {
            "steering_angle": format_n(max(-MAX_STEER_DEG, min(MAX_STEER_DEG, c.steer))),
            "throttle": format_n(c.throttle),
            "brake": format_n(c.brake),
            "speed": format_n(speed),
            "position": f"{format_n(s.x)};{format_n(s.y)}",
            "pitch": format_angle_0_360(s.pitch),
            "yaw": format_angle_0_360(s.yaw),
            "roll": format_angle_0_360(s.roll),
            "near_sample": "1" if near else "0",
            "picking_up": "1" if picking else "0",
            "sample_count": str(len(self.samples)),
            **self._sample_fields(),
            "image": self._image_b64(),
        }
        if self.sim_time_field:
            out["sim_time"] = f"{self.sim_time:.{SIM_TIME_DECIMALS}f}"
        self.arm.end_of_frame()
        return out

    def _sample_fields(self) -> dict:
        """samples_x / samples_y; rebuilt only when the samples changed (a pickup), not every frame."""
        key = tuple((smp.x, smp.y) for smp in self.samples)
        if key != self._sample_key:
            self._sample_key = key
            self._sample_text = {"samples_x": ";".join(format_n(x, 2) for x, _ in key),
                                 "samples_y": ";".join(format_n(y, 2) for _, y in key)}
        return self._sample_text

    @property
    def truth(self) -> TwinTruth:
        s = self.physics.state
        return TwinTruth(s.x, s.y, s.yaw, s.pitch, s.roll, s.v, self.sim_time, self.frame,
                         list(self.samples), list(self.arm.collected), list(self.initial_samples),
                         self.arm.active, self.arm.stuck, s.collided, tuple(self.world.start_xy))
