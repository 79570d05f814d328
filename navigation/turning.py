"""Turning in place: which targets a turn in place can face at all.

A point closer than TURN_POINT_MIN_M to the rover origin has no usable bearing: the origin itself moves
~0.3 m as the rover turns in place, so each turn toward such a point ends facing somewhere else and the
next one starts. On seed 16 (15 fps, 60 ms, matrix at 672bec0) a remembered rock 0.1-0.4 m from the
origin, not in view, drew nine turns in place in a row (67-83 s, over 700 deg) until the spin detector
dropped it: a 9.7 s stuck stretch.
"""
import math

TURN_POINT_MIN_M = 0.6  # a point nearer than this to the rover origin is no target for a turn in place, m


def bearing_usable(dist_m: float) -> bool:
    """Can the rover turn in place to face a point this far (m) from its origin?"""
    return math.isfinite(dist_m) and dist_m >= TURN_POINT_MIN_M
