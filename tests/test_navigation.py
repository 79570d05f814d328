"""Planning helpers on synthetic maps: grids, A*, pure pursuit, reactive profile, frontiers, stuck."""
import math

import cv2
import numpy as np
import pytest

from navigation import astar, explore, grid, pursuit, reactive, stuck, turning


def corridor_map():
    """Worldmap with a wall across x=100 that has one gap at y 150..155."""
    wm = np.zeros((200, 200, 3), np.uint8)
    wm[20:180, 20:180, 2] = 255
    wm[20:180, 100, 2] = 0
    wm[20:180, 100, 0] = 255
    wm[150:156, 100, 0] = 0
    wm[150:156, 100, 2] = 255
    return wm


def test_classify_splits_free_obstacle_unknown():
    free, obst, unknown = grid.classify(corridor_map())
    assert free[50, 50] and not obst[50, 50]
    assert obst[50, 100] and not free[50, 100]
    assert unknown[5, 5]
    assert not (free & obst).any()


def test_cost_grid_is_impassable_on_obstacles_and_dearer_near_them():
    free, obst, _ = grid.classify(corridor_map())
    cost = grid.cost_grid(free, obst)
    assert np.isinf(cost[50, 100])
    assert np.isinf(cost[5, 5]), "unknown is impassable unless allowed"
    assert cost[50, 99] > cost[50, 90] >= grid.FREE_COST
    cost_u = grid.cost_grid(free, obst, allow_unknown=True)
    assert np.isfinite(cost_u[5, 5])


def test_astar_goes_through_the_gap():
    free, obst, _ = grid.classify(corridor_map())
    cost = grid.cost_grid(free, obst)
    path = astar.astar(cost, (50, 50), (50, 150))
    assert path[0] == (50, 50) and path[-1] == (50, 150)
    rows_at_wall = [r for r, c in path if c == 100]
    assert rows_at_wall and all(150 <= r <= 155 for r in rows_at_wall)
    steps = np.abs(np.diff(np.asarray(path), axis=0))
    assert steps.max() <= 1


def test_astar_reports_no_path():
    cost = np.ones((50, 50), np.float32)
    cost[:, 25] = np.inf
    assert astar.astar(cost, (10, 10), (10, 40)) == []


def test_distance_field_matches_astar_length():
    free, obst, _ = grid.classify(corridor_map())
    cost = grid.cost_grid(free, obst)
    dist, parent = astar.distance_field(cost, (50, 50))
    p1 = astar.path_to(parent, cost.shape, (50, 150))
    p2 = astar.astar(cost, (50, 50), (50, 150))
    assert len(p1) > 0 and abs(astar.path_length(p1) - astar.path_length(p2)) < 3.0


def test_pursuit_steers_left_for_a_path_to_the_left():
    path = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0], [4.0, 4.0]])
    steer, alpha, *_ = pursuit.pursue(path, (0.0, 0.0), 0.0, 1.0)
    assert steer > 0 and alpha > 0
    steer, alpha, *_ = pursuit.pursue(path * [1, -1], (0.0, 0.0), 0.0, 1.0)
    assert steer < 0 and alpha < 0
    steer, alpha, *_ = pursuit.pursue(np.array([[0, 0], [5.0, 0.0]]), (0.0, 0.0), 0.0, 1.0)
    assert abs(steer) < 1e-6


def test_steer_command_grows_with_speed_for_the_same_curvature():
    slow = pursuit.steer_for_curvature(0.05, 0.5)
    fast = pursuit.steer_for_curvature(0.05, 4.5)
    assert 0 < slow < fast <= 15.0
    assert pursuit.steer_for_curvature(10.0, 0.0) == 15.0
    assert pursuit.steer_for_curvature(float("nan"), 1.0) == 0.0


def test_reactive_profile_avoids_a_blocked_centre():
    rng = np.random.default_rng(1)
    a = rng.uniform(-0.8, 0.8, 5000)
    d = rng.uniform(0.8, 8.0, 5000)
    keep = ~((np.abs(a) < 0.2) & (d > 1.5))  # a rock 1.5 m ahead hides the floor behind it
    reach = reactive.reach_profile(a[keep], d[keep])
    heading, clear = reactive.choose_heading(reach, 0.0)
    assert abs(heading) > 0.15 and clear >= reactive.CLEAR_REACH_M
    heading, clear = reactive.choose_heading(reactive.reach_profile(a, d), 0.0)
    assert heading == 0.0
    assert reactive.choose_heading(reactive.reach_profile([], []), 0.0)[1] == 0.0


def test_frontiers_are_mapped_cells_next_to_unknown_and_ranked_by_path():
    wm = np.zeros((200, 200, 3), np.uint8)
    wm[90:111, 50:151, 2] = 255  # open strip
    wm[89, 50:151, 0] = wm[111, 50:151, 0] = 255  # walls north and south
    free, obst, unknown = grid.classify(wm)
    mask = explore.frontier_mask(free, unknown)
    assert mask[100, 50] and mask[100, 150] and not mask[100, 100]
    cost = grid.cost_grid(free, obst)
    dist, _ = astar.distance_field(cost, (100, 95))
    targets = explore.frontier_targets(mask, dist)
    assert len(targets) == 2
    goal = explore.choose_target(targets, (95.5, 100.5), 0.0)
    assert goal[1] == 150, "heading east, the east frontier wins though slightly further"
    goal = explore.choose_target(targets, (95.5, 100.5), 180.0)
    assert goal[1] == 50
    ignored = np.zeros((200, 200), bool)
    explore.ignore_disc(ignored, (100, 50), radius=12)
    explore.ignore_disc(ignored, (100, 150), radius=12)
    assert explore.map_complete(explore.frontier_targets(explore.frontier_mask(free, unknown, ignored), dist))


def test_loop_detector_flags_circling_but_not_a_straight_drive():
    det = explore.LoopDetector()
    flagged = False
    for k in range(300):
        t = k * 0.04
        yaw = (k * 2.0) % 360
        flagged |= det.update(t, (100 + 2 * math.cos(math.radians(yaw)), 100 + 2 * math.sin(math.radians(yaw))), yaw)
    assert flagged
    det = explore.LoopDetector()
    assert not any(det.update(k * 0.04, (100 + 0.1 * k, 100), 0.0) for k in range(300))


def test_progress_monitor_and_recovery_script():
    mon = stuck.ProgressMonitor()
    hits = [mon.update(k * 0.04, (10.0, 10.0), True) for k in range(100)]
    assert not any(hits[:70]) and hits[-1]
    mon.reset()
    assert not any(mon.update(k * 0.04, (10 + 0.05 * k, 10.0), True) for k in range(200))
    assert not any(mon.update(k * 0.04, (10.0, 10.0), False) for k in range(200))
    rec = stuck.Recovery(0.0, turn_sign=1.0)
    back = rec.command(0.1)
    assert back[0] == "back" and back[1] < 0 and back[3] < 0, "reversing with right lock swings the nose left"
    phases = [out[0] for out in (rec.command(t) for t in np.arange(0.2, 3.0, 0.1)) if out]
    assert phases[0] == "back" and "turn" in phases
    assert rec.command(100.0) is None
    cells = stuck.blocked_cells_ahead((50.0, 50.0), 0.0)
    assert (cells[:, 1] >= 50).all() and len(cells) >= 2


def test_unconfirmed_far_obstacles_stay_frontier_until_seen_close():
    wm = np.zeros((200, 200, 3), np.uint8)
    wm[95:106, 50:80, 2] = 255  # mapped floor
    wm[95:106, 80:88, 0] = 255  # far ground mapped as obstacle (a narrowing canyon seen from afar)
    wm[94, 50:88, 0] = wm[106, 50:88, 0] = 255
    free, obst, unknown = grid.classify(wm)
    seen = np.zeros((200, 200), bool)
    explore.mark_seen_close(seen, (55.0, 100.0), 0.0)  # looked at from far away only
    mask = explore.frontier_mask(free, unknown, None, obst, seen)
    assert mask[100, 79], "the red band was never seen from close: it is still a frontier"
    explore.mark_seen_close(seen, (76.0, 100.0), 0.0)  # now from close
    assert seen[100, 82] and not seen[100, 66]
    mask = explore.frontier_mask(free, unknown, None, obst, seen)
    assert not mask[100, 79]


def test_forward_escape_drives_ahead_at_full_lock():
    rec = stuck.Recovery(0.0, turn_sign=-1.0, ahead=True)
    name, throttle, brake, steer = rec.command(0.1)
    assert name == "ahead" and throttle > 0 and brake == 0 and steer < 0
    assert [rec.command(t)[0] for t in np.arange(0, 3.0, 0.1) if rec.command(t)][-1] == "turn"


def _run_recovery(rec, pose_at, until=10.0, dt=0.04):
    """Drive a Recovery with poses from pose_at(t, out); returns the (t, phase, throttle, steer) it produced."""
    out, t = [], 0.0
    while t < until:
        cmd = rec.command(t, pose_at(t, out))
        if cmd is None:
            break
        out.append((t, cmd[0], cmd[1], cmd[3]))
        t += dt
    return out


def test_recovery_swaps_a_freeing_move_that_does_not_budge_the_rover():
    """Wedged so that only pulling away forward to the left moves it: the escape finds that move."""
    pose = [50.0, 50.0, 90.0]

    def pose_at(t, out):
        if out and out[-1][2] > 0 and out[-1][3] > 0:  # only forward with left lock moves
            pose[1] += 0.02
        return tuple(pose)

    out = _run_recovery(stuck.Recovery(0.0, turn_sign=1.0), pose_at)
    moves = [(name, np.sign(thr), np.sign(st)) for _, name, thr, st in out if name in ("back", "ahead")]
    tried = list(dict.fromkeys(moves))
    assert tried[0] == ("back", -1, -1) and ("ahead", 1, 1) in tried
    assert tried[-1] == ("ahead", 1, 1), "once a move frees the rover the escape keeps it"
    kept = sum(1 for m in moves if m == ("ahead", 1, 1)) * 0.04
    assert kept >= stuck.BACK_OFF_S - 0.1
    assert pose[1] > 50.5


def test_recovery_that_moves_keeps_its_first_move_and_full_turn():
    pose = [50.0, 50.0, 90.0]

    def pose_at(t, out):
        if out:
            pose[1] += 0.03 * np.sign(out[-1][2])
            pose[2] += 1.8 * np.sign(out[-1][3]) if out[-1][1] == "turn" else 0.0
        return tuple(pose)

    out = _run_recovery(stuck.Recovery(0.0, turn_sign=-1.0), pose_at)
    assert {name for _, name, thr, st in out if thr != 0} == {"back"}
    turn_s = sum(1 for o in out if o[1] == "turn") * 0.04
    assert turn_s >= stuck.TURN_S - 0.1


def test_pinned_rover_tries_every_move_and_cuts_the_blocked_turn_short():
    out = _run_recovery(stuck.Recovery(0.0, turn_sign=1.0), lambda t, o: (50.0, 50.0, 90.0))
    moves = {(name, np.sign(thr), np.sign(st)) for _, name, thr, st in out if name in ("back", "ahead")}
    assert len(moves) == len(stuck.escape_moves(1.0))
    turn_s = sum(1 for o in out if o[1] == "turn") * 0.04
    assert 0 < turn_s <= stuck.TURN_BLOCKED_S + 0.1 < stuck.TURN_S


def test_roughness_follows_the_obstacle_share_of_votes():
    nav = np.array([[0.9, 0.5, 0.1, 0.0]], np.float32)
    obs = np.array([[0.1, 0.5, 0.9, 0.0]], np.float32)
    r = grid.roughness(nav, obs)
    assert r[0, 0] == 0.0 and r[0, 3] == 0.0, "clean and never-seen cells are smooth"
    assert 0.0 < r[0, 1] < 1.0 and r[0, 2] == 1.0


def test_paths_go_round_a_field_of_small_rocks_the_map_shows_as_floor():
    free = np.zeros((200, 200), bool)
    free[90:111, 40:81] = True  # an open floor 20 m wide
    obstacle = np.zeros_like(free)
    rough = np.zeros((200, 200), np.float32)
    rough[96:105, 55:65] = 1.0  # a rock field across the straight line, floor around it
    start, goal = (100, 42), (100, 78)
    straight = astar.astar(grid.cost_grid(free, obstacle), start, goal)
    around = astar.astar(grid.cost_grid(free, obstacle, rough=rough), start, goal)
    assert any(rough[r, c] > 0 for r, c in straight)
    assert not any(rough[r, c] > 0 for r, c in around)


def _pocket_scene():
    """Sunlit corridor y 95..105, x 40..80; a shadowed inlet y 99..101 running east from x 80 to 88;
    a shadowed fringe one cell wide along the corridor's north wall.  Returns (free, shadow, dist)."""
    free = np.zeros((200, 200), bool)
    free[95:106, 40:80] = True
    shadow = np.zeros((200, 200), bool)
    shadow[99:102, 80:88] = True  # the inlet: 8 m deep
    shadow[106, 45:75] = True  # fringe along the wall
    cost = grid.cost_grid(free, ~free & ~shadow, soft_obstacles=True)
    cost[shadow] = 3.0  # shadowed floor: passable, dearer
    dist, _ = astar.distance_field(cost, (100, 50))
    return free, shadow, dist


def test_peek_targets_the_deepest_shadowed_cell_a_rover_may_enter():
    free, shadow, dist = _pocket_scene()
    looked = np.zeros((200, 200), bool)
    looked[90:111, 35:80] = True  # the corridor and its walls were seen from close, the inlet was not
    t = explore.peek_targets(free, shadow, looked, np.zeros((200, 200), bool), dist)
    assert len(t) == 1  # the fringe is too shallow to hide anything the corridor did not show
    row, col, cost, size = t[0]
    assert row in (99, 100, 101) and size == 24
    depth = col + 0.5 - 80  # metres into the shadow from the last sunlit cell (x = 79)
    assert explore.PEEK_MIN_DEPTH_M <= depth <= explore.PEEK_MAX_DEPTH_M + 1.0  # deep, but not into the trap
    assert np.isfinite(cost)


def test_peek_has_nothing_to_do_once_the_pocket_was_seen_or_searched():
    free, shadow, dist = _pocket_scene()
    looked = np.ones((200, 200), bool)
    assert len(explore.peek_targets(free, shadow, looked, np.zeros((200, 200), bool), dist)) == 0
    looked[:] = False
    done = np.zeros((200, 200), bool)
    done[95:106, 78:90] = True
    assert len(explore.peek_targets(free, shadow, looked, done, dist)) == 0


def _faint_slot_scene():
    """Floor y 95..105, x 40..80, wall elsewhere. A slot y 99..101 runs east from x 80 to 86 with a third of
    its votes sand (floor in deep shadow, voted down); the wall cell beside the floor along the north edge
    keeps a fuzzy 0.4, one further out 0.15 (an ordinary edge). Returns (free, obstacle, share)."""
    free = np.zeros((200, 200), bool)
    free[95:106, 40:80] = True
    obstacle = ~free
    share = np.zeros((200, 200), np.float32)
    share[free] = 1.0
    share[99:102, 80:86] = 0.3  # the slot
    share[106, 40:80] = 0.4  # the fuzzy edge
    share[107, 40:80] = 0.15
    return free, obstacle, share


def test_faint_pockets_finds_a_slot_of_weak_sand_but_not_a_fuzzy_edge():
    free, obstacle, share = _faint_slot_scene()
    pockets = explore.faint_pockets(free, obstacle, share)
    assert pockets[99:102, 80:86].all(), "the slot reaches 6 m from the floor"
    assert not pockets[106:108].any(), "an edge two cells deep is every wall's fringe"
    share[99:102, 80:86] = 0.05  # solid wall keeps almost no sand votes
    assert not explore.faint_pockets(free, obstacle, share).any()
    free2, obstacle2, share2 = _faint_slot_scene()
    share2[99:102, 80:82] = 0.0  # the weak sand does not touch the floor: not a slot opening onto it
    assert not explore.faint_pockets(free2, obstacle2, share2)[99:102, 82:86].any()


def _pocket_entries(pockets, unlooked, free, looked, done, dist):
    """(targets, clusters) as search_plan._pocket_goal gets them."""
    clusters = explore.enterable_pockets(pockets, unlooked, free)
    return explore.peek_targets(free, clusters > 0, looked, done, dist), clusters


def test_pocket_entry_drives_into_a_slot_whose_mouth_was_seen_but_not_its_depth():
    """Seed 17 (shadows on): the spur's mouth was looked at from 4 m while exploring; the sample lay 7 m in."""
    free, obstacle, share = _faint_slot_scene()
    pockets = explore.faint_pockets(free, obstacle, share)
    dist, _ = astar.distance_field(grid.cost_grid(free, obstacle, soft_obstacles=True), (100, 50))
    looked = np.zeros((200, 200), bool)
    looked[:, :82] = True  # the mouth (x 80-81) seen from close, the rest not
    done = np.zeros((200, 200), bool)
    targets, clusters = _pocket_entries(pockets, pockets & ~looked, free, looked, done, dist)
    assert len(targets) == 1
    row, col = int(targets[0][0]), int(targets[0][1])
    assert pockets[row, col] and 82 <= col <= 80 + explore.PEEK_MAX_DEPTH_M, "inside the slot, past the seen mouth"
    assert clusters[row, col] > 0 and (clusters > 0).sum() == pockets.sum()
    targets, _ = _pocket_entries(pockets, np.zeros((200, 200), bool), free, looked, done, dist)
    assert len(targets) == 0, "every cell looked at: nothing to drive into"
    done[pockets] = True
    assert len(_pocket_entries(pockets, pockets, free, looked, done, dist)[0]) == 0
    none_done = np.zeros((200, 200), bool)
    shallow = pockets & (np.arange(200) < 82)[None, :]  # 2 m past the floor: seen from the floor beside it
    assert len(_pocket_entries(shallow, shallow, free, looked, none_done, dist)[0]) == 0
    band = np.zeros((200, 200), bool)
    band[106:112, 40:80] = True  # a faint band 6 m deep along the whole north wall: a shaded wall face
    assert len(_pocket_entries(band, band, free, looked, none_done, dist)[0]) == 0


def _shapes(pocket, free):
    n, labels, _stats, _ = cv2.connectedComponentsWithStats(pocket.astype(np.uint8), connectivity=8)
    reach, width = explore.pocket_shapes(labels, n, free)
    return reach[1:], width[1:]


def _spur_scene():
    """A 2 m wide corridor (y 99..100) ending at x 79; its faint end runs on to x 84 and the faint wall
    fringe wraps along both side walls (y 98 and 101, x 72..80), as at seed 17's spur. (free, pocket)."""
    free = np.zeros((200, 200), bool)
    free[99:101, 40:80] = True
    pocket = np.zeros((200, 200), bool)
    pocket[99:101, 80:85] = True
    pocket[[98, 101], 72:81] = True
    return free, pocket


def test_pocket_shape_measures_a_spur_across_not_along_its_wrapped_fringe():
    free, pocket = _spur_scene()
    reach, width = _shapes(pocket, free)
    assert reach[0] == pytest.approx(5.0, abs=0.01), "x 84 is 5 cells past the last floor cell (x 79)"
    assert width[0] == pytest.approx(4.0, abs=0.05), "y 98..101 across; the old count along the floor called it 24"
    assert reach[0] >= explore.FAINT_ENTER_REACH_M and width[0] <= explore.FAINT_ENTER_WIDTH_M
    short = pocket & (np.arange(200) < 82)[None, :]  # its end 2 cells past the floor
    assert _shapes(short, free)[0][0] == pytest.approx(2.0, abs=0.01)


def test_pocket_shape_reach_counts_only_the_floor_the_pocket_opens_onto():
    free, pocket = _spur_scene()
    free[104:110, 80:90] = True  # another corridor behind the spur's south wall, not touching the pocket
    reach, _width = _shapes(pocket, free)
    assert reach[0] == pytest.approx(5.0, abs=0.01)


def test_pocket_shape_calls_a_faint_band_along_a_wall_face_wide():
    free = np.zeros((200, 200), bool)
    free[90:106, 40:80] = True
    band = np.zeros((200, 200), bool)
    band[106:108, 50:70] = True  # 2 m deep along 20 m of the north wall...
    band[108:109, 59:61] = True  # ...with a 2-cell bulge reaching 3 m
    reach, width = _shapes(band, free)
    assert reach[0] == pytest.approx(3.0, abs=0.01)
    assert width[0] == pytest.approx(20.0, abs=0.5) and width[0] > explore.FAINT_ENTER_WIDTH_M, "the whole band, not the bulge"


def test_pocket_shape_measures_a_diagonal_slot_across_its_run():
    free = np.zeros((200, 200), bool)
    free[90:106, 40:80] = True
    slot = np.zeros((200, 200), bool)
    for k in range(8):  # a slot 2 cells thick running north-east from the corridor's corner
        slot[106 + k, 80 + k:82 + k] = True
    reach, width = _shapes(slot, free)
    assert reach[0] > 7.0
    assert width[0] <= 3.5, "about 2 m across the run (+ one cell), not its 8 m length"


def test_pocket_shape_of_nothing_is_empty():
    reach, width = explore.pocket_shapes(np.zeros((200, 200), np.int32), 1, np.ones((200, 200), bool))
    assert reach.shape == (1,) and width.shape == (1,) and not reach.any() and not width.any()


def test_search_goes_to_the_nearest_floor_far_enough_from_the_trail():
    free = np.zeros((200, 200), bool)
    free[90:111, 50:151] = True  # a 21 m wide strip
    visited = np.zeros((200, 200), bool)
    visited[100, 50:151] = True  # driven along its middle
    cost = grid.cost_grid(free, ~free)
    dist, _ = astar.distance_field(cost, (100, 60))
    done = np.zeros((200, 200), bool)
    goal = explore.search_target(free, visited, done, dist)
    assert goal is not None
    assert abs(goal[0] - 100) >= explore.SEARCH_MIN_AWAY_M, "never on or beside the trail"
    assert goal[1] < 70, "the nearest such cell by path, not one at the strip's far end"
    done[:, :120] = True  # searched already
    assert explore.search_target(free, visited, done, dist)[1] >= 120
    visited[90:111, 50:151] = True  # every cell driven over: nothing left
    assert explore.search_target(free, visited, np.zeros((200, 200), bool), dist) is None


def test_search_visits_the_nearer_of_a_pocket_peek_and_far_floor():
    """Seed 0 stood 4 m from an arm's unsearched tip and went to a peek 180 m away first."""
    dist = np.full((200, 200), np.inf)
    dist[10, 10], dist[190, 100] = 4.0, 180.0
    assert explore.nearer_search_goal((190, 100), (10, 10), dist) == ("search", (10, 10))
    dist[10, 10] = 200.0
    assert explore.nearer_search_goal((190, 100), (10, 10), dist) == ("peek", (190, 100))
    assert explore.nearer_search_goal(None, (10, 10), dist) == ("search", (10, 10))
    assert explore.nearer_search_goal((190, 100), None, dist) == ("peek", (190, 100))
    assert explore.nearer_search_goal((50, 50), None, dist) is None  # unreachable
    assert explore.nearer_search_goal(None, None, dist) is None


def test_a_just_chosen_frontier_is_kept_while_the_rover_turns_away_from_the_other():
    """Seed 23: turning toward the path to one frontier made the other score best, and back, for 20 s."""
    targets = np.array([[100.0, 150.0, 55.0, 3.0], [100.0, 50.0, 45.0, 3.0]])  # east 55 m, west 45 m by path
    pos = (100.5, 100.5)
    assert explore.choose_target(targets, pos, 180.0, current=(100, 150)) == (100, 50)  # facing west: west wins
    assert explore.choose_target(targets, pos, 180.0, current=(100, 150), keep_margin_m=math.inf) == (100, 150)


def _nook_scene():
    """A corridor along x with a 3-cell nook in its south wall, mapped as wall from afar (seed 10's east nook)."""
    free = np.zeros((200, 200), bool)
    free[110:114, 120:180] = True  # corridor floor, rows 110-113
    obstacle = ~free
    return free, obstacle


def test_a_nook_seen_only_from_the_side_is_still_unsearched_and_gets_faced():
    """Seed 10: the rover stood 4.4 m from the east-nook sample, facing away, and called the place searched."""
    free, obstacle = _nook_scene()
    looked = np.zeros((200, 200), bool)
    looked[100:120, 110:190] = True  # the camera saw the corridor and its walls from close...
    looked[105:110, 146:151] = False  # ...but the south wall's foot at x 146-150 only from afar or from the side
    feet = explore.unsearched_wall_feet(free, obstacle, looked)
    assert feet[109, 147:150].all(), "the nook's wall feet stay unsearched"
    assert not feet[111, 140] and not feet[109, 140] and not feet[114, 148], "floor and wall feet seen from close are not"
    heading = explore.face_heading(feet, (145.0, 111.0), 90.0)  # standing 4 m west of the nook, facing north
    assert heading is not None
    bearing = math.degrees(math.atan2(109.5 - 111.0, 148.5 - 145.0)) % 360.0  # about 337 deg
    assert abs((heading - bearing + 180.0) % 360.0 - 180.0) <= explore.SEARCH_FACE_HALF_FOV_DEG


def _nook_seen_from_afar():
    """The nook scene with the corridor seen from close, but the nook's wall feet only from afar."""
    free, obstacle = _nook_scene()
    looked = np.zeros((200, 200), bool)
    looked[100:120, 110:190] = True
    looked[105:110, 146:151] = False
    return free, obstacle, looked


def test_no_turn_when_the_camera_faces_the_nook_or_it_was_searched():
    free, obstacle, looked = _nook_seen_from_afar()
    feet = explore.unsearched_wall_feet(free, obstacle, looked)
    assert explore.face_heading(feet, (145.0, 111.0), 340.0) is None  # already facing it
    assert explore.face_heading(feet, (120.0, 111.0), 90.0) is None  # nothing unsearched within reach
    looked[105:118, 130:155] = True  # the nook was seen from close
    feet = explore.unsearched_wall_feet(free, obstacle, looked)
    assert explore.face_heading(feet, (145.0, 111.0), 90.0) is None


def test_the_search_visits_an_unsearched_nook_beside_the_trail():
    """Seeds 10 and 23: the nook lay 4-5 m from the trail, so no far-floor target ever went near it."""
    free, obstacle, looked = _nook_seen_from_afar()
    feet = explore.unsearched_wall_feet(free, obstacle, looked)
    dist, _ = astar.distance_field(grid.cost_grid(free, obstacle), (111, 125))
    done = np.zeros((200, 200), bool)
    visited = np.zeros((200, 200), bool)
    visited[113, 120:180] = True  # driven along the corridor's north edge: the nook is 4 m off the trail
    assert len(explore.look_targets(feet, free, np.zeros((200, 200), bool), done, dist)) == 0, "far from any trail"
    t = explore.look_targets(feet, free, visited, done, dist)
    assert len(t) == 1
    row, col, cost, size = t[0]
    assert row == 110 and 145 <= col <= 151, "a floor cell right beside the nook"
    assert explore.nearest_target(t) == (int(row), int(col)) and np.isfinite(cost)
    assert explore.nearer_search_goal(None, None, dist, explore.nearest_target(t)) == ("look", (110, int(col)))
    explore.ignore_disc(done, (int(row), int(col)), explore.SEARCH_FACE_RADIUS_M)
    assert len(explore.look_targets(feet, free, visited, done, dist)) == 0, "visited and faced: searched"
    looked[:] = True
    assert len(explore.look_targets(explore.unsearched_wall_feet(free, obstacle, looked), free, visited,
                                    np.zeros((200, 200), bool), dist)) == 0, "seen from close: searched"


def _nook_behind_a_rock():
    """Worldmap: floor x 130-159, y 100-114, wall north of it; a rock cell at (148, 114) south-west
    of the wall foot (149, 115) (seeds 7 and 15's east nook, hidden behind rocks from the south-west)."""
    wm = np.zeros((200, 200, 3), np.uint8)
    wm[:, :, 0] = 255
    wm[100:115, 130:160, 0], wm[100:115, 130:160, 2] = 0, 255
    wm[114, 148, 0], wm[114, 148, 2] = 255, 0
    return wm


BEHIND_THE_ROCK = (147.2, 113.2)  # 3.3 m from the wall foot (149, 115), the rock between


def test_a_rock_in_front_hides_the_nook_behind_it_from_the_search():
    wm = _nook_behind_a_rock()
    behind = np.zeros((200, 200), bool)
    explore.mark_in_sight(behind, wm, BEHIND_THE_ROCK, 45.0, 4.0, 40.0)  # facing the wall foot
    assert behind[114, 148], "the rock itself is seen"
    assert not behind[115, 149], "the wall foot behind it is not"
    assert behind[113, 149] and behind[115, 147], "floor and wall foot in the clear are"
    clear = np.zeros((200, 200), bool)
    explore.mark_in_sight(clear, wm, (149.5, 112.5), 90.0, 4.0, 40.0)  # south of it, facing it
    assert clear[115, 149] and not clear[116, 149], "the wall foot is seen, not the wall 1 m behind it"
    away = np.zeros((200, 200), bool)
    explore.mark_in_sight(away, wm, (149.5, 112.5), 270.0, 4.0, 40.0)  # facing away
    assert not away[113:, :].any()
    explore.mark_in_sight(away, wm, (np.nan, 111.5), 90.0, 4.0, 40.0)  # bad pose: no change
    explore.mark_in_sight(away, np.zeros((5, 5)), (148.5, 111.5), 90.0, 4.0, 40.0)  # bad map: no change
    assert not away[113:, :].any()


def test_a_wall_foot_past_the_fringe_of_non_light_sand_is_in_sight():
    """The frame's light floor ends about a metre before a wall: the fringe where the wall's foot blends into
    the floor is darker sand. Lines of sight that stopped 0.7 m past the light floor never reached the wall
    feet, so the search kept them all as unsearched (and exploration, in a trial, kept every wall a frontier)."""
    wm = np.zeros((200, 200, 3), np.uint8)
    wm[:, :, 0] = 255
    wm[100:115, 130:160, 0], wm[100:115, 130:160, 2] = 0, 255  # floor y 100-114, wall from y 115 (its foot)
    n = int(round(2 * reactive.FOV_HALF_DEG / reactive.BIN_DEG))
    pos = (145.5, 111.0)  # the wall foot 4 m ahead (north)
    fringe = np.zeros((200, 200), bool)
    explore.mark_in_sight(fringe, wm, pos, 90.0, 4.5, 40.0, np.full(n, 3.0))  # light floor ends 1 m short of it
    assert fringe[115, 145], "the wall foot behind a 1 m fringe is in sight"
    assert not fringe[116, 145], "the wall behind its foot is not"
    blind = np.zeros((200, 200), bool)
    explore.mark_in_sight(blind, wm, pos, 90.0, 4.5, 40.0, np.full(n, 1.0))  # the frame shows floor to 1 m only
    assert not blind[115, 145], "a foot 3 m past the last floor the frame showed is not"


def test_a_rock_face_filling_the_frame_hides_what_the_map_calls_clear():
    """Seed 15: the rock in front of the nook was mapped as floor; the camera, pressed against it,
    saw no floor at all, and the nook behind must not count as searched."""
    wm = _nook_behind_a_rock()
    wm[114, 148, 0], wm[114, 148, 2] = 0, 255  # the rock mapped as floor
    clear_map = np.zeros((200, 200), bool)
    explore.mark_in_sight(clear_map, wm, BEHIND_THE_ROCK, 45.0, 4.0, 40.0)
    assert clear_map[115, 149], "by the map alone the wall foot is in sight"
    n = int(round(2 * reactive.FOV_HALF_DEG / reactive.BIN_DEG))
    blind = np.zeros((200, 200), bool)
    explore.mark_in_sight(blind, wm, BEHIND_THE_ROCK, 45.0, 4.0, 40.0, np.zeros(n))  # the frame shows no floor
    assert not blind[115, 149] and not blind[114, 149] and blind.any()
    seen = np.zeros((200, 200), bool)
    explore.mark_in_sight(seen, wm, BEHIND_THE_ROCK, 45.0, 4.0, 40.0, np.full(n, 4.0))  # floor seen 4 m out
    assert (seen == clear_map).all()


def test_a_look_stand_once_used_gives_way_to_another_stand_and_blind_feet_are_given_up():
    free, obstacle, looked = _nook_seen_from_afar()
    feet = explore.unsearched_wall_feet(free, obstacle, looked)
    dist, _ = astar.distance_field(grid.cost_grid(free, obstacle), (111, 125))
    visited = np.zeros((200, 200), bool)
    visited[113, 120:180] = True
    done, stand_done = np.zeros((200, 200), bool), np.zeros((200, 200), bool)
    first = explore.nearest_target(explore.look_targets(feet, free, visited, done, dist, stand_done))
    explore.ignore_disc(stand_done, first, explore.LOOK_STAND_DONE_M)
    second = explore.nearest_target(explore.look_targets(feet, free, visited, done, dist, stand_done))
    assert second is not None and second != first and second[0] == 110, "another stand beside the nook"
    tries = np.zeros((200, 200), np.int16)
    at = (first[1] + 0.5, first[0] + 0.5)
    explore.give_up_faced(tries, done, feet, at)
    assert not done[109, 147:150].any() and tries[109, 148] == 1
    explore.give_up_faced(tries, done, feet, at)
    assert done[109, 147:150].all() and not done[105, 148], "unseen after LOOK_TRIES looks: given up; out of reach untouched"


def _feet_at(bearing_deg, dist_m, pos=(16.7, 98.3)):
    """A 3x3 patch of unsearched wall feet dist_m from pos at world bearing bearing_deg."""
    feet = np.zeros((200, 200), bool)
    x = pos[0] + dist_m * math.cos(math.radians(bearing_deg))
    y = pos[1] + dist_m * math.sin(math.radians(bearing_deg))
    feet[int(y) - 1:int(y) + 2, int(x) - 1:int(x) + 2] = True
    return feet


def test_a_long_turn_goes_the_way_that_sweeps_unsearched_wall_feet():
    """Seed 31 at the west tip: turning 173 -> 16 deg the short way (right) never faced the sixth sample
    6.5 m away at 320 deg; the long way (left, 203 deg) sweeps over it."""
    pos = (16.7, 98.3)
    assert explore.sweep_direction(_feet_at(320.0, 6.5), pos, 173.0, 16.0) == 1
    assert explore.sweep_direction(np.zeros((200, 200), bool), pos, 173.0, 16.0) == -1  # nothing there: short way
    assert explore.sweep_direction(_feet_at(90.0, 6.5), pos, 173.0, 16.0) == -1  # on the short side anyway
    assert explore.sweep_direction(_feet_at(320.0, 12.0), pos, 173.0, 16.0) == -1  # too far to see a rock
    assert explore.sweep_direction(_feet_at(300.0, 6.5), pos, 100.0, 16.0) == -1  # long way 276 deg: too long


def test_a_turn_back_glances_first_at_unsearched_wall_feet_it_would_not_sweep():
    """Seed 15: turning back 304 -> 187 deg (the short way, right) 3.4 m from the east nook, which lay at
    about 10 deg on the other side; the glance faces it first."""
    pos = (16.7, 98.3)
    glance = explore.glance_heading(_feet_at(10.0, 3.5), pos, 304.0, 187.0)
    assert glance is not None and abs((glance - 10.0 + 180.0) % 360.0 - 180.0) <= explore.SEARCH_FACE_HALF_FOV_DEG
    assert explore.glance_heading(_feet_at(250.0, 3.5), pos, 304.0, 187.0) is None  # the short turn sweeps them
    assert explore.glance_heading(_feet_at(10.0, 7.0), pos, 304.0, 187.0) is None  # beyond SEARCH_FACE_RADIUS_M
    assert explore.glance_heading(np.zeros((200, 200), bool), pos, 304.0, 187.0) is None
    assert explore.glance_heading(_feet_at(180.0, 3.5), pos, 0.0, 30.0) is None  # a glance back would add 300 deg
    one = np.zeros((200, 200), bool)
    one[98, 20] = True  # a single cell (a map speck) is no nook
    assert explore.glance_heading(one, pos, 304.0, 187.0) is None


def test_the_search_keeps_going_the_way_it_faces_unless_going_back_is_much_nearer():
    """Seed 29 walked east, turned back 25 m for wall feet it had passed, then crossed the canyon east again."""
    free = np.zeros((200, 200), bool)
    free[99:102, 20:181] = True  # an east-west corridor, the rover at its middle facing east
    dist, _ = astar.distance_field(grid.cost_grid(free, ~free), (100, 100))
    pos = (100.5, 100.5)
    behind, ahead = (100, 85), (100, 120)  # 15 m back, 20 m on
    assert explore.nearer_search_goal(behind, None, dist, ahead) == ("peek", behind)  # path alone: nearest
    assert explore.nearer_search_goal(behind, None, dist, ahead, pos, 0.0) == ("look", ahead)
    assert explore.nearer_search_goal(behind, None, dist, ahead, pos, 180.0) == ("peek", behind)
    assert explore.nearer_search_goal((100, 97), None, dist, (100, 140), pos, 0.0)[1] == (100, 97)  # 3 m back beats 40 on
    targets = np.array([[100, 85, dist[100, 85], 5], [100, 120, dist[100, 120], 5]], np.float64)
    assert explore.nearest_target(targets) == behind and explore.nearest_target(targets, pos, 0.0) == ahead


def test_navigation_never_imports_decision():
    """decision.py's planners live in navigation/ and get what they need as arguments: an import of
    decision there would be a cycle (decision imports them)."""
    import ast
    from pathlib import Path

    folder = Path(__file__).resolve().parent.parent / "navigation"
    for path in folder.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            assert not any(n == "decision" or n.startswith("decision.") for n in names), path.name


def test_no_turn_in_place_toward_a_point_under_the_rover():
    assert not turning.bearing_usable(0.3)
    assert not turning.bearing_usable(float("nan"))
    assert turning.bearing_usable(turning.TURN_POINT_MIN_M + 0.1)
