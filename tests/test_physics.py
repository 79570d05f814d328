"""Twin physics against the real simulator's logs and basic invariants."""
import math
import re

import numpy as np
import pytest

import sim.contact as C
import sim.physics as P
from sim.world import World

WALL_X = 120.0  # m, x of the test wall in the flat world


def _flat_world(wall=True, ramp_deg=0.0):
    n = 513
    terrain = np.zeros((n, n), np.float32)
    if ramp_deg:
        xs = np.arange(n) * (200.0 / 512)
        rise = np.clip(xs - 110.0, 0, None) * math.tan(math.radians(ramp_deg))
        terrain[:] = rise[None, :].astype(np.float32)
    top = np.zeros((2001, 2001), np.float32)
    bottom = np.zeros((2001, 2001), np.float32)
    if wall:
        top[:, int(WALL_X / 0.1): int(WALL_X / 0.1) + 10] = 2.0
    return World(terrain_height=terrain, sand_weight=np.ones((512, 512), np.float32),
                 rock_top=top, rock_bottom=bottom, nav_truth=np.full((200, 200), 255, np.uint8),
                 sample_spots=np.array([[101.0, 100.0]]), start_xy=(100.0, 100.0),
                 start_yaw_training=0.0, name="flat-test")


@pytest.fixture(scope="module")
def flat_world():
    return _flat_world()


def _read_log(path):
    rows = [line.strip().split(";") for line in open(path)][1:]
    stamps = []
    for r in rows:
        h, mi, s, ms = map(int, re.search(r"(\d+)_(\d+)_(\d+)_(\d+)\.jpg", r[0]).groups())
        stamps.append(h * 3600 + mi * 60 + s + ms / 1000.0)
    t = np.array(stamps) - stamps[0]
    return t, np.array([[float(v) for v in r[1:]] for r in rows])


def _run(body, controls, seconds):
    for _ in range(int(round(seconds / P.PHYSICS_DT))):
        body.step(controls)


def test_acceleration_from_rest_matches_test_dataset(test_dataset_dir, world_dir):
    from sim.world import load_world

    t, a = _read_log(test_dataset_dir / "robot_log.csv")
    steer, thr, brake, speed = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    body = P.RoverPhysics(load_world("real"), a[0, 4], a[0, 5], a[0, 7])
    sim_t, sim_v, sim_pose = 0.0, [], []
    for i in range(len(t)):
        while sim_t < t[i] - 1e-9:
            j = max(i - 1, 0)
            body.step(P.Controls(thr[j], brake[j], steer[j]))
            sim_t += P.PHYSICS_DT
        sim_v.append(body.state.v)
        sim_pose.append((body.state.x, body.state.y, body.state.yaw))
    sim_v, sim_pose = np.array(sim_v), np.array(sim_pose)
    # open-loop replay of the whole 13 s / 45 m drive from the logged commands
    assert np.sqrt(np.mean((sim_v - speed) ** 2)) < 0.12
    yaw_err = (sim_pose[:, 2] - a[:, 7] + 180) % 360 - 180
    assert np.sqrt(np.mean(yaw_err ** 2)) < 4.0
    assert np.hypot(sim_pose[-1, 0] - a[-1, 4], sim_pose[-1, 1] - a[-1, 5]) < 2.0
    # throttle 1 from rest: ~0.8 m/s^2 between 1.5 s and 3.8 s in the log
    i0, i1 = np.searchsorted(t, 1.5), np.searchsorted(t, 3.77)
    real_acc = (speed[i1] - speed[i0]) / (t[i1] - t[i0])
    sim_acc = (sim_v[i1] - sim_v[i0]) / (t[i1] - t[i0])
    assert real_acc == pytest.approx(0.8, abs=0.1)
    assert sim_acc == pytest.approx(real_acc, rel=0.12)


def test_full_lock_yaw_rate_at_speed_matches_log(test_dataset_dir):
    t, a = _read_log(test_dataset_dir / "robot_log.csv")
    steer, speed, yaw = a[:, 0], a[:, 3], a[:, 7]
    sel = (steer == -15) & (speed > 4.1) & (speed < 4.7)  # one contiguous full-lock stretch
    yaw_unwrapped = np.degrees(np.unwrap(np.radians(yaw[sel])))
    real = float(np.polyfit(t[sel], yaw_unwrapped, 1)[0])  # deg/s, robust to frame jitter
    model = P.yaw_rate_deg(-15, float(np.mean(speed[sel])), 1.0, 0.0, False)
    assert real < -30
    assert model == pytest.approx(real, rel=0.1)


def test_turn_in_place_rate(flat_world, real_logs_dir):
    body = P.RoverPhysics(flat_world, 100.0, 100.0, 0.0)
    _run(body, P.Controls(0.0, 0.0, 15.0), 1.0)
    assert body.state.yaw == pytest.approx(45.0, abs=1.0)
    assert abs(body.state.x - 100.0) < 1e-6
    _run(body, P.Controls(0.0, 0.0, -7.5), 2.0)  # half lock: 22.5 deg/s the other way
    assert body.state.yaw == pytest.approx(0.0, abs=1.5) or body.state.yaw > 358.5
    # the real megalphian drive: turning in place at full lock, logged yaw rate
    t, a = _read_log(real_logs_dir / "megalphian" / "robot_log.csv")
    steer, thr, brake, speed, yaw = a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 7]
    m = (thr[:-1] == 0) & (brake[:-1] == 0) & (np.abs(steer[:-1]) == 15) & (np.abs(speed[:-1]) < 0.3)
    dt = np.diff(t)[m]
    rate = ((np.diff(yaw)[m] + 180) % 360 - 180) / dt * np.sign(steer[:-1][m])
    assert float(np.median(rate)) == pytest.approx(45.0, rel=0.15)


def test_brake_prevents_turn_in_place(flat_world):
    body = P.RoverPhysics(flat_world, 100.0, 100.0, 0.0)
    _run(body, P.Controls(0.0, 0.1, 15.0), 1.0)
    assert body.state.yaw == pytest.approx(0.0, abs=1e-6)


def test_speed_caps(flat_world):
    body = P.RoverPhysics(flat_world, 30.0, 100.0, 0.0)
    _run(body, P.Controls(1.0, 0.0, 0.0), 14.0)
    assert body.state.v == pytest.approx(P.MAX_FORWARD_SPEED)
    body = P.RoverPhysics(flat_world, 100.0, 100.0, 0.0)
    _run(body, P.Controls(-1.0, 0.0, 0.0), 8.0)
    assert body.state.v == pytest.approx(-P.MAX_REVERSE_SPEED)
    assert body.state.x < 100.0


def test_coasting_and_brake(flat_world):
    body = P.RoverPhysics(flat_world, 30.0, 100.0, 0.0)
    body.state.v = 4.9
    _run(body, P.Controls(0.0, 0.0, 0.0), 1.0)
    assert 4.9 - body.state.v == pytest.approx(0.3, abs=0.08)  # log: ~ -0.3 m/s^2
    _run(body, P.Controls(0.0, 1.0, 0.0), 3.0)
    assert body.state.v == 0.0


def test_steering_lock_shrinks_with_speed_and_doubles_in_reverse():
    assert P.front_wheel_angle_deg(15, 0.0, False) == pytest.approx(15.0)
    assert P.front_wheel_angle_deg(15, 5.0, False) == pytest.approx(5.0)
    assert P.front_wheel_angle_deg(-7.5, 2.5, False) == pytest.approx(-5.0)
    assert P.front_wheel_angle_deg(15, -1.0, True) == pytest.approx(2 * 13.0)
    assert P.front_wheel_angle_deg(40, 0.0, False) == pytest.approx(15.0)  # command clamped


def test_drive_into_wall_stops_and_can_reverse_out(flat_world):
    body = P.RoverPhysics(flat_world, 110.0, 100.0, 0.0)
    _run(body, P.Controls(1.0, 0.0, 0.0), 16.0)  # hits at ~4 m/s, bounces, ends pressed against the face
    front, speed = [], []
    for _ in range(100):
        body.step(P.Controls(1.0, 0.0, 0.0))
        front.append(body.state.x + C.FLATBED[1])
        speed.append(abs(body.state.v))
    assert WALL_X - 0.3 < min(front) and max(front) <= WALL_X + 0.05  # the flatbed's front edge at the face
    assert max(speed) < 0.35
    s = body.state
    x_hit = s.x
    _run(body, P.Controls(-1.0, 0.0, 0.0), 2.0)
    assert body.state.x < x_hit - 0.5  # backing away is unopposed
    assert body.state.v < 0


def test_frontal_hit_pitches_up_and_rebounds(flat_world):
    """Real impacts: the nose pitches up 16-36 deg and the rover rebounds at -0.2 to -1.8 m/s."""
    body = P.RoverPhysics(flat_world, WALL_X - 3.0, 100.0, 0.0)
    body.state.v = 4.0
    pitch, speed = [], []
    for _ in range(75):
        body.step(P.Controls(0.0, 0.0, 0.0))
        pitch.append(body.state.pitch)
        speed.append(body.state.v)
    assert -36.0 <= min(pitch) <= -16.0
    assert -1.8 <= min(speed) <= -0.2
    assert abs(body.state.pitch) < 6.0  # a transient that rights itself within 1.5 s


def test_turning_in_place_against_a_wall_is_never_refused(flat_world):
    """Yaw is applied to the transform; overlap is pushed out, so a pressed rover always turns."""
    body = P.RoverPhysics(flat_world, WALL_X - 0.6, 100.0, 30.0)
    hits = 0
    for _ in range(150):  # press the front corner into the wall
        body.step(P.Controls(1.0, 0.0, 0.0))
        hits += body.state.collided
    assert hits > 0
    body.state.v = 0.0
    yaw0 = body.state.yaw
    for steer in (-15.0, 15.0):
        _run(body, P.Controls(0.0, 0.0, steer), 2.0)
        turned = (body.state.yaw - yaw0 + 180) % 360 - 180
        assert abs(turned) == pytest.approx(90.0, abs=2.0)
        yaw0 = body.state.yaw
        assert body.state.x + 0.1 < WALL_X  # pushed out, never through


def _step_world(height_m):
    """Flat floor with a 2 m deep, wide rock slab of the given height from x = 120 m."""
    w = _flat_world(wall=False)
    w.rock_top[:, int(WALL_X / 0.1): int(WALL_X / 0.1) + 20] = height_m
    return w


@pytest.mark.parametrize("height_m, passes", [(0.10, True), (0.13, True), (0.17, False), (0.30, False)])
def test_low_rock_edges_pass_under_the_body(height_m, passes):
    """Steps below the axle rods (0.134 m above the floor plane) ride under the body on the wheels."""
    body = P.RoverPhysics(_step_world(height_m), WALL_X - 3.0, 100.0, 0.0)
    body.state.v = 2.0
    pitches = []
    for _ in range(150):
        body.step(P.Controls(0.5, 0.0, 0.0))
        pitches.append(body.state.pitch)
    if passes:
        assert body.state.x > WALL_X + 2.5  # carried on over it
        assert min(pitches) < -5.0  # the front wheels' rays lifted the nose onto it
    else:
        assert body.state.x < WALL_X  # a plate hit the face


def test_side_slope_of_38_degrees_is_drivable():
    """A real rover drove 27 m along a wall slope at up to 38 deg of roll."""
    n = 513
    ys = np.arange(n) * (200.0 / 512)
    rise = np.clip(ys - 100.0, 0, None) * math.tan(math.radians(38.0))
    w = _flat_world(wall=False)
    w.terrain_height[:] = rise[:, None].astype(np.float32)
    body = P.RoverPhysics(w, 60.0, 103.0, 0.0)  # on the slope, heading along it (uphill to the left)
    body.state.v = 3.0
    rolls, hits = [], 0
    for _ in range(int(8.0 / P.PHYSICS_DT)):
        body.step(P.Controls(1.0, 0.0, 0.0))
        rolls.append(body.state.roll)
        hits += body.state.collided
    assert body.state.x > 60.0 + 27.0
    assert hits == 0
    assert np.median(rolls) == pytest.approx(-38.0, abs=2.0)  # left side up
    assert abs(body.state.y - 103.0) < 1.0  # the tyres hold it on the slope


def test_real_wall_slope_at_36_degrees_of_roll_is_driven_without_contact(real_world):
    """The wall slope at (62-83, 80-95), where a real rover drove 27 m at up to 38 deg of roll."""
    body = P.RoverPhysics(real_world, 73.0, 94.5, 264.0)  # on a ~36 deg slope, heading along it
    body.state.v = 2.0
    rolls, hits = [], 0
    for _ in range(100):
        body.step(P.Controls(1.0, 0.0, 0.0))
        rolls.append(abs(body.state.roll))
        hits += body.state.collided
    assert hits == 0
    assert math.hypot(body.state.x - 73.0, body.state.y - 94.5) > 6.0
    assert 30.0 < rolls[0] < 40.0


def test_too_steep_side_slope_slides_down():
    n = 513
    ys = np.arange(n) * (200.0 / 512)
    w = _flat_world(wall=False)
    w.terrain_height[:] = (np.clip(ys - 100.0, 0, None) * math.tan(math.radians(55.0)))[:, None].astype(np.float32)
    body = P.RoverPhysics(w, 60.0, 104.0, 0.0)
    _run(body, P.Controls(0.0, 1.0, 0.0), 2.0)
    assert body.state.y < 103.0


def test_steep_ramp_stops_the_rover():
    body = P.RoverPhysics(_flat_world(wall=False, ramp_deg=12.0), 100.0, 100.0, 0.0)
    _run(body, P.Controls(1.0, 0.0, 0.0), 30.0)
    assert body.state.x < 118.0  # gravity (~2 m/s^2) beats the ~0.9 m/s^2 drive
    assert body.state.pitch < -5.0  # nose up on the ramp


def test_attitude_from_motion(flat_world):
    body = P.RoverPhysics(flat_world, 30.0, 100.0, 0.0)
    _run(body, P.Controls(1.0, 0.0, 0.0), 1.5)
    assert 0.8 < body.state.pitch < 1.6  # log: ~1.2-1.4 deg nose down accelerating
    body = P.RoverPhysics(flat_world, 60.0, 60.0, 0.0)
    body.state.v = 5.0
    _run(body, P.Controls(1.0, 0.0, 15.0), 2.0)
    assert 0.8 < body.state.roll < 4.5  # log: ~1.4 deg in a full-lock left turn at 5 m/s
    assert body.state.yaw_rate > 30


def test_fixed_turn_is_clockwise(flat_world):
    body = P.RoverPhysics(flat_world, 100.0, 100.0, 90.0)
    assert body.start_fixed_turn(90.0, 1.0)
    _run(body, P.Controls(), 1.5)
    assert body.state.yaw == pytest.approx(0.0, abs=1e-6) or body.state.yaw == pytest.approx(360.0)


def test_fixed_turn_default_time_is_45_deg_per_s_and_stops_on_target(flat_world):
    body = P.RoverPhysics(flat_world, 100.0, 100.0, 10.0)
    assert body.start_fixed_turn(-100.0, 0.0)  # counter-clockwise, time from the default rate
    _run(body, P.Controls(), 1.0)
    assert body.state.yaw == pytest.approx(55.0, abs=1e-6) and body.state.fixed_turning
    _run(body, P.Controls(), 2.0)
    assert body.state.yaw == pytest.approx(110.0, abs=1e-6) and not body.state.fixed_turning
    assert not body.start_fixed_turn(float("nan"), 1.0)


def test_move_towards_angle_matches_unity():
    assert P.move_towards_angle(350.0, 370.0, 5.0) == 355.0  # across 0
    assert P.move_towards_angle(10.0, 12.0, 5.0) == 12.0  # within reach: exactly the target
    assert P.move_towards_angle(10.0, 20.0, -5.0) == 5.0  # negative speed moves away


@pytest.mark.parametrize("name", ["megalphian", "royalejandro"])
def test_two_second_windows_of_real_drives(name, real_logs_dir, world_dir, real_world):
    """From logged states, 2 s of logged commands land where the real rover did.

    Before the contact model (issue 28) the medians were 0.023 / 0.022 m/s, 0.46 / 0.38 deg and
    0.087 / 0.073 m (megalphian / royalejandro, a window every 50 rows): they must not get worse.
    """
    from sim import physics_windows as W

    path = real_logs_dir / name
    if not path.exists():
        pytest.skip(f"{name} log not found under {real_logs_dir}")
    s = W.summarise(W.run_windows(real_world, W.find_log(path), every=50))
    assert s["windows"] > 100
    assert s["speed_median"] < 0.025 and s["speed_p90"] < 0.5, s
    assert s["yaw_median"] < 0.5 and s["yaw_p90"] < 6.0, s
    assert s["pos_median"] < 0.09 and s["pos_p90"] < 0.6, s


def test_test_dataset_carries_on_past_the_terrain_lip(test_dataset_dir, real_world):
    """All 2 s windows starting at (114-123, 98) carry on at ~5 m/s, as the real rover did."""
    from sim import physics_windows as W

    a = W.log_arrays(W.find_log(test_dataset_dir))
    starts = [(i0, i1) for i0, i1 in W.window_starts(a, 1)
              if 114 <= a["x"][i0] <= 123 and 97 <= a["y"][i0] <= 99.5]
    assert len(starts) >= 7
    for i0, i1 in starts:
        r = W.replay_window(real_world, a, i0, i1)
        assert r.twin_speed1 > 4.5 and r.err_pos < 1.0, r


@pytest.fixture(scope="module")
def real_world(world_dir):
    from sim.world import load_world

    return load_world("real")


def _turn_and_back_out(world, x, y, yaw, turn_s=2.0):
    """From a pose: (largest clockwise yaw change during turn_s of turning in place, metres moved by 3 s of
    reverse or of forward throttle, whichever gets farther)."""
    turn = P.RoverPhysics(world, x, y, yaw)
    turned = 0.0
    for _ in range(int(turn_s / P.PHYSICS_DT)):
        turn.step(P.Controls(0.0, 0.0, -15.0))
        turned = max(turned, (yaw - turn.state.yaw) % 360)
    moved = []
    for throttle in (-1.0, 1.0):
        out = P.RoverPhysics(world, x, y, yaw)
        _run(out, P.Controls(throttle, 0.0, 0.0), 3.0)
        moved.append(math.hypot(out.state.x - x, out.state.y - y))
    return turned, max(moved)


# the trap places of issue 28 (published clients got stuck there for good): start pose of a drive into the rock
TRAPS = {
    "rock 6 m east of the start": ((99.67, 85.59), 0.0),
    "low rocks 6-9 m south of the start": ((99.67, 85.59), 270.0),
    "0.43 m rock 9 m south of the start": ((99.2, 82.0), 270.0),
    "west-end rock lip": ((24.0, 94.5), 180.0),
}


@pytest.mark.parametrize("trap", sorted(TRAPS))
def test_rover_driven_into_a_trap_rock_can_turn_and_back_out(trap, real_world):
    (x, y), yaw = TRAPS[trap]
    body = P.RoverPhysics(real_world, x, y, yaw)
    hits = 0
    for _ in range(int(10.0 / P.PHYSICS_DT)):
        body.step(P.Controls(1.0, 0.0, 0.0))
        hits += body.state.collided
    assert hits > 0, "the drive should end against the rock"
    _run(body, P.Controls(0.0, 1.0, 0.0), 1.0)  # stop, as a client would
    s = body.state
    turned, backed = _turn_and_back_out(real_world, s.x, s.y, s.yaw, turn_s=4.0)
    # it backs out; and turning in place starts (a front wheel left on the rock tips it back so that it
    # rolls off faster than the 0.316 m/s of the simulator's turn-in-place rule for up to ~2.5 s first)
    assert backed > 1.0
    assert turned > 15.0


@pytest.mark.parametrize("yaw", [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0])
def test_rover_at_the_east_nook_sample_turns_clockwise_freely(yaw, real_world):
    """The rocks beside the sample spot (148.8, 109.6) locked clockwise turns at four headings."""
    turned, _ = _turn_and_back_out(real_world, 148.8, 109.6, yaw)
    assert turned == pytest.approx(90.0, abs=2.0)


def test_rover_placed_overlapping_a_rock_is_pushed_out(real_world):
    """A pose inside a rock's collider (teleport, or a client's replayed pose) resolves, it does not trap."""
    body = P.RoverPhysics(real_world, 97.35, 79.57 + 0.7, 270.0)  # the rear of the tallest near-start sphere
    assert body.contacts(body.state.x, body.state.y, body.state.yaw)[0].size > 0
    _run(body, P.Controls(0.0, 0.0, -15.0), 2.0)
    s = body.state
    assert body.contacts(s.x, s.y, s.yaw)[0].size == 0
    turned = (270.0 - s.yaw) % 360
    assert turned > 45.0  # it turns (a wheel left on the rock may tip it into rolling off)


def test_rock_colliders_come_from_the_collider_shapes(real_world):
    """The physics sees spheres and hulls of rock_colliders.csv, not the render meshes."""
    field = C.rock_field_for(real_world)
    assert real_world.rock_colliders and len(field.patches) >= 20
    # the tallest near-start sphere: r 0.455 m at (97.32, 79.57), centre 0.102 m up
    p = [q for q in field.patches if q.name == "rockClusterDirectional_lod"][0]
    _, top, _, _, _ = C.RockField.query([p], np.array([97.3239]), np.array([79.5659]))
    assert top[0] == pytest.approx(0.102 + 0.455, abs=0.01)
    # the second rockBigPillar_lod instance (west end) is rebuilt from the stored one's prefab
    pillars = [q for q in field.patches if q.name == "rockBigPillar_lod"]
    assert len(pillars) == 2 and min(q.x0 for q in pillars) < 0.0


def test_compiled_rock_query_equals_the_numpy_reference_bit_for_bit(real_world):
    """RockField.query's compiled path gives the very bits of query_numpy (points on and around every patch,
    cell centres and half-cell edges included, NaN too); a changed slab changes both."""
    field = C.rock_field_for(real_world)
    rng = np.random.default_rng(3)
    for p in field.patches:
        x0, y0, x1, y1 = p.bounds
        px = np.concatenate([rng.uniform(x0 - 1.0, x1 + 1.0, 300), x0 + p.cell * (np.arange(40) * 0.5 - 0.5), [np.nan]])
        py = np.concatenate([rng.uniform(y0 - 1.0, y1 + 1.0, 300), y0 + p.cell * (np.arange(40) * 0.5 - 0.5), [y0]])
        near = field.near(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * max(x1 - x0, y1 - y0) + 1.0)
        with np.errstate(invalid="ignore"):  # NumPy casts the NaN point to an index (out of range, so unused)
            fast, ref = C.RockField.query(near, px, py), C.RockField.query_numpy(near, px, py)
        for a, b in zip(fast, ref):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
    p = field.patches[0]
    x0, y0, x1, y1 = p.bounds
    pt = (np.array([0.5 * (x0 + x1)]), np.array([0.5 * (y0 + y1)]))
    changed = C.Patch(p.name, p.x0, p.y0, p.cell, p.bottom, p.top + np.float32(1.0), p.depth, p.ex, p.ey)
    assert C.RockField.query([changed], *pt)[1][0] == C.RockField.query_numpy([changed], *pt)[1][0]
    assert C.RockField.query([changed], *pt)[1][0] != C.RockField.query([p], *pt)[1][0]


def test_real_world_rocks_and_wall_slopes_stop_the_rover(real_world):
    world = real_world
    sx, sy = world.start_xy
    # south: the low spheres 6-9 m from the start are ridden over on their contact normals (their tops are
    # 0.06-0.17 m, the 0.40 m one is met on its flank), the 0.43 m rock ~13 m south stops the rover
    body = P.RoverPhysics(world, sx, sy, 270.0)
    _run(body, P.Controls(1.0, 0.0, 0.0), 20.0)
    assert abs(body.state.v) < 0.5 and 3.0 < sy - body.state.y < 14.0
    y_hit = body.state.y
    _run(body, P.Controls(-1.0, 0.0, 0.0), 3.0)
    assert body.state.y > y_hit + 1.0  # reversed out
    body = P.RoverPhysics(world, sx, sy, 90.0)  # north: the canyon wall slope
    heights = []
    for _ in range(int(30.0 / P.PHYSICS_DT)):
        body.step(P.Controls(1.0, 0.0, 0.0))
        heights.append(world.height_at(body.state.x, body.state.y))
    assert max(heights) < 2.0  # the wheels climb the foot of the wall, gravity stops them
    assert world.height_at(body.state.x, body.state.y) < 1.0


def test_compiled_contact_paths_equal_numpy():
    """The compiled open-ground paths (wheel heights, the terrain-overlap test) give the NumPy answers bit for bit:
    wheel heights and contacts at random poses on rough terrain with rocks, and whole drives (every step's state)."""
    from sim.world import load_world

    world = load_world("procedural:0")
    rng = np.random.default_rng(3)
    rows, cols = np.nonzero(world.nav_truth)
    pick = rng.integers(0, rows.size, 400)
    poses = [(cols[i] + rng.uniform(-1.5, 1.5), rows[i] + rng.uniform(-1.5, 1.5), rng.uniform(0, 360)) for i in pick]
    starts = [poses[k] for k in range(1, 6)]
    commands = [P.Controls(throttle=float(rng.uniform(-0.5, 1.0)), steer=float(rng.uniform(-15, 15)))
                for _ in range(40)]
    answers = {}
    for fast in (True, False):
        P.FAST_CONTACTS = fast
        try:
            body = P.RoverPhysics(world, *poses[0])
            found = []
            for x, y, yaw in poses:
                body._wheel_h = body._wheel_heights(x, y, yaw)
                found.append((body._wheel_h.copy(), *body.contacts(x, y, yaw)))
            states = []
            for start in starts:
                body = P.RoverPhysics(world, *start)
                for k in range(800):
                    body.step(commands[k // 20])
                    states.append(tuple(vars(body.state).values()))
            answers[fast] = found, states
        finally:
            P.FAST_CONTACTS = True
    (found_fast, states_fast), (found_ref, states_ref) = answers[True], answers[False]
    for a, b in zip(found_fast, found_ref):
        assert all(np.array_equal(p, q) for p, q in zip(a, b))
    assert sum(a[1].size > 0 for a in found_fast) > 5  # some poses really touch terrain or rock
    assert states_fast == states_ref
    assert sum(s[list(vars(body.state)).index("collided")] for s in states_fast) > 0  # the drives hit something


def test_a_low_rock_under_the_flatbed_lip_lifts_the_body_instead_of_stopping_it(real_world):
    """Seed 17's stuck spot (diag5): the flatbed's front lip overlapped a sphere of the cluster at (99.5, 77.6)
    (top 0.167 m) by ~1 cm vertically and the rover stopped dead in 0.1 m, pinned for 8 s.  Along the
    sphere's normal (centre -> contact, near vertical) that contact carries the body: it rides on."""
    body = P.RoverPhysics(real_world, 99.25, 77.81, 210.0)
    body.state.v = 1.2
    pitches = []
    for _ in range(int(2.0 / P.PHYSICS_DT)):
        body.step(P.Controls(0.5, 0.0, 0.0))
        pitches.append(body.state.pitch)
    s = body.state
    moved = math.hypot(s.x - 99.25, s.y - 77.81)
    assert moved > 1.0 or (min(pitches) < -5.0 and moved > 0.3), (moved, min(pitches))


def test_megalphian_ride_up_the_rock_cluster_pitches_nose_up_and_slides_to_a_stop(real_logs_dir, real_world):
    """megalphian rows 2736-2766 (0-based): at 2.1 m/s the real rover met the cluster's 0.40 m sphere, pitched
    20 deg nose up, slid to a stop over ~0.5 m without rebounding and rolled back.  The twin, open loop
    with the logged commands: nose up >= 10 deg, a gradual stop (>= 0.25 s from 1 m/s to rest; the old wall
    contact rebounded from 1.9 to -0.5 m/s in one step), stop within 0.6 m of the real one.
    (SUPPORT_IMPULSE_SHARE was set on this event.)"""
    from sim import physics_windows as W

    path = real_logs_dir / "megalphian"
    if not path.exists():
        pytest.skip(f"megalphian log not found under {real_logs_dir}")
    a = W.log_arrays(W.find_log(path))
    i0 = 2736
    assert math.hypot(a["x"][i0] - 99.13, a["y"][i0] - 78.52) < 0.05  # the row numbering is the expected one
    real_stop = next(i for i in range(i0, i0 + 40) if a["speed"][i] <= 0.05)
    i1 = int(np.searchsorted(a["t"], a["t"][i0] + 2.0))
    body = P.RoverPhysics(real_world, a["x"][i0], a["y"][i0], a["yaw"][i0])
    body.state.v = float(a["speed"][i0])
    sim_t, stop, min_pitch, last_fast, stop_t = a["t"][i0], None, 0.0, None, None
    for i in range(i0 + 1, i1 + 1):
        c = P.Controls(a["throttle"][i - 1], a["brake"][i - 1], a["steer"][i - 1])
        while sim_t < a["t"][i] - 1e-9:
            body.step(c)
            sim_t += P.PHYSICS_DT
            s = body.state
            min_pitch = min(min_pitch, s.pitch)
            if stop is None and s.v > 1.0:
                last_fast = sim_t
            if stop is None and s.v <= 0.05:
                stop, stop_t = (s.x, s.y), sim_t
    assert min_pitch <= -10.0
    assert stop is not None and last_fast is not None
    assert stop_t - last_fast >= 0.25
    assert math.hypot(stop[0] - a["x"][real_stop], stop[1] - a["y"][real_stop]) < 0.6
