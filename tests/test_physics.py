"""Twin physics against the real simulator's logs and basic invariants."""
import math
import re

import numpy as np
import pytest

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
    _run(body, P.Controls(1.0, 0.0, 0.0), 8.0)
    s = body.state
    assert s.x + P.BUMPER_FRONT_M <= WALL_X + 0.1
    assert s.x > WALL_X - 2.0
    assert s.v == 0.0 and s.collided
    x_hit = s.x
    _run(body, P.Controls(-1.0, 0.0, 0.0), 2.0)
    assert body.state.x < x_hit - 0.5
    assert body.state.v < 0


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


def test_two_second_windows_of_megalphian_drive(real_logs_dir, world_dir):
    """From logged states, 2 s of logged commands land where the real rover did."""
    from sim.world import load_world

    world = load_world("real")
    t, a = _read_log(real_logs_dir / "megalphian" / "robot_log.csv")
    steer, thr, brake, speed, x, y, yaw = (a[:, i] for i in (0, 1, 2, 3, 4, 5, 7))
    err_v, err_yaw, err_pos = [], [], []
    for i0 in range(0, len(t) - 80, 50):
        i1 = int(np.searchsorted(t, t[i0] + 2.0))
        if i1 >= len(t) or t[i1] - t[i0] > 2.3:
            continue
        body = P.RoverPhysics(world, x[i0], y[i0], yaw[i0])
        body.state.v = speed[i0]
        sim_t = t[i0]
        for i in range(i0 + 1, i1 + 1):
            while sim_t < t[i] - 1e-9:
                body.step(P.Controls(thr[i - 1], brake[i - 1], steer[i - 1]))
                sim_t += P.PHYSICS_DT
        err_v.append(abs(body.state.v - speed[i1]))
        err_yaw.append(abs((body.state.yaw - yaw[i1] + 180) % 360 - 180))
        err_pos.append(np.hypot(body.state.x - x[i1], body.state.y - y[i1]))
    assert len(err_v) > 80
    assert np.median(err_v) < 0.1 and np.percentile(err_v, 90) < 0.5
    assert np.median(err_yaw) < 1.5 and np.percentile(err_yaw, 90) < 6.0
    assert np.median(err_pos) < 0.2 and np.percentile(err_pos, 90) < 0.6


def test_real_world_rocks_and_wall_slopes_stop_the_rover(world_dir):
    from sim.world import load_world

    world = load_world("real")
    sx, sy = world.start_xy
    body = P.RoverPhysics(world, sx, sy, 270.0)  # south: the low rocks 6-8.5 m from the start
    _run(body, P.Controls(1.0, 0.0, 0.0), 20.0)
    assert body.state.v == 0.0 and 3.0 < sy - body.state.y < 9.0
    y_hit = body.state.y
    _run(body, P.Controls(-1.0, 0.0, 0.0), 3.0)
    assert body.state.y > y_hit + 1.0  # reversed out
    body = P.RoverPhysics(world, sx, sy, 90.0)  # north: the canyon wall slope
    _run(body, P.Controls(1.0, 0.0, 0.0), 30.0)
    assert world.height_at(body.state.x, body.state.y) < 1.0  # could not climb the wall
    assert abs(body.state.v) < 1.0
