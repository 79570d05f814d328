"""The canyon's sample spots: the only places the real simulator ever puts a sample, checked first by the search.

Why: the simulator spawns its six samples at 6 of 33 fixed points (its `ObjectiveSpawner`, children of the
scene's `Objectives`; ../shared/docs/simulator-facts.md section 3). Without them the sample search had to look
at every wall foot the camera had not seen from close, and a mission that saw five samples while exploring
spent up to four minutes of search on the sixth (seed 17, shadows on: 245 s, then home without it). With
them, the search drives only to the spots the camera has not yet faced from close, nearest first. A spot counts
as seen only from where the camera really shows it: a rock smaller than a map cell, or a slot's wall, hides some
spots from all but a few bearings (the east nook shows well only from 120-150 deg, up to 3.5 m), so the client ships a table of the
places each spot shows from (spot_views.json, rendered by ``python -m sim.spot_views``) and the search's stand for
a spot is one of them.

The spots belong to the real canyon. They are used only when the mission starts where the real simulator
starts every rover (`CANYON_START_XY`); anywhere else (the twin's procedural worlds, a changed scene) the
search works as before, from the map alone. When every spot is checked and samples are still missing (a
sample the camera missed, a scene that moved them), the map-only search takes over.
"""
import json
import logging
import math
from pathlib import Path

import numpy as np

import perception
from navigation import grid
from navigation.predict import wrap_deg

log = logging.getLogger(__name__)

USE_CANYON_SPOTS = True  # check the canyon's sample spots first when the mission starts at the canyon's start (False: map-only search)
CANYON_START_XY = (99.67, 85.589)  # where the real simulator starts the rover, world (x, y) m (simulator facts, section 4)
CANYON_START_MATCH_M = 1.0  # a mission whose first pose lies this close to it is on the real canyon, m
SPOT_CHECK_M = 4.5  # without a view table: a spot counts as seen once the camera faced it from this close (a scale-0.43 sample shows ~6 px at 4-5 m, 1 px at 5-6 m: docs/twin-realism.md round 9), m
SPOT_CHECK_HALF_DEG = 30.0  # ...within this angle of the heading (the camera's half-width is ~54 deg; a blob at the edge is cut off), deg
SPOT_SEEN_MIN_PX = 12  # with the table: a spot counts as seen from a place where the table shows it this many gold px (three times the client's floor: samples' size and yaw vary; the east nook at 9 px from 170 deg went unseen, seed 15)
SPOT_GLIMPSE_M = 5.5  # an open spot in the look cone this close along a clear line of sight on the map, from a bearing the table shows it well from, counts as seen too (the rover drives on; the table alone would leave half the canyon's spots to visit), m
SPOT_OPEN_MIN_BEARINGS = 12  # ...open: shown well (SPOT_SEEN_MIN_PX) from at least this many of the table's 36 bearings; the hidden ones (the east nook, the south arm's slot) count as seen only where they show well
SPOT_TAKEN_M = 2.0  # a spot this close to a collected sample held that sample, m
SPOT_STAND_MIN_PX = 15  # the search's stand for a spot is a place the table shows it this many px from, where one is reachable
SPOT_STAND_MIN_M = 2.5  # ...and at least this far from it where such a place allows (nearer, the rover noses into the wall foot), m
SPOT_STAND_REACH_M = 8.0  # without a view table, or when no place it shows well from is reachable on the map: the reachable floor cell nearest the spot, if this close to it, m
SPOT_STAND_REACHED_M = 1.0  # a stand counts as reached this close (a view a few metres off a bearing window may hide the sample), m
SPOT_FACE_TOLERANCE_DEG = 15.0  # at the stand, the rover turns to face the spot unless it already points within this, deg
SPOT_HOLD_S = 0.6  # ...then holds still this long so the camera's frames show it before the spot counts as checked, s
SPOT_NEAR_M = 7.5  # farther than this no look (the table's last range, 7 m) or glimpse (SPOT_GLIMPSE_M plus a cell) rules a spot out, so frames skip the checks, m
VIEWS_PATH = Path(__file__).resolve().parent / "spot_views.json"  # from where the twin's camera shows each spot (python -m sim.spot_views)

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


class SpotViews:
    """From where the camera shows each spot: per spot, bearing (from the spot to the camera, every ``step_deg``)
    and range, the gold pixels the twin's JPEG shows of a sample there (-1: no floor to stand on)."""

    def __init__(self, step_deg: float, ranges_m, px: np.ndarray):
        self.step_deg = float(step_deg)
        self.ranges_m = np.asarray(ranges_m, float)
        self.px = np.asarray(px, np.int16)  # (n spots, n bearings, n ranges)

    def bearing_bin(self, bearing_deg) -> np.ndarray:
        """Index of the tabled bearing nearest ``bearing_deg``."""
        return np.round(np.asarray(bearing_deg) / self.step_deg).astype(int) % self.px.shape[1]

    def px_at(self, rows, bearing_deg, range_m) -> np.ndarray:
        """Pixels shown of spots ``rows`` from the nearest tabled place (0 beyond the last range)."""
        b = self.bearing_bin(bearing_deg)
        r = np.asarray(range_m, float)
        j = np.clip(np.round((r - self.ranges_m[0]) / (self.ranges_m[1] - self.ranges_m[0])).astype(int), 0,
                    len(self.ranges_m) - 1)
        px = self.px[rows, b, j].astype(int)
        return np.where(r <= self.ranges_m[-1] + 0.5 * (self.ranges_m[1] - self.ranges_m[0]), px, 0)

    def _well(self):
        """(bool (n, bearings) shown well from the bearing, bool (n,) open), kept while the pixel lines stay."""
        key = (SPOT_SEEN_MIN_PX, SPOT_OPEN_MIN_BEARINGS)  # module constants a sweep may change between missions
        if getattr(self, "_well_key", None) != key:
            well = (self.px >= SPOT_SEEN_MIN_PX).any(axis=2)
            self._well_cache, self._well_key = (well, well.sum(axis=1) >= SPOT_OPEN_MIN_BEARINGS), key
        return self._well_cache

    def shows_from_bearing(self, rows, bearing_deg) -> np.ndarray:
        """Whether the spots ``rows`` show well (SPOT_SEEN_MIN_PX, any range) from that bearing: no rock or wall
        hides them there."""
        return self._well()[0][rows, self.bearing_bin(bearing_deg)]

    def open_spots(self) -> np.ndarray:
        """bool (n,): spots shown well from at least SPOT_OPEN_MIN_BEARINGS bearings (a glimpse may count for them)."""
        return self._well()[1]


def load_views(path=None, spots=None):
    """The SpotViews of ``path`` (spot_views.json) for ``spots`` (the canyon's), or None, logged, when the file is
    missing, unreadable or written for other spots: the search then checks spots by range and heading alone."""
    path = VIEWS_PATH if path is None else Path(path)
    spots = CANYON_SPOTS if spots is None else np.asarray(spots, float)
    try:
        data = json.loads(Path(path).read_text())
        xy = np.array([(e["x"], e["y"]) for e in data["spots"]], float)
        px = np.array([[[int(v) for v in row.split()] for row in e["px"]] for e in data["spots"]], np.int16)
        if xy.shape != spots.shape or np.abs(xy - spots).max() > 0.05 or px.ndim != 3:
            raise ValueError("written for other spots")
        if px.shape[1] * float(data["bearing_step_deg"]) != 360.0 or px.shape[2] != len(data["ranges_m"]):
            raise ValueError("bearings or ranges do not match the table")
        return SpotViews(data["bearing_step_deg"], data["ranges_m"], px)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        log.warning("no spot views from %s (%s): spots count as checked by range and heading alone", path, exc)
        return None


def _bearings(spots, pos, yaw_deg):
    """(distance m, bearing from the spot to the rover deg, angle of the spot off the heading deg) per spot."""
    dx, dy = pos[0] - spots[:, 0], pos[1] - spots[:, 1]
    bearing = np.degrees(np.arctan2(dy, dx)) % 360.0
    off = np.abs(((bearing + 180.0) - yaw_deg + 180.0) % 360.0 - 180.0)
    return np.hypot(dx, dy), bearing, off


def _pose_ok(spots, pos, yaw_deg):
    return len(spots) > 0 and pos is not None and all(np.isfinite(v) for v in (pos[0], pos[1], yaw_deg))


def in_view(spots, pos, yaw_deg, views=None) -> np.ndarray:
    """bool (n,): spots the camera shows well from ``pos`` facing ``yaw_deg``: within SPOT_CHECK_HALF_DEG of the
    heading and, with ``views``, from a place the table shows them SPOT_SEEN_MIN_PX from (never where a rock or
    wall hides them); without, no farther than SPOT_CHECK_M."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    if not _pose_ok(spots, pos, yaw_deg):
        return np.zeros(len(spots), bool)
    dist, bearing, off = _bearings(spots, pos, yaw_deg)
    ok = off <= SPOT_CHECK_HALF_DEG
    if views is not None and views.px.shape[0] == len(spots):
        return ok & (views.px_at(np.arange(len(spots)), bearing, dist) >= SPOT_SEEN_MIN_PX)
    return ok & (dist <= SPOT_CHECK_M)


def glimpse_candidates(spots, pos, views=None) -> np.ndarray:
    """bool (n,): open spots (SpotViews.open_spots) near enough (SPOT_GLIMPSE_M plus a cell) to be glimpsed, from a
    bearing the table shows them well from (no rock or wall hides them there); the caller's line of sight on the
    map, which reaches SPOT_GLIMPSE_M in the look cone, makes the ones whose cell it reaches seen."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    if not _pose_ok(spots, pos, 0.0):
        return np.zeros(len(spots), bool)
    dist, bearing, _off = _bearings(spots, pos, 0.0)
    ok = dist <= SPOT_GLIMPSE_M + 1.0
    if views is not None and views.px.shape[0] == len(spots):
        ok &= views.shows_from_bearing(np.arange(len(spots)), bearing) & views.open_spots()
    return ok


def open_spots_near(spots, done, pos) -> bool:
    """Whether a spot not yet seen lies within SPOT_NEAR_M: only then can a frame's look or glimpse rule one out."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    d2 = (spots[:, 0] - pos[0]) ** 2 + (spots[:, 1] - pos[1]) ** 2
    return bool(np.any(~np.asarray(done, bool) & (d2 <= SPOT_NEAR_M ** 2)))


def taken_spots(spots, collected=()) -> np.ndarray:
    """bool (n,): spots within SPOT_TAKEN_M of a collected sample (a spot holds one sample at most)."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    done = np.zeros(len(spots), bool)
    for cx, cy in collected:
        done |= np.hypot(spots[:, 0] - cx, spots[:, 1] - cy) <= SPOT_TAKEN_M
    return done


def spot_stands(spots, free, dist, views=None, only=None) -> np.ndarray:
    """(n, 3) int rows (row, col, ok) per spot: the search's stand, ok = 0 where it has none (and for spots
    ``only``, a bool mask, leaves out: the search asks for the open ones).

    With ``views``: the reachable (finite ``dist``) floor cell, by path the nearest, among the places the table
    shows the spot well from (_view_cells: where it shows best, not nosing into it, where such a place is
    reachable). Without, or when none of those is reachable on the map (a pocket's floor in deep shadow is voted
    wall: seed 17), the reachable floor cell nearest the spot, within SPOT_STAND_REACH_M."""
    spots = np.asarray(spots, float).reshape(-1, 2)
    out = np.zeros((len(spots), 3), int)
    size = free.shape[0]
    reachable = free & np.isfinite(dist)
    with_views = views is not None and views.px.shape[0] == len(spots)
    wanted = np.ones(len(spots), bool) if only is None else np.asarray(only, bool)
    for k in np.nonzero(wanted)[0]:  # up to 33 spots, a few hundred candidate places each
        stand = _best_reachable(_view_cells(views, k, spots[k]) if with_views else None, reachable, dist)
        if stand is None:  # no place it shows well from is reachable (floor in deep shadow is voted wall): the nearest floor
            stand = _best_reachable(_near_cells(spots[k], size), reachable, dist)
        if stand is not None:
            out[k] = (*stand, 1)
    return out


def _best_reachable(cells, reachable, dist):
    """(row, col) of the reachable one of ``cells`` (rows, cols, preference): preferred first, then the cheapest
    to reach; None when none is reachable."""
    if cells is None:
        return None
    rows, cols, pref = cells
    ok = reachable[rows, cols]
    if not ok.any():
        return None
    rows, cols, pref = rows[ok], cols[ok], pref[ok]
    j = int(np.lexsort((dist[rows, cols], -pref))[0])
    return int(rows[j]), int(cols[j])


def _view_cells(views, k, spot):
    """(rows, cols, preference) of the cells the table shows spot k from with SPOT_SEEN_MIN_PX or more (preferred:
    SPOT_STAND_MIN_PX or more, then SPOT_STAND_MIN_M or farther)."""
    px = views.px[k]
    b_idx, r_idx = np.nonzero(px >= SPOT_SEEN_MIN_PX)
    if len(b_idx) == 0:
        return None
    b = np.radians(b_idx * views.step_deg)
    r = views.ranges_m[r_idx]
    x, y = spot[0] + r * np.cos(b), spot[1] + r * np.sin(b)
    rows = np.clip(np.floor(y), 0, grid.GRID_SIZE - 1).astype(int)
    cols = np.clip(np.floor(x), 0, grid.GRID_SIZE - 1).astype(int)
    return rows, cols, 2 * (px[b_idx, r_idx] >= SPOT_STAND_MIN_PX) + (r >= SPOT_STAND_MIN_M)


def _near_cells(spot, size):
    """(rows, cols, preferred) of the cells within SPOT_STAND_REACH_M of the spot, the nearest preferred."""
    reach = int(math.ceil(SPOT_STAND_REACH_M))
    row, col = int(math.floor(spot[1])), int(math.floor(spot[0]))
    rr, cc = np.mgrid[max(row - reach, 0):min(row + reach + 1, size), max(col - reach, 0):min(col + reach + 1, size)]
    rr, cc = rr.ravel(), cc.ravel()
    d = np.hypot(cc + 0.5 - spot[0], rr + 0.5 - spot[1])
    keep = d <= SPOT_STAND_REACH_M
    rr, cc, d = rr[keep], cc[keep], d[keep]
    return rr, cc, -np.round(d * 100).astype(int)  # nearer is preferred over cheaper to reach


VIEWS = load_views()  # the table the client ships (None: range and heading alone)


def face_heading(spot_xy, pos, yaw_deg):
    """World heading (deg) from ``pos`` to the spot when the rover points more than SPOT_FACE_TOLERANCE_DEG
    away from it, else None (already facing it, or standing on it)."""
    dx, dy = spot_xy[0] - pos[0], spot_xy[1] - pos[1]
    if math.hypot(dx, dy) < 0.5:
        return None
    heading = math.degrees(math.atan2(dy, dx)) % 360.0
    return heading if abs(wrap_deg(heading - yaw_deg)) > SPOT_FACE_TOLERANCE_DEG else None
