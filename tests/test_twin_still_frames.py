"""RoverTwin reuses the last image while the rover stands still (sim/twin.py `_still_frame`)."""
import base64

import cv2
import numpy as np
import pytest

from sim.samples import NEAR_AHEAD_M
from sim.twin import STILL_ANGLE_DEG, STILL_POSITION_M, RoverTwin

from tests.test_twin import _data, _flat_world

pytest.importorskip("sim.render")


@pytest.fixture(scope="module")
def world():
    return _flat_world()


def _rgb(tel):
    return cv2.imdecode(np.frombuffer(base64.b64decode(tel["image"]), np.uint8), cv2.IMREAD_COLOR)


def _facing_a_sample(world, reuse=True):
    twin = RoverTwin(world, seed=3)
    twin.reuse_still_frames = reuse
    twin.reset(3, start_yaw=0.0)
    smp = twin.samples[0]
    st = twin.physics.state
    st.x, st.y, st.yaw = smp.x - NEAR_AHEAD_M - 0.2, smp.y, 0.0
    return twin


def _brake_to_standstill(twin, frames=60):
    tel = None
    for _ in range(frames):
        tel = twin.step("data", _data("0", brake="1"))
    return tel


def test_moving_rover_renders_every_frame(world):
    twin = RoverTwin(world, seed=3)
    twin.reset(3, start_yaw=0.0)
    for _ in range(30):
        tel = twin.step("data", _data("1"))
    assert float(tel["speed"]) > 0.3
    assert twin.reused_frames == 0


def test_still_rover_reuses_the_image_it_would_render_again(world):
    twin = _facing_a_sample(world)
    _brake_to_standstill(twin)
    reused = twin.reused_frames
    a = twin.step("data", _data("0", brake="1"))
    b = twin.step("data", _data("0", brake="1"))
    assert twin.reused_frames == reused + 2
    assert a["image"] == b["image"]
    fresh = twin.render_rgb().astype(int)  # what a render at the current pose gives
    assert np.abs(fresh - twin.last_rgb.astype(int)).mean() < 0.5


def test_pickup_reuses_while_the_arm_works_and_redraws_without_the_sample(world):
    twin = _facing_a_sample(world)
    tel = _brake_to_standstill(twin, 10)
    assert tel["near_sample"] == "1"
    tel = twin.step("pickup", {})
    previous, start = tel, twin.reused_frames
    while tel["sample_count"] == "6":
        previous = tel
        tel = twin.step("manual", {})
    assert twin.reused_frames - start > 200  # ~10 s of 25 Hz frames with the rover frozen
    gone = _rgb(tel).astype(int)
    assert np.abs(gone - _rgb(previous).astype(int)).max(axis=2).astype(bool).sum() > 100  # the rock vanished


def test_reuse_switched_off_renders_every_frame(world):
    twin = _facing_a_sample(world, reuse=False)
    _brake_to_standstill(twin)
    assert twin.reused_frames == 0


def test_a_renderer_setting_or_a_small_move_renders_again(world):
    twin = _facing_a_sample(world)
    _brake_to_standstill(twin)
    n = twin.reused_frames
    twin._renderer.backscatter = not twin._renderer.backscatter
    twin.step("data", _data("0", brake="1"))
    assert twin.reused_frames == n
    twin.step("data", _data("0", brake="1"))
    assert twin.reused_frames == n + 1
    twin.physics.state.x += 2 * STILL_POSITION_M
    twin.step("data", _data("0", brake="1"))
    assert twin.reused_frames == n + 1
    twin.physics.state.yaw += 2 * STILL_ANGLE_DEG
    twin.step("data", _data("0", brake="1"))
    assert twin.reused_frames == n + 1
