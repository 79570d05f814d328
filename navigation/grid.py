"""Occupancy and travel-cost grids built from the rover's own worldmap.

The planner never sees ground truth: it works on what perception has mapped
(blue = navigable, red = obstacle; decision hands in `perception.drive_map`, where
sand in shadow stays obstacle) plus the decision layer's memory of cells
where the rover got stuck. Costs grow near obstacles so planned paths keep to
the middle of the canyons, where the rover sees both walls and rarely scrapes.
"""
import math

import cv2
import numpy as np

GRID_SIZE = 200  # worldmap edge, cells (1 cell = 1 m)
NAV_MIN_VALUE = 1  # blue channel value from which a cell counts as seen navigable
OBSTACLE_DOMINANCE = 1.0  # a cell is an obstacle when red > this x blue
FREE_COST = 1.0  # travel cost of one metre over mapped navigable ground
UNKNOWN_COST = 4.0  # travel cost of one metre over unmapped ground (only when allowed)
CLEARANCE_M = 2.5  # within this distance of an obstacle a cell costs extra, m
CLEARANCE_PENALTY = 3.0  # extra cost per metre right next to an obstacle (falls linearly to 0 at CLEARANCE_M)
OBSTACLE_COST = 12.0  # travel cost of one metre through a mapped obstacle cell when soft (maps misjudge shadows behind rocks)
HARD_CLEARANCE_M = 1.5  # cells touching an obstacle (also diagonally) cost HARD_CLEARANCE_COST extra, m
HARD_CLEARANCE_COST = 12.0  # extra cost per metre of a cell inside HARD_CLEARANCE_M (used only to squeeze past)
ROUGH_FROM_SHARE = 0.4  # a mapped-free cell with more obstacle votes than this share is rough (small rocks), 0..1
ROUGH_FULL_SHARE = 0.8  # ...and fully rough from this share, 0..1
ROUGH_COST = 4.0  # extra travel cost of one metre over a fully rough cell


def classify(worldmap, nav_confidence=None):
    """Split a worldmap into (free, obstacle, unknown) boolean [y, x] masks.

    `nav_confidence` (optional, float [y, x], > 0 navigable, < 0 obstacle)
    overrides the colour test where it is non-zero; perception owns it.
    """
    wm = np.asarray(worldmap)
    blue = wm[:, :, 2].astype(np.float32)
    red = wm[:, :, 0].astype(np.float32)
    free = (blue >= NAV_MIN_VALUE) & (blue * OBSTACLE_DOMINANCE >= red)
    obstacle = (red > 0) & ~free
    if nav_confidence is not None:
        conf = np.asarray(nav_confidence, dtype=np.float32)
        if conf.shape == free.shape:
            free = np.where(conf > 0, True, np.where(conf < 0, False, free))
            obstacle = np.where(conf < 0, True, np.where(conf > 0, False, obstacle))
    unknown = ~(free | obstacle)
    return free, obstacle, unknown


def obstacle_distance(obstacle):
    """Distance in metres from every cell to the nearest obstacle cell (map border counts)."""
    passable = np.ones(obstacle.shape, np.uint8)
    passable[obstacle] = 0
    passable[0, :] = passable[-1, :] = 0
    passable[:, 0] = passable[:, -1] = 0
    return cv2.distanceTransform(passable, cv2.DIST_L2, 3)


def roughness(nav_confidence, obstacle_confidence):
    """0..1 per cell from its obstacle share of votes: a field of small rocks maps as free (each 1 m
    cell is mostly floor) but with many obstacle votes, and is where the rover gets stuck."""
    nav = np.asarray(nav_confidence, np.float32)
    obs = np.asarray(obstacle_confidence, np.float32)
    total = nav + obs
    share = np.divide(obs, total, out=np.zeros_like(total), where=total > 0)
    return np.clip((share - ROUGH_FROM_SHARE) / (ROUGH_FULL_SHARE - ROUGH_FROM_SHARE), 0.0, 1.0)


def cost_grid(free, obstacle, blocked=None, allow_unknown=False, soft_obstacles=False, rough=None):
    """Per-cell travel cost (float32, inf = impassable) for the path planner.

    Free cells cost FREE_COST plus a clearance penalty near obstacles; unknown
    cells are impassable unless `allow_unknown`; mapped obstacles are
    impassable, or cost OBSTACLE_COST per metre with `soft_obstacles` (the
    camera maps the ground behind a rock as obstacle until seen from the
    side); `blocked` (where the rover really got stuck) is always impassable;
    `rough` (0..1, see `roughness`) adds up to ROUGH_COST per metre.
    """
    obst = obstacle.copy()
    if blocked is not None:
        obst |= blocked
    dist = obstacle_distance(obst)
    base = np.where(free, FREE_COST, UNKNOWN_COST if allow_unknown else np.inf).astype(np.float32)
    near = np.clip(CLEARANCE_M - dist, 0.0, None) / CLEARANCE_M * CLEARANCE_PENALTY
    cost = base + near.astype(np.float32)
    cost[dist < HARD_CLEARANCE_M] += HARD_CLEARANCE_COST
    if rough is not None and np.shape(rough) == cost.shape:
        cost += ROUGH_COST * np.asarray(rough, np.float32)
    cost[obstacle] = OBSTACLE_COST + CLEARANCE_PENALTY + HARD_CLEARANCE_COST if soft_obstacles else np.inf
    if blocked is not None:
        cost[blocked] = np.inf
    cost[0, :] = cost[-1, :] = np.inf
    cost[:, 0] = cost[:, -1] = np.inf
    return cost


def world_to_cell(xy):
    """World (x, y) metres -> (row, col) cell, clipped to the grid; None for NaN."""
    x, y = float(xy[0]), float(xy[1])
    if not (math.isfinite(x) and math.isfinite(y)):
        return None
    col = min(max(math.floor(x), 0), GRID_SIZE - 1)  # plain ints (called every frame; NumPy scalars cost more)
    row = min(max(math.floor(y), 0), GRID_SIZE - 1)
    return row, col


def cell_to_world(row, col):
    """Centre of a cell in world metres (x, y)."""
    return float(col) + 0.5, float(row) + 0.5


def nearest_passable(cost, cell, max_radius=4):
    """The closest finite-cost cell to `cell` within max_radius (the rover may sit on a wall pixel)."""
    r0, c0 = cell
    if np.isfinite(cost[r0, c0]):
        return cell
    h, w = cost.shape
    r1, r2 = max(r0 - max_radius, 0), min(r0 + max_radius + 1, h)
    c1, c2 = max(c0 - max_radius, 0), min(c0 + max_radius + 1, w)
    win = cost[r1:r2, c1:c2]
    rr, cc = np.nonzero(np.isfinite(win))
    if rr.size == 0:
        return None
    d2 = (rr + r1 - r0) ** 2 + (cc + c1 - c0) ** 2
    k = int(np.argmin(d2))
    return int(rr[k] + r1), int(cc[k] + c1)
