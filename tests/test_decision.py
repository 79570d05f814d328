"""Behaviour of decision.decision_step: modes, stuck recovery, pickup safety, sane commands."""
import math

import numpy as np
import pytest

import decision
from navigation import exploration_plan, explore, paths, search_plan
from rover_state import RoverState

pytestmark = pytest.mark.usefixtures("map_only_search")  # these rules are the map-only search's

DT = 0.04  # twin telemetry period, s


@pytest.fixture(autouse=True)
def no_internal_errors(caplog):
    """decision_step swallows exceptions to keep servers alive; tests must still see them."""
    yield
    errors = [r for r in caplog.records if r.name == "decision" and r.levelname == "ERROR"]
    assert not errors, errors[0].getMessage()


def clear_view(n=2000, spread=0.6, far=8.0, seed=0):
    """Navigable pixels of an open floor ahead (rover frame, radians / metres)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(-spread, spread, n), rng.uniform(1.0, far, n)


def make_rover(pos=(100.0, 85.0), yaw=0.0, t=10.0):
    r = RoverState()
    r.pos, r.yaw, r.total_time, r.vel = pos, yaw, t, 0.0
    r.start_pos = (100.0, 85.0)
    r.samples_remaining, r.samples_initial = 6, 6
    r.nav_angles, r.nav_dists = clear_view()
    # a mapped corridor with walls north, south and west: the only frontier is east, ahead
    r.worldmap[80:91, 90:130, 2] = 255
    r.worldmap[79, 89:131, 0] = 255
    r.worldmap[91, 89:131, 0] = 255
    r.worldmap[79:92, 89, 0] = 255
    r.nav = decision.NavMemory()
    r.nav.seen_close[:] = True  # the walls have been looked at from close: they are not frontiers
    return r


def assert_sane(r):
    for v in (r.throttle, r.brake, r.steer):
        assert math.isfinite(v)
    assert -15.0 <= r.steer <= 15.0
    assert -1.0 <= r.throttle <= 1.0
    assert r.brake >= 0.0


def test_first_frame_defaults_are_safe():
    r = RoverState()
    decision.decision_step(r)
    assert_sane(r)
    assert r.send_pickup is False
    assert r.throttle <= 0.0


@pytest.mark.parametrize("field,value", [
    ("pos", (np.nan, np.nan)), ("pos", None), ("yaw", np.nan), ("vel", np.inf), ("total_time", np.nan),
    ("nav_angles", np.array([np.nan, 0.1])), ("nav_dists", np.zeros(0)), ("worldmap", None),
    ("rock_angles", np.array([0.1, 0.2, 0.3, 0.4])), ("samples_remaining", "x"),
])
def test_degenerate_inputs_never_nan(field, value):
    r = make_rover()
    setattr(r, field, value)
    for k in range(5):
        r.total_time = 10.0 + k * DT if field != "total_time" else value
        decision.decision_step(r)
        assert_sane(r)
    assert r.mode in ("forward", "stop", "stuck", "sample", "pickup", "search", "home", "done")


def test_empty_view_turns_in_place_not_forward():
    r = make_rover()
    r.nav_angles, r.nav_dists = np.zeros(0), np.zeros(0)
    r.worldmap[:] = 0
    decision.decision_step(r)
    assert_sane(r)
    assert r.throttle <= 0.0
    assert r.mode == "stop"
    assert abs(r.steer) > 0 or r.brake > 0


def test_drives_forward_on_open_floor():
    r = make_rover()
    for k in range(10):
        r.total_time = 10 + k * DT
        decision.decision_step(r)
    assert r.mode == "forward"
    assert r.throttle > 0 and r.brake == 0


def run_blocked(r, seconds, start_t=10.0):
    """Frames with the rover pinned in place while the view ahead stays clear."""
    modes, cmds = [], []
    n = int(seconds / DT)
    for k in range(n):
        r.total_time = start_t + k * DT
        decision.decision_step(r)
        assert_sane(r)
        modes.append(r.mode)
        cmds.append((r.throttle, r.brake, r.steer))
    return modes, cmds


def test_no_progress_with_throttle_becomes_stuck_then_backs_off_and_turns():
    r = make_rover()
    modes, cmds = run_blocked(r, 3.0 + 4.5)
    assert "stuck" in modes
    first = modes.index("stuck")
    # not before the detection window has elapsed
    assert first * DT >= decision.stuck.STUCK_WINDOW_S - 2 * DT
    during = [c for m, c in zip(modes[first:], cmds[first:]) if m == "stuck"]
    assert during[0][0] < 0, "recovery starts by reversing"
    turning = [c for c in during if c[0] == 0 and c[1] == 0 and abs(c[2]) == 15]
    assert turning, "recovery turns in place at full lock"
    # the cells the rover pushed against are remembered as blocked
    assert np.isfinite(r.nav.blocked_at).any()


def test_moving_rover_is_not_stuck():
    r = make_rover()
    for k in range(200):
        r.total_time = 10 + k * DT
        r.pos = (100.0 + 0.08 * k, 85.0)
        r.vel = 2.0
        decision.decision_step(r)
        assert r.mode != "stuck"


def test_pickup_only_when_near_and_stopped():
    r = make_rover()
    r.near_sample = True
    r.vel = 1.2
    decision.decision_step(r)
    assert r.mode == "pickup"
    assert r.send_pickup is False
    assert r.brake > 0 and r.throttle == 0
    r.vel = 0.0
    r.total_time += DT
    decision.decision_step(r)
    assert r.send_pickup is True
    # no repeat request on the next frames while the simulator starts the arm
    r.total_time += DT
    decision.decision_step(r)
    assert r.send_pickup is False
    r.picking_up = True
    for k in range(20):
        r.total_time += DT
        decision.decision_step(r)
        assert r.mode == "pickup" and r.send_pickup is False and r.throttle == 0


def test_never_requests_pickup_when_not_near():
    r = make_rover()
    for k in range(100):
        r.total_time = 10 + k * DT
        r.vel = 0.0
        decision.decision_step(r)
        assert r.send_pickup is False


def test_rock_in_view_switches_to_sample_and_steers_toward_it():
    r = make_rover()
    r.rock_angles = np.full(6, math.radians(10))
    r.rock_dists = np.full(6, 4.0)
    r.vel = 0.5
    decision.decision_step(r)
    assert r.mode == "sample"
    assert r.steer > 0
    assert r.target is not None
    r.rock_angles = np.full(6, math.radians(-10))
    r.total_time += DT
    decision.decision_step(r)
    assert r.steer < 0


def test_after_pickup_returns_to_exploring_and_forgets_the_rock():
    r = make_rover()
    r.rock_angles, r.rock_dists = np.full(6, 0.1), np.full(6, 1.0)
    decision.decision_step(r)
    assert r.mode == "sample"
    r.rock_angles, r.rock_dists = np.zeros(0), np.zeros(0)
    r.near_sample, r.picking_up = True, True
    r.total_time += DT
    decision.decision_step(r)
    assert r.mode == "pickup"
    r.near_sample, r.picking_up, r.samples_remaining = False, False, 5
    r.rocks_world = [r.nav.rock_target]  # perception still remembers it
    for k in range(5):
        r.total_time += DT
        decision.decision_step(r)
    assert r.mode in ("forward", "stop")
    assert len(r.nav.collected) == 1


@pytest.mark.parametrize("offset_m,chased", [(2.6, False), (6.0, True)])
def test_remembered_echo_of_a_collected_rock_is_not_chased(offset_m, chased):
    """A rock seen from afar is remembered a few metres off; once collected, that echo is no target.
    Samples lie at least 5 m apart, so a remembered rock 6 m away is another sample."""
    r = make_rover()
    r.nav.collected.append((105.0, 85.0))
    r.samples_remaining = 5
    r.rocks_world = [(105.0 + offset_m * math.cos(0.6), 85.0 + offset_m * math.sin(0.6))]
    r.rock_angles, r.rock_dists = np.zeros(0), np.zeros(0)
    decision.decision_step(r)
    assert (r.nav.rock_target is not None) == chased


def test_goes_home_when_done_and_parks():
    r = make_rover(pos=(110.0, 85.0))
    r.samples_remaining = 0
    r.worldmap[:] = 0
    r.worldmap[80:91, 90:130, 2] = 255  # fully enclosed: no frontier
    r.worldmap[79, 89:131, 0] = 255
    r.worldmap[91, 89:131, 0] = 255
    r.worldmap[79:92, 89, 0] = 255
    r.worldmap[79:92, 130, 0] = 255
    r.yaw = 180.0
    r.total_time = 30.0
    for k in range(150):  # a few plans must agree that no frontier is left, then home
        r.total_time += DT
        decision.decision_step(r)
        if r.mode == "home":
            break
    assert r.mode == "home"
    assert r.target is not None and abs(r.target[0] - 100.5) < 1.5
    r.pos = (100.3, 85.2)
    r.total_time += DT
    decision.decision_step(r)
    assert r.mode == "done"
    assert r.brake > 0 and r.throttle == 0
    assert r.mission_complete


@pytest.mark.parametrize("home_by,expect_home", [
    (None, False),  # the default deadline (570 s) is far off at t = 300 s
    (305.0, True),  # 10 m from home, estimated at 1.5 x 10 m / 2 m/s: arrival 307.5 s, too late: leave now
    (float("nan"), False), ("soon", False), (-5.0, False),  # unusable values: the default applies
])
def test_return_deadline_comes_from_the_rover_when_it_has_a_usable_one(home_by, expect_home):
    r = make_rover(pos=(110.0, 85.0), t=300.0)
    r.home_by_s = home_by
    r.nav.home = (100.0, 85.0)
    decision.decision_step(r)
    heading_home = r.nav.path_goal is not None and r.nav.path_goal[0] == "home"
    assert heading_home == expect_home  # (its mode may read "stop" while it turns round)


def test_spinning_twice_at_one_place_backs_off_then_drives_ahead():
    """A rover wedged tail-first can neither reverse nor turn in place: the second try pulls away forward."""
    nav = decision.NavMemory()
    empty = np.zeros(0)
    phases = []
    t = 0.0
    for _ in range(2):
        while nav.recovery is None:
            s = decision.Inputs(t, (81.5, 75.6), 43.7, 0.0, empty, empty, empty, empty, empty, empty,
                                False, False, 1)
            decision._check_spinning(nav, s, "stop")
            t += DT
        phases.append(nav.recovery.command(t)[0])
        nav.recovery = None
    assert phases == ["back", "ahead"]


def _turn_toward_frontier_behind(follow_steer, seconds=4.0):
    """The only frontier is behind (east, rover faces west): the rover turns in place.

    follow_steer: the heading responds to the steering (45 deg/s at full lock) or stays put (wedged).
    """
    r = make_rover(pos=(100.0, 85.0), yaw=180.0)
    modes = []
    for k in range(int(seconds / DT)):
        r.total_time = 10.0 + k * DT
        decision.decision_step(r)
        assert_sane(r)
        modes.append(r.mode)
        if follow_steer and r.throttle == 0 and r.brake == 0:
            r.yaw = (r.yaw + 3.0 * DT * r.steer) % 360.0
    return modes


def test_wedged_turn_in_place_escapes_within_seconds():
    modes = _turn_toward_frontier_behind(follow_steer=False)
    assert modes[0] == "stop"
    first = modes.index("stuck")
    assert decision.ROTATE_BLOCKED_S <= first * DT <= decision.ROTATE_BLOCKED_S + 0.5
    assert first * DT < decision.ROTATE_TIMEOUT_S


def test_turn_in_place_that_turns_is_not_stuck():
    modes = _turn_toward_frontier_behind(follow_steer=True)
    assert modes[0] == "stop" and "stuck" not in modes


@pytest.mark.parametrize("remaining, explored, home_by, expect_home", [
    (1, True, None, False),  # a sample is missing: the default deadline stretches to SEARCH_HOME_BY_S
    (0, False, None, False),  # all in but the map is not complete: it stretches as well
    (0, True, None, True),  # all in, map complete: the default deadline (570 s) holds
    (1, False, 570.0, True),  # a deadline given for the mission never stretches
])
def test_default_deadline_stretches_while_samples_or_map_are_missing(remaining, explored, home_by, expect_home):
    r = make_rover(pos=(110.0, 85.0), t=600.0)
    r.samples_remaining = remaining
    r.home_by_s = home_by
    r.nav.home = (100.0, 85.0)
    r.nav.explored = explored
    decision.decision_step(r)
    heading_home = r.nav.path_goal is not None and r.nav.path_goal[0] == "home"
    assert heading_home == expect_home


def test_stretched_deadline_ends_when_the_search_has_nowhere_left_to_go():
    r = make_rover(pos=(110.0, 85.0), t=600.0)
    r.samples_remaining = 1
    r.nav.home = (100.0, 85.0)
    r.nav.search_left = False
    r.nav.explored = True
    decision.decision_step(r)
    assert r.nav.path_goal is not None and r.nav.path_goal[0] == "home"


def test_a_rock_seen_beside_a_wrong_remembered_spot_is_chased():
    """Seed 0 at 15 fps: the remembered rock spot was 2.1 m off; standing on it, the rover turned in
    place for 20 s ignoring the rock its camera showed (neither 'same' nor 2 m nearer)."""
    r = make_rover(pos=(97.0, 76.8), yaw=270.0)
    r.nav.rock_target = (97.0, 76.8)  # the rover stands on the remembered spot
    r.nav.rock_since, r.nav.rock_seen_time = 0.0, 0.0  # last seen long ago
    r.rock_angles, r.rock_dists = np.full(5, math.radians(10.0)), np.full(5, 2.1)  # the real rock, 2.1 m ahead
    decision.decision_step(r)
    tx, ty = r.nav.rock_target
    assert math.hypot(tx - 97.0, ty - 76.8) > 1.5  # now heading for the rock in view
    assert r.nav.rock_seen_time == r.total_time


def test_a_search_target_beside_a_stuck_spot_is_given_up():
    """Seed 23: the far-floor search went for the same target in the rock field by the start three times."""
    r = make_rover(pos=(92.0, 85.0))
    s = decision._read_inputs(r)
    r.nav.path_goal = ("search", (87, 94))  # 3 m away
    search_plan.give_up_search_goal_near(r.nav, s)
    assert r.nav.path_goal is None and r.nav.search_done[87, 94]
    r.nav.path_goal = ("search", (87, 140))  # far away: the stuck was on the way, not at the target
    search_plan.give_up_search_goal_near(r.nav, s)
    assert r.nav.path_goal == ("search", (87, 140)) and not r.nav.search_done[87, 140]


def test_turns_that_lined_up_a_collected_sample_are_no_spin():
    r = make_rover()
    nav = r.nav
    for k in range(150):  # 15 s of turning in place before the pickup
        nav.spin_hist.append((100.0 + 0.1 * k, True, 100.0, 85.0))
    r.total_time, r.picking_up, nav.was_picking = 125.0, False, True  # the 10 s pickup just ended
    s = decision._read_inputs(r)
    decision._update_memory(r, nav, s)
    decision._check_spinning(nav, s, "stop")
    assert nav.recovery is None and len(nav.collected) == 1


@pytest.mark.parametrize("leaving_pickup", [True, False])
def test_leaving_a_pickup_spot_turns_to_the_way_on_before_driving(leaving_pickup):
    """Seeds 3 and 23: after the pickup at a wall foot the rover arced off at full lock and climbed the wall."""
    r = make_rover()
    s = decision._read_inputs(r)
    r.nav.leaving_pickup = leaving_pickup
    cmd = decision._drive_heading(r.nav, s, math.radians(55.0), 3.0, planned=True)
    if leaving_pickup:
        assert cmd.throttle == 0.0 and r.nav.rotate_heading is not None  # turning in place first
    else:
        assert cmd.throttle > 0.0 and r.nav.rotate_heading is None  # arcing off as before
    cmd = decision._drive_heading(r.nav, s, math.radians(5.0), 3.0, planned=True)
    r.nav.rotate_heading = None
    assert not r.nav.leaving_pickup  # facing the way on: the next turns are ordinary driving


def test_a_reached_look_goal_turns_to_face_an_unsearched_nook_first():
    """Seed 10: at a search goal 4.4 m from the east-nook sample the rover marked the place searched
    and turned away; a goal beside a nook must first face wall feet the camera never saw from close by."""
    import perception
    r = make_rover(pos=(121.5, 82.5), yaw=90.0, t=500.0)
    mem = perception.get_memory(r)
    mem.look_range[:] = 1.0  # everything seen from close...
    mem.look_range[76:80, 123:127] = np.inf  # ...but the south wall's foot at x 123-126
    r.nav.in_sight[:] = True
    s = decision._read_inputs(r)
    r.nav.path_goal = ("look", (82, 121))  # reached
    r.nav.path_xy, r.nav.path_idx, r.nav.plan_time = np.array([(120.5, 82.5), (121.5, 82.5)]), 0, s.t
    decision.mode_search(r, r.nav, s)
    assert r.nav.rotate_heading is not None, "turns to look before calling the place searched"
    bearing = math.degrees(math.atan2(79.5 - 82.5, 124.5 - 121.5)) % 360.0  # about 315 deg
    assert abs((r.nav.rotate_heading - bearing + 180.0) % 360.0 - 180.0) <= 30.0
    assert not r.nav.search_done[82, 121], "not searched until the camera has faced it"
    mem.look_range[:] = 1.0  # now seen from close
    r.nav.rotate_heading = None
    decision.mode_search(r, r.nav, s)
    assert r.nav.rotate_heading is None and r.nav.look_stand_done[82, 121]


def test_wall_feet_a_look_stand_could_not_see_stay_open_for_another_stand():
    """Seeds 7 and 15: from a stand behind the rocks south-west of the east nook the rover faced the
    nook, saw only the rocks, and the whole place counted as searched; the sample was never found."""
    import perception
    r = make_rover(pos=(121.5, 82.5), yaw=315.0, t=500.0)
    perception.get_memory(r).look_range[:] = 1.0  # the footprint covered everything...
    r.nav.in_sight[:] = True
    r.nav.in_sight[76:80, 123:127] = False  # ...but a rock hid the nook's wall feet
    s = decision._read_inputs(r)
    r.nav.search_faced_goal, r.nav.search_faces = (82, 121), decision.SEARCH_FACES_PER_GOAL  # turned already
    r.nav.path_goal = ("look", (82, 121))
    r.nav.path_xy, r.nav.path_idx, r.nav.plan_time = np.array([(120.5, 82.5), (121.5, 82.5)]), 0, s.t
    decision.mode_search(r, r.nav, s)
    assert r.nav.look_stand_done[82, 121], "this stand is used up"
    assert not r.nav.look_done[76:80, 123:127].any(), "the hidden wall feet are still to be searched"
    assert r.nav.look_tries[79, 123] == 1  # the south wall (row 79) at x 123
    r.nav.search_faced_goal = (84, 125)  # a second stand, also blind
    search_plan.leave_look_stand(r, r.nav, s, (84, 125))
    assert r.nav.look_done[79, 123], "faced from two stands and still unseen: given up"


@pytest.mark.parametrize("feet_side, expect_left", [(True, True), (False, False)])
def test_turning_round_with_a_sample_missing_sweeps_the_camera_over_unsearched_wall_feet(feet_side, expect_left):
    """A path behind the rover (173 -> 16 deg): with unsearched wall feet at 320 deg, 6.5 m off, the turn
    goes the long way round (left) past them and still ends at 16 deg within the turn timeout."""
    pos = (16.7, 98.3)
    nav = decision.NavMemory()
    nav.unsearched = np.zeros((200, 200), bool)
    if feet_side:
        nav.unsearched[93:96, 20:23] = True  # around (21.7, 94.1)
    empty = np.zeros(0)
    yaw, t, faced = 173.0, 10.0, False
    s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(nav, s, 16.0, "path-behind")
    first = None
    while nav.rotate_heading is not None and t < 10.0 + decision.ROTATE_TIMEOUT_S + 1.0:
        s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
        cmd = decision.mode_stop(nav, s)
        if cmd is None:
            break
        first = cmd.steer if first is None else first
        yaw = (yaw + 3.0 * DT * cmd.steer) % 360.0  # 45 deg/s at full lock
        faced |= abs((yaw - 320.0 + 180.0) % 360.0 - 180.0) < 10.0
        t += DT
    assert (first > 0) == expect_left
    assert faced == expect_left
    assert abs((yaw - 16.0 + 180.0) % 360.0 - 180.0) <= decision.ROTATE_EXIT_DEG + 3.0
    assert t - 10.0 < decision.ROTATE_TIMEOUT_S


def test_a_turn_back_faces_unsearched_wall_feet_first_then_ends_at_the_wanted_heading():
    """Seed 15: the rover turned back 304 -> 187 deg the short way 3.4 m from the east nook (at ~10 deg)
    and never faced it; now it glances at the nook first, once per place."""
    pos = (145.5, 109.1)
    nav = decision.NavMemory()
    nav.unsearched = np.zeros((200, 200), bool)
    nav.unsearched[109:112, 148:150] = True  # around (149, 110.5)
    empty = np.zeros(0)
    yaw, t, faced = 304.0, 10.0, False
    s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(nav, s, 187.0, "path-behind")
    while nav.rotate_heading is not None and t < 10.0 + decision.ROTATE_TIMEOUT_S + 1.0:
        s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
        cmd = decision.mode_stop(nav, s)
        if cmd is None:
            break
        yaw = (yaw + 3.0 * DT * cmd.steer) % 360.0  # 45 deg/s at full lock
        faced |= abs((yaw - 20.0 + 180.0) % 360.0 - 180.0) < 15.0
        t += DT
    assert faced, "the camera faced the nook"
    assert nav.glance_hold_until > t, "and holds still there so a rock in view can be chosen"
    s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(nav, s, 187.0, "path-behind")
    assert nav.rotate_via is None, "glanced here already: the next turn back goes straight"
    while nav.rotate_heading is not None and t < 30.0:
        s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
        cmd = decision.mode_stop(nav, s)
        if cmd is None:
            break
        yaw = (yaw + 3.0 * DT * cmd.steer) % 360.0
        t += DT
    assert abs((yaw - 187.0 + 180.0) % 360.0 - 180.0) <= decision.ROTATE_EXIT_DEG + 3.0
    fresh = decision.NavMemory()
    fresh.unsearched = nav.unsearched
    s = decision.Inputs(t, pos, 304.0, 0.0, empty, empty, empty, empty, empty, empty, False, False, 0)
    decision._start_rotation(fresh, s, 187.0, "path-behind")
    assert fresh.rotate_via is None and fresh.rotate_heading == 187.0, "all samples in: no glance"
    fresh = decision.NavMemory()
    fresh.unsearched = nav.unsearched
    s = decision.Inputs(t, pos, 304.0, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(fresh, s, 187.0, "leave-pickup")
    assert fresh.rotate_via is None, "leaving a pickup: no glance"
    fresh = decision.NavMemory()
    fresh.unsearched = nav.unsearched
    angles = np.repeat(np.radians(np.arange(-40.0, 40.0, 0.5)), 20)
    dists = np.tile(np.linspace(1.0, 8.0, 20), angles.size // 20)  # open floor 8 m ahead
    s = decision.Inputs(t, pos, 304.0, 0.0, angles, dists, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(fresh, s, 187.0, "path-behind")
    assert fresh.rotate_via is None, "a way on ahead: no dead end, no glance"


def _turn_until_done(nav, pos, yaw, t, t_end):
    """Steer the turn in place in nav to its end (45 deg/s at full lock); (yaw, t, headings passed)."""
    empty = np.zeros(0)
    passed = []
    while nav.rotate_heading is not None and t < t_end:
        s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
        cmd = decision.mode_stop(nav, s)
        if cmd is None:
            break
        yaw = (yaw + 3.0 * DT * cmd.steer) % 360.0
        passed.append(yaw)
        t += DT
    return yaw, t, np.array(passed)


def test_the_turn_back_after_a_glance_the_other_way_still_sweeps_the_planned_arc():
    """Seed 0 at 10 fps: turning back 48 -> 291 deg (right, over the east nook at ~350 deg) the rover glanced
    left at wall feet at ~120 deg, then turned back the short way from there (left again) and never faced the
    nook. The turn back now goes right, through where the glance began, over the nook."""
    pos = (145.5, 109.8)
    nav = decision.NavMemory()
    nav.unsearched = np.zeros((200, 200), bool)
    nav.unsearched[112:115, 142:145] = True  # north-west wall feet, ~3.5 m off at ~120 deg: the glance
    empty = np.zeros(0)
    s = decision.Inputs(10.0, pos, 48.0, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(nav, s, 291.0, "path-behind")
    assert nav.rotate_via == 291.0 and 90.0 <= nav.rotate_heading <= 150.0, "glances left first"
    yaw, t, _ = _turn_until_done(nav, pos, 48.0, 10.0, 20.0)
    t = max(t, nav.glance_hold_until)
    s = decision.Inputs(t, pos, yaw, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(nav, s, 215.0, "path-behind")  # the path re-planned meanwhile: 215 deg, left of it
    assert nav.rotate_dir == -1
    yaw, t, passed = _turn_until_done(nav, pos, yaw, t, t + 10.0)
    assert abs((yaw - 215.0 + 180.0) % 360.0 - 180.0) <= decision.ROTATE_EXIT_DEG + 3.0
    assert (np.abs((passed - 350.0 + 180.0) % 360.0 - 180.0) < 10.0).any(), "the camera swept the nook"
    fresh = decision.NavMemory()  # no glance before it: the short way
    s = decision.Inputs(t, pos, 119.0, 0.0, empty, empty, empty, empty, empty, empty, False, False, 1)
    decision._start_rotation(fresh, s, 215.0, "path-behind")
    assert fresh.rotate_dir is None
    nav.glance_return = (-1, pos, t + 10.0)  # a glance long ago or elsewhere does not steer the turn
    s = decision.Inputs(t, (pos[0] + 5.0, pos[1]), 119.0, 0.0, empty, empty, empty, empty, empty, empty, False,
                        False, 1)
    decision._start_rotation(nav, s, 215.0, "path-behind")
    assert nav.rotate_dir is None and nav.glance_return is None


def test_a_rock_approach_decided_again_after_a_stuck_gets_its_own_close_timeout():
    """Seed 37 wedged twice at the east nook; the 30 s close timer ran out on the way to the third
    staging point (the one that works) and the rock was given up for 60 s."""
    r = make_rover(pos=(110.0, 85.0), yaw=0.0, t=100.0)
    nav = r.nav
    nav.rock_target, nav.rock_since = (113.0, 85.0), 60.0  # 3 m ahead, chased for 40 s of the 90
    nav.rock_close_since = 100.0 - decision.SAMPLE_CLOSE_TIMEOUT_S + 1.0  # close for 29 s
    nav.stage_for = None  # a stuck just now: the approach is decided again
    empty = np.zeros(0)
    for t in (100.0, 100.0 + 2.0):  # 31 s after first coming close
        s = decision.Inputs(t, r.pos, 0.0, 0.0, *clear_view(), empty, empty, empty, empty, False, False, 1)
        decision.mode_sample(r, nav, s)
    assert nav.rock_target is not None, "given up although the new approach had just started"
    nav.stage_for = nav.rock_target  # no new stuck: the timer runs on to the end
    s = decision.Inputs(100.0 + 2.0 + decision.SAMPLE_CLOSE_TIMEOUT_S + 0.5, r.pos, 0.0, 0.0, *clear_view(),
                        empty, empty, empty, empty, False, False, 1)
    decision.mode_sample(r, nav, s)
    assert nav.rock_target is None


def test_a_search_goal_under_the_wheels_is_ticked_off_not_a_reason_to_go_home():
    """Seed 15 (shadows on): a look stand in the rover's own cell gave a one-point path; mode_search
    returned nothing for that frame and the rover went home with two samples missing."""
    import perception
    r = make_rover(pos=(121.5, 80.5), yaw=270.0, t=480.0)  # beside the south wall (row 79), facing it
    r.samples_remaining = 2
    r.nav.home = (100.0, 85.0)
    r.nav.explored, r.nav.second_sweep_done = True, True
    perception.get_memory(r).look_range[:] = 1.0
    r.nav.in_sight[:] = True
    r.nav.in_sight[79, 119:124] = False  # wall feet right beside the rover, unseen
    r.nav.visits.last_visit[80:91, 90:130] = 400.0  # the whole corridor driven: no far floor
    r.nav.search_faced_goal, r.nav.search_faces = (80, 121), decision.SEARCH_FACES_PER_GOAL  # turned there already
    s = decision._read_inputs(r)
    cmd = decision.mode_search(r, r.nav, s)
    assert r.nav.look_stand_done[80, 121], "the stand under the wheels was ticked off"
    assert cmd is not None
    decision.decision_step(r)
    assert r.nav.path_goal is None or r.nav.path_goal[0] != "home"


def test_a_frontier_that_became_reachable_after_the_map_was_called_complete_is_explored():
    """Seed 15 (shadows on): the way into the west arm was blocked when the map was called complete;
    the rover later drove through it for a sample and went home with a fifth of the canyon unmapped."""
    r = make_rover(pos=(110.0, 85.0), t=400.0)  # the corridor's east end (x 130) is still open
    r.samples_remaining = 0
    r.nav.home = (100.0, 85.0)
    r.nav.explored, r.nav.second_sweep_done = True, True
    s = decision._read_inputs(r)
    assert not decision._should_go_home(r, r.nav, s)
    assert not r.nav.explored
    r.worldmap[80:91, 130, 0], r.worldmap[80:91, 130, 2] = 255, 0  # closed: nothing left to explore
    r.nav.explored = True
    assert decision._should_go_home(r, r.nav, s)


def test_the_search_keeps_an_open_goal_unless_another_is_much_nearer():
    """Seed 17 (15 fps): replanning every 1.5 s picked the cheapest goal afresh and the search went
    back and forth between the same few stands."""
    r = make_rover(pos=(100.5, 85.5), yaw=0.0, t=500.0)
    s = decision._read_inputs(r)
    free, obstacle, _ = paths.grids(r)
    dist = np.full((200, 200), np.inf)
    dist[80:91, 90:130] = np.abs(np.arange(90, 130) + 0.5 - 100.5)[None, :]
    unsearched = np.zeros((200, 200), bool)
    unsearched[79, 110:113] = True  # wall feet beside the current stand (80, 111)
    r.nav.path_goal = ("look", (80, 111))
    near = ("search", (85, 109))  # 9 m by path, straight ahead; the stand: 11 m and 24 deg off (14.4)
    assert search_plan.keep_search_goal(r.nav, s, near, dist, free, unsearched) == ("look", (80, 111))
    much_nearer = ("search", (85, 101))
    assert search_plan.keep_search_goal(r.nav, s, much_nearer, dist, free, unsearched) == much_nearer
    r.nav.look_stand_done[80, 111] = True  # the stand was used meanwhile: no longer open
    assert search_plan.keep_search_goal(r.nav, s, near, dist, free, unsearched) == near
    r.nav.look_stand_done[80, 111] = False
    unsearched[:] = False  # its wall feet were seen
    assert search_plan.keep_search_goal(r.nav, s, near, dist, free, unsearched) == near


def test_with_samples_missing_an_arm_tip_seen_from_6_m_is_still_a_frontier():
    """Seed 38: the north-arm tip, with a sample in it, was called explored from 7.7 m."""
    r = make_rover(pos=(110.0, 85.0), t=100.0)
    r.worldmap[80:91, 130, 0], r.worldmap[80:91, 130, 2] = 255, 0  # the corridor ends at x 130
    r.nav.seen_close[:] = False
    r.pos, r.yaw = (123.5, 85.5), 0.0  # the tip's end wall 7 m ahead: seen from close, not from near
    decision.decision_step(r)
    assert r.nav.seen_close[85, 130] and not r.nav.seen_near[85, 130]
    s = decision._read_inputs(r)
    assert exploration_plan.seen_for_frontiers(r.nav, s) is r.nav.seen_near
    r.samples_remaining = 0
    assert exploration_plan.seen_for_frontiers(r.nav, decision._read_inputs(r)) is r.nav.seen_close


def _rover_beside_a_faint_slot():
    """make_rover's corridor with its east end closed (no frontier left) and a slot running south from
    the south wall at x 108-110, mapped as wall but keeping 30 % of its votes as shadowed sand."""
    import perception
    r = make_rover(pos=(112.0, 85.0), yaw=180.0, t=300.0)
    wall = np.ones((200, 200), bool)
    wall[80:91, 90:130] = False
    r.worldmap[60:100, 80:140, 0][wall[60:100, 80:140]] = 255  # thick walls all round
    r.nav.seen_near[:] = True  # ...looked at from close
    mem = perception.get_memory(r)
    mem.obs_votes[70:80, 105:114] = 100.0
    mem.shade_votes[71:80, 108:111] = 30.0  # from the wall feet (row 79) 9 m deep
    return r


def _search_left_with_only_the_slot():
    """The faint-slot rover once the map is complete: floor far from the trail and every stand done."""
    r = _rover_beside_a_faint_slot()
    r.nav.search_done[:] = True
    r.nav.look_done[:] = True
    return r, decision._read_inputs(r)


def test_faint_pockets_are_search_goals_not_exploration_goals():
    """Seed 3 (shadows on): pockets counted as unsearched from the start moved glances while exploring
    and cost 49 s with all six found anyway; seeds 14 and 17 need them once the map is done. Exploration
    leaves them to the sample search, which drives in like to any other goal."""
    r, s = _search_left_with_only_the_slot()
    free, obstacle, _unknown = paths.grids(r)
    assert not search_plan.unsearched_wall_feet(r, r.nav, None, free, obstacle)[71:78, 108:111].any()
    exploration_plan.plan_explore(r, r.nav, s)
    assert r.nav.path_goal is None, "no frontier left: exploration has nothing to drive to"
    search_plan.plan_search(r, r.nav, s)
    kind, (row, col) = r.nav.path_goal
    assert kind == "pocket" and r.nav.pocket_goal is not None and r.nav.pocket_goal[row, col]
    assert 75 <= row <= 78 and 108 <= col <= 110, "up to 3.5 m into the slot"
    search_plan.pocket_done(r.nav, (row, col))  # driven into
    search_plan.plan_search(r, r.nav, s)
    assert r.nav.path_goal is None and not r.nav.search_left, "a pocket driven into is not chased again"


def test_a_nearer_search_goal_comes_before_a_faint_pocket():
    """Seed 0 (shadows on): exploration toured pockets first and drove from 13 m beside the east nook to
    the south arm's pockets; the sixth sample, in the nook, was found 170 s later. Nearest goal first."""
    dist = np.full((200, 200), np.inf)
    dist[85, 100], dist[60, 100] = 10.0, 40.0
    look, pocket = (85, 100), (60, 100)
    assert explore.nearer_search_goal(None, None, dist, look, pocket=pocket) == ("look", look)
    dist[85, 100] = 50.0
    assert explore.nearer_search_goal(None, None, dist, look, pocket=pocket) == ("pocket", pocket)


def test_the_search_finishes_where_it_began_then_looks_into_faint_pockets_then_goes_nearest_first():
    """Seed 0 (shadows on): exploration's pocket tour drove from 13 m beside the east nook to the south arm's
    pockets; the nook's sample was found 170 s later. Seed 17 (shadows on): nearest first without the
    pockets' turn reached the south spur's pocket, and its sample, at 792 s."""
    from types import SimpleNamespace
    nav = SimpleNamespace(search_began=(400.0, (100.5, 100.5)))
    s = SimpleNamespace(t=410.0, pos=(100.5, 100.5), yaw=0.0)
    dist = np.full((200, 200), np.inf)
    near_look, far_look, pocket = (100, 110), (100, 125), (40, 100)  # 9.5 m and 24.5 m from the start; pocket 60 m
    dist[near_look], dist[far_look], dist[pocket] = 10.0, 25.0, 70.0
    goals = {"peek": None, "search": None, "look": near_look, "pocket": pocket}
    assert search_plan._tiered_goal(nav, s, dist, goals) == ("look", near_look), "near the start: first"
    goals["look"] = far_look
    assert search_plan._tiered_goal(nav, s, dist, goals) == ("pocket", pocket), "then the pockets, before the rest"
    s.t = 400.0 + search_plan.SEARCH_POCKETS_FIRST_S + 1.0
    assert search_plan._tiered_goal(nav, s, dist, goals) == ("look", far_look), "then nearest first"
    goals["look"] = None
    assert search_plan._tiered_goal(nav, s, dist, goals) == ("pocket", pocket)
    goals["pocket"] = None
    assert search_plan._tiered_goal(nav, s, dist, goals) is None


def test_a_faint_pocket_the_rover_got_stuck_in_is_done():
    """Seed 17 (shadows on): the rover spent 40 s stuck on a shaded slope it took for a pocket."""
    r, s = _search_left_with_only_the_slot()
    search_plan.plan_search(r, r.nav, s)
    kind, (row, col) = r.nav.path_goal
    assert kind == "pocket"
    s.pos = (col + 0.5, row + 3.5)  # 3 m short of it, wedged
    search_plan.give_up_search_goal_near(r.nav, s)
    assert r.nav.pocket_reached[row, col] and r.nav.path_goal is None
    search_plan.plan_search(r, r.nav, s)
    assert r.nav.path_goal is None, "not chased again"


def test_a_remembered_rock_under_the_rover_is_given_up_not_turned_to():
    """Seed 16 at 15 fps: a rock remembered 0.1-0.4 m from the rover origin drew nine turns in place."""
    r = make_rover(pos=(131.1, 115.3), yaw=190.0, t=67.0)
    r.nav.rock_target = (131.08, 115.37)
    r.nav.rock_since, r.nav.rock_seen_time = 60.0, 60.0  # last seen in the camera 7 s ago
    decision.decision_step(r)
    assert r.nav.rotate_heading is None and r.throttle == 0.0
    assert r.nav.rock_target is None
    assert any(abs(x - 131.08) < 0.01 for x, _y, _until in r.nav.rock_skip)


def _rock_beside(seen_close=True, seen_time=198.0, lateral_m=0.5):
    """A rover at (110, 85) facing east, in sample mode for a rock lateral_m to its right, and a step(t, pos)
    that runs mode_sample with an open floor in view and no rock pixels."""
    r = make_rover(pos=(110.0, 85.0), yaw=0.0, t=200.0)
    nav = r.nav
    nav.rock_target, nav.rock_since, nav.rock_close_since = (110.0, 85.0 - lateral_m), 195.0, 196.0
    nav.rock_seen_time, nav.rock_seen_close, nav.rock_came_close = seen_time, seen_close, True
    nav.stage_for, nav.stage_done = nav.rock_target, True
    empty = np.zeros(0)

    def step(t, pos=r.pos):
        s = decision.Inputs(t, pos, 0.0, 0.0, *clear_view(), empty, empty, empty, empty, False, False, 1)
        return decision.mode_sample(r, nav, s)

    return nav, step


def test_a_rock_seen_close_and_now_beside_the_rover_is_backed_off_from_once_then_given_up():
    """Held-out seed 89 (shadows on) drove to 0.5 m of the east-nook rock with it beside the rover
    (near_sample off, out of the camera's view) and gave it up as a phantom at 801 s."""
    nav, step = _rock_beside()
    cmd = step(200.0)
    assert nav.rock_target is not None and cmd.throttle < 0 and cmd.steer == 0.0
    assert step(200.0 + decision.ROCK_BESIDE_BACK_S - 0.1).throttle < 0, "still reversing"
    step(200.0 + decision.ROCK_BESIDE_BACK_S + 0.1)  # the rover did not move here: the rock is still beside it
    assert nav.rock_target is None, "a second time beside the rover: given up as before"


def test_backing_off_from_a_rock_beside_the_rover_ends_once_it_is_clear():
    nav, step = _rock_beside()
    assert step(200.0).throttle < 0
    back = (110.0 - decision.ROCK_BESIDE_CLEAR_M, 85.0)  # reversed far enough: the rock is ahead, to the right
    assert step(201.0, back).throttle >= 0 and nav.rock_target is not None


def test_a_rock_never_seen_close_under_the_rover_is_given_up_at_once():
    nav, step = _rock_beside(seen_close=False, seen_time=180.0, lateral_m=0.3)
    step(200.0)
    assert nav.rock_target is None
