"""The sample search's planning: which place to visit next once the map is complete and samples are missing.

On the real canyon the search first drives to the sample spots the camera has not seen from close
(navigation.sample_spots: the only places the simulator puts samples), nearest first. Elsewhere, or once
they are all checked, four kinds of goal compete, nearest by path first (explore.nearer_search_goal): a peek into shadowed
floor the camera never saw from close, mapped floor far from the trail, a stand facing wall feet
the camera never saw from close (nooks), and the way into a faint pocket (a slot whose floor in deep
shadow was voted wall). The search keeps its goal against flip-flops, ticks places off
as searched, and gives up a goal where the rover got stuck. Kept apart from decision.py so the state
machine there reads as modes; mode_search drives the goals chosen here. Functions take the rover, its
`nav` memory (decision.NavMemory) and the frame's sanitised inputs `s` (decision.Inputs).
"""
import logging
import math

import numpy as np

import perception
from navigation import astar, explore, grid, paths, sample_spots

log = logging.getLogger(__name__)

SEARCH_GOAL_KINDS = ("spot", "peek", "search", "look", "pocket")  # path goals of the sample search: a sample spot's stand, pocket peek, far floor, unsearched wall feet, faint pocket
SEARCH_KEEP_MARGIN_M = 6.0  # a look or far-floor goal still open is kept unless another is this much cheaper (explore.search_cost), m
SEARCH_COMMIT_M = 3.0  # a search goal still open is kept until the rover has driven this far from where it chose it (a turn away from an arm's tip revealed new wall feet there and the rover turned back, twice: seed 7), m
SEARCH_LOCAL_M = 15.0  # while pockets come first (SEARCH_POCKETS_FIRST_S), goals this close (straight line) to where the search began come before them: finishing where the rover stands costs less than coming back, m
SEARCH_POCKETS_FIRST_S = 120.0  # for this long after the search began, faint pockets come before every goal but those near its start (about the tour exploration once made), s
SEARCH_STUCK_GIVE_UP_M = 5.0  # a search / peek target this close to where the rover got stuck is given up, m


def samples_missing(s):
    """Whether samples may still be out there (an unknown count counts as missing)."""
    return s.samples_remaining is None or s.samples_remaining > 0


def plan_search(rover, nav, s, frame_maps=None):
    """Set nav's path to the nearest open search goal (peek, far floor, look stand or faint pocket; for a
    while pockets first, see _search_tier); when none is left, clear nav.search_left. ``frame_maps`` shares per-frame maps with the face turn (unsearched_wall_feet)."""
    free, obstacle, _unknown = paths.grids(rover)
    cost = grid.cost_grid(free, obstacle, paths.blocked_cells(nav, s), allow_unknown=False, soft_obstacles=True,
                          rough=paths.roughness(rover))
    cell = grid.world_to_cell(s.pos)
    paths.open_around_rover(cost, cell)
    dist, parent = astar.distance_field(cost, cell)
    unsearched = remember_unsearched(rover, nav, s, free, obstacle, frame_maps)
    visited = nav.visits.visited()
    if nav.search_began is None:
        nav.search_began = (s.t, s.pos)
    spot = _spot_goal(rover, nav, s, free, dist)
    if spot is not None:
        if nav.path_goal != ("spot", spot):
            log.info("sample search: spot %d (%.1f, %.1f) from its stand %s, from (%.1f, %.1f), %d open, t=%.1f",
                     nav.spot_goal, *nav.spots[nav.spot_goal], spot, s.pos[0], s.pos[1],
                     np.count_nonzero(~nav.spot_done), s.t)
        paths.set_path(nav, s, "spot", spot, astar.path_to(parent, cost.shape, spot))
        return
    candidates = {"peek": _peek_goal(rover, nav, s, free, dist),
                  "search": explore.search_target(free, visited, nav.search_done, dist, s.pos, s.yaw),
                  "look": explore.nearest_target(explore.look_targets(unsearched, free, visited, nav.look_done, dist,
                                                                      nav.look_stand_done), s.pos, s.yaw)}
    candidates["pocket"], pocket_cluster = _pocket_goal(rover, nav, s, free, obstacle, dist)
    chosen = _tiered_goal(nav, s, dist, candidates)
    cur = nav.path_goal
    if chosen is None or cur is None or cur[1] is None or _search_tier(nav, s, *cur) <= _search_tier(nav, s, *chosen):
        chosen = keep_search_goal(nav, s, chosen, dist, free, unsearched)
    nav.pocket_goal = pocket_cluster if chosen is not None and chosen[0] == "pocket" else None
    kind, goal = chosen if chosen is not None else ("search", None)
    if goal is None:
        nav.search_left = False
        log.info("sample search finished at t=%.1f", s.t)
        paths.set_path(nav, s, "search", None, [])
        return
    if nav.path_goal != (kind, goal):
        log.info("sample search: %s at %s from (%.1f, %.1f), t=%.1f", kind, goal, s.pos[0], s.pos[1], s.t)
    paths.set_path(nav, s, kind, goal, astar.path_to(parent, cost.shape, goal))


def _spot_goal(rover, nav, s, free, dist):
    """The stand (row, col) of the sample spot to check next (the current one while it is still open, else the
    cheapest by explore.search_cost), setting nav.spot_goal; None when no open spot has a reachable stand."""
    if nav.spots is None:
        init_spots(nav)
    if len(nav.spots) == 0:
        return None
    nav.spot_done |= sample_spots.taken_spots(nav.spots, nav.collected)
    stands = sample_spots.spot_stands(nav.spots, free, dist, sample_spots.VIEWS, only=~nav.spot_done)
    usable = ~nav.spot_done & (stands[:, 2] == 1)
    if not usable.any():
        nav.spot_goal = None
        return None
    current = nav.path_goal is not None and nav.path_goal[0] == "spot"
    if current and nav.spot_goal is not None and usable[nav.spot_goal]:
        k = nav.spot_goal
    else:
        idx = np.nonzero(usable)[0]
        costs = explore.search_cost(stands[idx, 0], stands[idx, 1], dist[stands[idx, 0], stands[idx, 1]], s.pos, s.yaw)
        k = int(idx[int(np.argmin(costs))])
    nav.spot_goal = k
    return int(stands[k, 0]), int(stands[k, 1])


def init_spots(nav):
    """The sample spots this mission can hold (sample_spots.spots_for_start at nav.home), none checked yet."""
    nav.spots = sample_spots.spots_for_start(nav.home)
    nav.spot_done = np.zeros(len(nav.spots), bool)
    if len(nav.spots):
        log.info("the canyon's %d sample spots are searched first once the map is complete", len(nav.spots))


def spot_done(nav, s):
    """The search's current sample spot is checked (faced from its stand, or given up): not driven to again."""
    if nav.spot_goal is not None and nav.spot_done is not None:
        nav.spot_done[nav.spot_goal] = True
        log.info("sample search: spot %d checked, t=%.1f", nav.spot_goal, s.t)
    nav.spot_goal = None


def keep_search_goal(nav, s, chosen, dist, free, unsearched):
    """The current look or far-floor goal while it is still open and no more than SEARCH_KEEP_MARGIN_M
    dearer (search_cost) than `chosen`, else `chosen`.

    Replanning every 1.5 s picked the cheapest goal afresh; as the rover moved, a cluster's nearest
    stand and the heading term moved too, and on seed 17 (15 fps) the search went back and forth
    between the same few stands in the rock field by the start (one chosen three times in 40 s)."""
    cur = nav.path_goal
    if chosen is None or cur is None or cur == chosen or cur[0] not in ("look", "search") or cur[1] is None:
        return chosen
    kind, (r, c) = cur
    if not (free[r, c] and np.isfinite(dist[r, c])):
        return chosen
    if kind == "look":
        beside = unsearched[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2] & ~nav.look_done[max(r - 1, 0):r + 2,
                                                                                        max(c - 1, 0):c + 2]
        if nav.look_stand_done[r, c] or not beside.any():
            return chosen
    elif nav.search_done[r, c]:
        return chosen
    if search_goal_committed(nav, s):
        return cur
    (cr, cc) = chosen[1]
    costs = explore.search_cost([r, cr], [c, cc], [dist[r, c], dist[cr, cc]], s.pos, s.yaw)
    return cur if costs[0] <= costs[1] + SEARCH_KEEP_MARGIN_M else chosen


def search_goal_committed(nav, s):
    """True until the rover has driven SEARCH_COMMIT_M from where it chose its (still open) search goal.

    Turning in place to leave an arm's tip, the camera swept the tip and mapped a little more floor
    there; the wall feet beside that new floor, 4-5 m off, were not yet searched, their stand lay under
    the rover and won, and the rover turned back (seed 7: twice in 25 s, then the spin detector fired).
    Those wall feet stay open and are visited when they are the cheapest goal from somewhere else."""
    if nav.goal_from is None:
        return False
    return math.hypot(s.pos[0] - nav.goal_from[0], s.pos[1] - nav.goal_from[1]) < SEARCH_COMMIT_M


def _peek_goal(rover, nav, s, free, dist):
    """Best shadowed pocket to look into (see explore.peek_targets) on perception's pocket floor, or None."""
    shadow_floor = perception.pocket_floor(rover) & ~free
    looked = perception.looked_at_within(rover, explore.PEEK_RANGE_M)
    targets = explore.peek_targets(free, shadow_floor, looked, nav.search_done, dist)
    current = nav.path_goal[1] if nav.path_goal is not None and nav.path_goal[0] == "peek" else None
    return explore.choose_target(targets, s.pos, s.yaw, current)


def _tiered_goal(nav, s, dist, candidates):
    """The cheapest (explore.nearer_search_goal) of the `candidates` {kind: cell or None} in the best
    _search_tier that has any, or None."""
    tiers = {k: _search_tier(nav, s, k, c) for k, c in candidates.items()}
    for tier in range(3):
        pick = {k: c if c is not None and tiers[k] == tier else None for k, c in candidates.items()}
        chosen = explore.nearer_search_goal(pick["peek"], pick["search"], dist, pick["look"], s.pos, s.yaw,
                                            pick["pocket"])
        if chosen is not None:
            return chosen
    return None


def _search_tier(nav, s, kind, cell):
    """Rank of a search goal while pockets come first: 0 near where the search began (SEARCH_LOCAL_M), 1 a faint
    pocket, 2 the rest; 0 for all once SEARCH_POCKETS_FIRST_S has passed (nearest first from then on).

    Exploration used to tour the pockets first, for up to 120 s, as soon as it ran out of frontier: on
    seed 0 (shadows on) the tour drove from 13 m beside the east nook to the south arm's pockets, and the
    search found the nook's sample 170 s later. Nearest first, with the pockets as one more goal, lost
    seed 17 (shadows on): its sample was in the hub's south-west pocket, 75 m off, reached at 792 s.
    Finishing the place the rover stands in costs a few look stands; coming back to it, a crossing."""
    if cell is None or nav.search_began is None or s.t - nav.search_began[0] > SEARCH_POCKETS_FIRST_S:
        return 0
    if kind == "pocket":
        return 1
    (x0, y0), (row, col) = nav.search_began[1], cell
    return 0 if math.hypot(col + 0.5 - x0, row + 0.5 - y0) <= SEARCH_LOCAL_M else 2


def _pocket_goal(rover, nav, s, free, obstacle, dist):
    """(cell, cluster): the way into the nearest faint pocket not driven into yet (explore.faint_pockets,
    enterable_pockets, entered at peek_targets' cell) and the pocket's bool map, or (None, None).

    They come before most other goals for a while (_search_tier)."""
    pockets = explore.faint_pockets(free, obstacle, perception.sand_share(rover)) & ~nav.pocket_reached
    unlooked = pockets & ~perception.looked_at_within(rover, explore.SEARCH_LOOK_M)
    if not unlooked.any():
        return None, None
    clusters = explore.enterable_pockets(pockets, unlooked, free)
    looked = perception.looked_at_within(rover, explore.PEEK_RANGE_M)
    targets = explore.peek_targets(free, clusters > 0, looked, nav.pocket_reached, dist)
    goal = explore.nearest_target(targets, s.pos, s.yaw)
    return (goal, clusters == clusters[goal]) if goal is not None else (None, None)


def pocket_done(nav, goal):
    """The faint pocket of the search's pocket goal (reached or given up) is not gone into again."""
    if nav.pocket_goal is not None:
        nav.pocket_reached |= nav.pocket_goal
    explore.ignore_disc(nav.pocket_reached, goal)
    nav.pocket_goal = None


def unsearched_wall_feet(rover, nav, frame_maps, free, obstacle):
    """explore.unsearched_wall_feet, computed once per frame: a search replan and the face turn at a
    reached goal can both ask in the same frame, from the same drive map and look map. ``frame_maps``
    is the frame's dict (None: no sharing)."""
    cached = None if frame_maps is None else frame_maps.get("unsearched_wall_feet")
    if cached is None:
        looked = perception.looked_at_within(rover, explore.SEARCH_LOOK_M) & nav.in_sight  # in view, not behind a rock
        cached = explore.unsearched_wall_feet(free, obstacle, looked)
        if frame_maps is not None:
            frame_maps["unsearched_wall_feet"] = cached
    return cached


def remember_unsearched(rover, nav, s, free, obstacle, frame_maps=None):
    """Unsearched wall feet now (see unsearched_wall_feet), kept in nav for the turns in place
    until the next plan; None is kept once every sample is in."""
    unsearched = unsearched_wall_feet(rover, nav, frame_maps, free, obstacle)
    nav.unsearched = unsearched if samples_missing(s) else None
    return unsearched


def search_done_radius(kind):
    """How far around a reached (or given-up) search goal counts as searched, m: a peek rules out the
    shadow beside it, a far-floor visit the floor around it, a look the wall feet it turned to face."""
    return {"peek": explore.PEEK_DONE_M, "look": explore.SEARCH_FACE_RADIUS_M}.get(kind, explore.SEARCH_MIN_AWAY_M)


def leave_look_stand(rover, nav, s, goal, frame_maps=None):
    """A look stand is done once reached and faced; the wall feet around it that are still unseen
    (hidden behind a rock) stay open for another stand until LOOK_TRIES stands faced them."""
    explore.ignore_disc(nav.look_stand_done, goal, explore.LOOK_STAND_DONE_M)
    free, obstacle, _unknown = paths.grids(rover)
    unsearched = unsearched_wall_feet(rover, nav, frame_maps, free, obstacle)
    explore.give_up_faced(nav.look_tries, nav.look_done, unsearched, s.pos)


def give_up_search_goal_near(nav, s):
    """A search or peek target beside the place the rover just got stuck is not worth another try:
    the floor far from the trail near the start is a field of small rocks (seed 23 got stuck there
    three times in 30 s going for one search target)."""
    goal = paths.goal_cell_near(nav, s, SEARCH_GOAL_KINDS, SEARCH_STUCK_GIVE_UP_M)
    if goal is None:
        return
    kind = nav.path_goal[0]
    if kind == "spot":
        spot_done(nav, s)
    elif kind == "pocket":
        pocket_done(nav, goal)  # many are a shaded slope, not a slot (seed 17, shadows on: 40 s stuck on one)
    else:
        explore.ignore_disc(nav.look_done if kind == "look" else nav.search_done, goal, search_done_radius(kind))
    nav.path_goal = None
