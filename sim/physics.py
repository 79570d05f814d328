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
* contact as the real rigid body has it (sim/contact.py holds the geometry): four
  ray-cast wheels stand on the floor plane, terrain or a rock top their ray reaches,
  and set pitch and roll; the body collides only through its plates and axle rods,
  against the rocks' collider shapes and the terrain.  A rock contact is resolved along
  the collider's own normal: where it is within SUPPORT_MAX_TILT_DEG of vertical (a low
  rock top under a plate) the body is carried (lifted and pitched about its far axle);
  otherwise it is a wall: the body is pushed out sideways (turning in place is never
  refused, backing away from a face is never opposed), the approach speed is removed
  with a little rebound, and a hard hit kicks the nose up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from sim import contact as C
from sim import scene

PHYSICS_DT = 0.02  # s, Unity fixed timestep
FAST_CONTACTS = True  # open-ground contact tests and wheel heights through compiled calls (False: NumPy only)
GRAVITY = 9.81  # m/s^2

# --- longitudinal dynamics (fitted to test_dataset + megalphian logs) ---------
DRIVE_ACCEL = 0.90  # m/s^2 per unit throttle at rest
DRIVE_FADE = 0.02  # m/s^2 per (m/s) per unit throttle: drive weakens with speed
DRAG_CONST = 0.03  # m/s^2, rolling resistance always opposing motion
DRAG_LINEAR = 0.052  # m/s^2 per m/s, speed-proportional resistance
BRAKE_DECEL = 2.5  # m/s^2 per unit brake (brake is not clamped, as in the sim)
MAX_FORWARD_SPEED = 5.0  # m/s, hard clamp (RoverController.moveSpeed)
MAX_REVERSE_SPEED = 2.0  # m/s, hard clamp (maxReverseSpeed)
STATIC_HOLD_ACCEL = 1.0  # m/s^2, a standing rover with no throttle does not start rolling on slopes gentler than
# this along its heading (~6 deg; megalphian stands still at 3-3.6 deg of pitch for seconds)
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
TURN_PITCH_FADE_DEG_S = 25.0  # deg/s of yaw rate at which acceleration pitch has faded out (log: ~0 in hard turns)
ATTITUDE_ACCEL_CLAMP = 3.0  # m/s^2, accelerations beyond this (impacts) do not tilt further

# --- contact response (geometry in sim/contact.py) -----------------------------------------
RESTITUTION = 0.3  # share of the approach speed returned on a hard hit (real rebounds -0.2..-1.8 m/s)
REBOUND_MIN_SPEED = 0.5  # m/s, slower approaches just stop against the face
IMPACT_PITCH_GAIN = 80.0  # deg/s of pitch rate per m/s of approach speed (nose up on a frontal hit)
IMPACT_OMEGA = 7.0  # rad/s, natural frequency of the impact pitch transient
IMPACT_DAMPING = 0.5  # damping ratio of the impact pitch transient
MAX_IMPACT_PITCH = 40.0  # deg, clamp of the impact pitch (real hits: 16-36 deg)
CONTACT_ITERATIONS = 4  # push-out passes per physics step
CONTACT_SLOP_M = 0.001  # m pushed beyond the measured overlap
MAX_PUSH_M = 0.3  # m, largest push-out in one pass
TERRAIN_SLOPE_PROBE_M = 0.1  # m, half distance of the terrain-gradient probe at a contact
SIDE_GRIP = 1.0  # tan of the steepest roll the tyres hold without sliding sideways (sideways friction
# asymptote 1.0; a real rover drove 27 m at up to 38 deg of roll)
MIN_WALL_TAN = 0.25  # terrain contacts on gentler slopes push out at most overlap / this
SUPPORT_MAX_TILT_DEG = 70.0  # deg from vertical: rock contact normals steeper than this carry the body (lift,
# pitch), flatter ones are walls that push it sideways (the real rover rode up a 0.40 m sphere met at ~63 deg)
SUPPORT_MIN_NZ = math.cos(math.radians(SUPPORT_MAX_TILT_DEG))  # vertical share of the steepest carrying normal
SUPPORT_IMPULSE_SHARE = 0.5  # share of the speed along the contact normal removed when the body meets a rock top
# (1 = inelastic point contact; 0.5 fitted on the one megalphian rock ride, rows 2736-2766)
LIFT_PASSES = 3  # lift passes per push-out pass (a lift can bring another body point onto rock)
MAX_LIFT_M = 0.3  # m, largest raise of an axle in one lift pass


@njit(cache=True, nogil=True)
def _wheel_ground(x, y, c, s, wheel_f, wheel_l, grid, size_m, cell_m, floor_m):
    """`_ground_at(*_to_world(...))` for the four wheels in one compiled call: the same operations in the same
    order (x + f c - l s, y + f s + l c, the world's compiled bilinear, NumPy's NaN-keeping maximum)."""
    n = wheel_f.size
    xs = np.empty(n)
    ys = np.empty(n)
    for i in range(n):
        xs[i] = x + wheel_f[i] * c - wheel_l[i] * s
        ys[i] = y + wheel_f[i] * s + wheel_l[i] * c
    h = np.empty(n)
    scene._clamped_bilinear(grid, xs, ys, size_m, cell_m, h)
    for i in range(n):
        if not (h[i] != h[i] or h[i] >= floor_m):
            h[i] = floor_m
    return h


@njit(cache=True, nogil=True)
def _terrain_touches(x, y, c, s, bp, z0, a, b, grid, size_m, cell_m):
    """True when the terrain rises above the bottom of any body point at this pose (contacts' first test, with
    the same arithmetic: point = pose + rotated offset, plane = z0 + a f + b l, bottom = plane + offset)."""
    n = bp.shape[0]
    xs = np.empty(n)
    ys = np.empty(n)
    for i in range(n):
        xs[i] = x + bp[i, 0] * c - bp[i, 1] * s
        ys[i] = y + bp[i, 0] * s + bp[i, 1] * c
    t = np.empty(n)
    scene._clamped_bilinear(grid, xs, ys, size_m, cell_m, t)
    for i in range(n):
        bottom = (z0 + a * bp[i, 0] + b * bp[i, 1]) + bp[i, 2]
        if t[i] - bottom > 0:
            return True
    return False


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
    fixed_turning: bool = False  # a fixed_turn is running (the body is kinematic)
    fixed_turn_target_u: float = 0.0  # deg, Unity yaw (clockwise) the fixed_turn moves toward, any range
    fixed_turn_speed: float = 0.0  # deg/s, angle / time as sent; negative never reaches the target
    pitch_impact: float = 0.0  # deg, transient pitch from hitting something (negative = nose up)
    pitch_impact_rate: float = 0.0
    impact_speed: float = 0.0  # m/s, approach speed of the last hit (0 when none this step)
    v_side: float = 0.0  # m/s, sideways slide down a slope too steep for the tyres (+ = to the left)

    @property
    def pitch(self) -> float:
        return self.pitch_terrain + self.pitch_dyn + self.pitch_impact

    @property
    def roll(self) -> float:
        return self.roll_terrain + self.roll_dyn


# ------------------------------------------------------------------ helpers
def unity_yaw(yaw_deg: float) -> float:
    """Unity's clockwise yaw in [0, 360) for a telemetry yaw (counter-clockwise from +x)."""
    return (90.0 - yaw_deg) % 360.0


def delta_angle(current: float, target: float) -> float:
    """Shortest signed difference target - current in (-180, 180], as Unity's Mathf.DeltaAngle."""
    d = (target - current) % 360.0
    return d - 360.0 if d > 180.0 else d


def move_towards_angle(current: float, target: float, max_delta: float) -> float:
    """Unity's Mathf.MoveTowardsAngle, including its behaviour for a negative max_delta (moves away)."""
    d = delta_angle(current, target)
    if -max_delta < d < max_delta:
        return target
    goal = current + d
    if abs(goal - current) <= max_delta:
        return goal
    return current + (1.0 if goal - current >= 0.0 else -1.0) * max_delta


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
    if v == 0.0 and throttle == 0.0 and abs(GRAVITY * slope_sin) < STATIC_HOLD_ACCEL:
        return 0.0
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
        self.rocks = C.rock_field_for(world)
        self.state = BodyState(float(x), float(y), float(yaw) % 360.0)
        self._supported = False  # the body rested on a rock top last step
        self._wheel_f = np.array(C.WHEEL_F_M)
        self._wheel_l = np.array(C.WHEEL_L_M)
        self._wheel_h = self._ground_at(*self._to_world(x, y, yaw, self._wheel_f, self._wheel_l))
        self._wheel_h = self._wheel_heights(x, y, yaw)
        self._update_terrain_attitude()

    # -- geometry ---------------------------------------------------------------
    @staticmethod
    def _to_world(x, y, yaw_deg, f, lat):
        c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
        return x + f * c - lat * s, y + f * s + lat * c

    def _ground_at(self, px, py):
        """What a wheel ray always finds: the terrain or the floor plane 1 cm above it."""
        return np.maximum(np.asarray(self.world.height_at(px, py), dtype=np.float64), C.FLOOR_PLANE_M)

    def _compiled_terrain(self) -> bool:
        """The world's heights are the plain bilinear terrain `_clamped_bilinear` computes (World.height_at's own
        compiled path), so the fast paths below may read them directly."""
        w = self.world
        return (type(w).height_at is scene.World.height_at and w.terrain_height.ndim == 2
                and w.terrain_height.shape[0] == w.terrain_height.shape[1])

    def _wheel_heights(self, x, y, yaw_deg) -> np.ndarray:
        """Contact height under each wheel: ground, or a rock top the wheel's ray reaches from where it stood."""
        near = self.rocks.near(x, y, C.BODY_RADIUS_M + 0.1)
        if not near and FAST_CONTACTS and self._compiled_terrain():
            # no rock patch near: the ground under the wheels, in one compiled call (the same arithmetic)
            yaw = math.radians(yaw_deg)
            w = self.world
            return _wheel_ground(float(x), float(y), math.cos(yaw), math.sin(yaw), self._wheel_f, self._wheel_l,
                                 w.terrain_height, float(w.size_m), float(w.terrain_cell_m), C.FLOOR_PLANE_M)
        wx, wy = self._to_world(x, y, yaw_deg, self._wheel_f, self._wheel_l)
        h = self._ground_at(wx, wy)
        if near:
            _, top, _, _, _ = C.RockField.query(near, wx, wy)
            found = (top > h) & (top <= self._wheel_h + C.WHEEL_REACH_M)
            h = np.where(found, top, h)
        return h

    def contacts(self, x, y, yaw_deg, wheel_h=None):
        """Overlaps of the body colliders at a pose that push it sideways: (push distance, unit push x, unit push y)
        per touching point (terrain, and rock whose contact normal is near horizontal)."""
        return self._overlaps(x, y, yaw_deg, wheel_h)[0]

    def _overlaps(self, x, y, yaw_deg, wheel_h=None):
        """(walls, supports) of the body colliders at a pose.

        walls: (push distance, unit push x, unit push y) per point to be pushed out sideways.
        supports: None, or (f, lift, normal x, normal y, normal z) per body point resting on a rock top whose
        contact normal (the collider's own, sim.contact.RockField.contact_normals) is within
        SUPPORT_MAX_TILT_DEG of vertical: the body must rise `lift` metres there.
        """
        if wheel_h is None:
            wheel_h = self._wheel_heights(x, y, yaw_deg)
        bp = C.BODY_POINTS
        z0, a, b = C.wheel_plane(wheel_h)
        near = self.rocks.near(x, y, C.BODY_RADIUS_M + 0.1)
        if FAST_CONTACTS and not near and self._compiled_terrain():
            # open ground (the common step): one compiled test that no body point is under the terrain
            yaw = math.radians(yaw_deg)
            w = self.world
            if not _terrain_touches(float(x), float(y), math.cos(yaw), math.sin(yaw), bp, float(z0), float(a),
                                    float(b), w.terrain_height, float(w.size_m), float(w.terrain_cell_m)):
                empty = np.zeros(0)
                return (empty, empty, empty), None
        px, py = self._to_world(x, y, yaw_deg, bp[:, 0], bp[:, 1])
        plane = z0 + a * bp[:, 0] + b * bp[:, 1]
        bottom, top = plane + bp[:, 2], plane + bp[:, 3]
        depths, dxs, dys = [], [], []
        supports = None
        terrain = np.asarray(self.world.height_at(px, py), dtype=np.float64)
        over = terrain - bottom
        hit = over > 0
        if hit.any():  # terrain rising into a plate or rod: slide off it downhill (terrain friction is 0)
            hx, hy, o = px[hit], py[hit], over[hit]
            d = TERRAIN_SLOPE_PROBE_M
            hs = np.asarray(self.world.height_at(np.concatenate([hx + d, hx - d, hx, hx]),
                                                 np.concatenate([hy, hy, hy + d, hy - d])), dtype=np.float64)
            k = len(hx)
            gx, gy = (hs[:k] - hs[k:2 * k]) / (2 * d), (hs[2 * k:3 * k] - hs[3 * k:]) / (2 * d)
            g = np.hypot(gx, gy)
            ok = g > 1e-6
            depths.append(o[ok] / np.maximum(g[ok], MIN_WALL_TAN))
            dxs.append(-gx[ok] / g[ok])
            dys.append(-gy[ok] / g[ok])
        if near:
            rb, rt, rd, ex, ey = C.RockField.query(near, px, py)
            touch = (rt > bottom) & (rb < top)
            if touch.any():
                idx = np.nonzero(touch)[0]
                nx, ny, nz = C.RockField.contact_normals(near, px[idx], py[idx], bottom[idx], rt[idx])
                lift = rt[idx] - bottom[idx]
                rest = (nz >= SUPPORT_MIN_NZ) & (rb[idx] < bottom[idx])  # the rock is under the plate, not over it
                if rest.any():
                    k = idx[rest]
                    supports = (bp[k, 0], lift[rest], nx[rest], ny[rest], nz[rest])
                wall = idx[~rest]
                wall = wall[rd[wall] > 0]
                if wall.size:
                    depths.append(rd[wall])
                    dxs.append(ex[wall])
                    dys.append(ey[wall])
        if not depths:
            empty = np.zeros(0)
            return (empty, empty, empty), supports
        return (np.concatenate(depths), np.concatenate(dxs), np.concatenate(dys)), supports

    @staticmethod
    def _lifted(wheel_h, supports):
        """Wheel contact heights raised so that the plane through them carries the body over its rock supports:
        a support ahead of the middle tilts the body about the rear axle (nose up), one behind it about the
        front axle, as a rigid body on its far wheels would."""
        f, lift = supports[0], supports[1] + CONTACT_SLOP_M
        f_front, f_rear = C.WHEEL_F_M[0], C.WHEEL_F_M[2]
        ahead = f >= 0.5 * (f_front + f_rear)
        raise_front = np.where(ahead, lift * C.WHEELBASE_M / np.maximum(f - f_rear, 1e-3), 0.0)
        raise_rear = np.where(ahead, 0.0, lift * C.WHEELBASE_M / np.maximum(f_front - f, 1e-3))
        df = min(float(raise_front.max()), MAX_LIFT_M)
        dr = min(float(raise_rear.max()), MAX_LIFT_M)
        return wheel_h + np.array([df, df, dr, dr])

    def _settle(self, x, y, yaw_deg, wheel_h):
        """(wheel heights lifted onto the rock supports, walls at that attitude, supports met on the way)."""
        met = None
        for _ in range(LIFT_PASSES):
            walls, supports = self._overlaps(x, y, yaw_deg, wheel_h)
            if supports is None:
                return wheel_h, walls, met
            met = supports if met is None else tuple(np.concatenate([p, q]) for p, q in zip(met, supports))
            wheel_h = self._lifted(wheel_h, supports)
        walls, _ = self._overlaps(x, y, yaw_deg, wheel_h)
        return wheel_h, walls, met

    def _resolve(self, x, y, yaw_deg):
        """Lift the body onto rock tops it rests on, push it out of side overlap (PhysX depenetration along the
        contact normal); returns (x, y, wheel heights, total push x, y, supports met or None)."""
        push_x = push_y = 0.0
        wheel_h = self._wheel_heights(x, y, yaw_deg)
        supports = None
        for _ in range(CONTACT_ITERATIONS):
            wheel_h, (d, ex, ey), met = self._settle(x, y, yaw_deg, wheel_h)
            if met is not None:
                supports = met
            if d.size == 0:
                break
            vx, vy = float(np.sum(d * ex)), float(np.sum(d * ey))
            n = math.hypot(vx, vy)
            if n < 1e-9:  # pushes cancel (wedged): follow the deepest
                i = int(np.argmax(d))
                vx, vy, n = float(ex[i]), float(ey[i]), 1.0
            step = min(float(d.max()) + CONTACT_SLOP_M, MAX_PUSH_M)
            x += step * vx / n
            y += step * vy / n
            push_x += step * vx / n
            push_y += step * vy / n
            wheel_h = self._wheel_heights(x, y, yaw_deg)
        else:
            if supports is not None:  # pushed on every pass: carry the body on its supports where it ended
                wheel_h, _, _ = self._settle(x, y, yaw_deg, wheel_h)
        return x, y, wheel_h, push_x, push_y, supports

    def _update_terrain_attitude(self):
        """Pitch and roll of the plane the wheels stand on."""
        s, h = self.state, self._wheel_h
        front, rear = 0.5 * (h[0] + h[1]), 0.5 * (h[2] + h[3])
        left, right = 0.5 * (h[0] + h[2]), 0.5 * (h[1] + h[3])
        s.pitch_terrain = math.degrees(math.atan2(rear - front, C.WHEELBASE_M))  # nose down +
        s.roll_terrain = math.degrees(math.atan2(right - left, C.TRACK_M))  # right side up +

    # -- commands ---------------------------------------------------------------
    def start_fixed_turn(self, angle_deg: float, duration_s: float = 0.0) -> bool:
        """Kinematic turn in place; positive angle = clockwise (yaw decreases).

        As Unity's FixedTurn: speed = angle / time (time 0: the default angle / 45), so an angle and
        a time of opposite signs give a negative speed that never reaches its target.
        """
        s = self.state
        if s.fixed_turning or abs(s.v) >= 0.01 or not math.isfinite(angle_deg):
            return False
        if not math.isfinite(duration_s):
            return False
        if duration_s == 0.0:
            duration_s = angle_deg / TURN_IN_PLACE_RATE
        if duration_s == 0.0:  # angle 0: Unity divides 0 by 0 and never moves; nothing to do here
            return True
        s.fixed_turning = True
        s.fixed_turn_target_u = unity_yaw(s.yaw) + float(angle_deg)
        s.fixed_turn_speed = float(angle_deg) / duration_s
        return True

    def freeze(self):
        """Made kinematic (pickup): stops instantly."""
        self.state.v = 0.0
        self.state.accel = 0.0

    # -- integration ----------------------------------------------------------------
    def step(self, controls: Controls, frozen: bool = False, dt: float = PHYSICS_DT):
        s = self.state
        s.collided = False
        s.impact_speed = 0.0
        throttle = max(-INPUT_LIMIT, min(INPUT_LIMIT, float(controls.throttle)))
        brake = max(-INPUT_LIMIT, min(INPUT_LIMIT, float(controls.brake)))
        steer = clamp_steer(float(controls.steer))
        v0 = s.v
        if frozen:
            s.v, rate = 0.0, 0.0
        elif s.fixed_turning:
            s.v = 0.0
            now_u = unity_yaw(s.yaw)
            new_u = move_towards_angle(now_u, s.fixed_turn_target_u, s.fixed_turn_speed * dt)
            if new_u == s.fixed_turn_target_u:
                s.fixed_turning = False
            rate = -delta_angle(now_u, new_u) / dt  # Unity yaw is clockwise, telemetry yaw counter-clockwise
        else:
            s.reversing = throttle < 0  # megalphian: coasting backwards (throttle 0) is not doubled
            slope_sin = math.sin(math.radians(s.pitch_terrain))
            s.v = longitudinal_step(s.v, throttle, brake, slope_sin, dt)
            rate = yaw_rate_deg(steer, s.v, throttle, brake, s.reversing)
        new_yaw = (s.yaw + rate * dt) % 360.0  # yaw is applied to the transform: nothing refuses it
        mid = math.radians(s.yaw + 0.5 * rate * dt)
        self._side_slide(dt, frozen)
        nx = s.x + (s.v * math.cos(mid) - s.v_side * math.sin(mid)) * dt
        ny = s.y + (s.v * math.sin(mid) + s.v_side * math.cos(mid)) * dt
        nx, ny, self._wheel_h, push_x, push_y, supports = self._resolve(nx, ny, new_yaw)
        if push_x or push_y:
            self._respond(push_x, push_y, new_yaw)
        if supports is not None and not self._supported:
            self._respond_support(supports, new_yaw)
        self._supported = supports is not None
        s.x, s.y, s.yaw = nx, ny, new_yaw
        s.yaw_rate = rate
        s.accel = (s.v - v0) / dt
        self._update_terrain_attitude()
        self._attitude_step(dt)

    def _side_slide(self, dt: float, frozen: bool):
        """Sideways slide where the roll exceeds what the tyres' side grip holds; grip stops it otherwise."""
        s = self.state
        roll = math.radians(s.roll_terrain)
        downhill = math.copysign(1.0, roll)  # right side up: the slope falls to the left (+)
        excess = GRAVITY * (math.sin(abs(roll)) - SIDE_GRIP * math.cos(abs(roll)))
        if frozen:
            s.v_side = 0.0
        elif excess > 0.0:
            s.v_side += downhill * excess * dt
        else:
            grip = -excess * dt
            s.v_side = 0.0 if abs(s.v_side) <= grip else s.v_side - math.copysign(grip, s.v_side)

    def _respond(self, push_x: float, push_y: float, yaw_deg: float):
        """Velocity after a contact: the approach part is removed (with a rebound on a hard hit) and the
        nose kicks up on a frontal hit (down when backing into something)."""
        s = self.state
        s.collided = True
        n = math.hypot(push_x, push_y)
        nx, ny = push_x / n, push_y / n
        hx, hy = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
        along = hx * nx + hy * ny  # heading . normal: -1 head-on, +1 backing straight in
        side = -hy * nx + hx * ny  # left . normal
        if s.v_side * side < 0.0:  # sliding into the face: stop the slide
            s.v_side = 0.0
        vn = s.v * along
        if vn >= 0.0:  # already moving away from the face
            return
        impact = -vn
        e = RESTITUTION if impact > REBOUND_MIN_SPEED else 0.0
        s.v -= (1.0 + e) * vn * along  # the wheels' side grip keeps only the heading component
        s.impact_speed = impact
        if impact > REBOUND_MIN_SPEED:
            s.pitch_impact_rate += IMPACT_PITCH_GAIN * impact * along

    def _respond_support(self, supports, yaw_deg: float):
        """Velocity when the body first comes to rest on a rock top: the part of the speed along the contact
        normal is removed (an inelastic contact), i.e. the speed times the squared horizontal share of the
        normal along the heading; a near-vertical normal (a low rock top) costs almost nothing."""
        s = self.state
        hx, hy = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
        along = hx * supports[2] + hy * supports[3]  # heading . normal (horizontal share, signed)
        opposing = s.v * along
        k = int(np.argmin(opposing))
        if opposing[k] >= 0.0:  # moving off the slope
            return
        s.v -= SUPPORT_IMPULSE_SHARE * s.v * along[k] * along[k]
        s.collided = True

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
        w2i, ci = IMPACT_OMEGA ** 2, 2 * IMPACT_DAMPING * IMPACT_OMEGA
        s.pitch_impact_rate += (-w2i * s.pitch_impact - ci * s.pitch_impact_rate) * dt
        s.pitch_impact += s.pitch_impact_rate * dt
        s.pitch_impact = max(-MAX_IMPACT_PITCH, min(MAX_IMPACT_PITCH, s.pitch_impact))
        s.roll_dyn = max(-MAX_DYNAMIC_ROLL, min(MAX_DYNAMIC_ROLL, s.roll_dyn))
