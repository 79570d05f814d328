"""Exploration's planning: which frontier to drive to next, and when the map counts as complete.

Around explore.choose_target grew the rules that decide what counts as a frontier goal: a frontier
voted wall before the camera saw it from close is still driven to (navigation.vanished), faint pockets
are toured once the ordinary frontier runs out with samples missing, given-up frontiers are remembered
for the second sweep, and the map is complete only after several plans in a row found nothing. Kept
apart from decision.py so the state machine there reads as modes; mode_forward drives the goal chosen
here. Functions take the rover, its `nav` memory (decision.NavMemory) and the frame's sanitised inputs
`s` (decision.Inputs).
"""
import logging
import math

import perception
from navigation import astar, explore, grid, paths, search_plan, vanished

log = logging.getLogger(__name__)

FRONTIER_REACHED_M = 1.5  # a frontier target this close is reached (and ignored if still frontier), m
FRONTIER_COMMIT_S = 10.0  # a frontier target chosen this recently is kept while it is still frontier (no flip-flop while turning toward it), s
VANISHED_REACH_M = 3.0  # a frontier goal voted wall before it was seen from close is still driven to: the floor cell nearest it within this, m
POCKET_TOUR_S = 120.0  # exploration looks into faint pockets (nearest first) for at most this long after it first ran out of frontier with samples missing, then leaves the rest to the sample search (a sample in no pocket waited for every pocket's tour); two or three cross-canyon drives, s
EXPLORED_CONFIRM_PLANS = 3  # plans in a row without any frontier before the map counts as complete
EXPLORED_MIN_TIME_S = 20.0  # never declare the map complete before this, s


def plan_explore(rover, nav, s):
    """Dijkstra from the rover over mapped ground; head for the best reachable frontier."""
    free, obstacle, unknown = paths.grids(rover)
    search_plan.remember_unsearched(rover, nav, s, free, obstacle)
    mask = explore.frontier_mask(free, unknown, nav.frontier_ignored, obstacle, seen_for_frontiers(nav, s))
    targets, cost, parent, dist = _frontier_targets(rover, nav, s, free, obstacle, mask)
    was_pocket, nav.pocket_goal = nav.pocket_goal is not None, None
    if not len(targets) and search_plan.samples_missing(s):
        targets, cost, parent, dist = _pocket_targets(rover, nav, s, free, obstacle, (targets, cost, parent, dist))
    nav.frontier_count = len(targets)
    # a pocket goal is mapped wall on purpose: not a frontier that vanished under a far vote
    stand = None if was_pocket or nav.pocket_goal is not None else _vanished_frontier_stand(nav, s, free, obstacle,
                                                                                            dist)
    if stand is not None:
        nav.no_frontier_plans = 0
        nav.explored = False
        paths.set_path(nav, s, "frontier", stand, astar.path_to(parent, cost.shape, stand))
        return
    current = nav.path_goal[1] if nav.path_goal is not None and nav.path_goal[0] == "frontier" else None
    committed = current is not None and s.t - nav.goal_since < FRONTIER_COMMIT_S
    goal = explore.choose_target(targets, s.pos, s.yaw, current,
                                 math.inf if committed else explore.KEEP_TARGET_MARGIN_M)
    if goal is None:
        nav.no_frontier_plans += 1
        if dist is not None:  # dist is from the last cost grid: without the stuck memory when there is any
            nav.hidden_frontiers = len(explore.ignored_frontiers(free, unknown, nav.frontier_abandoned, dist,
                                                                 obstacle, seen_for_frontiers(nav, s)))
        nav.explored = nav.no_frontier_plans >= EXPLORED_CONFIRM_PLANS and s.t > EXPLORED_MIN_TIME_S
        paths.set_path(nav, s, "frontier", None, [])
        nav.plan_time = s.t - paths.REPLAN_S + 0.5  # look again soon
        return
    nav.no_frontier_plans = 0
    nav.explored = False
    paths.set_path(nav, s, "frontier", goal, astar.path_to(parent, cost.shape, goal))


def _frontier_targets(rover, nav, s, free, obstacle, mask):
    """(targets, cost, parent, dist): the reachable frontier clusters of `mask` under the first cost grid
    that reaches any (explore.frontier_targets), with that grid and its distance field; the last grid's
    when none does (no grid: [], None, None, None)."""
    targets, cost, parent, dist = [], None, None, None
    for cost in paths.cost_grids(rover, nav, s, free, obstacle, allow_unknown=False):
        dist, parent = astar.distance_field(cost, grid.world_to_cell(s.pos))
        targets = explore.frontier_targets(mask, dist)
        if len(targets):
            break
    return targets, cost, parent, dist


def seen_for_frontiers(nav, s):
    """Walls looked at from close enough to close a frontier: from SEEN_CLOSE_SAMPLES_M while samples
    are missing (an arm's tip or a side pocket may hold one; small samples show from 3-5 m), from
    SEEN_CLOSE_M once all are in (the map alone is done sooner: seed 1 took 612 s instead of 507 s
    exploring at 5 m after its sixth sample)."""
    return nav.seen_near if search_plan.samples_missing(s) else nav.seen_close


def _vanished_frontier_stand(nav, s, free, obstacle, dist):
    """The floor cell to keep driving to when the frontier goal was voted wall before the camera saw it
    from close (see navigation.vanished), or None. Ends once that cell is reached or the goal seen close."""
    cur = nav.path_goal
    if nav.vanished is not None:
        cell = nav.vanished[0]
    elif cur is not None and cur[0] == "frontier" and cur[1] is not None:
        cell = cur[1]
    else:
        return None
    stand = None
    if dist is not None and vanished.vanished_by_far_vote(cell, obstacle, seen_for_frontiers(nav, s)):
        stand = vanished.stand_beside(cell, free, dist, VANISHED_REACH_M)
    if stand is not None:
        sx, sy = grid.cell_to_world(*stand)
        if math.hypot(sx - s.pos[0], sy - s.pos[1]) < FRONTIER_REACHED_M:
            stand = None  # there: the camera looks at the goal from here
    if stand is not None and nav.vanished is None:
        log.info("frontier %s voted wall before it was seen from close: driving to %s to look", cell, stand)
    nav.vanished = (cell, stand) if stand is not None else None
    return stand


def _pocket_targets(rover, nav, s, free, obstacle, none_left):
    """Frontier targets inside faint pockets (explore.enterable_pockets) once no ordinary frontier is left with
    samples missing: drive in to look before calling the map complete. Only then, so exploration keeps its
    order (every pocket a frontier from the start cost seed 0 290 s), and only that: counting pocket cells
    as unsearched wall feet moved glances and gave the search more stands (seed 3 on +49 s, seed 51 on
    +212 s). A pocket driven into (or given up) stays done through the second sweep, which only reopens
    ordinary frontier, and the tour ends POCKET_TOUR_S after it began (a missing sample in no pocket waited
    for the whole tour before the search). `none_left` (the empty _frontier_targets result) is returned when
    there is none."""
    if not nav.pockets_open:
        nav.pockets_open = True
        nav.pocket_tour_end = s.t + POCKET_TOUR_S
        log.info("no frontier left with samples missing at t=%.1f: looking into faint pockets", s.t)
    if s.t > nav.pocket_tour_end:
        return none_left
    pockets = explore.faint_pockets(free, obstacle, perception.sand_share(rover)) & ~nav.pocket_reached
    unlooked = pockets & ~perception.looked_at_within(rover, explore.SEARCH_LOOK_M)
    if not unlooked.any():
        return none_left
    clusters = explore.enterable_pockets(pockets, unlooked, free)
    looked = perception.looked_at_within(rover, explore.PEEK_RANGE_M)
    for cost in paths.cost_grids(rover, nav, s, free, obstacle, allow_unknown=False):
        dist, parent = astar.distance_field(cost, grid.world_to_cell(s.pos))
        targets = explore.peek_targets(free, clusters > 0, looked, nav.pocket_reached, dist)
        if len(targets):
            goal = explore.choose_target(targets, s.pos, s.yaw)
            nav.pocket_goal = clusters == clusters[goal]
            return targets[(targets[:, 0] == goal[0]) & (targets[:, 1] == goal[1])], cost, parent, dist
    return none_left


def frontier_reachable(rover, nav, s):
    """Any reachable frontier cluster on today's map (plan_explore's test)."""
    free, obstacle, unknown = paths.grids(rover)
    mask = explore.frontier_mask(free, unknown, nav.frontier_ignored, obstacle, seen_for_frontiers(nav, s))
    return bool(mask.any()) and len(_frontier_targets(rover, nav, s, free, obstacle, mask)[0]) > 0


def pocket_done(nav):
    """The faint pocket the current frontier goal drove into (if it was one) is done: reached or given up."""
    if nav.pocket_goal is not None:
        nav.pocket_reached |= nav.pocket_goal
        explore.ignore_disc(nav.pocket_reached, nav.path_goal[1])


def give_up_frontier(nav):
    """Ignore the current frontier goal, remembering it was given up (not reached): see hidden_frontiers."""
    nav.vanished = None  # a given-up goal is not driven to again as a vanished one
    explore.ignore_disc(nav.frontier_ignored, nav.path_goal[1])
    explore.ignore_disc(nav.frontier_abandoned, nav.path_goal[1])


def give_up_pocket_near(nav, s):
    """A faint pocket the rover got stuck driving into is done (pocket_done): many are a shaded slope, not
    a slot (seed 17, shadows on: 40 s of stuck on the slope at (64, 85) before the second sweep)."""
    if nav.pocket_goal is not None and paths.goal_cell_near(nav, s, ("frontier",),
                                                            search_plan.SEARCH_STUCK_GIVE_UP_M) is not None:
        pocket_done(nav)
        nav.pocket_goal = None
        nav.path_goal = None
