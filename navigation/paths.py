"""The path to the current goal: the maps every planner plans on, and nav's path / goal bookkeeping.

Exploration, the sample search, rock approaches and the way home all plan the same way (perception's
drive map, the stuck memory, the rover's own cells open) and all keep one path in `nav`
(decision.NavMemory: path_xy, path_goal, plan_time, the goal-progress watch); this module is that
shared part, so the planners beside it and decision.py's modes do not each carry a copy.
Functions take the rover, its `nav` memory and the frame's sanitised inputs `s` (decision.Inputs).
"""
import logging
import math

import numpy as np

import perception
from navigation import astar, grid, pursuit

log = logging.getLogger(__name__)

REPLAN_S = 1.5  # replan the path at least this often, s
OFF_PATH_M = 2.5  # replan when the rover is further than this from its path, m
GOAL_PROGRESS_S = 12.0  # a goal whose path length did not shrink for this long is given up, s
GOAL_PROGRESS_M = 1.0  # ...by at least this much, m
OWN_CELLS_RADIUS = 1  # cells around the rover's own cell always treated as drivable, cells
BLOCKED_MEMORY_S = 600.0  # cells the rover got stuck on stay blocked this long (the hub near the start is crossed again and again), s


def grids(rover):
    """(free, obstacle, unknown) from perception's drive map: sand in shadow is not driven on."""
    wm = perception.drive_map(rover)
    if not isinstance(wm, np.ndarray) or wm.shape != (grid.GRID_SIZE, grid.GRID_SIZE, 3):
        wm = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE, 3), np.uint8)
    return grid.classify(wm)


def roughness(rover):
    """Per-cell roughness from perception's votes, or None before perception has run."""
    if getattr(rover, "perception_memory", None) is None:
        return None
    return grid.roughness(*perception.occupancy_grids(rover))


def blocked_cells(nav, s):
    """Cells remembered as blocked (stuck spots), forgotten after BLOCKED_MEMORY_S."""
    return (s.t - nav.blocked_at) < BLOCKED_MEMORY_S


def open_around_rover(cost, cell):
    """The rover stands here, so its own cells are drivable whatever the map says (first frames, shadows)."""
    r = OWN_CELLS_RADIUS
    r1, r2 = max(cell[0] - r, 0), min(cell[0] + r + 1, grid.GRID_SIZE)
    c1, c2 = max(cell[1] - r, 0), min(cell[1] + r + 1, grid.GRID_SIZE)
    win = cost[r1:r2, c1:c2]
    np.minimum(win, grid.UNKNOWN_COST, out=win)


def cost_grids(rover, nav, s, free, obstacle, allow_unknown):
    """Cost grids to plan on, each with the rover's own cells open: with the stuck memory, then
    (when there is any) without it, because stale stuck memory must never hide a goal."""
    blocked = blocked_cells(nav, s)
    rough = roughness(rover)
    for use_blocked in (True, False):
        if not use_blocked and not blocked.any():
            return
        cost = grid.cost_grid(free, obstacle, blocked if use_blocked else None, allow_unknown=allow_unknown,
                              soft_obstacles=True, rough=rough)
        open_around_rover(cost, grid.world_to_cell(s.pos))
        yield cost


def _start_cell(cost, s):
    """The passable cell nearest the rover's own, or None off the map."""
    cell = grid.world_to_cell(s.pos)
    return grid.nearest_passable(cost, cell) if cell is not None else None


def set_path(nav, s, kind, goal, cells):
    """Make `cells` the path to (kind, goal); a new goal restarts the progress watch and the loop detector."""
    if nav.path_goal is None or nav.path_goal[0] != kind or nav.path_goal[1] != goal:
        log.debug("new %s goal %s from (%.1f, %.1f) at t=%.1f, %d path cells", kind, goal, s.pos[0], s.pos[1],
                  s.t, len(cells))
        reset_goal_progress(nav, s)
        nav.loops.reset()
        nav.goal_since = s.t
        nav.goal_from = s.pos
    nav.path_goal = (kind, goal) if goal is not None else None
    nav.path_xy = astar.cells_to_world(cells)
    nav.path_idx = 0
    nav.plan_time = s.t


def plan_to(rover, nav, s, kind, goal):
    """A* to a fixed goal cell (rock, home), allowed through unmapped ground at a premium."""
    free, obstacle, _unknown = grids(rover)
    cells = []
    for cost in cost_grids(rover, nav, s, free, obstacle, allow_unknown=True):
        start = _start_cell(cost, s)
        g = goal if np.isfinite(cost[goal]) else grid.nearest_passable(cost, goal)
        cells = astar.astar(cost, start, g) if (start is not None and g is not None) else []
        if cells:
            break
    if not cells:
        cells = [grid.world_to_cell(s.pos), goal]
    set_path(nav, s, kind, goal, cells)


def needs_replan(nav, s):
    """The path is due for a replan: older than REPLAN_S, too short to follow, or the rover left it."""
    if s.t - nav.plan_time >= REPLAN_S or len(nav.path_xy) < 2:
        return True
    i = pursuit.closest_index(nav.path_xy, s.pos, nav.path_idx)
    p = nav.path_xy[i]
    return math.hypot(p[0] - s.pos[0], p[1] - s.pos[1]) > OFF_PATH_M


def track_goal_progress(nav, s, remaining):
    """Note the path length left to the goal when it beat the best so far by GOAL_PROGRESS_M."""
    if remaining < nav.goal_best - GOAL_PROGRESS_M:
        nav.goal_best = remaining
        nav.goal_best_time = s.t


def goal_stalled(nav, s):
    """No progress toward the goal for GOAL_PROGRESS_S, or the rover is circling."""
    return s.t - nav.goal_best_time > GOAL_PROGRESS_S or nav.loops.circling()


def reset_goal_progress(nav, s):
    """Start the progress watch afresh (a new goal, or time spent on something else)."""
    nav.goal_best = math.inf
    nav.goal_best_time = s.t


def goal_cell_near(nav, s, kinds, radius_m):
    """The current path goal's cell when the goal is of one of `kinds`, has a cell and lies within radius_m
    of the rover; else None (the search's give-up-where-stuck rule)."""
    if nav.path_goal is None or nav.path_goal[0] not in kinds or nav.path_goal[1] is None:
        return None
    gx, gy = grid.cell_to_world(*nav.path_goal[1])
    return nav.path_goal[1] if math.hypot(gx - s.pos[0], gy - s.pos[1]) <= radius_m else None
