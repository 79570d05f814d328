"""`RoverTwin-v0`: the headless twin of the RoboND rover simulator as a Gymnasium env."""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from rover_gym.coverage import SEEN_RANGE_M, CameraCoverage

IMAGE_SHAPE = (160, 320, 3)  # camera frame, rows x columns x RGB (the simulator's 320x160 view)
TELEMETRY_FIELDS = ("speed", "x", "y", "yaw", "pitch", "roll", "steer", "throttle", "brake",
                    "near_sample", "picking_up", "samples_remaining", "sim_time")  # obs["telemetry"] order
MAX_STEER_DEG = 15.0  # simulator steering clamp, degrees (positive = left)
MAX_BRAKE = 10.0  # largest brake the action space offers (the starter brakes with 10; 1 = 2.5 m/s^2)
PICKUP_THRESHOLD = 0.5  # action[3] at or above this requests a pickup
MAP_REWARD_TOTAL = 100.0  # reward for seeing every truth-navigable cell (so mapping pays in map percent)
SAMPLE_REWARD = 10.0  # reward per sample collected
HOME_REWARD = 50.0  # reward for stopping at home with every sample collected (ends the episode)
HOME_RADIUS_M = 3.0  # m from the start that counts as home (as sim.mission)
HOME_STILL_SPEED = 0.1  # m/s, below this the rover counts as stopped at home
EPISODE_S = 900.0  # simulated seconds before an episode is truncated (as sim.mission)
SIM_TIME_DECIMALS = 4  # obs sim_time rounding (as the twin's lockstep sim_time field)
RENDER_MAP_PX = 320  # side of the map panel in render(), px (camera + text panel on its left)

_WORLDS: dict = {}  # (spec, shadows) -> World, shared by every env in this process (bakes are costly)


def load_env_world(world="default", shadows: bool = False):
    """A `sim.world.World` for a spec (cached per process) or the World object itself."""
    from sim.world import World, load_world, with_shadows

    if isinstance(world, World):
        return with_shadows(world, shadows)
    key = (str(world), bool(shadows))
    if key not in _WORLDS:
        _WORLDS[key] = with_shadows(load_world(str(world)), shadows)
    return _WORLDS[key]


def _signed(deg: float) -> float:
    """0..360 telemetry angle -> (-180, 180]."""
    d = deg % 360.0
    return d - 360.0 if d > 180.0 else d


def _num(text) -> float:
    return float(str(text).replace(",", ""))


def telemetry_vector(tel: dict, sim_time: float) -> np.ndarray:
    """The env's telemetry observation from the simulator's string telemetry (same rounding).

    sim_time: when this telemetry was captured, s (the real simulator sends no clock)."""
    x, y = (_num(v) for v in tel["position"].split(";"))
    values = {
        "speed": _num(tel["speed"]), "x": x, "y": y, "yaw": _num(tel["yaw"]) % 360.0,
        "pitch": _signed(_num(tel["pitch"])), "roll": _signed(_num(tel["roll"])),
        "steer": _num(tel["steering_angle"]), "throttle": _num(tel["throttle"]),
        "brake": _num(tel["brake"]), "near_sample": float(tel["near_sample"]),
        "picking_up": float(tel["picking_up"]), "samples_remaining": float(tel["sample_count"]),
        "sim_time": round(float(sim_time), SIM_TIME_DECIMALS),
    }
    return np.array([values[k] for k in TELEMETRY_FIELDS], np.float64)


def _telemetry_space() -> spaces.Box:
    inf = np.inf
    from sim.physics import MAX_FORWARD_SPEED, MAX_REVERSE_SPEED
    from sim.samples import SPAWN_COUNT

    bounds = {"speed": (-MAX_REVERSE_SPEED, MAX_FORWARD_SPEED), "x": (-inf, inf), "y": (-inf, inf), "yaw": (0.0, 360.0),
              "pitch": (-180.0, 180.0), "roll": (-180.0, 180.0), "steer": (-MAX_STEER_DEG, MAX_STEER_DEG),
              "throttle": (-1.0, 1.0), "brake": (0.0, MAX_BRAKE), "near_sample": (0.0, 1.0),
              "picking_up": (0.0, 1.0), "samples_remaining": (0.0, float(SPAWN_COUNT)), "sim_time": (0.0, inf)}
    low = np.array([bounds[k][0] for k in TELEMETRY_FIELDS], np.float64)
    high = np.array([bounds[k][1] for k in TELEMETRY_FIELDS], np.float64)
    return spaces.Box(low, high, dtype=np.float64)


def _decode_jpeg(jpeg: bytes) -> np.ndarray:
    import cv2

    bgr = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    return np.ascontiguousarray(bgr[:, :, ::-1])


class RoverTwinEnv(gym.Env):
    """
    ## Description

    The Udacity RoboND "Search and Sample Return" task on the project's headless
    digital twin of the Unity simulator (`sim/`): a rover starts in a canyon
    (the simulator's own scene with `world="real"`, or a seeded procedural canyon)
    and must map the navigable floor, pick up the six gold samples and drive back
    to where it started.  Physics, sample spawning, the pickup arm and the
    camera renderer are the twin's, fitted to real simulator recordings.

    ## Action Space

    `Box(4,)` float32, in the simulator's own units:

    | index | action   | range     | meaning |
    |-------|----------|-----------|---------|
    | 0     | throttle | -1 .. 1   | drive torque (negative reverses) |
    | 1     | brake    | 0 .. 10   | 1 brakes at 2.5 m/s^2 |
    | 2     | steer    | -15 .. 15 | steering angle, degrees, positive = left |
    | 3     | pickup   | 0 .. 1    | >= 0.5 sends the simulator's `pickup` command instead of driving |

    A pickup with no sample in reach freezes the real simulator for good.  With
    `pickup_guard=True` (default) the env forwards a pickup only while telemetry
    says `near_sample` and the arm is idle, otherwise it drives with the other
    three values; with `pickup_guard=False` it is forwarded and the episode
    terminates (the rover would never move again).

    ## Observation Space

    `Dict`:
    * `"image"`: `Box(0, 255, (160, 320, 3), uint8)`, the RGB camera frame exactly
      as a client receives it (the twin's render after the simulator's JPEG, q 75).
    * `"telemetry"`: `Box((13,), float64)`, the simulator's telemetry values with
      its rounding (4 decimals): speed (m/s, negative in reverse), x, y (m),
      yaw (deg 0..360, CCW from east), pitch, roll (deg, signed, pitch + = nose
      down), steer, throttle, brake (last command), near_sample, picking_up (0/1),
      samples_remaining, sim_time (s, when the frame was captured; the real
      simulator sends no clock, a client has its own).  Order in `TELEMETRY_FIELDS`.

    The real simulator also sends the remaining samples' positions; the env
    leaves them out (a policy that reads them would not need to find samples).

    ## Rewards

    * Mapping: `100 / N` for every truth-navigable cell (N cells in the world's
      `nav_truth`) whose floor the camera sees for the first time within 9 m
      (`rover_gym.coverage`): a full map is worth 100.  The agent outputs no map,
      so the env judges from the renderer's ray hits, not from any perception
      code, which cells a mapper *could* have mapped correctly from this drive;
      `info["seen_truth_pct"]` is that running percentage.
    * +10 per sample collected (when the arm finishes, 10 s after `pickup`).
    * +50 for stopping (|v| < 0.1 m/s) within 3 m of the start with every sample
      collected.

    ## Starting State

    The world's start position (the simulator's (99.7, 85.6) on the real world)
    with a yaw drawn uniformly from 0..360 and 6 of the world's candidate sample
    spots, both from the scene seed: `reset(seed=S)` gives scene S (identical
    to `python -m sim.mission --seed S`), `reset()` draws a scene seed from the
    env's RNG (the first `reset()` uses the `seed` argument of the constructor
    when given).

    ## Episode End

    * Terminated: home with every sample collected (above), or a blind pickup
      froze the rover (`pickup_guard=False` only).
    * Truncated: `max_episode_s` of simulated time (default 900 s).

    `info["end_reason"]` says which.

    ## Arguments

    `gymnasium.make("RoverTwin-v0", world="default", seed=None, timing="unity",
    shadows=False, render_mode=None, max_episode_s=900.0, pickup_guard=True,
    fps=None, latency_ms=None, compute_ms=None)`

    * `world`: `"real"` (../shared world), `"procedural:K"`, a navigable-map PNG
      path, `"default"` (real when present) or a `sim.world.World`.
    * `seed`: scene seed of the first `reset()` without a seed.
    * `timing`: `"unity"` (default): the real simulator's loop (sim/timing.py):
      physics runs on while the agent "thinks"; its action reaches the simulator
      `compute_ms + latency_ms` after the frame it answers (2 + 5 ms by default)
      and acts at the next render frame (`fps`, 30 by default), where the next
      observation is captured: one step is one render frame (1/30 s), and the
      rover moves on the action from the next observation on.  `"lockstep"`: the twin's
      easier debugging loop, every step applies the action and advances one
      0.04 s frame (two 0.02 s physics steps) at once.  A `sim.timing.Timing`
      is accepted too; `fps`, `latency_ms`, `compute_ms` override its defaults.
    * `shadows`: terrain cast shadows (the simulator's Simple..Fantastic quality)
      or none (Fastest/Fast, the default, as the held-out real drives show).
    * `render_mode`: `"rgb_array"`: `render()` returns a (320, 640, 3) image: the
      camera frame and a status panel beside a map of the truth (grey), the floor
      seen so far (blue) and the rover's path.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(self, world="default", seed: int | None = None, timing="unity",
                 shadows: bool = False, render_mode: str | None = None, max_episode_s: float = EPISODE_S,
                 pickup_guard: bool = True, seen_range_m: float = SEEN_RANGE_M, fps: float | None = None,
                 latency_ms: float | None = None, compute_ms: float | None = None):
        from sim.timing import TwinLoop
        from sim.twin import RoverTwin

        self.timing = make_timing(timing, fps, latency_ms, compute_ms)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', not {render_mode!r}")
        if not (max_episode_s > 0 and math.isfinite(max_episode_s)):
            raise ValueError(f"max_episode_s must be a positive number of seconds, not {max_episode_s!r}")
        self.world = load_env_world(world, shadows)
        self.render_mode = render_mode
        self.max_episode_s = float(max_episode_s)
        self.pickup_guard = bool(pickup_guard)
        self._first_seed = None if seed is None else int(seed)
        self.twin = RoverTwin(self.world, seed=self._first_seed or 0, render=True)
        self._loop = TwinLoop(self.twin, self.timing)  # sends sim_time in telemetry only under lockstep
        self.coverage = CameraCoverage(self.world.nav_truth, seen_range_m)
        self.action_space = spaces.Box(np.array([-1.0, 0.0, -MAX_STEER_DEG, 0.0], np.float32),
                                       np.array([1.0, MAX_BRAKE, MAX_STEER_DEG, 1.0], np.float32),
                                       dtype=np.float32)
        self.observation_space = spaces.Dict({
            "image": spaces.Box(0, 255, IMAGE_SHAPE, dtype=np.uint8),
            "telemetry": _telemetry_space(),
        })
        self._tel = None
        self._image = None
        self._trail = []
        self.scene_seed = None

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is None and self._first_seed is not None:
            seed = self._first_seed  # the constructor's seed stands in for the first reset's
        self._first_seed = None
        super().reset(seed=seed)
        scene = int(seed) if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
        self.scene_seed = scene
        self._tel = self._loop.reset(scene)
        self._image = _decode_jpeg(self.twin.last_jpeg)
        self.coverage.reset()
        self._see()  # the first view is free: reward only what the agent's driving reveals
        self._collected = 0
        self._return = 0.0
        self._trail = [(self.twin.truth.x, self.twin.truth.y)]
        return self._obs(), self._info("")

    def step(self, action):
        if self._tel is None:
            raise RuntimeError("call reset() before step()")
        event, payload = self._command(action)
        self._tel, _ = self._loop.step(event, payload)  # our commands always parse: no CommandError
        self._image = _decode_jpeg(self.twin.last_jpeg)
        truth = self.twin.truth
        self._trail.append((truth.x, truth.y))

        reward = MAP_REWARD_TOTAL * self._see() / max(1, self.coverage.truth_cells)
        collected = len(truth.collected)
        reward += SAMPLE_REWARD * (collected - self._collected)
        self._collected = collected

        terminated, reason = False, ""
        if self._home(truth):
            reward += HOME_REWARD
            terminated, reason = True, "home with every sample"
        elif truth.pickup_stuck:
            terminated, reason = True, "pickup with no sample in reach froze the rover"
        truncated = not terminated and truth.sim_time >= self.max_episode_s - 1e-9
        if truncated:
            reason = "time limit"
        self._return += reward
        return self._obs(), float(reward), terminated, truncated, self._info(reason)

    def render(self):
        if self.render_mode != "rgb_array" or self._image is None:
            return None
        truth = self.twin.truth
        lines = (f"{self.world.name}  scene {self.scene_seed}  t = {truth.sim_time:.1f} s  {self.timing.model}",
                 f"floor seen: {self.coverage.seen_truth_pct:.1f} % of the truth map",
                 f"samples collected: {len(truth.collected)} / {len(truth.initial_samples)}",
                 f"speed {truth.v:.2f} m/s  episode reward {self._return:.1f}")
        return render_panel(self._image, self.world.nav_truth, self.coverage.seen_map(), self._trail, lines)

    def close(self):
        self._tel = None

    # ------------------------------------------------------------------ helpers
    def _command(self, action):
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (4,):
            raise ValueError(f"action must have 4 values (throttle, brake, steer, pickup), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a.tolist()}")
        low, high = self.action_space.low.astype(np.float64), self.action_space.high.astype(np.float64)
        throttle, brake, steer, pickup = np.clip(a, low, high)
        if pickup >= PICKUP_THRESHOLD:
            if not self.pickup_guard or (self._tel["near_sample"] == "1" and self._tel["picking_up"] == "0"):
                return "pickup", {}
        return "data", {"throttle": f"{throttle:.4f}", "brake": f"{brake:.4f}", "steering_angle": f"{steer:.4f}"}

    def _see(self) -> int:
        r = self.twin.renderer()
        origin, rot = r.camera(self.twin.pose())  # the camera of the frame just rendered
        return self.coverage.update(r.last_depth, origin, rot)

    def _home(self, truth) -> bool:
        n = len(truth.initial_samples)
        return (n > 0 and len(truth.collected) == n and abs(truth.v) < HOME_STILL_SPEED
                and math.hypot(truth.x - truth.start_xy[0], truth.y - truth.start_xy[1]) <= HOME_RADIUS_M)

    def _obs(self):
        return {"image": self._image, "telemetry": telemetry_vector(self._tel, self._loop.captured_at)}

    def _info(self, end_reason: str) -> dict:
        truth = self.twin.truth
        return {"scene_seed": self.scene_seed, "sim_time": truth.sim_time, "collected": len(truth.collected),
                "samples": len(truth.initial_samples), "seen_truth_cells": self.coverage.seen_truth_cells,
                "seen_truth_pct": self.coverage.seen_truth_pct, "true_pose": (truth.x, truth.y, truth.yaw),
                "end_reason": end_reason}

    @property
    def client_clock(self):
        """What a client's wall clock reads when it gets the last observation (unity: capture + half the
        round trip; lockstep: the capture time), for policies that want one (`AutonomyPolicy.for_env`)."""
        return self._loop.clock

    @property
    def telemetry(self) -> dict:
        """The simulator-format telemetry of the last step (strings, base64 JPEG)."""
        return self._tel


def make_timing(timing="unity", fps=None, latency_ms=None, compute_ms=None):
    """A sim.timing.Timing from a model name (or a Timing) and optional parameter overrides."""
    from dataclasses import replace

    from sim.timing import TIMING_MODELS, Timing

    if not isinstance(timing, Timing):
        if timing not in TIMING_MODELS:
            raise ValueError(f"timing must be one of {TIMING_MODELS} or a sim.timing.Timing, not {timing!r}")
        timing = Timing(model=timing)
    overrides = {k: float(v) for k, v in (("fps", fps), ("latency_ms", latency_ms), ("compute_ms", compute_ms))
                 if v is not None}
    return replace(timing, **overrides) if overrides else timing


def render_panel(image, nav_truth, seen, trail, lines=()) -> np.ndarray:
    """(320, 640) RGB: camera frame over a text panel | map, north up: truth grey, seen truth floor blue,
    seen floor outside the truth dark blue, path yellow, rover white."""
    import cv2

    truth = np.asarray(nav_truth) > 0
    m = np.zeros((200, 200, 3), np.uint8)
    m[truth] = (90, 90, 90)
    m[seen & ~truth] = (20, 40, 120)
    m[seen & truth] = (60, 130, 255)
    scale = RENDER_MAP_PX / 200.0
    big = cv2.resize(np.ascontiguousarray(m[::-1]), (RENDER_MAP_PX, RENDER_MAP_PX), interpolation=cv2.INTER_NEAREST)
    if len(trail) > 1:
        pts = np.array([(x * scale, (200 - y) * scale) for x, y in trail], np.float64)
        pts = np.round(pts).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(big, [pts], False, (255, 220, 0), 1, cv2.LINE_AA)
    if trail:
        x, y = trail[-1]
        cv2.circle(big, (int(round(x * scale)), int(round((200 - y) * scale))), 3, (255, 255, 255), -1)
    text = np.zeros((RENDER_MAP_PX - image.shape[0], image.shape[1], 3), np.uint8)
    for i, line in enumerate(lines):
        cv2.putText(text, str(line), (8, 22 + 22 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (230, 230, 230), 1,
                    cv2.LINE_AA)
    return np.ascontiguousarray(np.hstack([np.vstack([image, text]), big]))
