"""RoverTwin-v0: Gymnasium API conformance, rewards, episode ends and the baseline policy."""
import math

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rover_gym
from rover_gym.baseline import AutonomyPolicy, telemetry_from_obs
from rover_gym.env import HOME_REWARD, SAMPLE_REWARD, RoverTwinEnv
from sim.samples import NEAR_AHEAD_M, PICKUP_DURATION_S
from sim.world import World

UNITY_STEP_S = 1 / 30  # one render frame at the default 30 fps


def _flat_world(spots):
    """Open floor everywhere (every cell truth-navigable) with the given sample spots."""
    return World(terrain_height=np.zeros((513, 513), np.float32), sand_weight=np.ones((512, 512), np.float32),
                 rock_top=np.zeros((2001, 2001), np.float32), rock_bottom=np.zeros((2001, 2001), np.float32),
                 nav_truth=np.full((200, 200), 255, np.uint8), sample_spots=np.asarray(spots, float),
                 start_xy=(100.0, 100.0), start_yaw_training=0.0, name="flat-gym-test")


def _one_sample_ahead(seed):
    """A flat world whose single sample lies in the pickup capsule at the start of scene `seed`."""
    yaw = np.random.default_rng(seed).uniform(0.0, 360.0)  # RoverTwin.reset draws the start yaw first
    x = 100.0 + NEAR_AHEAD_M * math.cos(math.radians(yaw))
    y = 100.0 + NEAR_AHEAD_M * math.sin(math.radians(yaw))
    return _flat_world([[x, y]])


DRIVE = np.array([0.6, 0.0, 0.0, 0.0], np.float32)
STOP = np.array([0.0, 1.0, 0.0, 0.0], np.float32)
PICKUP = np.array([0.0, 0.0, 0.0, 1.0], np.float32)


@pytest.mark.parametrize("timing", ["unity", "lockstep"])
def test_make_registers_and_passes_check_env(timing):
    env = gymnasium.make(rover_gym.ENV_ID, world="procedural:0", seed=1, timing=timing, shadows=True,
                         render_mode="rgb_array", max_episode_s=2.0)
    check_env(env.unwrapped)
    obs, info = env.reset(seed=5)
    assert env.observation_space.contains(obs)
    assert info["scene_seed"] == 5 and info["samples"] == 6
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (320, 640, 3)
    env.close()


def test_constructor_seed_sets_the_first_scene_and_bad_arguments_are_refused():
    world = _flat_world([[120.0, 120.0]])
    a = RoverTwinEnv(world=world, seed=7)
    b = RoverTwinEnv(world=world, seed=7)
    (oa, ia), (ob, ib) = a.reset(), b.reset()
    assert ia["scene_seed"] == ib["scene_seed"] == 7
    np.testing.assert_array_equal(oa["telemetry"], ob["telemetry"])
    with pytest.raises(ValueError, match="timing"):
        RoverTwinEnv(world=world, timing="realtime")
    with pytest.raises(ValueError, match="4 values"):
        a.step([0.1, 0.0])
    with pytest.raises(ValueError, match="finite"):
        a.step([float("nan"), 0.0, 0.0, 0.0])


def test_mapping_reward_counts_newly_seen_truth_floor_and_truncates_at_the_time_limit():
    env = RoverTwinEnv(world=_flat_world([[20.0, 20.0]]), seed=2, max_episode_s=3.0)
    _, info0 = env.reset()
    rewards, truncated = [], False
    while not truncated:
        _, r, terminated, truncated, info = env.step(DRIVE)
        assert not terminated
        rewards.append(r)
    assert math.isclose(info["sim_time"], 3.0, abs_tol=1e-6) and info["end_reason"] == "time limit"
    assert info["seen_truth_cells"] > info0["seen_truth_cells"]
    # the reward is 100 / truth cells per newly seen cell: the sum is the growth in seen percent
    assert math.isclose(sum(rewards), info["seen_truth_pct"] - info0["seen_truth_pct"], rel_tol=1e-9)
    assert min(rewards) >= 0.0


def test_sample_then_home_rewards_end_the_episode():
    env = RoverTwinEnv(world=_one_sample_ahead(4), seed=4)
    obs, _ = env.reset()
    assert obs["telemetry"][9] == 1.0  # near_sample
    total, terminated, steps = 0.0, False, 0
    obs, r, terminated, _, info = env.step(PICKUP)
    total += r
    while not terminated and steps < PICKUP_DURATION_S / UNITY_STEP_S + 20:
        obs, r, terminated, _, info = env.step(STOP)
        total += r
        steps += 1
    assert terminated and info["end_reason"] == "home with every sample"
    assert info["collected"] == 1
    assert total >= SAMPLE_REWARD + HOME_REWARD


def test_blind_pickup_is_guarded_by_default_and_terminates_when_unguarded():
    world = _flat_world([[20.0, 20.0]])
    guarded = RoverTwinEnv(world=world, seed=3)
    guarded.reset()
    _, _, terminated, _, _ = guarded.step(PICKUP)
    assert not terminated and guarded.twin.truth.picking_up is False
    raw = RoverTwinEnv(world=world, seed=3, pickup_guard=False)
    raw.reset()
    _, _, terminated, _, info = raw.step(PICKUP)
    assert terminated and "froze" in info["end_reason"]


@pytest.mark.parametrize("timing", ["unity", "lockstep"])
def test_baseline_policy_drives_exactly_like_the_client_on_the_twin(timing):
    """obs -> telemetry -> AutonomyClient: same commands, same path as sim.mission's loop (TwinLoop)."""
    from autonomy import AutonomyClient
    from sim.timing import TwinLoop
    from sim.twin import RoverTwin

    frames = 120
    env = RoverTwinEnv(world="procedural:0", seed=3, timing=timing)
    policy = AutonomyPolicy.for_env(env)
    obs, _ = env.reset()
    gym_path = []
    for _ in range(frames):
        obs, *_ = env.step(policy(obs))
        gym_path.append(env.twin.pose())

    loop = TwinLoop(RoverTwin(env.world, seed=3), env.timing)
    client = AutonomyClient(ground_truth=env.world.nav_truth, insets=False, clock=loop.clock, fixed_turns=False)
    tel = loop.reset(3)
    twin_path = []
    for _ in range(frames):
        tel, _ = loop.step(*client.handle_telemetry(tel))
        twin_path.append(loop.twin.pose())
    assert np.abs(np.array(twin_path)[-1, :2] - np.array(twin_path)[0, :2]).max() > 0.5  # it drove
    np.testing.assert_allclose(np.array(gym_path), np.array(twin_path), rtol=0, atol=1e-9)


def test_telemetry_round_trip_keeps_the_simulator_strings():
    env = RoverTwinEnv(world="procedural:0", seed=11, timing="lockstep")
    obs, _ = env.reset()
    for _ in range(30):
        obs, *_ = env.step(np.array([0.5, 0.0, 8.0, 0.0], np.float32))
    tel = telemetry_from_obs(obs)
    real = env.telemetry
    for key in ("speed", "position", "pitch", "yaw", "roll", "steering_angle", "throttle", "brake",
                "near_sample", "picking_up", "sample_count", "sim_time"):
        assert tel[key] == real[key], key
    unity = RoverTwinEnv(world="procedural:0", seed=11, timing="unity", fps=20.0)
    obs, _ = unity.reset()
    obs, *_ = unity.step(np.array([0.5, 0.0, 8.0, 0.0], np.float32))
    assert "sim_time" not in unity.telemetry  # the real simulator sends no clock
    assert obs["telemetry"][-1] == pytest.approx(1 / 20.0, abs=1e-4)  # the frame it was captured at
