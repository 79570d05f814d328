"""Which remembered sample rocks have been refuted: approached and not found.

A far, misprojected sighting leaves a rock in the map's memory where there is none
(seed 5 at 15 fps: (104.5, 91.5), 5 m short of the real sample).  The rover drives
there, the camera shows nothing, it turns about, gives up; a skip timer then
brought the phantom back every 60 s (7 choices, 89 s of turning).  A timer is the
wrong rule: going there and looking IS the evidence.  A rock the rover came close to
without the camera ever confirming it stays refuted until the camera shows a rock
there again, close, with more pixels than the attempt ever saw of it.
A rock the camera did see close (a real rock that was hard to reach) is not refuted:
it keeps the old timed skip.  Pure functions over a list of (x, y, best_pixels).
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

Refuted = Tuple[float, float, int]  # world x, y (m) and the most rock pixels any matched sighting had


def was_refuted(came_close: bool, seen_close: bool) -> bool:
    """An attempt refutes its rock when the rover got close and the camera never confirmed it there."""
    return bool(came_close) and not bool(seen_close)


def nearest_refuted(refuted: Sequence[Refuted], xy, same_m: float) -> Optional[int]:
    """Index of the refuted spot within same_m of xy (the nearest), or None."""
    best, best_d = None, same_m
    for k, (x, y, _) in enumerate(refuted):
        d = math.hypot(xy[0] - x, xy[1] - y)
        if d < best_d:
            best, best_d = k, d
    return best


def add_refuted(refuted: Sequence[Refuted], xy, best_pixels: int, same_m: float) -> List[Refuted]:
    """The list with xy refuted; a spot already refuted nearby keeps the larger pixel bar."""
    out = list(refuted)
    k = nearest_refuted(out, xy, same_m)
    if k is None:
        out.append((float(xy[0]), float(xy[1]), int(best_pixels)))
    else:
        x, y, px = out[k]
        out[k] = (x, y, max(int(px), int(best_pixels)))
    return out


def revives(bar_pixels: int, pixels: int, dist_m: float, close_m: float) -> bool:
    """New, stronger evidence: a camera sighting within close_m with more pixels than the attempt saw."""
    return dist_m <= close_m and pixels > bar_pixels
