"""Latency lead (navigation.predict) and frontiers hidden behind given-up goals (explore.ignored_frontiers)."""
import math

import numpy as np
import pytest

import decision
from navigation import approach, astar, explore, grid, predict


# ------------------------------------------------------------------ lead estimator
def test_lead_is_the_smoothed_frame_interval_on_the_clients_clock():
    est = predict.LeadEstimator()
    assert est.lead_s == 0.0  # nothing measured yet: no prediction
    for k in range(60):
        est.update(k / 15.0, 90.0)  # 15 fps
    assert est.lead_s == pytest.approx(1 / 15.0, rel=1e-3)
    assert est.yaw_rate_dps == pytest.approx(0.0)


def test_lead_is_capped_and_pauses_are_not_intervals():
    est = predict.LeadEstimator()
    est.update(0.0, 0.0)
    est.update(0.5, 0.0)  # a slow machine: 2 fps
    assert est.lead_s == predict.LEAD_MAX_S
    est.update(10.0, 0.0)  # a 9.5 s pause (simulator menu) is not a frame interval
    assert est.interval_s == pytest.approx(0.5)


def test_yaw_rate_wraps_across_north_and_ignores_bad_input():
    est = predict.LeadEstimator()
    est.update(0.0, 359.0)
    est.update(0.1, 3.5)  # turned 4.5 deg CCW through 0
    assert est.yaw_rate_dps == pytest.approx(45.0)
    est.update(float("nan"), 10.0)
    est.update(0.2, float("inf"))
    assert est.yaw_rate_dps == pytest.approx(45.0) and est.interval_s == pytest.approx(0.1)


# ------------------------------------------------------------------ pose prediction
def test_straight_prediction_moves_along_the_heading():
    x, y, yaw = predict.predict_pose(10.0, 20.0, 90.0, 2.0, 0.0, 0.1)
    assert (x, y, yaw) == pytest.approx((10.0, 20.2, 90.0))


def test_arc_prediction_stays_on_the_circle():
    # 1 m/s at 45 deg/s for 2 s: a quarter... of a circle of radius 1/(pi/4) m, heading 0 -> 90
    r = 1.0 / math.radians(45.0)
    x, y, yaw = predict.predict_pose(0.0, 0.0, 0.0, 1.0, 45.0, 2.0)
    assert yaw == pytest.approx(90.0)
    assert (x, y) == pytest.approx((r, r))


def test_prediction_with_bad_numbers_returns_the_pose():
    assert predict.predict_pose(1.0, 2.0, 30.0, float("nan"), 0.0, 0.1) == (1.0, 2.0, 30.0)
    assert predict.predict_pose(1.0, 2.0, 30.0, 3.0, 0.0, -1.0) == (1.0, 2.0, 30.0)


@pytest.mark.parametrize("err,rate,lead,expect", [
    (20.0, 45.0, 0.1, 15.5),  # turning toward the target: 4.5 deg of it happen before the command acts
    (3.0, 45.0, 0.1, 0.0),  # the target is passed within the lead: done now
    (-20.0, -45.0, 0.1, -15.5),  # the same, clockwise
    (20.0, -45.0, 0.1, 20.0),  # still swinging the other way: no credit
    (20.0, 0.0, 0.1, 20.0),  # not yet turning
])
def test_turn_in_place_is_judged_at_the_lead(err, rate, lead, expect):
    assert predict.heading_error_at_lead(100.0 + err, 100.0, rate, lead) == pytest.approx(expect)


def test_distance_at_lead_never_negative_and_ignores_reverse():
    assert predict.distance_at_lead(1.0, 2.0, 0.1) == pytest.approx(0.8)
    assert predict.distance_at_lead(0.1, 2.0, 0.1) == 0.0
    assert predict.distance_at_lead(1.0, -1.0, 0.1) == 1.0


def test_turn_in_place_stops_earlier_with_latency():
    """The same turn, measured at 10 fps with the rover turning at 45 deg/s, ends a frame sooner."""
    def frames_until_done(with_lead):
        nav = decision.NavMemory()
        nav.rotate_heading, nav.rotate_since = 90.0, 0.0
        yaw, t = 60.0, 0.0
        for k in range(40):
            s = decision.Inputs(t=t, pos=(100.0, 85.0), yaw=yaw, vel=0.0, nav_angles=np.zeros(0),
                                nav_dists=np.zeros(0), obs_angles=np.zeros(0), obs_dists=np.zeros(0),
                                rock_angles=np.zeros(0), rock_dists=np.zeros(0), near_sample=False,
                                picking_up=False, samples_remaining=6)
            if with_lead:
                nav.lead.update(t, yaw)
            if decision.mode_stop(nav, s) is None:
                return k
            yaw, t = yaw + 4.5, t + 0.1
        return None
    assert frames_until_done(True) < frames_until_done(False)


# ------------------------------------------------------------------ frontiers behind given-up goals
def _arm_behind_a_given_up_goal():
    """A mapped hub with one arm going east; the arm's open end (x 140) was given up."""
    wm = np.zeros((200, 200, 3), np.uint8)
    wm[80:91, 90:141, 2] = 255  # hub + arm, open at the east end (x 141+ unknown)
    wm[79, 89:142, 0] = 255
    wm[91, 89:142, 0] = 255
    wm[79:92, 89, 0] = 255
    free, obstacle, unknown = grid.classify(wm)
    ignored = np.zeros_like(free)
    explore.ignore_disc(ignored, (85, 140), radius=6.0)
    cost = grid.cost_grid(free, obstacle)
    dist, _ = astar.distance_field(cost, (85, 95))
    return free, obstacle, unknown, ignored, dist


def test_the_only_frontier_given_up_leaves_the_map_complete_to_the_planner():
    free, obstacle, unknown, ignored, dist = _arm_behind_a_given_up_goal()
    mask = explore.frontier_mask(free, unknown, ignored)
    assert explore.map_complete(explore.frontier_targets(mask, dist))  # what used to send the rover home


def test_a_reachable_given_up_frontier_is_reported():
    free, obstacle, unknown, ignored, dist = _arm_behind_a_given_up_goal()
    hidden = explore.ignored_frontiers(free, unknown, ignored, dist)
    assert len(hidden) == 1 and abs(hidden[0][1] - 140) <= 1


def test_an_unreachable_given_up_frontier_is_not_reported():
    free, obstacle, unknown, ignored, _ = _arm_behind_a_given_up_goal()
    cost = grid.cost_grid(free, obstacle)
    cost[80:91, 120] = np.inf  # a wall across the arm (e.g. a rock)
    dist, _ = astar.distance_field(cost, (85, 95))
    assert len(explore.ignored_frontiers(free, unknown, ignored, dist)) == 0


def _rover_with_abandoned_arm():
    from rover_state import RoverState
    r = RoverState()
    r.pos, r.yaw, r.total_time, r.vel = (110.0, 85.0), 0.0, 100.0, 0.0
    r.start_pos = (100.0, 85.0)
    r.samples_remaining, r.samples_initial = 0, 6  # every sample is in
    rng = np.random.default_rng(0)
    r.nav_angles, r.nav_dists = rng.uniform(-0.6, 0.6, 2000), rng.uniform(1.0, 8.0, 2000)  # open floor ahead
    r.worldmap[80:91, 90:141, 2] = 255
    r.worldmap[79, 89:142, 0] = 255
    r.worldmap[91, 89:142, 0] = 255
    r.worldmap[79:92, 89, 0] = 255
    r.nav = decision.NavMemory()
    r.nav.seen_close[:] = True
    return r


@pytest.mark.parametrize("abandoned", [True, False])
def test_all_samples_in_but_an_arm_given_up_is_explored_before_going_home(abandoned):
    r = _rover_with_abandoned_arm()
    explore.ignore_disc(r.nav.frontier_ignored, (85, 140), radius=6.0)
    if abandoned:  # given up (stuck / not getting closer), not reached
        explore.ignore_disc(r.nav.frontier_abandoned, (85, 140), radius=6.0)
    goal = None
    for _ in range(200):
        r.total_time += 0.1
        decision.decision_step(r)
        goal = r.nav.path_goal
        if goal is not None and goal[1] is not None and goal[0] in ("home", "frontier"):
            break
    if abandoned:
        assert r.nav.second_sweep_done and goal[0] == "frontier" and abs(goal[1][1] - 140) <= 2
    else:  # a frontier the rover reached and could not see past does not hold it back
        assert goal[0] == "home"


def test_a_frontier_behind_cells_remembered_as_stuck_is_still_explored():
    """Stuck memory across the only way into an arm must not make the map look complete."""
    r = _rover_with_abandoned_arm()
    r.samples_remaining = 0
    r.nav.blocked_at[79:92, 118:121] = r.total_time  # stuck there just now: across the arm, walls included
    goal = None
    for _ in range(40):
        r.total_time += 0.1
        decision.decision_step(r)
        goal = r.nav.path_goal
        if goal is not None and goal[1] is not None:
            break
    assert not r.nav.explored and goal[0] == "frontier" and abs(goal[1][1] - 140) <= 2


# ------------------------------------------------------------------ nook approach
def _nook():
    """Open floor x 80..120, y 80..100, and a 2 m wide nook going east at y 90..91 to x 126; sample at its end."""
    free = np.zeros((200, 200), bool)
    free[80:101, 80:121] = True
    free[89:92, 121:127] = True
    return free, (125.5, 90.5)


def test_sample_in_a_nook_is_lined_up_from_its_opening_whatever_side_the_rover_comes_from():
    free, sample = _nook()
    for rover in [(118.0, 99.0), (118.0, 81.0), (100.0, 90.0), (119.5, 85.0)]:
        stage = approach.staging_point(free, sample, rover)
        assert stage is not None
        x, y, heading = stage
        assert x < sample[0] - 2.0 and abs(y - sample[1]) < 1.0  # in the opening (3 m wide), near its axis
        assert abs(predict.wrap_deg(heading - 0.0)) < 16.0  # facing east, into the nook
        assert approach.direct_run_clear(free, (x, y), sample)


def test_direct_run_is_clear_on_open_floor_and_blocked_past_a_corner():
    free, sample = _nook()
    assert approach.direct_run_clear(free, (121.0, 90.5), sample)  # straight down the nook
    assert not approach.direct_run_clear(free, (119.0, 98.0), sample)  # the corner is in the way
    assert approach.staging_point(np.zeros((200, 200), bool), sample) is None  # nowhere clear: no staging
    assert approach.staging_point(free, (float("nan"), 1.0)) is None


def test_east_nook_of_the_real_map_has_a_clear_staging_point_from_any_side():
    import shared_data
    from evaluation.metrics import load_ground_truth
    path = shared_data.ground_truth_map_path()
    if not shared_data.available(path):
        pytest.skip(f"no ground-truth map at {path} (set ROVER_SHARED)")
    free = load_ground_truth(path) > 0
    sample = (148.8, 109.6)
    for a in range(0, 360, 45):
        rover = (sample[0] + 6 * math.cos(math.radians(a)), sample[1] + 6 * math.sin(math.radians(a)))
        stage = approach.staging_point(free, sample, rover)
        assert stage is not None, a
        assert free[int(stage[1]), int(stage[0])]
        assert 145.0 < stage[0] < 148.0 and stage[1] > 109.6  # in the opening, north-west of the sample
        assert abs(predict.wrap_deg(stage[2] - 340.0)) < 20.0  # facing into the nook (east-south-east)
    assert not approach.direct_run_clear(free, (146.0, 104.0), sample)  # from the south the rocks are in the way


def test_a_nook_approach_that_wedged_is_replanned_from_the_open_side():
    """East-nook pattern: low rocks south of the sample map as floor (a clear straight run), the real
    opening (west here) reads as wall foot on the 1 m map.  Once the rover got stuck on the false
    floor, the approach must use another side, not the same run again."""
    free = np.zeros((200, 200), bool)
    free[80:101, 100:120] = True  # open floor
    free[84:90, 120:123] = True  # false floor south of the sample
    free[89:92, 119] = False  # the real opening, west of the sample, mapped as wall foot
    sample, arrival = (121.8, 90.5), (121.5, 85.5)
    blocked = np.zeros_like(free)
    assert approach.plan_approach(free, blocked, sample, arrival) is None  # the map says: straight in
    blocked[87:90, 120:123] = True  # stuck there
    x, y, heading = approach.plan_approach(free, blocked, sample, arrival)
    assert x < sample[0] - 2.0 and abs(y - sample[1]) < 1.0  # west of the sample, in the opening
    assert abs(predict.wrap_deg(heading)) < 20.0  # facing east, into the nook
    far_blocked = np.zeros_like(free)
    far_blocked[40, 40] = True  # stuck elsewhere: no reason to doubt the map here
    assert approach.plan_approach(free, far_blocked, sample, arrival) is None


def _gap_nook():
    """East-nook pattern with two ways in: false floor south of the sample (wide, ranked first) and the real
    opening west of it (narrower)."""
    free = np.zeros((200, 200), bool)
    free[80:101, 100:120] = True  # open floor west and south-west
    free[80:90, 120:126] = True  # false floor south of the sample (the gap between two rocks)
    free[90:92, 119:121] = True  # the real opening, west of the sample
    return free, (121.8, 91.0)


def test_a_staging_side_whose_approach_wedged_is_not_chosen_again():
    free, sample = _gap_nook()
    first = approach.staging_point(free, sample, (123.0, 84.0))
    assert first is not None and first[1] < sample[1] - 1.5  # the wide false floor to the south wins at first
    again = approach.staging_point(free, sample, (123.0, 84.0), wedged_stages=[first[:2]])
    assert again is not None
    bearing = math.degrees(math.atan2(again[1] - sample[1], again[0] - sample[0]))
    wedged = math.degrees(math.atan2(first[1] - sample[1], first[0] - sample[0]))
    assert abs(predict.wrap_deg(bearing - wedged)) > approach.STAGE_WEDGED_DEG
    assert again[0] < sample[0] - 1.5  # from the west, the real opening
    # a staging point wedged at another sample, or none at all, changes nothing
    assert approach.staging_point(free, sample, (123.0, 84.0), wedged_stages=[]) == first
    blocked = np.zeros_like(free)
    blocked[88:90, 121:123] = True  # where it wedged, on its run in from that staging point
    assert approach.plan_approach(free, blocked, sample, (123.0, 84.0), wedged_stages=[first[:2]]) == again


def test_a_stuck_on_the_way_to_a_staging_point_is_remembered_for_that_rock_only():
    r = _rover_with_abandoned_arm()
    nav = r.nav
    nav.rock_target = nav.stage_for = (115.0, 85.0)
    nav.stage = (112.5, 85.0, 0.0)
    nav.mode = "sample"
    s = decision._read_inputs(r)
    decision._begin_recovery(nav, s, "stuck", 3.0)
    assert nav.stages_wedged == [(115.0, 85.0, 112.5, 85.0)]
    nav.stage, nav.stage_for, nav.mode = (118.0, 85.0, 180.0), (130.0, 85.0), "forward"
    decision._begin_recovery(nav, s, "stuck", 3.0)  # exploring, not approaching: nothing to remember
    assert nav.stages_wedged == [(115.0, 85.0, 112.5, 85.0)]


def test_a_stuck_during_a_rock_approach_makes_it_decided_again():
    r = _rover_with_abandoned_arm()
    r.nav.rock_target = r.nav.stage_for = (115.0, 85.0)
    r.nav.stage = None
    s = decision._read_inputs(r)
    decision._begin_recovery(r.nav, s, "stuck", 3.0)
    assert r.nav.stage_for is None


def test_a_staging_point_just_behind_the_rover_counts_as_reached():
    """Seed 23: 0.7 m past its staging point, the rover turned 180 deg to face it, then back to the rock."""
    free, sample = _nook()
    r = _rover_with_abandoned_arm()
    r.worldmap[:] = 0
    r.worldmap[free, 2] = 255
    r.pos, r.yaw = (122.0, 90.5), 0.0  # facing the rock, 1 m past the staging point
    nav = r.nav
    nav.rock_target = nav.stage_for = sample
    nav.stage, nav.stage_done = (121.0, 90.5, 0.0), False
    s = decision._read_inputs(r)
    assert decision._stage_approach(r, nav, s, math.hypot(sample[0] - 122.0, 0.0)) is None
    assert nav.stage_done and nav.rotate_heading is None
