"""Where to line up for a sample that sits in a nook, so the last metres are a straight, clear run.

A sample at a wall foot or between rocks (the east nook at (148.8, 109.6) is the
known case) can be entered from one side only.  A path to the sample's own cell
arrives at whatever angle the planner's corner-cutting gives, and the rover
wedges on the rock beside the opening.  Instead: when the straight final metres
from the rover to the sample are not all mapped floor, pick a staging point on
open floor from which the sample is a straight, clear run, drive there, turn to
face the sample, and creep in.  This works whatever heading the rover arrives
with.  Pure functions over the drive map's ``free`` grid ([row=y, col=x], 1 m cells).
"""
from __future__ import annotations

import math
from typing import Optional, Tuple

import cv2
import numpy as np

from navigation.predict import wrap_deg

STANDOFF_M = 2.5  # staging point this far from the sample, m
DIRECTIONS = 24  # candidate approach directions around the sample
FINAL_RUN_M = 3.0  # the straight run to the sample that must be clear for a direct approach, m
SAMPLE_CLEAR_M = 0.8  # the run is checked only from this far out (the sample's own cell may read as wall), m
CORRIDOR_HALF_M = 0.3  # half width of the swept corridor checked beside the run's centre line, m
RUN_CLEAR_SHARE = 0.6  # a straight run counts as clear when this share of its corridor points is mapped free (lower: wall-foot samples go straight in as before), 0..1
STAGE_MIN_SHARE = 0.6  # a staging direction needs at least this share free (a nook narrower than a 1 m cell), 0..1
SHARE_WEIGHT = 4.0  # score per unit of free share of the run in (ranks directions before the room behind), 1/share
LINE_STEP_M = 0.25  # spacing of the checked points along a run, m
SIDE_PREFERENCE = 0.5  # score bonus per unit cosine toward the rover's own side (fewer detours), 0..
WEDGED_NEAR_M = 4.0  # stuck cells this close to the sample mean the last approach wedged there, m
STAGE_WEDGED_DEG = 45.0  # no staging direction within this of one whose approach wedged is tried again for that sample (seen from the sample), degrees


def _free_at(free: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Mapped-free test for world points (outside the map is not free)."""
    cols = np.floor(xs).astype(np.int64)
    rows = np.floor(ys).astype(np.int64)
    inside = (rows >= 0) & (rows < free.shape[0]) & (cols >= 0) & (cols < free.shape[1])
    out = np.zeros(xs.shape, bool)
    out[inside] = free[rows[inside], cols[inside]]
    return out


def corridor_free(free: np.ndarray, a: Tuple[float, float], b: Tuple[float, float],
                  half_width_m: Optional[float] = None) -> bool:
    """True when the straight corridor from a to b (world m) is all mapped free."""
    return corridor_share(free, a, b, half_width_m) >= 1.0


def corridor_share(free: np.ndarray, a: Tuple[float, float], b: Tuple[float, float],
                   half_width_m: Optional[float] = None) -> float:
    """Share (0..1) of points on the straight corridor from a to b (world m), half_width_m
    (default CORRIDOR_HALF_M) to each side, that are mapped free.

    A share rather than all-or-nothing: the map's 1 m cells are coarser than a nook's opening.
    """
    half_width_m = CORRIDOR_HALF_M if half_width_m is None else half_width_m
    ax, ay = float(a[0]), float(a[1])
    bx, by = float(b[0]), float(b[1])
    length = math.hypot(bx - ax, by - ay)
    if not math.isfinite(length):
        return 0.0
    n = max(2, int(math.ceil(length / LINE_STEP_M)) + 1)
    t = np.linspace(0.0, 1.0, n)
    ux, uy = ((bx - ax) / length, (by - ay) / length) if length > 1e-9 else (1.0, 0.0)
    xs, ys = [], []
    for off in (-half_width_m, 0.0, half_width_m):
        xs.append(ax + t * (bx - ax) - uy * off)
        ys.append(ay + t * (by - ay) + ux * off)
    return float(_free_at(free, np.concatenate(xs), np.concatenate(ys)).mean())


def direct_run_clear(free: np.ndarray, rover_xy, sample_xy) -> bool:
    """Is the straight final run from the rover toward the sample (last FINAL_RUN_M) mapped free?"""
    sx, sy = float(sample_xy[0]), float(sample_xy[1])
    dx, dy = float(rover_xy[0]) - sx, float(rover_xy[1]) - sy
    d = math.hypot(dx, dy)
    if d <= SAMPLE_CLEAR_M:
        return True
    ux, uy = dx / d, dy / d
    far = min(d, FINAL_RUN_M)
    inner, outer = (sx + ux * SAMPLE_CLEAR_M, sy + uy * SAMPLE_CLEAR_M), (sx + ux * far, sy + uy * far)
    return corridor_share(free, inner, outer) >= RUN_CLEAR_SHARE


def staging_point(free: np.ndarray, sample_xy, rover_xy=None,
                  standoff_m: float = STANDOFF_M, wedged_stages=()) -> Optional[Tuple[float, float, float]]:
    """(x, y, heading_deg) to line up at: standoff_m from the sample, facing it, with a clear run in.

    Directions are ranked by the free share of their run in (from SAMPLE_CLEAR_M out to
    standoff_m + a margin; at least STAGE_MIN_SHARE, the staging cell itself free), then by
    the free room behind the staging point, nudged toward the rover's own side.  Directions within
    STAGE_WEDGED_DEG of a staging point in wedged_stages are skipped.  None when no direction qualifies.
    """
    sx, sy = float(sample_xy[0]), float(sample_xy[1])
    if not (math.isfinite(sx) and math.isfinite(sy)):
        return None
    side = None
    if rover_xy is not None:
        rx, ry = float(rover_xy[0]) - sx, float(rover_xy[1]) - sy
        if math.hypot(rx, ry) > 1e-6:
            side = math.atan2(ry, rx)
    wedged_bearings = [math.degrees(math.atan2(wy - sy, wx - sx)) for wx, wy in wedged_stages]  # from the sample
    best, best_score = None, -math.inf
    for k in range(DIRECTIONS):
        a = 2.0 * math.pi * k / DIRECTIONS
        ux, uy = math.cos(a), math.sin(a)
        inner = (sx + ux * SAMPLE_CLEAR_M, sy + uy * SAMPLE_CLEAR_M)
        stage = (sx + ux * standoff_m, sy + uy * standoff_m)
        share = corridor_share(free, inner, (sx + ux * (standoff_m + 0.5), sy + uy * (standoff_m + 0.5)))
        if share < STAGE_MIN_SHARE or not _free_at(free, np.array([stage[0]]), np.array([stage[1]]))[0]:
            continue
        if any(abs(wrap_deg(math.degrees(a) - b)) <= STAGE_WEDGED_DEG for b in wedged_bearings):
            continue
        room = 0.0  # free run behind the staging point: room to arrive and turn
        for extra in (1.0, 2.0, 3.0):
            if corridor_share(free, stage, (stage[0] + ux * extra, stage[1] + uy * extra)) < RUN_CLEAR_SHARE:
                break
            room = extra
        score = SHARE_WEIGHT * share + room + (SIDE_PREFERENCE * math.cos(a - side) if side is not None else 0.0)
        if score > best_score:
            heading = math.degrees(math.atan2(-uy, -ux)) % 360.0
            best, best_score = (stage[0], stage[1], heading), score
    return best


def plan_approach(free: np.ndarray, blocked: np.ndarray, sample_xy, arrival_xy, wedged_stages=()
                  ) -> Optional[Tuple[float, float, float]]:
    """Staging point (x, y, heading_deg) for the final run to a sample, or None: straight in.

    Cells the rover got stuck on (`blocked`) are not floor, whatever the map says: low rocks
    beside the east nook map as floor, and the rover wedged on them from the south again and
    again.  Once it wedged near this sample and no staging point is left on mapped floor, the
    opening is taken to be narrower than a map cell: staging may then use cells next to mapped
    floor (the nook's real opening reads as wall foot on the 1 m map).  A staging point whose
    approach already wedged (``wedged_stages``, world x, y) is not chosen again: the gap between the
    east nook's two rocks maps as floor, and the same point there was chosen four times in a row.
    """
    usable = free & ~blocked
    if direct_run_clear(usable, arrival_xy, sample_xy):
        return None
    stage = staging_point(usable, sample_xy, arrival_xy, wedged_stages=wedged_stages)
    if stage is None and (_blocked_near(blocked, sample_xy) or wedged_stages):
        grown = cv2.dilate(free.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        stage = staging_point(grown & ~blocked, sample_xy, arrival_xy, wedged_stages=wedged_stages)
    return stage


def _blocked_near(blocked: np.ndarray, sample_xy) -> bool:
    """Any stuck cell within WEDGED_NEAR_M of the sample?"""
    rows, cols = np.nonzero(blocked)
    if rows.size == 0:
        return False
    d = np.hypot(cols + 0.5 - float(sample_xy[0]), rows + 0.5 - float(sample_xy[1]))
    return bool((d <= WEDGED_NEAR_M).any())
