"""Systematic exploration: frontier targets, loop/revisit detection, map completeness.

A frontier is a mapped-navigable cell touching unmapped ground. One Dijkstra
from the rover ranks every frontier cluster by true path cost, so the rover
works through the canyon tree depth first (nearest unexplored branch next)
instead of wandering. Frontiers the rover reached without resolving (cells the
camera cannot see) are ignored so they never pull it back.
"""
import math
from collections import deque

import cv2
import numpy as np
from numba import njit

from navigation import grid, reactive

FRONTIER_MIN_CELLS = 1  # smaller frontier clusters are noise, cells (a 2 m wide canyon has a 1-2 cell frontier)
FRONTIER_WINDOW = 5  # window edge for counting unknown cells around a frontier cell, cells
FRONTIER_MIN_UNKNOWN = 8  # unknown cells needed in that window (a lone unseen wall pixel is not a frontier)
HEADING_WEIGHT_M_PER_RAD = 8.0  # extra cost per radian a target lies off the current heading, m/rad
SIZE_BONUS_M_PER_CELL = 0.3  # cost discount per frontier cell (bigger = more to see), m
SIZE_BONUS_CAP_CELLS = 20  # clusters larger than this get no further bonus, cells
KEEP_TARGET_MARGIN_M = 6.0  # a new target must be this much cheaper to replace the current one, m
KEEP_TARGET_RADIUS_M = 8.0  # a frontier cell this close to the current target continues it (frontiers recede), m
IGNORE_RADIUS_M = 3.0  # frontier cells within this of an abandoned target are ignored, m
CIRCLE_WINDOW_S = 15.0  # window for circling detection, s
CIRCLE_TURN_DEG = 400.0  # net heading change within the window that means circling, degrees
CIRCLE_MAX_SPAN_M = 10.0  # ...while staying within a box this size, m
SEEN_CLOSE_M = 7.0  # a mapped obstacle counts as confirmed once the camera looked at it from this close, m
SEEN_CLOSE_SAMPLES_M = 6.0  # ...this close while samples are missing (7 called arm tips and side pockets explored with a sample in them: seeds 38, 17; 5 cost seed 1 70 s), m
SEEN_HALF_FOV_DEG = 45.0  # ...within this half-angle of the heading, degrees
SEARCH_MIN_AWAY_M = 3.0  # sample search visits mapped floor at least this far from the trail (4 missed a rock seen only from a wall strip), m
PEEK_RANGE_M = 3.0  # the smallest sample shows in the camera from about this close, m
PEEK_MIN_CELLS = 3  # shadowed-floor clusters smaller than this are not worth a peek, cells
PEEK_MIN_DEPTH_M = 2.0  # ...nor those not reaching this far from sunlit floor (a shadowed fringe along a wall), m
PEEK_MAX_DEPTH_M = 3.5  # the rover peeks no deeper into shadow than this (dark slots are traps; 3 m more are seen), m
PEEK_DONE_M = 1.5  # a reached peek target rules out the shadowed floor this close to it, m
SEARCH_LOOK_M = 4.0  # a wall foot counts as searched once the camera saw it from this close (its footprint is its field of view; perception records looks up to 4 m), m
SEARCH_LOOK_TRAIL_M = 5.0  # the search visits unsearched wall feet this close to the trail (farther ones are the far-floor search's), m
SEARCH_LOOK_MIN_CELLS = 3  # smaller clusters of unsearched wall feet are not worth a visit (a sample nook is wider), cells
SEARCH_FACE_RADIUS_M = 5.0  # at a reached search / peek target the rover turns to face unsearched wall feet this close, m
SEARCH_FACE_HALF_FOV_DEG = 30.0  # ...counting those within this half-angle of a heading (inside the camera's ~55 deg), degrees
SEARCH_FACE_STEP_DEG = 10.0  # candidate headings are tried at this spacing, degrees
SEARCH_FACE_MIN_CELLS = 2  # fewer unsearched wall-foot cells than this in view are not worth a turn, cells
SEARCH_HEADING_WEIGHT_M_PER_RAD = 8.0  # sample search: extra cost per radian a goal lies off the heading (keep sweeping one way), m/rad
SWEEP_RADIUS_M = 8.0  # a long turn in place counts unsearched wall feet this close as swept by the camera (rocks show from ~6-8 m), m
SWEEP_HALF_FOV_DEG = 40.0  # ...within this half-angle of the heading (perception's look cone), degrees
SWEEP_MAX_TURN_DEG = 225.0  # the long way round is taken only up to this (ROTATE_TIMEOUT_S at ~45 deg/s is 270), degrees
SWEEP_MIN_CELLS = 3  # ...and only when it sweeps at least this many unsearched wall-foot cells the short way does not, cells
GLANCE_MIN_CELLS = 3  # a turn back glances first at unsearched wall feet within SEARCH_FACE_RADIUS_M only when the best heading outside its sweep holds this many (a sample nook is wider), cells
GLANCE_MAX_EXTRA_DEG = 180.0  # ...and only when the glance adds at most this much turning to the turn back (~4 s at 45 deg/s; glancing at every turn back cost seeds 0, 3 and 7 40-70 s), degrees
SIGHT_WALL_DEPTH_M = 0.7  # a line of sight sees mapped wall this deep past where it first meets wall, no deeper (map edges are a cell fuzzy; a rock in front hides the nook behind it: seeds 7, 15), m
SIGHT_REACH_MARGIN_M = 1.5  # ...and this far past where the frame's light floor ends in its direction (the fringe where a wall's foot blends into the floor is not light sand), m
SIGHT_STEP_M = 0.2  # line-of-sight march step, m
SIGHT_RAY_DEG = 2.0  # angle between lines of sight (0.14 m apart at 4 m, well under a cell), degrees
SIGHT_MIN_FORWARD_M = 0.6  # ground nearer than this (ahead of the rover) is hidden under the camera (perception.GRID_MIN_FORWARD_M), m
LOOK_STAND_DONE_M = 1.5  # a reached look stand rules out stands this close; the wall feet it faced stay open if still unseen, m
LOOK_TRIES = 2  # wall feet faced from this many look stands and still unseen are given up (a cell the camera cannot see never holds the search)
FAINT_SAND_MIN_SHARE = 0.1  # a wall cell keeping at least this share of sand votes may be shadowed floor (a slot's floor keeps 0.1-0.3, solid wall ~0), 0..1
FAINT_MIN_DEPTH_M = 2.0  # ...counted only in clusters reaching this far from mapped floor (every floor edge has a fuzzy 1-2 cell fringe), m
FAINT_MIN_CELLS = 3  # ...of at least this many cells, cells
FAINT_ENTER_REACH_M = PEEK_RANGE_M  # exploration drives into pockets reaching this far past the floor they open onto (the camera shows the smallest sample from about this far, so a shallower pocket's end shows from its floor), m
FAINT_ENTER_WIDTH_M = 5.0  # ...and at most this wide across the way it runs (the narrow places that hold sample points are 2.5-4 m of height-0 floor across, plus a cell of map fuzz; wider is a shaded wall face or slope), m
FAINT_EDGE_M = 1.5  # pocket cells this close to the floor they open onto are its fuzzy edge, left out of the run direction (a cell and its diagonal neighbour), m
REVISIT_AGE_S = 60.0  # a cell last visited longer ago than this counts as a revisit, s


def _seen_offsets():
    r = int(np.ceil(SEEN_CLOSE_M))
    dy, dx = np.mgrid[-r:r + 1, -r:r + 1]
    keep = np.hypot(dx, dy) <= SEEN_CLOSE_M
    return dy[keep].astype(np.float64), dx[keep].astype(np.float64)


def _build_tables():
    """mark_seen_close's offset tables from SEEN_CLOSE_M and SEEN_HALF_FOV_DEG (sim.sweep calls this again
    after it sets either constant)."""
    global _SEEN_DY, _SEEN_DX, _SEEN_R, _SEEN_RNG, _SEEN_NEAR, _SEEN_HALF_FOV_RAD, _LAST_VIEW
    _SEEN_DY, _SEEN_DX = _seen_offsets()
    _SEEN_R = int(np.ceil(SEEN_CLOSE_M))  # largest offset from the rover's cell, cells
    _SEEN_RNG = np.hypot(_SEEN_DX, _SEEN_DY)  # distance of each offset, cells
    _SEEN_NEAR = _SEEN_RNG <= 1.5  # offsets marked whatever the heading (under the rover)
    _SEEN_HALF_FOV_RAD = np.radians(SEEN_HALF_FOV_DEG)
    _LAST_VIEW = (None, None)  # ((x, y, yaw, type of yaw), offsets within the camera's half-angle) of the last call


_build_tables()


def mark_seen_close(seen, pos, yaw_deg, radius_m=SEEN_CLOSE_M):
    """Mark cells the camera looks at from close range this frame (in place).

    Far ground in a narrowing canyon is often mapped as obstacle (walls fill the
    view); such cells stay 'unconfirmed' and keep pulling exploration until
    the rover has looked at them from close.
    """
    global _LAST_VIEW
    if not (np.isfinite(pos[0]) and np.isfinite(pos[1]) and np.isfinite(yaw_deg)):
        return seen
    cx, cy = float(pos[0]) - 0.5, float(pos[1]) - 0.5
    rx, ry = round(cx), round(cy)  # the cell under the rover (half to even, as np.round)
    key = (cx, cy, yaw_deg, type(yaw_deg))
    last_key, in_view = _LAST_VIEW  # one tuple, read and replaced whole
    if last_key != key:  # a new pose (decision marks two maps a frame from the same one: the same angles)
        ang = np.arctan2(_SEEN_DY + (ry - cy), _SEEN_DX + (rx - cx))
        ang -= np.radians(yaw_deg)
        ang += np.pi
        ang %= 2 * np.pi
        ang -= np.pi
        in_view = np.abs(ang) <= _SEEN_HALF_FOV_RAD
        _LAST_VIEW = (key, in_view)
    keep = in_view & (_SEEN_RNG <= radius_m)
    keep |= _SEEN_NEAR
    h, w = seen.shape
    if _SEEN_R <= ry < h - _SEEN_R and _SEEN_R <= rx < w - _SEEN_R and seen.flags.c_contiguous:
        seen.reshape(-1)[ry * w + rx + (_SEEN_DY[keep] * w + _SEEN_DX[keep]).astype(np.int64)] = True  # all inside
        return seen
    rows = (ry + _SEEN_DY[keep]).astype(np.int64)
    cols = (rx + _SEEN_DX[keep]).astype(np.int64)
    ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    seen[rows[ok], cols[ok]] = True
    return seen


@njit(cache=True)
def _sight_kernel(worldmap, seen, x, y, yaw, half_fov, n_rays, max_range, step, min_forward, wall_depth,
                  nav_min, dominance, reach, reach_half_fov_deg, reach_bin_deg, reach_margin):
    """March n_rays lines of sight over yaw +- half_fov (radians) from (x, y) out to max_range and mark
    every cell they reach in ``seen``. A cell is opaque when the worldmap calls it obstacle (red > 0
    and not navigable by grid.classify's rule, with nav_min / dominance passed in); a line stops
    once it has run more than wall_depth through opaque cells. With a non-empty ``reach`` (this
    frame's free distance per angular bin, navigation.reactive.reach_profile) a line also stops
    reach_margin beyond where the camera saw the floor end."""
    size_y, size_x = seen.shape
    for i in range(n_rays):
        off = -half_fov + 2.0 * half_fov * i / (n_rays - 1) if n_rays > 1 else 0.0
        c, s = math.cos(yaw + off), math.sin(yaw + off)
        r = min_forward / math.cos(off)
        wall = 0.0
        far = max_range
        if reach.size > 0:
            k = int(math.floor((off * (180.0 / math.pi) + reach_half_fov_deg) / reach_bin_deg))
            far = min(far, reach[k] + reach_margin) if 0 <= k < reach.size else far
        while r <= far:
            cx = int(math.floor(x + r * c))
            cy = int(math.floor(y + r * s))
            if cx < 0 or cx >= size_x or cy < 0 or cy >= size_y:
                break
            blue = np.float32(worldmap[cy, cx, 2])
            red = np.float32(worldmap[cy, cx, 0])
            if red > 0 and not (blue >= nav_min and blue * dominance >= red):
                wall += step
                if wall > wall_depth:
                    break
            seen[cy, cx] = True
            r += step


def mark_in_sight(seen, worldmap, pos, yaw_deg, range_m, half_fov_deg, reach=None):
    """Mark (in place) the cells within range_m and half_fov_deg of the heading that the camera can
    see from pos: lines of sight pass mapped floor freely and stop SIGHT_WALL_DEPTH_M into mapped wall
    and, with `reach` (this frame's reactive.reach_profile), SIGHT_REACH_MARGIN_M beyond the light floor
    the camera saw in their direction (the darker fringe at a wall's foot lies past it).

    Perception's closest-look map records every cell of the ground footprint, including the cells
    a rock in front hides: on seeds 7 and 15 the rover faced the east-nook sample from 3.5 m across
    the rocks south-west of it, called the nook searched, and never saw the rock. The map alone is not
    enough: on seed 15 the rock in front was mapped as floor; the frame, a rock face filling the view,
    showed no floor at all.
    """
    if not (np.isfinite(pos[0]) and np.isfinite(pos[1]) and np.isfinite(yaw_deg)):
        return seen
    wm = np.asarray(worldmap)
    if wm.ndim != 3 or wm.shape[:2] != seen.shape or wm.shape[2] < 3:
        return seen
    half = math.radians(half_fov_deg)
    n_rays = int(math.ceil(2.0 * half_fov_deg / SIGHT_RAY_DEG)) + 1
    reach = np.zeros(0) if reach is None else np.ascontiguousarray(reach, dtype=np.float64)
    _sight_kernel(wm, seen, float(pos[0]), float(pos[1]), math.radians(yaw_deg), half, n_rays, float(range_m),
                  SIGHT_STEP_M, SIGHT_MIN_FORWARD_M, SIGHT_WALL_DEPTH_M, np.float32(grid.NAV_MIN_VALUE),
                  np.float32(grid.OBSTACLE_DOMINANCE), reach, float(reactive.FOV_HALF_DEG), float(reactive.BIN_DEG),
                  SIGHT_REACH_MARGIN_M)
    return seen


def frontier_mask(free, unknown, ignored=None, obstacle=None, seen_close=None):
    """Navigable cells 8-adjacent to unknown cells (minus ignored ones).

    With `obstacle` and `seen_close`, obstacle cells never looked at from close
    count as unknown.
    """
    if obstacle is not None and seen_close is not None:
        unknown = unknown | (obstacle & ~seen_close)
    unk = unknown.astype(np.uint8)
    grown = cv2.dilate(unk, np.ones((3, 3), np.uint8)) > 0
    around = cv2.boxFilter(unk, cv2.CV_32F, (FRONTIER_WINDOW, FRONTIER_WINDOW), normalize=False,
                           borderType=cv2.BORDER_CONSTANT)
    mask = free & grown & (around >= FRONTIER_MIN_UNKNOWN)
    mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = False
    if ignored is not None:
        mask &= ~ignored
    return mask


def frontier_targets(mask, dist):
    """Reachable frontier clusters as a structured list: one (row, col, path_cost, size) per cluster.

    The target cell of a cluster is its cell with the lowest path cost.
    """
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return np.zeros((0, 4))
    lab = labels[rows, cols]
    d = dist[rows, cols]
    ok = np.isfinite(d) & (stats[lab, cv2.CC_STAT_AREA] >= FRONTIER_MIN_CELLS)
    if not ok.any():
        return np.zeros((0, 4))
    rows, cols, lab, d = rows[ok], cols[ok], lab[ok], d[ok]
    return _first_per_cluster(rows, cols, lab, d, stats, np.lexsort((d, lab)))


def _first_per_cluster(rows, cols, lab, d, stats, order):
    """(row, col, path_cost, size) of each cluster's first cell in `order` (which must group clusters)."""
    first = np.ones(order.size, bool)
    first[1:] = lab[order][1:] != lab[order][:-1]
    pick = order[first]
    sizes = stats[lab[pick], cv2.CC_STAT_AREA].astype(np.float64)
    return np.stack([rows[pick], cols[pick], d[pick], sizes], axis=1).astype(np.float64)


def score_targets(targets, pos, yaw_deg):
    """Lower is better: path cost + heading change penalty - size bonus."""
    if len(targets) == 0:
        return np.zeros(0)
    tx = targets[:, 1] + 0.5
    ty = targets[:, 0] + 0.5
    ang = np.arctan2(ty - pos[1], tx - pos[0]) - np.radians(yaw_deg)
    off = np.abs((ang + np.pi) % (2 * np.pi) - np.pi)
    bonus = SIZE_BONUS_M_PER_CELL * np.minimum(targets[:, 3], SIZE_BONUS_CAP_CELLS)
    return targets[:, 2] + HEADING_WEIGHT_M_PER_RAD * off - bonus


def choose_target(targets, pos, yaw_deg, current=None, keep_margin_m=KEEP_TARGET_MARGIN_M):
    """Best frontier cell (row, col), keeping `current` unless one scores keep_margin_m better.

    A caller that has just committed to `current` passes an infinite margin: the heading term
    changes as the rover turns toward its path, and two targets on either side once took turns
    at being best, leaving the rover turning in place for 20 s (seed 23).
    """
    if len(targets) == 0:
        return None
    scores = score_targets(targets, pos, yaw_deg)
    best = int(np.argmin(scores))
    if current is not None:
        d = np.hypot(targets[:, 0] - current[0], targets[:, 1] - current[1])
        near = d <= KEEP_TARGET_RADIUS_M
        if near.any():
            cur_score = scores[near].min()
            if cur_score <= scores[best] + keep_margin_m:
                k = np.nonzero(near)[0][int(np.argmin(scores[near]))]
                return int(targets[k, 0]), int(targets[k, 1])
    return int(targets[best, 0]), int(targets[best, 1])


def ignore_disc(ignored, cell, radius=IGNORE_RADIUS_M):
    """Mark a disc of cells around `cell` as ignored frontier (in place)."""
    cv2.circle(ignored.view(np.uint8), (int(cell[1]), int(cell[0])), int(np.ceil(radius)), 1, -1)
    return ignored


def peek_targets(free, shadow_floor, looked, done, dist):
    """Pockets of shadowed floor beside ground the camera never saw from within PEEK_RANGE_M.

    The drive map keeps the rover off shadowed floor, so exploration never goes there, and
    pockets in deep shadow (a slot beside a pillar, a narrow inlet) hide small samples that
    only show from a few metres.  The sample search peeks into them before anything else.
    A pocket is a cluster of at least PEEK_MIN_CELLS such cells (minus `done` ones) reaching
    PEEK_MIN_DEPTH_M from sunlit floor (every wall has a thin shadowed fringe); its target is
    its deepest reachable cell no more than PEEK_MAX_DEPTH_M in (a narrow dark slot is a trap).
    Returns one (row, col, path_cost, size) per pocket, like frontier_targets.
    """
    unlooked = cv2.dilate((~looked).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    mask = shadow_floor & unlooked & ~done
    mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = False
    if not mask.any():
        return np.zeros((0, 4))
    depth = cv2.distanceTransform((~free).astype(np.uint8), cv2.DIST_L2, 3)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    rows, cols = np.nonzero(mask)
    lab, dep, d = labels[rows, cols], depth[rows, cols], dist[rows, cols]
    deepest = np.zeros(n, np.float32)
    np.maximum.at(deepest, lab, dep)
    ok = ((deepest[lab] >= PEEK_MIN_DEPTH_M) & (stats[lab, cv2.CC_STAT_AREA] >= PEEK_MIN_CELLS)
          & (dep <= PEEK_MAX_DEPTH_M) & np.isfinite(d))
    if not ok.any():
        return np.zeros((0, 4))
    rows, cols, lab, dep, d = rows[ok], cols[ok], lab[ok], dep[ok], d[ok]
    return _first_per_cluster(rows, cols, lab, d, stats, np.lexsort((d, -dep, lab)))  # deepest, then cheapest


def search_target(free, visited, done, dist, pos=None, yaw_deg=None):
    """Nearest (by path, plus the heading term when pos / yaw_deg are given: see search_cost) mapped
    floor cell far from everywhere the rover has been, or None.

    Used when the map is complete but samples are missing: a sample hidden in
    a pocket (behind a rock at an arm's tip) is only seen from close by.
    """
    away = cv2.distanceTransform((~visited).astype(np.uint8), cv2.DIST_L2, 3)
    cand = free & (away >= SEARCH_MIN_AWAY_M) & ~done & np.isfinite(dist)
    if not cand.any():
        return None
    rows, cols = np.nonzero(cand)
    k = int(np.argmin(search_cost(rows, cols, dist[rows, cols], pos, yaw_deg)))
    return int(rows[k]), int(cols[k])


def search_cost(rows, cols, path_cost, pos=None, yaw_deg=None):
    """Cost of sample-search goals at cells (rows, cols): path cost + SEARCH_HEADING_WEIGHT_M_PER_RAD per
    radian off the heading (just the path cost without pos / yaw_deg).

    Nearest first by path alone zig-zagged: on seed 29 (15 fps) the search walked east along the
    west arm, turned back 25 m for wall feet it had passed, went to the west tip, then crossed the
    whole canyon east to where the sixth sample lay (220 s of search). Like exploration, the search
    now keeps going the way it faces unless going back is much nearer.
    """
    cost = np.asarray(path_cost, np.float64)
    if pos is None or yaw_deg is None or not (np.isfinite(pos[0]) and np.isfinite(pos[1]) and np.isfinite(yaw_deg)):
        return cost
    ang = np.arctan2(np.asarray(rows) + 0.5 - pos[1], np.asarray(cols) + 0.5 - pos[0]) - np.radians(yaw_deg)
    off = np.abs((ang + np.pi) % (2 * np.pi) - np.pi)
    return cost + SEARCH_HEADING_WEIGHT_M_PER_RAD * off


def unsearched_wall_feet(free, obstacle, looked):
    """bool map: obstacle cells touching mapped floor that the camera never saw from close by.

    Samples lie at wall feet, and one in a nook (a pocket of floor mapped as wall from afar) only
    shows once the camera faces it from a few metres.  Passing by with the nook beside or
    behind the camera does not count: `looked` (perception's closest-look map) only holds cells
    that were inside the camera's ground footprint, i.e. within its field of view.
    """
    floor_near = cv2.dilate(free.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    return obstacle & floor_near & ~looked


def look_targets(unsearched, free, visited, done, dist, stand_done=None):
    """Clusters of unsearched wall feet within SEARCH_LOOK_TRAIL_M of the trail (`visited`, minus `done`
    cells), each with the floor cell beside it that is nearest by path: one (row, col, path_cost, size)
    per cluster, like frontier_targets.

    The far-floor search visits floor away from the trail and so never went near a nook beside it
    (seeds 10 and 23: the east-nook sample lay 4-5 m from the trail, never in the camera's view).
    Wall feet farther from the trail get faced when a far-floor visit nears them (face_heading).
    Stands in `stand_done` (reached before) are not offered again, so wall feet a stand could not
    see are next looked at from another side (see give_up_faced).
    """
    trail_dist = cv2.distanceTransform((~visited).astype(np.uint8), cv2.DIST_L2, 3)
    mask = unsearched & ~done & (trail_dist <= SEARCH_LOOK_TRAIL_M)
    mask[0, :] = mask[-1, :] = mask[:, 0] = mask[:, -1] = False
    if not mask.any():
        return np.zeros((0, 4))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    beside = cv2.dilate(labels.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int64)
    stand = free & (beside > 0) & np.isfinite(dist)
    if stand_done is not None:
        stand &= ~stand_done
    rows, cols = np.nonzero(stand)
    if rows.size == 0:
        return np.zeros((0, 4))
    lab, d = beside[rows, cols], dist[rows, cols]
    ok = stats[lab, cv2.CC_STAT_AREA] >= SEARCH_LOOK_MIN_CELLS
    if not ok.any():
        return np.zeros((0, 4))
    rows, cols, lab, d = rows[ok], cols[ok], lab[ok], d[ok]
    return _first_per_cluster(rows, cols, lab, d, stats, np.lexsort((d, lab)))


def faint_pockets(free, obstacle, sand_share):
    """bool map: wall cells that may be floor in deep shadow: mapped obstacle keeping at least
    FAINT_SAND_MIN_SHARE of sand votes, in 8-connected clusters of FAINT_MIN_CELLS or more touching
    mapped floor (through the wall feet) and reaching FAINT_MIN_DEPTH_M from it.

    Shadowed floor is voted down to wall, so a slot's floor is wall on the map and its mouth's wall
    feet count as searched while the sample lies 2-4 m deeper (seeds 14 and 17, shadows on: 5/6 at
    850 s). Nothing else in the map tells such a slot from a wall."""
    cand = obstacle & (sand_share >= FAINT_SAND_MIN_SHARE)
    cand[0, :] = cand[-1, :] = cand[:, 0] = cand[:, -1] = False
    if not cand.any():
        return cand
    depth = cv2.distanceTransform((~free).astype(np.uint8), cv2.DIST_L2, 3)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(cand.astype(np.uint8), connectivity=8)
    lab = labels[cand]
    deepest = np.zeros(n, np.float32)
    np.maximum.at(deepest, lab, depth[cand])
    nearest = np.full(n, np.inf, np.float32)
    np.minimum.at(nearest, lab, depth[cand])
    keep = (deepest >= FAINT_MIN_DEPTH_M) & (nearest <= 1.5) & (stats[:, cv2.CC_STAT_AREA] >= FAINT_MIN_CELLS)
    keep[0] = False
    return keep[labels] & cand


def pocket_shapes(labels, n, free):
    """(reach_m, width_m): float arrays indexed by label 0..n-1 of the pocket clusters in `labels` (int map,
    0 = none). Reach: how far the cluster's farthest cell lies from the floor it opens onto (the `free`
    cells beside it), cell centre to cell centre. Width: the cluster's extent across the direction it runs
    (from the opening floor's centre to the centre of its cells past FAINT_EDGE_M), plus one cell.

    A cell count along the floor called seed 17's spur (3 m across, its faint end wrapped along the side
    walls) 11 cells wide, and a 3-cell chamfer distance called its 3 m reach 2.87 m (seed 17 off: 5/6)."""
    reach = np.zeros(n)
    width = np.zeros(n)
    pocket = labels > 0
    if n <= 1 or not pocket.any():
        return reach, width
    beside = cv2.dilate(labels.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int64)
    opening = free & (beside > 0)  # a floor cell beside two clusters counts for the higher label only
    if not opening.any():
        return reach, width
    away = cv2.distanceTransform((~opening).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    rows, cols = np.nonzero(pocket)
    lab, far = labels[rows, cols], away[rows, cols]
    np.maximum.at(reach, lab, far)
    orows, ocols = np.nonzero(opening)
    olab = beside[orows, ocols]
    on = np.maximum(np.bincount(olab, minlength=n), 1)
    deep = far >= FAINT_EDGE_M
    dn = np.bincount(lab[deep], minlength=n)
    run_y = np.bincount(lab[deep], rows[deep], minlength=n) / np.maximum(dn, 1) - np.bincount(olab, orows, minlength=n) / on
    run_x = np.bincount(lab[deep], cols[deep], minlength=n) / np.maximum(dn, 1) - np.bincount(olab, ocols, minlength=n) / on
    norm = np.hypot(run_x, run_y)
    norm[norm == 0] = 1.0
    across = (rows * run_x[lab] - cols * run_y[lab]) / norm[lab]  # position across the run direction
    lo = np.full(n, np.inf)
    hi = np.full(n, -np.inf)
    np.minimum.at(lo, lab, across)
    np.maximum.at(hi, lab, across)
    width[dn > 0] = hi[dn > 0] - lo[dn > 0] + 1.0
    return reach, width


def enterable_pockets(pockets, unlooked, free):
    """int32 label map (0 elsewhere) of the clusters of `pockets` (faint_pockets) worth driving into: each
    still holds an `unlooked` cell, reaches FAINT_ENTER_REACH_M past the floor it opens onto and is at most
    FAINT_ENTER_WIDTH_M wide across (pocket_shapes: a nook, not a faint band along a shaded wall face or
    slope). Their entry targets are peek_targets(free, clusters > 0, ...): the deepest cell the rover can
    reach no more than PEEK_MAX_DEPTH_M from mapped floor. Independent of the cost grid, so a planner
    trying several grids labels the pockets once. Driving into every pocket on the map first (the west
    arm's 48-cell faint band, the south tip) cost seed 0 (shadows on) the east-nook sample, in no pocket.

    Exploration drives in there, once no ordinary frontier is left with samples missing. The floor at a
    pocket's mouth was not enough: on seed 17 (shadows on) the mouth of the spur was looked at from 4 m
    while exploring, which hid the deeper cells from the mouth rule, and the sample lies 7 m in."""
    n, labels, _stats, _ = cv2.connectedComponentsWithStats(pockets.astype(np.uint8), connectivity=8)
    reach, width = pocket_shapes(labels, n, free)
    keep = np.zeros(n, bool)
    keep[np.unique(labels[pockets & unlooked])] = True
    keep &= (reach >= FAINT_ENTER_REACH_M) & (width <= FAINT_ENTER_WIDTH_M)
    keep[0] = False
    return np.where(keep[labels], labels, 0).astype(np.int32)


def _window(shape, pos, radius_m):
    """(y0, y1, x0, x1): the grid rows and columns, clipped to shape, of a square holding every cell
    within radius_m of pos (may be empty when pos is off the grid)."""
    r = int(np.ceil(radius_m)) + 1
    cy, cx = int(np.floor(pos[1])), int(np.floor(pos[0]))
    return max(cy - r, 0), min(cy + r + 1, shape[0]), max(cx - r, 0), min(cx + r + 1, shape[1])


def give_up_faced(tries, done, unsearched, pos, radius_m=SEARCH_FACE_RADIUS_M, max_tries=LOOK_TRIES):
    """Count one more look at the unsearched cells within radius_m of pos (in `tries`, int array) and
    add those looked at max_tries times to `done` (both in place). Returns done.

    A reached look stand used to rule out every wall foot within 5 m, seen or not; from a stand
    behind a rock the nook stayed hidden and was never looked at again (seeds 7 and 15)."""
    if not (np.isfinite(pos[0]) and np.isfinite(pos[1])):
        return done
    y0, y1, x0, x1 = _window(unsearched.shape, pos, radius_m)
    if y0 >= y1 or x0 >= x1:
        return done
    ys, xs = np.mgrid[y0:y1, x0:x1]
    near = (np.hypot(xs + 0.5 - pos[0], ys + 0.5 - pos[1]) <= radius_m) & unsearched[y0:y1, x0:x1]
    tries[y0:y1, x0:x1] += near
    done[y0:y1, x0:x1] |= near & (tries[y0:y1, x0:x1] >= max_tries)
    return done


def _unsearched_offsets_within(unsearched, pos, radius_m):
    """(dx, dy) in metres from pos to the centre of every unsearched cell within radius_m: the cells
    a turn in place at pos could bring into view (face_heading and sweep_direction)."""
    y0, y1, x0, x1 = _window(unsearched.shape, pos, radius_m)
    rows, cols = np.nonzero(unsearched[y0:y1, x0:x1])
    dx, dy = cols + x0 + 0.5 - pos[0], rows + y0 + 0.5 - pos[1]
    near = np.hypot(dx, dy) <= radius_m
    return dx[near], dy[near]


def _most_in_view(dx, dy, headings):
    """(heading, count): of `headings` (deg, non-empty), the first that puts the most of the cells at
    offsets (dx, dy) inside SEARCH_FACE_HALF_FOV_DEG, and how many it puts there (face_heading and
    glance_heading choose where to look by this count)."""
    bearing = np.degrees(np.arctan2(dy, dx))
    off = np.abs((bearing[None, :] - headings[:, None] + 180.0) % 360.0 - 180.0)
    counts = (off <= SEARCH_FACE_HALF_FOV_DEG).sum(axis=1)
    best = int(np.argmax(counts))
    return float(headings[best]), int(counts[best])


def face_heading(unsearched, pos, yaw_deg):
    """World heading (deg) that puts the most unsearched cells within SEARCH_FACE_RADIUS_M of `pos`
    inside SEARCH_FACE_HALF_FOV_DEG, or None when fewer than SEARCH_FACE_MIN_CELLS would be in view
    or the camera already faces them (best heading within SEARCH_FACE_HALF_FOV_DEG of yaw_deg).

    Reaching a search target used to mark everything around it searched whichever way the camera
    pointed (seed 10: the rover stood 4.4 m from the east-nook sample and turned away from it).
    """
    if not (np.isfinite(pos[0]) and np.isfinite(pos[1]) and np.isfinite(yaw_deg)):
        return None
    dx, dy = _unsearched_offsets_within(unsearched, pos, SEARCH_FACE_RADIUS_M)
    if len(dx) < SEARCH_FACE_MIN_CELLS:
        return None
    heading, count = _most_in_view(dx, dy, np.arange(0.0, 360.0, SEARCH_FACE_STEP_DEG))
    if count < SEARCH_FACE_MIN_CELLS:
        return None
    if abs((heading - yaw_deg + 180.0) % 360.0 - 180.0) <= SEARCH_FACE_HALF_FOV_DEG:
        return None
    return heading


def glance_heading(unsearched, pos, yaw_deg, target_deg):
    """World heading (deg) to face first, before a turn in place the short way from yaw_deg to target_deg:
    the one putting the most unsearched cells within SEARCH_FACE_RADIUS_M inside SEARCH_FACE_HALF_FOV_DEG
    among headings the short turn does not sweep (nor start or end on) and that add at most
    GLANCE_MAX_EXTRA_DEG of turning, or None when it holds fewer than GLANCE_MIN_CELLS.

    A turn back happens where a path doubles back (an arm's tip, a pocket's end), which is where nooks
    are; the camera then faces the ones beside the dead end whichever side the rover came from.
    """
    if unsearched is None or not (np.isfinite(pos[0]) and np.isfinite(pos[1]) and np.isfinite(yaw_deg)
                                  and np.isfinite(target_deg)):
        return None
    dx, dy = _unsearched_offsets_within(unsearched, pos, SEARCH_FACE_RADIUS_M)
    if len(dx) < GLANCE_MIN_CELLS:
        return None
    err = (float(target_deg) - float(yaw_deg) + 180.0) % 360.0 - 180.0
    h = SEARCH_FACE_HALF_FOV_DEG
    # candidate offsets from yaw, measured the short turn's way: [-h, |err| + h] is swept anyway
    way = 1.0 if err >= 0 else -1.0
    offs = np.arange(0.0, 360.0, SEARCH_FACE_STEP_DEG)
    swept = (offs <= abs(err) + h) | (offs >= 360.0 - h)
    cand = offs[~swept]
    if cand.size == 0:
        return None
    headings = (float(yaw_deg) + way * cand) % 360.0
    turned = (np.abs((headings - float(yaw_deg) + 180.0) % 360.0 - 180.0)
              + np.abs((float(target_deg) - headings + 180.0) % 360.0 - 180.0))
    headings = headings[turned - abs(err) <= GLANCE_MAX_EXTRA_DEG]
    if headings.size == 0:
        return None
    heading, count = _most_in_view(dx, dy, headings)
    return heading if count >= GLANCE_MIN_CELLS else None


def sweep_direction(unsearched, pos, yaw_deg, target_deg):
    """Which way to turn in place from yaw_deg to target_deg: +1 (yaw increasing, left) or -1, so that
    the camera sweeps over unsearched wall feet on the way.

    The short way is the default. The long way is taken when it is at most SWEEP_MAX_TURN_DEG and
    its arc alone (not the short arc, nor the start and end views both share) holds at least
    SWEEP_MIN_CELLS unsearched cells within SWEEP_RADIUS_M, more than the short arc alone. At an
    arm's tip the rover turns round with samples missing; seed 31 (15 fps) turned 157 deg the short
    way at the west tip, the sixth sample 6.5 m off on the other side, and found it 630 s later.
    """
    err = (float(target_deg) - float(yaw_deg) + 180.0) % 360.0 - 180.0
    short = 1 if err >= 0 else -1
    if 360.0 - abs(err) > SWEEP_MAX_TURN_DEG or not (np.isfinite(pos[0]) and np.isfinite(pos[1])):
        return short
    dx, dy = _unsearched_offsets_within(unsearched, pos, SWEEP_RADIUS_M)
    # offset of each cell counter-clockwise from the start heading; the left arc spans [0, left]
    off = (np.degrees(np.arctan2(dy, dx)) - float(yaw_deg)) % 360.0
    left = err % 360.0
    h = SWEEP_HALF_FOV_DEG
    only_left = int(((off > h) & (off < left - h)).sum())
    only_right = int(((off > left + h) & (off < 360.0 - h)).sum())
    long_cells, short_cells = (only_right, only_left) if short > 0 else (only_left, only_right)
    if long_cells >= SWEEP_MIN_CELLS and long_cells > short_cells:
        return -short
    return short


def arc_swept_cells(cells, pos, yaw_deg, turn_ccw_deg):
    """How many of the cells (a bool [y, x] map: unsearched wall feet, frontier) within SWEEP_RADIUS_M a
    turn in place of turn_ccw_deg (CCW +, any length) from yaw_deg brings into view that neither the
    start nor the end view (SWEEP_HALF_FOV_DEG either side) holds: what the camera sees only while it turns."""
    if cells is None or not (np.isfinite(pos[0]) and np.isfinite(pos[1])) or abs(turn_ccw_deg) <= 2 * SWEEP_HALF_FOV_DEG:
        return 0
    dx, dy = _unsearched_offsets_within(cells, pos, SWEEP_RADIUS_M)
    # offset of each cell from the start heading, measured the way the rover turns
    off = ((np.degrees(np.arctan2(dy, dx)) - float(yaw_deg)) * np.sign(turn_ccw_deg)) % 360.0
    h = SWEEP_HALF_FOV_DEG
    return int(((off > h) & (off < abs(turn_ccw_deg) - h)).sum())


def nearest_target(targets, pos=None, yaw_deg=None):
    """(row, col) of the target with the lowest search_cost (path cost alone without pos / yaw_deg), or None."""
    if len(targets) == 0:
        return None
    k = int(np.argmin(search_cost(targets[:, 0], targets[:, 1], targets[:, 2], pos, yaw_deg)))
    return int(targets[k, 0]), int(targets[k, 1])


def nearer_search_goal(peek, far, dist, look=None, pos=None, yaw_deg=None, pocket=None):
    """("peek" | "search" | "look" | "pocket", cell) for whichever of the best pocket peek, the best far-floor
    cell, the best stand beside unsearched wall feet and the way into the nearest faint pocket is cheapest
    by search_cost (by path alone without pos / yaw_deg), or None when none exists.

    Both are places a small sample may hide; the search visits them nearest first. Peeks used to
    go first wherever they were: on seed 0 the rover stood 4 m from the unsearched tip of the
    north arm (where the sixth sample lay) and drove 180 m to a peek at the south tip first.
    """
    options = [(kind, cell) for kind, cell in (("peek", peek), ("search", far), ("look", look), ("pocket", pocket))
               if cell is not None and np.isfinite(dist[cell])]
    if not options:
        return None
    costs = search_cost([c[0] for _k, c in options], [c[1] for _k, c in options],
                        [dist[c] for _k, c in options], pos, yaw_deg)
    kind, cell = options[int(np.argmin(costs))]
    return kind, cell


def ignored_frontiers(free, unknown, ignored, dist, obstacle=None, seen_close=None):
    """Reachable frontier clusters that only the ignore mask hides (same layout as frontier_targets).

    A frontier is ignored after the rover gave up on it, often because it got stuck on the
    way; when that was the only way into an arm, the map is not complete: the caller should
    look again (with the stuck memory off) before it calls the map done.
    """
    mask = frontier_mask(free, unknown, None, obstacle, seen_close) & ignored
    return frontier_targets(mask, dist)


def map_complete(targets):
    """The map is complete when no reachable frontier cluster is left."""
    return len(targets) == 0


class LoopDetector:
    """Detects circling: large accumulated heading change while staying in a small area."""

    def __init__(self):
        self.hist = deque()  # (t, x, y, unwrapped yaw deg)
        self._unwrapped = None
        self._last_yaw = None

    def update(self, t, pos, yaw_deg):
        if not (math.isfinite(t) and math.isfinite(pos[0]) and math.isfinite(pos[1]) and math.isfinite(yaw_deg)):
            return False
        if self._last_yaw is None:
            self._unwrapped = float(yaw_deg)
        else:
            self._unwrapped += ((yaw_deg - self._last_yaw + 180.0) % 360.0) - 180.0
        self._last_yaw = float(yaw_deg)
        self.hist.append((t, pos[0], pos[1], self._unwrapped))
        while self.hist and t - self.hist[0][0] > CIRCLE_WINDOW_S:
            self.hist.popleft()
        return self.circling()

    def circling(self):
        if len(self.hist) < 3:
            return False
        # plain Python on the deque (the same float64 values as NumPy would give): this runs every
        # frame, and building an array of ~600 tuples cost more than the rest of the test
        if abs(self.hist[-1][3] - self.hist[0][3]) < CIRCLE_TURN_DEG:
            return False
        xs = [entry[1] for entry in self.hist]
        ys = [entry[2] for entry in self.hist]
        return max(max(xs) - min(xs), max(ys) - min(ys)) <= CIRCLE_MAX_SPAN_M

    def reset(self):
        self.hist.clear()


class VisitMap:
    """When each cell was last driven over; tells fresh ground from revisits."""

    def __init__(self, shape=(200, 200)):
        self.last_visit = np.full(shape, -np.inf, np.float32)
        self.revisit_frames = 0  # frames spent on cells left more than REVISIT_AGE_S ago
        self.frames = 0

    def update(self, t, cell):
        if cell is None:
            return False
        self.frames += 1
        last = self.last_visit[cell]
        revisit = bool(np.isfinite(last) and t - last > REVISIT_AGE_S)
        self.revisit_frames += revisit
        self.last_visit[cell] = t
        return revisit

    def visited(self):
        return np.isfinite(self.last_visit)
