"""A frontier voted wall from afar is still driven to (navigation.vanished); a search goal is kept
until the rover has driven away from where it chose it (search_plan.search_goal_committed)."""
import math

import numpy as np
import pytest

import decision
from navigation import paths, search_plan, vanished
from tests.test_decision import make_rover

pytestmark = pytest.mark.usefixtures("map_only_search")  # these rules are the map-only search's


def neck_map():
    """A 2-cell neck of floor (rows 183-188, cols 102-103) ending in wall; the tip (190, 104) reads wall."""
    free = np.zeros((200, 200), bool)
    free[183:189, 102:104] = True
    obstacle = np.zeros_like(free)
    obstacle[189:193, 98:108] = True
    return free, obstacle


def test_a_goal_voted_wall_counts_as_vanished_only_while_unseen_from_close():
    free, obstacle = neck_map()
    seen = np.zeros_like(free)
    assert vanished.vanished_by_far_vote((190, 104), obstacle, seen)
    assert not vanished.vanished_by_far_vote((186, 103), obstacle, seen)  # floor: an ordinary goal
    seen[190, 104] = True
    assert not vanished.vanished_by_far_vote((190, 104), obstacle, seen)  # looked at from close: closed


def test_the_stand_is_the_nearest_reachable_floor_within_reach():
    free, _ = neck_map()
    dist = np.where(free, 1.0, np.inf)
    assert vanished.stand_beside((190, 104), free, dist, 3.0) == (188, 103)
    dist[188, :] = np.inf  # the neck's end unreachable: the next row down
    assert vanished.stand_beside((190, 104), free, dist, 3.0) is None  # (187, 103) is 3.2 m off
    assert vanished.stand_beside((190, 104), free, dist, 3.5) == (187, 103)
    assert vanished.stand_beside((195, 104), free, dist, 3.0) is None  # no floor within reach


def test_a_search_goal_is_kept_until_the_rover_drove_away_from_where_it_chose_it():
    r = make_rover(pos=(103.8, 190.2))
    s = decision._read_inputs(r)
    paths.set_path(r.nav, s, "look", (179, 100), [(190, 103), (179, 100)])
    assert search_plan.search_goal_committed(r.nav, s)  # turning in place to leave: kept
    r.pos = (103.8, 190.2 - search_plan.SEARCH_COMMIT_M - 0.1)
    assert not search_plan.search_goal_committed(r.nav, decision._read_inputs(r))
