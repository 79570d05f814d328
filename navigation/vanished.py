"""Where to keep driving when the frontier being driven to is voted wall before it was seen from close.

Seed 5 (15 fps): the north arm narrows to a two-cell neck and bends behind a wall. The one
frontier cell at the tip was voted wall from 8 m off (wall-foot floor seen from afar often is),
the frontier vanished, the map looked complete and the rover turned back 8.4 m short of the
sample at the tip. A frontier closed by a far vote is not closed: the rover still goes to the
floor beside it and looks. Pure functions over [row=y, col=x] grids with 1 m cells.
"""
from __future__ import annotations

from typing import Optional, Tuple

import numpy as np

Cell = Tuple[int, int]


def vanished_by_far_vote(cell: Cell, obstacle: np.ndarray, seen: np.ndarray) -> bool:
    """The goal cell now reads as wall, and the camera never looked at it from close."""
    r, c = cell
    return bool(obstacle[r, c]) and not bool(seen[r, c])


def stand_beside(cell: Cell, free: np.ndarray, dist: np.ndarray, reach_m: float) -> Optional[Cell]:
    """The reachable (finite `dist`) free cell nearest (straight line) to `cell`, within reach_m of it;
    ties go to the cheaper path. None when there is none."""
    r, c = cell
    k = int(np.ceil(reach_m))
    r0, r1 = max(r - k, 0), min(r + k + 1, free.shape[0])
    c0, c1 = max(c - k, 0), min(c + k + 1, free.shape[1])
    ok = free[r0:r1, c0:c1] & np.isfinite(dist[r0:r1, c0:c1])
    rows, cols = np.nonzero(ok)
    if rows.size == 0:
        return None
    rows, cols = rows + r0, cols + c0
    d = np.hypot(rows - r, cols - c)
    near = d <= reach_m
    if not near.any():
        return None
    rows, cols, d = rows[near], cols[near], d[near]
    best = int(np.lexsort((dist[rows, cols], d))[0])
    return int(rows[best]), int(cols[best])
