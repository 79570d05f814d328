"""A rock the camera shows while the rover is in a fixed turn (rock_choice.note_turn_sighting): the state
machine only waits for the yaw then, so the sighting is kept and gone back for once the turn is over."""
import math

import numpy as np

import decision
from navigation import rock_choice, rockmem
from tests.test_decision import make_rover

TURN_STEP_DEG = 18.0  # yaw change per frame of the simulated 180 deg/s fixed turn at 10 fps, degrees
ROCK_XY = (100.0 + 4.2 * math.cos(math.radians(-18.0 + 39.0)), 85.0 + 4.2 * math.sin(math.radians(-18.0 + 39.0)))


def _turn_back(r, rock_frames=(1,), rock_px=16):
    """Turn the rover at (100, 85) facing east back to 180 deg as the simulator's fixed turn does (one
    frame to release, one to send, then TURN_STEP_DEG a frame clockwise); the camera shows a rock at
    ROCK_XY in the turn's frames listed in rock_frames (1 = the first frame after the yaw moved).
    Stops once the turn has arrived and the next turn in place (if any) is chosen."""
    r.fixed_turns = True
    r.rock_angles, r.rock_dists = np.zeros(0), np.zeros(0)
    decision._start_rotation(r.nav, decision._read_inputs(r), 180.0, "test")
    sent = None
    turned = 0
    for _ in range(30):
        r.total_time += 0.1
        if sent is not None and turned < 180:
            turned += TURN_STEP_DEG
            r.yaw = (r.yaw - TURN_STEP_DEG) % 360.0
        in_view = sent is not None and turned // TURN_STEP_DEG in rock_frames
        if in_view:
            dx, dy = ROCK_XY[0] - r.pos[0], ROCK_XY[1] - r.pos[1]
            bearing = math.atan2(dy, dx) - math.radians(r.yaw)
            r.rock_angles = np.full(rock_px, math.atan2(math.sin(bearing), math.cos(bearing)))
            r.rock_dists = np.full(rock_px, math.hypot(dx, dy))
        else:
            r.rock_angles, r.rock_dists = np.zeros(0), np.zeros(0)
        decision.decision_step(r)
        if r.fixed_turn is not None:
            sent = r.total_time
        if turned >= 180 and r.nav.fixed is None:
            return


def test_a_rock_seen_mid_turn_is_the_target_once_the_turn_is_over():
    """Seed 0 at 10 fps: 16 px of the north-tip sample in the first frame of a 180 deg/s turn back."""
    r = make_rover(pos=(100.0, 85.0), yaw=0.0)
    _turn_back(r)
    assert r.nav.rock_target is not None
    assert math.hypot(r.nav.rock_target[0] - ROCK_XY[0], r.nav.rock_target[1] - ROCK_XY[1]) < 0.1
    assert r.nav.turn_sighting is None
    # the approach turns back to face it (the camera then takes over)
    bearing = math.degrees(math.atan2(ROCK_XY[1] - 85.0, ROCK_XY[0] - 100.0))
    assert r.nav.rotate_heading is not None and abs(decision.predict.wrap_deg(r.nav.rotate_heading - bearing)) < 5.0


def test_without_a_sighting_the_turn_ends_with_no_rock_target():
    r = make_rover(pos=(100.0, 85.0), yaw=0.0)
    _turn_back(r, rock_frames=())
    assert r.nav.rock_target is None and r.nav.turn_sighting is None


def test_a_sighting_at_a_refuted_spot_or_a_collected_rock_is_not_gone_back_for():
    r = make_rover(pos=(100.0, 85.0), yaw=0.0)
    r.nav.rock_refuted = rockmem.add_refuted([], ROCK_XY, 40, rock_choice.ROCK_SAME_M)
    _turn_back(r)
    assert r.nav.rock_target is None and r.nav.turn_sighting is None
    r = make_rover(pos=(100.0, 85.0), yaw=0.0)
    r.nav.collected = [ROCK_XY]
    _turn_back(r)
    assert r.nav.rock_target is None and r.nav.turn_sighting is None


def test_the_strongest_sighting_of_a_turn_is_kept_and_an_old_one_expires():
    r = make_rover(pos=(100.0, 85.0), yaw=0.0)
    nav = r.nav
    for px, dist in ((5, 4.0), (16, 4.5), (8, 3.0)):
        r.rock_angles, r.rock_dists = np.zeros(px), np.full(px, dist)
        rock_choice.note_turn_sighting(nav, decision._read_inputs(r))
    assert nav.turn_sighting[3] == 16 and nav.turn_sighting[0] == 104.5
    r.rock_angles, r.rock_dists = np.zeros(40), np.full(40, rock_choice.ROCK_CHASE_M + 1.0)
    rock_choice.note_turn_sighting(nav, decision._read_inputs(r))
    assert nav.turn_sighting[3] == 16  # too far to chase: not kept
    r.rock_angles, r.rock_dists = np.zeros(0), np.zeros(0)
    r.total_time += rock_choice.TURN_SIGHTING_KEEP_S + 0.5
    assert not rock_choice.choose_rock(r, nav, decision._read_inputs(r))
    assert nav.turn_sighting is None and nav.rock_target is None


def test_no_sighting_is_kept_once_every_sample_is_collected():
    r = make_rover(pos=(100.0, 85.0), yaw=0.0)
    r.samples_remaining = 0
    r.rock_angles, r.rock_dists = np.zeros(16), np.full(16, 4.0)
    rock_choice.note_turn_sighting(r.nav, decision._read_inputs(r))
    assert r.nav.turn_sighting is None
