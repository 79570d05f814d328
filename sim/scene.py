"""The twin's scene type and grid constants: what every world is, whoever built it.

`World` and the raster constants live here, apart from the loaders in sim/world.py, so
the world builders (sim/world.py for the simulator's own scene, sim/procedural.py for
the project's canyons and map PNGs) both depend on this module and never on each other.

Conventions (docs/ARCHITECTURE.md): x east, y north, z up, metres; rasters are
`[row = y, col = x]`, row 0 = y 0, never flipped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

WORLD_SIZE_M = 200.0  # side of the square world, m
TERRAIN_SAMPLES = 513  # terrain height vertex grid side, samples
TERRAIN_CELL_M = WORLD_SIZE_M / (TERRAIN_SAMPLES - 1)  # terrain vertex spacing, m (0.390625)
SAND_TEXELS = 512  # sand-weight texel grid side, texels
SAND_CELL_M = WORLD_SIZE_M / SAND_TEXELS  # sand texel size, m
ROCK_SAMPLES = 2001  # rock envelope vertex grid side, samples
ROCK_CELL_M = 0.1  # rock envelope vertex spacing, m
MAP_CELLS = 200  # ground-truth map side, cells of 1 m
FLOOR_TOLERANCE_M = 0.05  # a point this close to height 0 counts as floor, m


def _clip(a, lo, hi):
    """np.clip(a, lo, hi) for arrays and scalars, without np.clip's per-call overhead (~5 us: the
    physics calls this a dozen times per step); same values, NaN stays NaN."""
    return np.minimum(np.maximum(a, lo), hi)


def _bilinear(grid: np.ndarray, fx, fy):
    """Bilinear interpolation of a square grid at fractional (column, row) indices; scalars give a float."""
    n = grid.shape[0] - 1
    c0 = _clip(np.floor(fx).astype(np.int64), 0, n - 1)
    r0 = _clip(np.floor(fy).astype(np.int64), 0, n - 1)
    tx = fx - c0
    ty = fy - r0
    out = ((grid[r0, c0] * (1 - tx) + grid[r0, c0 + 1] * tx) * (1 - ty)
           + (grid[r0 + 1, c0] * (1 - tx) + grid[r0 + 1, c0 + 1] * tx) * ty)
    return float(out) if np.ndim(out) == 0 else out


@njit(cache=True, nogil=True)
def _clamped_bilinear(grid, xs, ys, size_m, cell_m, out):
    """World.height_at for flat float64 arrays, compiled: the same clamp, divisions, floor, clip and
    blend, in the same order, as clamp_xy + _bilinear (so bit-identical); NaN in gives NaN out."""
    n = grid.shape[0] - 1
    for i in range(xs.size):
        fx = min(max(xs[i], 0.0), size_m) / cell_m if xs[i] == xs[i] else xs[i]
        fy = min(max(ys[i], 0.0), size_m) / cell_m if ys[i] == ys[i] else ys[i]
        if fx != fx or fy != fy:
            out[i] = math.nan
            continue
        c0 = min(max(math.floor(fx), 0), n - 1)
        r0 = min(max(math.floor(fy), 0), n - 1)
        tx = fx - c0
        ty = fy - r0
        out[i] = ((grid[r0, c0] * (1 - tx) + grid[r0, c0 + 1] * tx) * (1 - ty)
                  + (grid[r0 + 1, c0] * (1 - tx) + grid[r0 + 1, c0 + 1] * tx) * ty)


@dataclass
class World:
    """Static scene. Arrays are the contract; methods are vectorised conveniences."""

    terrain_height: np.ndarray  # float32 (513, 513) m, vertex grid, [row=y, col=x]
    sand_weight: np.ndarray  # float32 (512, 512) 0..1, weight of the light floor sand texture
    rock_top: np.ndarray  # float32 (2001, 2001) m, absolute top of rock (0 = no rock)
    rock_bottom: np.ndarray  # float32 (2001, 2001) m, absolute bottom of rock (0 = none)
    nav_truth: np.ndarray  # uint8 (200, 200), 255 = navigable floor (scoring ground truth)
    sample_spots: np.ndarray  # float64 (N, 2) candidate sample (x, y), m
    start_xy: tuple  # (x, y) start position, m
    start_yaw_training: float  # yaw at start in training mode, degrees CCW from +x
    name: str
    terrain_cell_m: float = TERRAIN_CELL_M
    sand_cell_m: float = SAND_CELL_M
    rock_cell_m: float = ROCK_CELL_M
    size_m: float = WORLD_SIZE_M
    obstacles: list = field(default_factory=list)  # optional dicts {name, x, y, radius_m, ...}
    rock_colliders: list | None = None  # sim.contact.Shape list the rover collides with; None: the render envelopes
    cast_shadows: bool = False  # True: terrain casts shadows (the quality levels with shadows: test_dataset, dimaga,
    # royalejandro); off (megalphian, no shadows) stays the missions' default; sim.realism detects a log's level

    # ------------------------------------------------------------------ geometry
    def clamp_xy(self, x, y):
        """Clamp coordinates into the world square (out-of-world queries see the border)."""
        x = _clip(np.asarray(x, dtype=np.float64), 0.0, self.size_m)
        y = _clip(np.asarray(y, dtype=np.float64), 0.0, self.size_m)
        return x, y

    def height_at(self, x, y):
        """Terrain height (m) by bilinear interpolation; scalars or arrays; clamped to the world.

        Same-shape inputs take a compiled path (the physics asks a few times per step for four
        points; NumPy's per-call overhead was most of the time); broadcasting shapes the NumPy one."""
        xa = np.asarray(x, dtype=np.float64)
        ya = np.asarray(y, dtype=np.float64)
        if xa.shape == ya.shape and self.terrain_height.shape[0] == self.terrain_height.shape[1]:
            out = np.empty(xa.shape)
            _clamped_bilinear(self.terrain_height, np.ascontiguousarray(xa).ravel(), np.ascontiguousarray(ya).ravel(),
                              float(self.size_m), float(self.terrain_cell_m), out.reshape(-1))
            return float(out) if out.ndim == 0 else out
        return self._height_at_numpy(x, y)

    def _height_at_numpy(self, x, y):
        """height_at in NumPy (any broadcastable shapes; the reference the compiled path is tested against)."""
        x, y = self.clamp_xy(x, y)
        return _bilinear(self.terrain_height, x / self.terrain_cell_m, y / self.terrain_cell_m)

    def sand_at(self, x, y):
        """Light floor sand weight (0..1) by bilinear interpolation between texel centres, which lie at
        (i + 0.5) * sand_cell_m; scalars or arrays; clamped to the world."""
        x, y = self.clamp_xy(x, y)
        last = self.sand_weight.shape[0] - 1
        fx = _clip(x / self.sand_cell_m - 0.5, 0.0, last - 1e-6)
        fy = _clip(y / self.sand_cell_m - 0.5, 0.0, last - 1e-6)
        return _bilinear(self.sand_weight, fx, fy)

    def _rock_index(self, x, y):
        x, y = self.clamp_xy(x, y)
        n = self.rock_top.shape[0] - 1
        c = _clip(np.rint(x / self.rock_cell_m).astype(np.int64), 0, n)
        r = _clip(np.rint(y / self.rock_cell_m).astype(np.int64), 0, n)
        return r, c

    def rock_span_at(self, x, y):
        """(bottom, top) of rock at the nearest 0.1 m cell, m; (0, 0) where there is no rock."""
        if type(x) is float and type(y) is float and math.isfinite(x) and math.isfinite(y):
            # one finite point (tyre tracks ask per laid quad): the same clamp, half-to-even rounding and clip
            # as _rock_index, in plain Python
            n = self.rock_top.shape[0] - 1
            c = min(max(round(min(max(x, 0.0), self.size_m) / self.rock_cell_m), 0), n)
            r = min(max(round(min(max(y, 0.0), self.size_m) / self.rock_cell_m), 0), n)
            return float(self.rock_bottom[r, c]), float(self.rock_top[r, c])
        r, c = self._rock_index(x, y)
        bottom, top = self.rock_bottom[r, c], self.rock_top[r, c]
        if np.ndim(bottom) == 0:
            return float(bottom), float(top)
        return bottom, top

    def is_solid(self, x, y, z):
        """True where (x, y, z) is inside terrain (z <= height) or inside a rock slab."""
        z = np.asarray(z, dtype=np.float64)
        bottom, top = self.rock_span_at(x, y)
        in_rock = (np.asarray(top) > 0) & (z >= bottom) & (z <= top)
        out = (z <= self.height_at(x, y)) | in_rock
        return bool(out) if np.ndim(out) == 0 else out

    def surface_at(self, x, y):
        """Highest solid surface (terrain or rock top), m: what a body dropped from above lands on."""
        return np.maximum(self.height_at(x, y), self.rock_span_at(x, y)[1])

    def is_floor(self, x, y):
        """True where the terrain is at floor height and no rock stands on it."""
        _, top = self.rock_span_at(x, y)
        out = (np.asarray(self.height_at(x, y)) <= FLOOR_TOLERANCE_M) & (np.asarray(top) <= 0)
        return bool(out) if np.ndim(out) == 0 else out

    def summary(self) -> dict:
        return {
            "name": self.name,
            "nav_cells": int(np.count_nonzero(self.nav_truth)),
            "sample_spots": int(len(self.sample_spots)),
            "start_xy": [float(v) for v in self.start_xy],
            "max_height_m": float(self.terrain_height.max()),
        }


# ---------------------------------------------------------------------- helpers
def nav_truth_from_geometry(world_like_height_at, rock_top, size=MAP_CELLS):
    """Ground truth from geometry: 1 m cells whose centre is floor and not under rock."""
    cy, cx = np.mgrid[0:size, 0:size] + 0.5
    h = world_like_height_at(cx, cy)
    rc = _clip(np.rint(cx / ROCK_CELL_M).astype(int), 0, rock_top.shape[1] - 1)
    rr = _clip(np.rint(cy / ROCK_CELL_M).astype(int), 0, rock_top.shape[0] - 1)
    floor = (h <= FLOOR_TOLERANCE_M) & (rock_top[rr, rc] <= 0)
    return np.where(floor, 255, 0).astype(np.uint8)
