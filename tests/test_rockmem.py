"""Refuted rocks (navigation.rockmem): approached and not found stays given up until stronger evidence."""
import math

import numpy as np

import decision
from navigation import rock_choice, rockmem
from tests.test_decision import make_rover


def test_an_attempt_refutes_only_a_rock_the_rover_came_close_to_without_seeing_it():
    assert rockmem.was_refuted(came_close=True, seen_close=False)
    assert not rockmem.was_refuted(came_close=True, seen_close=True)  # real, hard to reach: timed skip
    assert not rockmem.was_refuted(came_close=False, seen_close=False)  # never got there: no evidence


def test_refuted_spots_merge_within_same_distance_keeping_the_larger_bar():
    spots = rockmem.add_refuted([], (104.5, 91.5), 12, 2.0)
    spots = rockmem.add_refuted(spots, (104.0, 92.1), 30, 2.0)
    assert len(spots) == 1 and spots[0][2] == 30
    spots = rockmem.add_refuted(spots, (110.0, 91.5), 0, 2.0)
    assert len(spots) == 2
    assert rockmem.nearest_refuted(spots, (104.9, 91.0), 2.0) == 0
    assert rockmem.nearest_refuted(spots, (107.2, 91.5), 2.0) is None


def test_only_a_close_sighting_with_more_pixels_revives():
    assert rockmem.revives(bar_pixels=12, pixels=13, dist_m=2.0, close_m=3.5)
    assert not rockmem.revives(bar_pixels=12, pixels=12, dist_m=2.0, close_m=3.5)
    assert not rockmem.revives(bar_pixels=12, pixels=80, dist_m=6.0, close_m=3.5)


def test_a_remembered_rock_given_up_after_standing_on_it_unseen_is_never_chosen_again():
    """Seed 5 at 15 fps: the phantom at (104.5, 91.5) came back every 60 s, 7 times."""
    r = make_rover(pos=(103.7, 91.4))  # 0.8 m short: nearer, the spot is under the rover and given up at once (turning)
    r.samples_remaining = 5
    r.rocks_world = [(104.5, 91.5)]
    r.rock_angles, r.rock_dists = np.zeros(0), np.zeros(0)
    decision.decision_step(r)
    assert r.nav.rock_target == (104.5, 91.5)
    s = decision._read_inputs(r)
    decision._abandon_goal(r.nav, s)  # the stuck monitor gives it up
    assert r.nav.rock_refuted and r.nav.rock_target is None
    r.total_time += 10 * rock_choice.ROCK_SKIP_S
    assert not rock_choice.choose_rock(r, r.nav, decision._read_inputs(r))
    # the camera shows a rock there from 2 m: stronger evidence, chased again
    r.pos, r.yaw = (102.5, 91.5), 0.0
    r.rock_angles, r.rock_dists = np.zeros(8), np.full(8, 2.0)
    assert rock_choice.choose_rock(r, r.nav, decision._read_inputs(r))
    assert r.nav.rock_target is not None and math.hypot(r.nav.rock_target[0] - 104.5, r.nav.rock_target[1] - 91.5) < 1
    assert not r.nav.rock_refuted


def test_a_rock_the_camera_saw_close_keeps_the_timed_skip():
    r = make_rover(pos=(102.0, 91.5), yaw=0.0)
    r.samples_remaining = 5
    r.rock_angles, r.rock_dists = np.zeros(8), np.full(8, 2.0)
    decision.decision_step(r)
    s = decision._read_inputs(r)
    decision._abandon_goal(r.nav, s)
    assert not r.nav.rock_refuted and r.nav.rock_skip
