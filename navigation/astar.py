"""Shortest paths on the cost grid (8-connected A* / Dijkstra, compiled with numba).

One Dijkstra from the rover gives the path length to every cell, which is
what frontier selection needs; A* with an octile heuristic serves single
goals (a rock, home). Both cost ~1-10 ms on the 200x200 grid, so callers
replan every few frames or on events, never every frame.
"""
import heapq

import numpy as np
from numba import njit

SQRT2 = 1.4142135623730951  # diagonal step length, cells
NO_PARENT = -1  # parent index of the start cell / unreached cells


@njit(cache=True)
def _search(cost, start_r, start_c, goal_r, goal_c, max_dist):
    """Dijkstra (goal_r < 0) or A* to (goal_r, goal_c); returns (dist, parent) flat arrays."""
    h, w = cost.shape
    n = h * w
    dist = np.full(n, np.inf)
    parent = np.full(n, NO_PARENT, np.int64)
    closed = np.zeros(n, np.bool_)
    s = start_r * w + start_c
    dist[s] = 0.0
    heap = [(0.0, s)]
    dr = (-1, -1, -1, 0, 0, 1, 1, 1)
    dc = (-1, 0, 1, -1, 1, -1, 0, 1)
    use_goal = goal_r >= 0
    g = goal_r * w + goal_c
    while len(heap) > 0:
        _, u = heapq.heappop(heap)
        if closed[u]:
            continue
        closed[u] = True
        if use_goal and u == g:
            break
        du = dist[u]
        if du > max_dist:
            break
        ur = u // w
        uc = u - ur * w
        cu = cost[ur, uc]
        for k in range(8):
            vr = ur + dr[k]
            vc = uc + dc[k]
            if vr < 0 or vr >= h or vc < 0 or vc >= w:
                continue
            cv = cost[vr, vc]
            if not np.isfinite(cv):
                continue
            step = 1.0
            if dr[k] != 0 and dc[k] != 0:
                # no corner cutting between two blocked orthogonal cells
                if not np.isfinite(cost[ur, vc]) or not np.isfinite(cost[vr, uc]):
                    continue
                step = SQRT2
            v = vr * w + vc
            nd = du + step * 0.5 * (cu + cv)
            if nd < dist[v]:
                dist[v] = nd
                parent[v] = u
                pri = nd
                if use_goal:
                    ar = abs(vr - goal_r)
                    ac = abs(vc - goal_c)
                    pri = nd + (max(ar, ac) + (SQRT2 - 1.0) * min(ar, ac))
                heapq.heappush(heap, (pri, v))
    return dist, parent


def distance_field(cost, start, max_dist=np.inf):
    """Path cost from `start` (row, col) to every cell; also the parent array for `path_to`."""
    cost = np.ascontiguousarray(cost, dtype=np.float64)
    dist, parent = _search(cost, int(start[0]), int(start[1]), -1, -1, float(max_dist))
    return dist.reshape(cost.shape), parent


def path_to(parent, shape, goal):
    """Cells [(row, col), ...] from the search start to `goal`, or [] when unreached."""
    w = shape[1]
    g = int(goal[0]) * w + int(goal[1])
    cells = []
    guard = shape[0] * shape[1]
    while g != NO_PARENT and guard > 0:
        cells.append((g // w, g % w))
        g = int(parent[g])
        guard -= 1
    cells.reverse()
    return cells


def astar(cost, start, goal):
    """Cheapest 8-connected path of cells from start to goal, or [] if none (cost inf = wall)."""
    cost = np.ascontiguousarray(cost, dtype=np.float64)
    h, w = cost.shape
    if not (0 <= goal[0] < h and 0 <= goal[1] < w and 0 <= start[0] < h and 0 <= start[1] < w):
        return []
    if not np.isfinite(cost[goal[0], goal[1]]) or not np.isfinite(cost[start[0], start[1]]):
        return []
    dist, parent = _search(cost, int(start[0]), int(start[1]), int(goal[0]), int(goal[1]), np.inf)
    if not np.isfinite(dist[int(goal[0]) * w + int(goal[1])]):
        return []
    return path_to(parent, cost.shape, goal)


def path_length(cells):
    """Geometric length of a cell path in metres."""
    if len(cells) < 2:
        return 0.0
    a = np.asarray(cells, dtype=np.float64)
    return float(np.hypot(*np.diff(a, axis=0).T).sum())


def cells_to_world(cells):
    """(N, 2) array of world (x, y) cell centres for a path of (row, col) cells."""
    if not cells:
        return np.zeros((0, 2))
    a = np.asarray(cells, dtype=np.float64)
    return np.stack([a[:, 1] + 0.5, a[:, 0] + 0.5], axis=1)
