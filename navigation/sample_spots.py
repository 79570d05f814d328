"""The canyon's sample spots: the only places the real simulator ever puts a sample, checked first by the search.

Why: the simulator spawns its six samples at 6 of 33 fixed points (its `ObjectiveSpawner`, children of the
scene's `Objectives`; ../shared/docs/simulator-facts.md section 3). Without them the sample search had to look
at every wall foot the camera had not seen from close, and a mission that saw five samples while exploring
spent up to four minutes of search on the sixth (seed 17, shadows on: 245 s, then home without it). With
them, the search drives only to the spots the camera has not yet seen from close, nearest first.

The spots belong to the real canyon. They are used only when the mission starts where the real simulator
starts every rover (`CANYON_START_XY`); anywhere else (the twin's procedural worlds, a changed scene) the
search works as before, from the map alone. When every spot is checked and samples are still missing (a
sample the camera missed, a scene that moved them), the map-only search takes over.
"""
import math

import numpy as np

from navigation import grid

USE_CANYON_SPOTS = True  # check the canyon's sample spots first when the mission starts at the canyon's start (False: map-only search)
CANYON_START_XY = (99.67, 85.589)  # where the real simulator starts the rover, world (x, y) m (simulator facts, section 4)
CANYON_START_MATCH_M = 1.0  # a mission whose first pose lies this close to it is on the real canyon, m
SPOT_CHECK_M = 5.5  # a spot is checked once its cell was in the camera's look cone this close, along a clear line of sight (explore.mark_in_sight; a 0.15 m sample spans ~3 px there), m
SPOT_TAKEN_M = 2.0  # a spot this close to a collected sample held that sample, m
SPOT_STAND_REACH_M = 8.0  # the search drives to the reachable floor cell nearest a spot, if one lies this close to it (a shadowed pocket voted wall runs ~7 m past its mouth: seed 17), m
SPOT_FACE_TOLERANCE_DEG = 15.0  # at the stand, the rover turns to face the spot unless it already points within this, deg
SPOT_HOLD_S = 0.6  # ...then holds still this long so the camera's frames show it before the spot counts as checked, s

CANYON_SPOTS = np.array([
    (97.44, 74.65), (104.56, 80.78), (109.78, 89.84), (113.27, 12.97), (122.28, 51.66), (109.00, 101.96),
    (144.63, 94.53), (148.78, 109.56), (110.70, 165.01), (103.77, 192.69), (76.22, 71.36), (61.86, 105.15),
    (39.67, 94.30), (21.72, 102.18), (12.10, 101.04), (21.69, 94.14), (32.63, 99.64), (62.63, 96.25),
    (62.71, 88.00), (70.31, 87.77), (76.47, 78.36), (82.80, 75.00), (86.03, 83.67), (102.95, 96.36),
    (106.96, 66.13), (106.12, 53.51), (110.14, 36.94), (117.49, 20.45), (125.22, 99.41), (127.46, 121.26),
    (116.03, 131.28), (115.73, 151.23), (102.46, 170.09)])  # the 33 candidate points, world (x, y) m (simulator facts, section 3)


def spots_for_start(start_xy, enabled=None) -> np.ndarray:
    """(n, 2) world (x, y) of the sample spots a mission starting at ``start_xy`` can hold: the canyon's when
    it starts at the canyon's start, else none (n = 0)."""
    enabled = USE_CANYON_SPOTS if enabled is None else enabled
    none = np.zeros((0, 2))
    if not enabled or start_xy is None:
        return none
    try:
        x, y = float(start_xy[0]), float(start_xy[1])
    except (TypeError, ValueError, IndexError):
        return none
    if not (math.isfinite(x) and math.isfinite(y)):
        return none
    near = math.hypot(x - CANYON_START_XY[0], y - CANYON_START_XY[1]) <= CANYON_START_MATCH_M
    return CANYON_SPOTS.copy() if near else none


def spot_cells(spots) -> np.ndarray:
    """(n, 2) int (row, col) of each spot's map cell (1 cell = 1 m)."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    rows = np.clip(np.floor(spots[:, 1]), 0, grid.GRID_SIZE - 1).astype(int)
    cols = np.clip(np.floor(spots[:, 0]), 0, grid.GRID_SIZE - 1).astype(int)
    return np.stack([rows, cols], 1)


def checked_spots(spots, seen_close, collected=()) -> np.ndarray:
    """bool (n,): spots ruled out by the map alone: the camera saw the spot's cell from close (``seen_close``,
    a bool map of cells in view within SPOT_CHECK_M along a clear line of sight), or a collected sample
    lay within SPOT_TAKEN_M of it."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    if len(spots) == 0:
        return np.zeros(0, bool)
    cells = spot_cells(spots)
    done = np.asarray(seen_close, bool)[cells[:, 0], cells[:, 1]].copy()
    for cx, cy in collected:
        done |= np.hypot(spots[:, 0] - cx, spots[:, 1] - cy) <= SPOT_TAKEN_M
    return done


def spot_stands(spots, free, dist) -> np.ndarray:
    """(n, 3) int rows (row, col, ok) per spot: the reachable (finite ``dist``) floor cell nearest it, within
    SPOT_STAND_REACH_M; ok = 0 when there is none."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    out = np.zeros((len(spots), 3), int)
    reach = int(math.ceil(SPOT_STAND_REACH_M))
    size = free.shape[0]
    for k, (row, col) in enumerate(spot_cells(spots)):  # 33 spots, a 13 x 13 window each
        r0, r1, c0, c1 = max(row - reach, 0), min(row + reach + 1, size), max(col - reach, 0), min(col + reach + 1, size)
        ok = free[r0:r1, c0:c1] & np.isfinite(dist[r0:r1, c0:c1])
        if not ok.any():
            continue
        rr, cc = np.nonzero(ok)
        d = np.hypot(cc + c0 + 0.5 - spots[k, 0], rr + r0 + 0.5 - spots[k, 1])
        j = int(np.argmin(d + 1e-3 * dist[rr + r0, cc + c0]))  # ties go to the cheaper cell to reach
        if d[j] <= SPOT_STAND_REACH_M:
            out[k] = (rr[j] + r0, cc[j] + c0, 1)
    return out


def face_heading(spot_xy, pos, yaw_deg):
    """World heading (deg) from ``pos`` to the spot when the rover points more than SPOT_FACE_TOLERANCE_DEG
    away from it, else None (already facing it, or standing on it)."""
    dx, dy = spot_xy[0] - pos[0], spot_xy[1] - pos[1]
    if math.hypot(dx, dy) < 0.5:
        return None
    heading = math.degrees(math.atan2(dy, dx)) % 360.0
    off = abs((heading - yaw_deg + 180.0) % 360.0 - 180.0)
    return heading if off > SPOT_FACE_TOLERANCE_DEG else None
