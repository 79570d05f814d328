"""Worlds the project builds itself: a seeded canyon, and any 2-D navigable map extruded into 3-D.

Both start from a floor mask on the terrain vertex grid and share one extrusion:
walls rise with distance from the floor (plus smooth noise so they are not flat),
the light sand texture covers the floor and fades on the walls, so the renderer and
the starter's colour threshold treat them like the simulator's scene.
"""
from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from sim.scene import (FLOOR_TOLERANCE_M, MAP_CELLS, ROCK_CELL_M, ROCK_SAMPLES, SAND_CELL_M,
                       SAND_TEXELS, TERRAIN_CELL_M, TERRAIN_SAMPLES, WORLD_SIZE_M, World,
                       nav_truth_from_geometry)

log = logging.getLogger(__name__)

# extrusion of walls from a floor mask
WALL_SLOPE = 2.5  # wall height gained per metre away from the floor, m/m
WALL_HEIGHT_M = 12.0  # wall height far from any floor, m
WALL_NOISE_M = 2.0  # amplitude of smooth height noise on walls, m
WALL_NOISE_CELLS = 24  # coarse noise grid side (smaller = broader bumps), cells
WALL_NOISE_RAMP_M = 2.0  # distance from floor over which noise fades in, m
SAND_EDGE_M = 0.6  # sand weight ramps from full to WALL_SAND across this band of floor next to the wall, m
WALL_SAND = 0.05  # sand weight deep on a wall (rock texture dominates), 0..1

# canyon generator
CANYON_MARGIN_M = 18.0  # canyons stay this far inside the world edge, m
CANYON_STEP_M = 1.0  # random-walk step, m
TRUNK_STEPS = (160, 240)  # main canyon length range, steps
BRANCH_COUNT = (5, 8)  # number of side branches
BRANCH_STEPS = (35, 90)  # branch length range, steps
HALF_WIDTH_M = (2.2, 5.0)  # canyon half-width range, m
TURN_SIGMA_DEG = 9.0  # heading random change per step, degrees (1 sigma)
CLEARING_COUNT = 3  # wide round clearings on the trunk
CLEARING_RADIUS_M = (7.0, 10.0)  # clearing radius range, m
START_CLEARING_RADIUS_M = 6.0  # clear floor around the start, m
ROCK_COUNT = (3, 6)  # obstacle rocks on the floor
ROCK_RADIUS_M = (0.6, 1.3)  # obstacle rock radius range, m
ROCK_HEIGHT_M = (0.6, 1.6)  # obstacle rock height range, m
ROCK_CLEARANCE_M = 2.5  # free floor kept all around an obstacle rock, m
ROCK_START_EXCLUSION_M = 8.0  # no rocks this close to the start, m
SAMPLE_COUNT = 30  # sample spots to place
SAMPLE_WALL_DIST_M = (0.7, 3.0)  # sample distance from the nearest wall, m
SAMPLE_MIN_SEPARATION_M = 5.0  # minimum distance between sample spots, m
SAMPLE_START_EXCLUSION_M = 4.0  # no samples this close to the start, m

# map-PNG worlds
MAP_NAV_THRESHOLD = 127  # grey level above which a map pixel is navigable
MAP_SAMPLE_SEED = 0  # seed for sample spots on a map world (deterministic per map)


# ---------------------------------------------------------------------- extrusion
def _vertex_xy():
    coords = np.arange(TERRAIN_SAMPLES, dtype=np.float64) * TERRAIN_CELL_M
    return np.meshgrid(coords, coords)  # xs, ys with [row=y, col=x]


def _smooth_noise(rng: np.random.Generator, shape, cells: int) -> np.ndarray:
    import cv2

    coarse = rng.uniform(-1.0, 1.0, size=(cells, cells)).astype(np.float32)
    return cv2.resize(coarse, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)


def extrude_floor(floor_vertices: np.ndarray, rng: np.random.Generator):
    """Heights and sand weight from a bool (513, 513) vertex floor mask."""
    import cv2

    not_floor = (~floor_vertices).astype(np.uint8)
    dist_m = cv2.distanceTransform(not_floor, cv2.DIST_L2, 5).astype(np.float64) * TERRAIN_CELL_M
    height = np.minimum(dist_m * WALL_SLOPE, WALL_HEIGHT_M)
    ramp = np.clip(dist_m / WALL_NOISE_RAMP_M, 0.0, 1.0)
    height += WALL_NOISE_M * ramp * _smooth_noise(rng, height.shape, WALL_NOISE_CELLS)
    base = np.minimum(dist_m * WALL_SLOPE, WALL_HEIGHT_M)
    height = np.where(floor_vertices, 0.0, np.maximum(height, 0.5 * base))  # noise never sinks a wall
    # sand texels: weight from the signed distance of the texel centre to the floor edge.
    # Texels are 0.39 m and walls rise 2.5 m per metre, so sand must be gone by the edge:
    # any sand on the wall foot is seen below the horizon and projects onto the wall as floor.
    inside_m = cv2.distanceTransform(floor_vertices.astype(np.uint8), cv2.DIST_L2, 5).astype(np.float64)
    signed_m = dist_m - inside_m * TERRAIN_CELL_M  # > 0 on walls, < 0 inside the floor
    centres = (np.arange(SAND_TEXELS) + 0.5) * SAND_CELL_M / TERRAIN_CELL_M
    cc, rr = np.meshgrid(centres, centres)
    d_tex = cv2.remap(signed_m.astype(np.float32), cc.astype(np.float32), rr.astype(np.float32),
                      cv2.INTER_LINEAR)
    sand = WALL_SAND + (1.0 - WALL_SAND) * np.clip(-d_tex / SAND_EDGE_M, 0.0, 1.0)
    return height.astype(np.float32), sand.astype(np.float32)


def _empty_rocks():
    return (np.zeros((ROCK_SAMPLES, ROCK_SAMPLES), np.float32),
            np.zeros((ROCK_SAMPLES, ROCK_SAMPLES), np.float32))


def _stamp_rock(rock_top, rock_bottom, x, y, radius, height, rng):
    """Add a lumpy dome rock standing on the floor (bottom slab at floor level)."""
    n = int(math.ceil((radius + 0.3) / ROCK_CELL_M))
    c0, r0 = int(round(x / ROCK_CELL_M)), int(round(y / ROCK_CELL_M))
    rows = np.arange(max(r0 - n, 0), min(r0 + n + 1, ROCK_SAMPLES))
    cols = np.arange(max(c0 - n, 0), min(c0 + n + 1, ROCK_SAMPLES))
    cc, rr = np.meshgrid(cols, rows)
    dx, dy = cc * ROCK_CELL_M - x, rr * ROCK_CELL_M - y
    ang = np.arctan2(dy, dx)
    k = rng.integers(3, 6)
    wobble = 1.0 + 0.18 * np.sin(k * ang + rng.uniform(0, 2 * np.pi))
    q = np.hypot(dx, dy) / (radius * wobble)
    inside = q < 1.0
    top = height * np.sqrt(np.clip(1.0 - q ** 2, 0.0, 1.0))
    top = np.maximum(top, 0.05)
    sub_t = rock_top[rr, cc]
    sub_t[inside] = np.maximum(sub_t[inside], top[inside])
    rock_top[rr, cc] = sub_t
    sub_b = rock_bottom[rr, cc]
    sub_b[inside] = 0.0  # rock sits on the floor (height 0)
    rock_bottom[rr, cc] = sub_b


def _pick_spots(rng, candidates_xy, count, min_sep, avoid_xy, avoid_r):
    """Greedy random picks with a minimum separation."""
    order = rng.permutation(len(candidates_xy))
    chosen = []
    for i in order:
        p = candidates_xy[i]
        if math.hypot(p[0] - avoid_xy[0], p[1] - avoid_xy[1]) < avoid_r:
            continue
        if all(math.hypot(p[0] - q[0], p[1] - q[1]) >= min_sep for q in chosen):
            chosen.append(p)
            if len(chosen) >= count:
                break
    return np.array(chosen, dtype=np.float64).reshape(-1, 2)


def _floor_wall_distance(nav_truth: np.ndarray) -> np.ndarray:
    """Distance (m) from each 1 m floor cell centre to the nearest non-floor cell."""
    import cv2

    return cv2.distanceTransform((nav_truth > 0).astype(np.uint8), cv2.DIST_L2, 5).astype(np.float64)


def _sample_spots(rng, nav_truth, start_xy, height_at, count=SAMPLE_COUNT):
    """Spots on the floor near walls (where the simulator's samples tend to lie)."""
    dist = _floor_wall_distance(nav_truth)
    lo, hi = SAMPLE_WALL_DIST_M
    rows, cols = np.nonzero((dist >= lo) & (dist <= hi))
    if rows.size == 0:
        rows, cols = np.nonzero(nav_truth > 0)
    cand = np.stack([cols + 0.5, rows + 0.5], axis=1)
    cand += rng.uniform(-0.3, 0.3, size=cand.shape)
    cand = cand[np.asarray(height_at(cand[:, 0], cand[:, 1])) <= FLOOR_TOLERANCE_M]
    return _pick_spots(rng, cand, count, SAMPLE_MIN_SEPARATION_M, start_xy, SAMPLE_START_EXCLUSION_M)


# ---------------------------------------------------------------------- canyon
def _random_walk(rng, x, y, heading, steps, width0):
    """Centre line of one canyon: (x, y, half_width) points, turning away from the edge."""
    pts = []
    lo, hi = CANYON_MARGIN_M, WORLD_SIZE_M - CANYON_MARGIN_M
    width = width0
    turn = 0.0
    for _ in range(steps):
        turn = 0.7 * turn + rng.normal(0.0, math.radians(TURN_SIGMA_DEG))
        heading += turn
        nx, ny = x + CANYON_STEP_M * math.cos(heading), y + CANYON_STEP_M * math.sin(heading)
        if not (lo <= nx <= hi and lo <= ny <= hi):
            to_centre = math.atan2(WORLD_SIZE_M / 2 - y, WORLD_SIZE_M / 2 - x)
            heading = to_centre + rng.normal(0.0, 0.5)
            turn = 0.0
            nx, ny = x + CANYON_STEP_M * math.cos(heading), y + CANYON_STEP_M * math.sin(heading)
        x, y = nx, ny
        width = float(np.clip(width + rng.normal(0.0, 0.15), *HALF_WIDTH_M))
        pts.append((x, y, width))
    return pts, heading


def _carve(points, shape):
    """Rasterise discs (x, y, r in metres) onto the vertex grid as a bool floor mask."""
    import cv2

    mask = np.zeros(shape, np.uint8)
    shift = 4  # sub-pixel bits for cv2.circle
    scale = (1 << shift) / TERRAIN_CELL_M
    for x, y, r in points:
        cv2.circle(mask, (int(round(x * scale)), int(round(y * scale))), int(round(r * scale)),
                   1, thickness=-1, lineType=cv2.LINE_8, shift=shift)
    return mask.astype(bool)


def canyon_world(seed: int = 0) -> World:
    """A seeded winding canyon with branches: floor 0 m, walls, a few rocks, ~30 sample spots."""
    rng = np.random.default_rng(int(seed))
    start = np.array([WORLD_SIZE_M / 2, WORLD_SIZE_M / 2]) + rng.uniform(-10, 10, size=2)
    heading = rng.uniform(0, 2 * np.pi)
    trunk_a, _ = _random_walk(rng, *start, heading, int(rng.integers(*TRUNK_STEPS)) // 2,
                              rng.uniform(*HALF_WIDTH_M))
    trunk_b, _ = _random_walk(rng, *start, heading + np.pi, int(rng.integers(*TRUNK_STEPS)) // 2,
                              rng.uniform(*HALF_WIDTH_M))
    trunk = trunk_a[::-1] + [(start[0], start[1], START_CLEARING_RADIUS_M)] + trunk_b
    points = list(trunk)
    for _ in range(int(rng.integers(*BRANCH_COUNT))):
        src = points[int(rng.integers(len(points)))]
        branch, _ = _random_walk(rng, src[0], src[1], rng.uniform(0, 2 * np.pi),
                                 int(rng.integers(*BRANCH_STEPS)), rng.uniform(*HALF_WIDTH_M))
        points += branch
    for _ in range(CLEARING_COUNT):
        p = trunk[int(rng.integers(len(trunk)))]
        points.append((p[0], p[1], rng.uniform(*CLEARING_RADIUS_M)))
    floor = _carve(points, (TERRAIN_SAMPLES, TERRAIN_SAMPLES))
    height, sand = extrude_floor(floor, rng)
    rock_top, rock_bottom = _empty_rocks()
    world = World(terrain_height=height, sand_weight=sand, rock_top=rock_top,
                  rock_bottom=rock_bottom, nav_truth=np.zeros((MAP_CELLS, MAP_CELLS), np.uint8),
                  sample_spots=np.zeros((0, 2)), start_xy=(float(start[0]), float(start[1])),
                  start_yaw_training=float(rng.uniform(0, 360)), name=f"procedural:{seed}")
    floor_nav = nav_truth_from_geometry(world.height_at, rock_top)
    _place_rocks(rng, world, floor_nav)
    world.nav_truth = _largest_component(nav_truth_from_geometry(world.height_at, world.rock_top),
                                         world.start_xy)
    world.sample_spots = _sample_spots(rng, world.nav_truth, world.start_xy, world.height_at)
    return world


def _place_rocks(rng, world: World, floor_nav: np.ndarray):
    dist = _floor_wall_distance(floor_nav)
    placed = []
    want = int(rng.integers(*ROCK_COUNT))
    for _ in range(200):
        if len(placed) >= want:
            break
        radius = rng.uniform(*ROCK_RADIUS_M)
        rows, cols = np.nonzero(dist >= radius + ROCK_CLEARANCE_M + 1.0)
        if rows.size == 0:
            break
        i = int(rng.integers(rows.size))
        x, y = cols[i] + rng.uniform(0.2, 0.8), rows[i] + rng.uniform(0.2, 0.8)
        if math.hypot(x - world.start_xy[0], y - world.start_xy[1]) < ROCK_START_EXCLUSION_M:
            continue
        if any(math.hypot(x - px, y - py) < radius + pr + 2 * ROCK_CLEARANCE_M for px, py, pr in placed):
            continue
        _stamp_rock(world.rock_top, world.rock_bottom, x, y, radius, rng.uniform(*ROCK_HEIGHT_M), rng)
        placed.append((x, y, radius))
        world.obstacles.append({"name": f"rock {len(placed)}", "x": x, "y": y, "radius_m": radius,
                                "height_above_ground_m": float(world.rock_top[
                                    int(round(y / ROCK_CELL_M)), int(round(x / ROCK_CELL_M))]),
                                "touches_floor": True})


def _largest_component(nav: np.ndarray, prefer_xy) -> np.ndarray:
    """Keep the 4-connected floor component holding the start (or the largest one)."""
    import cv2

    n, labels = cv2.connectedComponents((nav > 0).astype(np.uint8), connectivity=4)
    if n <= 2:
        return nav
    r, c = int(prefer_xy[1]), int(prefer_xy[0])
    keep = labels[r, c] if 0 <= r < nav.shape[0] and 0 <= c < nav.shape[1] else 0
    if keep == 0:
        keep = 1 + int(np.argmax(np.bincount(labels.ravel())[1:]))
    return np.where(labels == keep, 255, 0).astype(np.uint8)


# ---------------------------------------------------------------------- map PNG
def world_from_map_png(path) -> World:
    """Extrude a 2-D navigable map (white = floor) into a world; the map is the ground truth.

    The image is read as `[row = y, col = x]` (row 0 = y 0, like map_bw.png) and resized
    to 200 x 200 cells of 1 m if it has another size.
    """
    import cv2

    path = Path(path)
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ValueError(f"cannot read navigable map {path}")
    if img.shape != (MAP_CELLS, MAP_CELLS):
        img = cv2.resize(img, (MAP_CELLS, MAP_CELLS), interpolation=cv2.INTER_NEAREST)
    nav = img > MAP_NAV_THRESHOLD
    if not nav.any():
        raise ValueError(f"navigable map {path} has no navigable pixel (> {MAP_NAV_THRESHOLD})")
    xs, ys = _vertex_xy()
    # a vertex is floor when every map cell touching it is navigable (walls stay off the floor)
    floor = np.ones(xs.shape, bool)
    for ox in (-0.01, 0.01):
        for oy in (-0.01, 0.01):
            c = np.clip(np.floor(xs + ox).astype(int), 0, MAP_CELLS - 1)
            r = np.clip(np.floor(ys + oy).astype(int), 0, MAP_CELLS - 1)
            floor &= nav[r, c]
    rng = np.random.default_rng(MAP_SAMPLE_SEED)
    height, sand = extrude_floor(floor, rng)
    rock_top, rock_bottom = _empty_rocks()
    nav_truth = np.where(nav, 255, 0).astype(np.uint8)
    start_xy = _interior_point(nav_truth)
    world = World(terrain_height=height, sand_weight=sand, rock_top=rock_top,
                  rock_bottom=rock_bottom, nav_truth=nav_truth, sample_spots=np.zeros((0, 2)),
                  start_xy=start_xy, start_yaw_training=0.0, name=f"map:{path.name}")
    world.sample_spots = _sample_spots(rng, nav_truth, start_xy, world.height_at)
    return world


def _interior_point(nav_truth: np.ndarray):
    """Centre of the cell deepest inside the largest floor component (a safe start)."""
    comp = _largest_component(nav_truth, (-1, -1))
    dist = _floor_wall_distance(comp)
    r, c = np.unravel_index(int(np.argmax(dist)), dist.shape)
    return (float(c) + 0.5, float(r) + 0.5)


__all__ = ["canyon_world", "world_from_map_png", "extrude_floor", "FLOOR_TOLERANCE_M"]
