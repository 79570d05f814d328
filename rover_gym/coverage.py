"""What the rover's camera has seen of the truth map: the env's mapping reward.

A Gymnasium agent outputs commands, not a map, so "correctly mapped" cannot be
judged from its output the way `evaluation.metrics.score_map` judges a client's
worldmap.  The env instead credits the *opportunity* the agent created: a truth
navigable cell counts as mapped once the camera has seen its floor from close
enough that a mapper could have classified it.  That is judged from the
renderer's own ray hits (client-independent truth), not from any perception
code:

* a pixel sees floor when its ray hit terrain at floor height (not a wall face,
  not a rock top, not sky) within ``SEEN_RANGE_M`` of the camera (distance along
  the camera's forward axis, the renderer's depth);
* a 1 m cell is seen once any such pixel lands in it;
* only cells that are navigable in the world's ``nav_truth`` score.

It is roughly the most any client could map on the same path (a client still
has to classify what it saw), which is what a reward for exploration should be.
"""
from __future__ import annotations

import numpy as np

SEEN_RANGE_M = 9.0  # m, floor farther than this from the camera does not count as seen (our client maps to 9 m)
FLOOR_HIT_MAX_Z_M = 0.1  # m, a ray hit at most this high is floor (world floor is at 0 m; walls rise above)
PIXEL_STRIDE = 2  # use every n-th pixel row and column (a 1 m cell spans many pixels within range)
MAP_CELLS = 200  # truth map side, cells of 1 m


def hit_points(depth: np.ndarray, origin, rot, stride: int = PIXEL_STRIDE) -> np.ndarray:
    """World (x, y, z) of every `stride`-th pixel's surface from the renderer's depth (nan for sky).

    depth is the distance along each ray over |forward| (sim.render's `last_depth`), so a pixel's
    hit is origin + depth * (a * right + b * up + forward) with a, b its pinhole ray slopes.
    """
    from sim.render import CX, CY, FOCAL_PX

    h, w = depth.shape
    a = (np.arange(0, w, stride) + 0.5 - CX) / FOCAL_PX
    b = (CY - (np.arange(0, h, stride) + 0.5)) / FOCAL_PX
    rot = np.asarray(rot, np.float64)
    dirs = rot[:, 0] * a[None, :, None] + rot[:, 1] * b[:, None, None] + rot[:, 2]
    d = depth[::stride, ::stride].astype(np.float64)
    with np.errstate(invalid="ignore"):
        hit = np.asarray(origin, np.float64) + d[..., None] * dirs
    hit[~np.isfinite(d)] = np.nan
    return hit


def seen_floor_cells(hit: np.ndarray, dist: np.ndarray, seen_range_m: float = SEEN_RANGE_M) -> np.ndarray:
    """Flat indices (y * 200 + x) of the 1 m cells whose floor these pixels saw within range.

    hit: (..., 3) world hit points (nan for sky), dist: (...) their distance from the camera, m.
    """
    z = hit[..., 2]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(z) & (z <= FLOOR_HIT_MAX_Z_M) & (dist <= seen_range_m)
    if not ok.any():
        return np.zeros(0, np.int64)
    cx = np.clip(np.floor(hit[..., 0][ok]).astype(np.int64), 0, MAP_CELLS - 1)
    cy = np.clip(np.floor(hit[..., 1][ok]).astype(np.int64), 0, MAP_CELLS - 1)
    return np.unique(cy * MAP_CELLS + cx)


class CameraCoverage:
    """Accumulates seen truth-navigable cells over an episode; `update` returns the new ones."""

    def __init__(self, nav_truth: np.ndarray, seen_range_m: float = SEEN_RANGE_M):
        self.truth = np.asarray(nav_truth).reshape(-1) > 0
        self.truth_cells = int(self.truth.sum())
        self.seen_range_m = float(seen_range_m)
        self.seen = np.zeros(MAP_CELLS * MAP_CELLS, bool)  # any floor seen, truth or not

    def reset(self) -> None:
        self.seen[:] = False

    def update(self, depth, origin, rot) -> int:
        """Mark a frame's seen floor (renderer depth + camera); returns how many truth-navigable cells are new."""
        cells = seen_floor_cells(hit_points(depth, origin, rot), depth[::PIXEL_STRIDE, ::PIXEL_STRIDE],
                                 self.seen_range_m)
        fresh = cells[~self.seen[cells]]
        self.seen[fresh] = True
        return int(np.count_nonzero(self.truth[fresh]))

    @property
    def seen_truth_cells(self) -> int:
        return int(np.count_nonzero(self.seen & self.truth))

    @property
    def seen_truth_pct(self) -> float:
        return 100.0 * self.seen_truth_cells / self.truth_cells if self.truth_cells else 0.0

    def seen_map(self) -> np.ndarray:
        """bool (200, 200) [y, x]: floor cells seen so far."""
        return self.seen.reshape(MAP_CELLS, MAP_CELLS)
