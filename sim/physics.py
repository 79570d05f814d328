"""Rover dynamics at the simulator's 0.02 s physics step, fitted to real logs.

The Unity rover is a rigidbody on four WheelColliders; reproducing that solver is
neither possible nor needed.  What the client sees is speed, yaw, position and a
little pitch/roll, so this module uses a point-mass longitudinal model and a
kinematic bicycle for heading, with every constant fitted to the real recordings
(test_dataset and real-logs/megalphian):

* throttle 1 from rest ~0.8 m/s^2, ~0.5 near 4.5 m/s; coasting -(0.03 + 0.052 v);
  brake 1 ~ -2.5 m/s^2; gravity along the slope (the real rover cannot climb
  more than ~5 deg from rest either);
* hard caps of 5 m/s forward and 2 m/s reverse (RoverController.cs);
* front-wheel angle (cmd/15)*lerp(5, 15, 1-|v|/5) deg, doubled while the
  throttle is negative (coasting backwards at throttle 0 is not doubled in the
  megalphian log), times a 0.93 slip factor fitted to real full-lock turns; turn in place at 45 deg/s * cmd/15 when steering with no
  throttle, no brake and |v| < 0.316 m/s;
* pitch/roll = terrain attitude under the wheels + a damped spring driven by the
  longitudinal and lateral acceleration (~1.2 deg accelerating, ~1.4 deg in a
  full-lock turn at 5 m/s);
* collisions against a precomputed 0.1 m raster of rock slabs in the body's
  height band and of too-steep terrain: the leading bumper points stop the rover
  (speed 0), so it can get stuck but can always reverse or turn out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PHYSICS_DT = 0.02  # s, Unity fixed timestep
GRAVITY = 9.81  # m/s^2

# --- longitudinal dynamics (fitted to test_dataset + megalphian logs) ---------
DRIVE_ACCEL = 0.90  # m/s^2 per unit throttle at rest
DRIVE_FADE = 0.02  # m/s^2 per (m/s) per unit throttle: drive weakens with speed
DRAG_CONST = 0.03  # m/s^2, rolling resistance always opposing motion
DRAG_LINEAR = 0.052  # m/s^2 per m/s, speed-proportional resistance
BRAKE_DECEL = 2.5  # m/s^2 per unit brake (brake is not clamped, as in the sim)
MAX_FORWARD_SPEED = 5.0  # m/s, hard clamp (RoverController.moveSpeed)
MAX_REVERSE_SPEED = 2.0  # m/s, hard clamp (maxReverseSpeed)
INPUT_LIMIT = 1000.0  # |throttle|, |brake| beyond this change nothing (speed is capped) and would overflow

# --- steering -------------------------------------------------------------------
MAX_STEER_DEG = 15.0  # deg, command clamp
WHEEL_LOCK_SLOW_DEG = 15.0  # deg, front-wheel lock at standstill
WHEEL_LOCK_FAST_DEG = 5.0  # deg, front-wheel lock at MAX_FORWARD_SPEED
REVERSE_STEER_GAIN = 2.0  # wheel angle multiplier while the throttle command is negative
WHEELBASE_M = 0.722  # m, kinematic bicycle length
YAW_SLIP_FACTOR = 0.93  # achieved / kinematic yaw rate at full lock (tyre slip; megalphian 0.3-5 m/s, test_dataset)
TURN_IN_PLACE_RATE = 45.0  # deg/s at full lock when turning in place
TURN_IN_PLACE_MAX_SPEED = 0.316  # m/s, turning in place only below this (sqrMagnitude < 0.1)

# --- attitude (pitch / roll) ------------------------------------------------------
PITCH_PER_ACCEL = 1.55  # deg of nose-down pitch per m/s^2 of forward acceleration
ROLL_PER_LATERAL = 0.45  # deg of roll per m/s^2 of lateral (v * yaw rate) acceleration
ATTITUDE_OMEGA = 8.0  # rad/s, natural frequency of the body-attitude spring
ATTITUDE_DAMPING = 0.6  # damping ratio of the body-attitude spring
MAX_DYNAMIC_PITCH = 5.0  # deg, clamp of the motion-induced pitch
MAX_DYNAMIC_ROLL = 6.0  # deg, clamp of the motion-induced roll
PITCH_PROBE_M = 0.40  # m, half distance of the front/rear terrain probes
ROLL_PROBE_M = 0.40  # m, half distance of the left/right terrain probes
TURN_PITCH_FADE_DEG_S = 25.0  # deg/s of yaw rate at which acceleration pitch has faded out (log: ~0 in hard turns)
ATTITUDE_ACCEL_CLAMP = 3.0  # m/s^2, accelerations beyond this (impacts) do not tilt further

# --- collision ------------------------------------------------------------------------
COLLISION_CELL_M = 0.1  # m, raster cell (same grid as the rock envelopes)
BODY_BOTTOM_M = 0.06  # m above ground, lowest part of the body that can hit a rock
BODY_TOP_M = 0.60  # m above ground, highest part of the body
MAX_SLOPE_DEG = 40.0  # deg, terrain steeper than this is a wall
BUMPER_FRONT_M = 0.55  # m ahead of the rover origin
BUMPER_REAR_M = 0.50  # m behind the rover origin
BUMPER_HALF_WIDTH_M = 0.42  # m, half body width
HEIGHT_ROWS_PER_CHUNK = 250  # rows of the 0.1 m grid evaluated per height_at call


@dataclass
class Controls:
    """The last command, re-applied every physics step (sticky, as in the sim)."""

    throttle: float = 0.0
    brake: float = 0.0
    steer: float = 0.0  # deg, positive = left (clamped on use)


@dataclass
class BodyState:
    x: float
    y: float
    yaw: float  # deg CCW from +x, [0, 360)
    v: float = 0.0  # m/s along the heading, negative = reverse
    reversing: bool = False  # throttle command is negative (doubles the wheel angle)
    pitch_dyn: float = 0.0  # deg, motion part of pitch (positive = nose down)
    pitch_rate: float = 0.0
    roll_dyn: float = 0.0  # deg, motion part of roll (positive = right side up)
    roll_rate: float = 0.0
    pitch_terrain: float = 0.0  # deg, from the ground under the wheels
    roll_terrain: float = 0.0
    yaw_rate: float = 0.0  # deg/s, last step
    accel: float = 0.0  # m/s^2, last step
    collided: bool = False  # last step hit something
    fixed_turn_left: float = 0.0  # deg still to turn in a fixed_turn (signed, + = CCW)
    fixed_turn_rate: float = 0.0  # deg/s of the running fixed_turn (signed)

    @property
    def pitch(self) -> float:
        return self.pitch_terrain + self.pitch_dyn

    @property
    def roll(self) -> float:
        return self.roll_terrain + self.roll_dyn


# ------------------------------------------------------------------ collision raster
def _bumper_points():
    """Rover-frame (forward, left) points, grouped as front / rear / sides."""
    w = BUMPER_HALF_WIDTH_M
    front = [(BUMPER_FRONT_M, -w), (BUMPER_FRONT_M, 0.0), (BUMPER_FRONT_M, w),
             (BUMPER_FRONT_M, -w / 2), (BUMPER_FRONT_M, w / 2)]
    rear = [(-BUMPER_REAR_M, -w), (-BUMPER_REAR_M, 0.0), (-BUMPER_REAR_M, w)]
    sides = [(0.25, -w), (0.25, w), (-0.2, -w), (-0.2, w)]
    pts = np.array(front + rear + sides, dtype=np.float64)
    front_mask = np.zeros(len(pts), bool)
    front_mask[: len(front)] = True
    front_mask[len(front) + len(rear):][[0, 1]] = True  # forward side points lead too
    rear_mask = np.zeros(len(pts), bool)
    rear_mask[len(front): len(front) + len(rear)] = True
    rear_mask[len(front) + len(rear):][[2, 3]] = True
    return pts, front_mask, rear_mask


BUMPER_POINTS, FRONT_MASK, REAR_MASK = _bumper_points()


def build_blocked_raster(world) -> np.ndarray:
    """Bool raster on the 0.1 m vertex grid, True where the rover body cannot be.

    Blocked: a rock slab overlapping [ground + BODY_BOTTOM_M, ground + BODY_TOP_M],
    terrain steeper than MAX_SLOPE_DEG, or the world border.
    """
    n = int(round(world.size_m / COLLISION_CELL_M)) + 1
    coords = np.arange(n) * COLLISION_CELL_M
    ground = np.empty((n, n), np.float32)
    for r0 in range(0, n, HEIGHT_ROWS_PER_CHUNK):
        ys = coords[r0:r0 + HEIGHT_ROWS_PER_CHUNK]
        gx, gy = np.meshgrid(coords, ys)
        ground[r0:r0 + len(ys)] = world.height_at(gx, gy)
    top = np.asarray(world.rock_top, np.float32)
    bottom = np.asarray(world.rock_bottom, np.float32)
    if top.shape != (n, n):  # a world on another grid: sample it at our vertices
        import cv2

        top = cv2.resize(top, (n, n), interpolation=cv2.INTER_NEAREST)
        bottom = cv2.resize(bottom, (n, n), interpolation=cv2.INTER_NEAREST)
    rock = (top > 0) & (bottom <= ground + BODY_TOP_M) & (top >= ground + BODY_BOTTOM_M)
    gy_, gx_ = np.gradient(ground.astype(np.float64), COLLISION_CELL_M)
    steep = np.hypot(gx_, gy_) > math.tan(math.radians(MAX_SLOPE_DEG))
    blocked = rock | steep
    blocked[0, :] = blocked[-1, :] = blocked[:, 0] = blocked[:, -1] = True
    return blocked


def blocked_raster_for(world) -> np.ndarray:
    """The world's collision raster, built once per World object and cached on it."""
    cached = getattr(world, "_twin_blocked_raster", None)
    if cached is None:
        cached = build_blocked_raster(world)
        try:
            setattr(world, "_twin_blocked_raster", cached)
        except AttributeError:  # a frozen/slotted world: just do not cache
            pass
    return cached


# ------------------------------------------------------------------ helpers
def clamp_steer(cmd: float) -> float:
    return float(min(MAX_STEER_DEG, max(-MAX_STEER_DEG, cmd)))


def front_wheel_angle_deg(steer_cmd: float, speed: float, reversing: bool) -> float:
    """Speed-dependent steering lock of RoverController: full lock 15 deg at rest, 5 at 5 m/s."""
    t = min(1.0, max(0.0, 1.0 - abs(speed) / MAX_FORWARD_SPEED))
    lock = WHEEL_LOCK_FAST_DEG + (WHEEL_LOCK_SLOW_DEG - WHEEL_LOCK_FAST_DEG) * t
    angle = clamp_steer(steer_cmd) / MAX_STEER_DEG * lock
    return angle * REVERSE_STEER_GAIN if reversing else angle


def yaw_rate_deg(steer_cmd: float, speed: float, throttle: float, brake: float,
                 reversing: bool) -> float:
    """Yaw rate (deg/s, + = CCW) from the turn-in-place rule or the kinematic bicycle."""
    steer = clamp_steer(steer_cmd)
    if steer != 0.0 and throttle == 0.0 and brake == 0.0 and abs(speed) < TURN_IN_PLACE_MAX_SPEED:
        return TURN_IN_PLACE_RATE * steer / MAX_STEER_DEG
    delta = math.radians(front_wheel_angle_deg(steer, speed, reversing))
    return YAW_SLIP_FACTOR * math.degrees(speed / WHEELBASE_M * math.tan(delta))


def longitudinal_step(v: float, throttle: float, brake: float, slope_sin: float, dt: float) -> float:
    """New speed: drive and gravity push, drag and brake only ever bring v toward 0."""
    push = throttle * (DRIVE_ACCEL - DRIVE_FADE * abs(v)) + GRAVITY * slope_sin
    v_new = v + push * dt
    resist = (DRAG_CONST + DRAG_LINEAR * abs(v_new) + BRAKE_DECEL * max(0.0, brake)) * dt
    if abs(v_new) <= resist:
        v_new = 0.0
    else:
        v_new -= math.copysign(resist, v_new)
    return min(MAX_FORWARD_SPEED, max(-MAX_REVERSE_SPEED, v_new))


# ------------------------------------------------------------------ the body
class RoverPhysics:
    """One rover body in one World; `step` advances PHYSICS_DT seconds."""

    def __init__(self, world, x: float, y: float, yaw: float):
        self.world = world
        self.blocked = blocked_raster_for(world)
        self._n = self.blocked.shape[0] - 1
        self.state = BodyState(float(x), float(y), float(yaw) % 360.0)
        self._update_terrain_attitude()

    # -- queries ----------------------------------------------------------------
    def _points_world(self, x, y, yaw_deg):
        c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
        px = x + BUMPER_POINTS[:, 0] * c - BUMPER_POINTS[:, 1] * s
        py = y + BUMPER_POINTS[:, 0] * s + BUMPER_POINTS[:, 1] * c
        return px, py

    def blocked_points(self, x, y, yaw_deg) -> np.ndarray:
        """Bool per bumper point: inside a blocked raster cell."""
        px, py = self._points_world(x, y, yaw_deg)
        c = np.clip(np.rint(px / COLLISION_CELL_M).astype(np.int64), 0, self._n)
        r = np.clip(np.rint(py / COLLISION_CELL_M).astype(np.int64), 0, self._n)
        return self.blocked[r, c]

    def _update_terrain_attitude(self):
        s = self.state
        c, sn = math.cos(math.radians(s.yaw)), math.sin(math.radians(s.yaw))
        px = np.array([s.x + PITCH_PROBE_M * c, s.x - PITCH_PROBE_M * c,
                       s.x - ROLL_PROBE_M * sn, s.x + ROLL_PROBE_M * sn])
        py = np.array([s.y + PITCH_PROBE_M * sn, s.y - PITCH_PROBE_M * sn,
                       s.y + ROLL_PROBE_M * c, s.y - ROLL_PROBE_M * c])
        h = self.world.height_at(px, py)
        front, rear, left, right = (float(v) for v in h)
        s.pitch_terrain = math.degrees(math.atan2(rear - front, 2 * PITCH_PROBE_M))  # nose down +
        s.roll_terrain = math.degrees(math.atan2(right - left, 2 * ROLL_PROBE_M))  # right side up +

    # -- commands ---------------------------------------------------------------
    def start_fixed_turn(self, angle_deg: float, duration_s: float) -> bool:
        """Kinematic turn in place; positive angle = clockwise (yaw decreases)."""
        s = self.state
        if s.fixed_turn_left != 0.0 or abs(s.v) >= 0.01 or not math.isfinite(angle_deg):
            return False
        if angle_deg == 0.0:
            return True
        if not (math.isfinite(duration_s) and duration_s > 0):
            duration_s = abs(angle_deg) / TURN_IN_PLACE_RATE
        s.fixed_turn_left = -float(angle_deg)
        s.fixed_turn_rate = -float(angle_deg) / duration_s
        return True

    def freeze(self):
        """Made kinematic (pickup): stops instantly."""
        self.state.v = 0.0
        self.state.accel = 0.0

    # -- integration ----------------------------------------------------------------
    def step(self, controls: Controls, frozen: bool = False, dt: float = PHYSICS_DT):
        s = self.state
        s.collided = False
        throttle = max(-INPUT_LIMIT, min(INPUT_LIMIT, float(controls.throttle)))
        brake = max(-INPUT_LIMIT, min(INPUT_LIMIT, float(controls.brake)))
        steer = clamp_steer(float(controls.steer))
        v0 = s.v
        if frozen:
            s.v, rate = 0.0, 0.0
        elif s.fixed_turn_left != 0.0:
            s.v = 0.0
            turn = s.fixed_turn_rate * dt
            if abs(turn) >= abs(s.fixed_turn_left):
                turn = s.fixed_turn_left
            rate = turn / dt
            s.fixed_turn_left -= turn
            if abs(s.fixed_turn_left) < 1e-9:
                s.fixed_turn_left = 0.0
        else:
            s.reversing = throttle < 0  # megalphian: coasting backwards (throttle 0) is not doubled
            slope_sin = math.sin(math.radians(s.pitch_terrain))
            s.v = longitudinal_step(s.v, throttle, brake, slope_sin, dt)
            rate = yaw_rate_deg(steer, s.v, throttle, brake, s.reversing)
        new_yaw = (s.yaw + rate * dt) % 360.0
        mid = math.radians(s.yaw + 0.5 * rate * dt)
        nx = s.x + s.v * math.cos(mid) * dt
        ny = s.y + s.v * math.sin(mid) * dt
        if s.v != 0.0:
            lead = FRONT_MASK if s.v > 0 else REAR_MASK
            if self.blocked_points(nx, ny, new_yaw)[lead].any():
                s.collided = True
                s.v = 0.0
                nx, ny = s.x, s.y
        if new_yaw != s.yaw:
            before = int(self.blocked_points(s.x, s.y, s.yaw).sum())
            if int(self.blocked_points(nx, ny, new_yaw).sum()) > before:
                s.collided = True
                new_yaw, rate = s.yaw, 0.0
                s.fixed_turn_left = 0.0
        s.x, s.y, s.yaw = nx, ny, new_yaw
        s.yaw_rate = rate
        s.accel = (s.v - v0) / dt
        self._update_terrain_attitude()
        self._attitude_step(dt)

    def _attitude_step(self, dt: float):
        s = self.state
        a_long = max(-ATTITUDE_ACCEL_CLAMP, min(ATTITUDE_ACCEL_CLAMP, s.accel))
        a_lat = s.v * math.radians(s.yaw_rate)
        a_lat = max(-2 * ATTITUDE_ACCEL_CLAMP, min(2 * ATTITUDE_ACCEL_CLAMP, a_lat))
        w2, c = ATTITUDE_OMEGA ** 2, 2 * ATTITUDE_DAMPING * ATTITUDE_OMEGA
        fade = max(0.0, 1.0 - abs(s.yaw_rate) / TURN_PITCH_FADE_DEG_S)
        target_p = PITCH_PER_ACCEL * a_long * fade
        target_r = ROLL_PER_LATERAL * a_lat
        s.pitch_rate += (w2 * (target_p - s.pitch_dyn) - c * s.pitch_rate) * dt
        s.pitch_dyn += s.pitch_rate * dt
        s.roll_rate += (w2 * (target_r - s.roll_dyn) - c * s.roll_rate) * dt
        s.roll_dyn += s.roll_rate * dt
        s.pitch_dyn = max(-MAX_DYNAMIC_PITCH, min(MAX_DYNAMIC_PITCH, s.pitch_dyn))
        s.roll_dyn = max(-MAX_DYNAMIC_ROLL, min(MAX_DYNAMIC_ROLL, s.roll_dyn))
