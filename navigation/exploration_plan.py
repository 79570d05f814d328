"""Exploration's planning: which frontier to drive to next, and when the map counts as complete.

Around explore.choose_target grew the rules that decide what counts as a frontier goal: a frontier
voted wall before the camera saw it from close is still driven to (navigation.vanished), given-up frontiers
are remembered for the second sweep, and the map is complete only after several plans in a row found
nothing (faint pockets are the sample search's: search_plan). Kept
apart from decision.py so the state machine there reads as modes; mode_forward drives the goal chosen
here. Functions take the rover, its `nav` memory (decision.NavMemory) and the frame's sanitised inputs
`s` (decision.Inputs).
"""
import logging
import math

from navigation import astar, explore, grid, paths, search_plan, vanished

log = logging.getLogger(__name__)

FRONTIER_REACHED_M = 1.5  # a frontier target this close is reached (and ignored if still frontier), m
FRONTIER_COMMIT_S = 10.0  # a frontier target chosen this recently is kept while it is still frontier (no flip-flop while turning toward it), s
VANISHED_REACH_M = 3.0  # a frontier goal voted wall before it was seen from close is still driven to: the floor cell nearest it within this, m
EXPLORED_CONFIRM_PLANS = 3  # plans in a row without any frontier before the map counts as complete
EXPLORED_MIN_TIME_S = 20.0  # never declare the map complete before this, s


def plan_explore(rover, nav, s):
    """Dijkstra from the rover over mapped ground; head for the best reachable frontier."""
    free, obstacle, unknown = paths.grids(rover)
    search_plan.remember_unsearched(rover, nav, s, free, obstacle)
    mask = explore.frontier_mask(free, unknown, nav.frontier_ignored, obstacle, seen_for_frontiers(nav, s))
    targets, cost, parent, dist = _frontier_targets(rover, nav, s, free, obstacle, mask)
    nav.frontier_count = len(targets)
    stand = _vanished_frontier_stand(nav, s, free, obstacle, dist)
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


def frontier_reachable(rover, nav, s):
    """Any reachable frontier cluster on today's map (plan_explore's test)."""
    free, obstacle, unknown = paths.grids(rover)
    mask = explore.frontier_mask(free, unknown, nav.frontier_ignored, obstacle, seen_for_frontiers(nav, s))
    return bool(mask.any()) and len(_frontier_targets(rover, nav, s, free, obstacle, mask)[0]) > 0


def give_up_frontier(nav):
    """Ignore the current frontier goal, remembering it was given up (not reached): see hidden_frontiers."""
    nav.vanished = None  # a given-up goal is not driven to again as a vanished one
    explore.ignore_disc(nav.frontier_ignored, nav.path_goal[1])
    explore.ignore_disc(nav.frontier_abandoned, nav.path_goal[1])
