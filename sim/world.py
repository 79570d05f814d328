"""The twin's static world: terrain heights, sand texture weight, rocks, samples, start.

One `World` type serves three sources so physics, rendering and scoring never care
where a world came from:
  * `real`            - the simulator's own scene exported to ../shared/udacity-rover/world
  * `procedural:SEED` - the project's own seeded canyon (embedded default without ../shared)
  * a PNG path        - any 2-D navigable map (white = navigable) extruded into walls

Conventions (docs/ARCHITECTURE.md): x east, y north, z up, metres; rasters are
`[row = y, col = x]`, row 0 = y 0, never flipped.
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

import shared_data

log = logging.getLogger(__name__)

WORLD_SIZE_M = 200.0  # side of the square world, m
TERRAIN_SAMPLES = 513  # terrain height vertex grid side, samples
TERRAIN_CELL_M = WORLD_SIZE_M / (TERRAIN_SAMPLES - 1)  # terrain vertex spacing, m (0.390625)
SAND_TEXELS = 512  # sand-weight texel grid side, texels
SAND_CELL_M = WORLD_SIZE_M / SAND_TEXELS  # sand texel size, m
ROCK_SAMPLES = 2001  # rock envelope vertex grid side, samples
ROCK_CELL_M = 0.1  # rock envelope vertex spacing, m
MAP_CELLS = 200  # ground-truth map side, cells of 1 m
HEIGHT_M_PER_UNIT_REAL = 300.0 / 32766.0  # real terrain PNG value -> metres (Unity constant)
ROCK_M_PER_UNIT_REAL = 0.01  # real rock PNG value -> metres (centimetres)
FLOOR_TOLERANCE_M = 0.05  # a point this close to height 0 counts as floor, m
DEFAULT_PROCEDURAL_SEED = 0  # seed of the embedded default world


def _bilinear(grid: np.ndarray, fx, fy):
    """Bilinear interpolation of a square grid at fractional (column, row) indices; scalars give a float."""
    n = grid.shape[0] - 1
    c0 = np.clip(np.floor(fx).astype(np.int64), 0, n - 1)
    r0 = np.clip(np.floor(fy).astype(np.int64), 0, n - 1)
    tx = fx - c0
    ty = fy - r0
    out = ((grid[r0, c0] * (1 - tx) + grid[r0, c0 + 1] * tx) * (1 - ty)
           + (grid[r0 + 1, c0] * (1 - tx) + grid[r0 + 1, c0 + 1] * tx) * ty)
    return float(out) if np.ndim(out) == 0 else out


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
    cast_shadows: bool = True  # False: the simulator's Fastest/Fast graphics quality, no cast shadows

    # ------------------------------------------------------------------ geometry
    def clamp_xy(self, x, y):
        """Clamp coordinates into the world square (out-of-world queries see the border)."""
        x = np.clip(np.asarray(x, dtype=np.float64), 0.0, self.size_m)
        y = np.clip(np.asarray(y, dtype=np.float64), 0.0, self.size_m)
        return x, y

    def height_at(self, x, y):
        """Terrain height (m) by bilinear interpolation; scalars or arrays; clamped to the world."""
        x, y = self.clamp_xy(x, y)
        return _bilinear(self.terrain_height, x / self.terrain_cell_m, y / self.terrain_cell_m)

    def sand_at(self, x, y):
        """Light floor sand weight (0..1) by bilinear interpolation between texel centres, which lie at
        (i + 0.5) * sand_cell_m; scalars or arrays; clamped to the world."""
        x, y = self.clamp_xy(x, y)
        last = self.sand_weight.shape[0] - 1
        fx = np.clip(x / self.sand_cell_m - 0.5, 0.0, last - 1e-6)
        fy = np.clip(y / self.sand_cell_m - 0.5, 0.0, last - 1e-6)
        return _bilinear(self.sand_weight, fx, fy)

    def _rock_index(self, x, y):
        x, y = self.clamp_xy(x, y)
        n = self.rock_top.shape[0] - 1
        c = np.clip(np.rint(x / self.rock_cell_m).astype(np.int64), 0, n)
        r = np.clip(np.rint(y / self.rock_cell_m).astype(np.int64), 0, n)
        return r, c

    def rock_span_at(self, x, y):
        """(bottom, top) of rock at the nearest 0.1 m cell, m; (0, 0) where there is no rock."""
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
    rc = np.clip(np.rint(cx / ROCK_CELL_M).astype(int), 0, rock_top.shape[1] - 1)
    rr = np.clip(np.rint(cy / ROCK_CELL_M).astype(int), 0, rock_top.shape[0] - 1)
    floor = (h <= FLOOR_TOLERANCE_M) & (rock_top[rr, rc] <= 0)
    return np.where(floor, 255, 0).astype(np.uint8)


def _read_png(path: Path) -> np.ndarray:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"cannot read image {path}")
    return img


# ---------------------------------------------------------------------- loaders
def load_real_world(world_dir: Path | None = None) -> World:
    """The simulator's exported scene (see ../shared/udacity-rover/world/README.md)."""
    world_dir = Path(world_dir) if world_dir is not None else shared_data.world_dir()
    if not world_dir.exists():
        raise FileNotFoundError(f"real world export not found at {world_dir} "
                                f"(set {shared_data.SHARED_ENV_VAR})")
    meta = json.loads((world_dir / "world.json").read_text())
    per_unit = float(meta["terrain"].get("height_m_per_unit", HEIGHT_M_PER_UNIT_REAL))
    terrain = _read_png(world_dir / "terrain_height.png").astype(np.float32) * np.float32(per_unit)
    sand = _read_png(world_dir / "terrain_sand.png").astype(np.float32) / np.float32(255.0)
    rock_unit = float(meta["rocks_raster"].get("height_m_per_unit", ROCK_M_PER_UNIT_REAL))
    rock_top = _read_png(world_dir / "rocks_height.png").astype(np.float32) * np.float32(rock_unit)
    rock_bottom = _read_png(world_dir / "rocks_bottom.png").astype(np.float32) * np.float32(rock_unit)
    start = json.loads((world_dir / "start.json").read_text())
    samples = _read_samples_csv(world_dir / "samples.csv")
    obstacles = _read_obstacles_csv(world_dir / "obstacles.csv")
    world = World(
        terrain_height=terrain, sand_weight=sand, rock_top=rock_top, rock_bottom=rock_bottom,
        nav_truth=np.zeros((MAP_CELLS, MAP_CELLS), np.uint8), sample_spots=samples,
        start_xy=(float(start["position_m"]["x"]), float(start["position_m"]["y"])),
        start_yaw_training=float(start["training_mode"]["telemetry_yaw_deg"]),
        name="real", obstacles=obstacles,
    )
    gt_path = shared_data.ground_truth_map_path()
    if world_dir == shared_data.world_dir() and gt_path.exists():
        from evaluation.metrics import load_ground_truth

        world.nav_truth = load_ground_truth(gt_path)  # the scoring map itself
    else:
        world.nav_truth = nav_truth_from_geometry(world.height_at, rock_top)
    return world


def _read_samples_csv(path: Path) -> np.ndarray:
    import csv

    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return np.array([[float(r["x"]), float(r["y"])] for r in rows], dtype=np.float64).reshape(-1, 2)


def _read_obstacles_csv(path: Path) -> list:
    import csv

    if not path.exists():
        return []
    out = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            out.append({
                "name": r["name"], "x": float(r["x"]), "y": float(r["y"]),
                "radius_m": float(r["radius_equiv_m"]),
                "height_above_ground_m": float(r["height_above_ground_m"]),
                "touches_floor": r["touches_floor"] == "1",
            })
    return out


def load_world(spec: str = "default") -> World:
    """`real`, `procedural:SEED` (or `procedural`), `default`, or a path to a navigable-map PNG."""
    spec = str(spec).strip()
    if spec in ("", "default"):
        return default_world()
    if spec == "real":
        return load_real_world()
    if spec.startswith("procedural"):
        from sim.procedural import canyon_world

        _, _, seed_text = spec.partition(":")
        try:
            seed = int(seed_text) if seed_text else DEFAULT_PROCEDURAL_SEED
        except ValueError:
            raise ValueError(f"bad procedural seed in world spec {spec!r}") from None
        return canyon_world(seed)
    path = Path(spec).expanduser()
    if path.suffix.lower() == ".png" or path.exists():
        from sim.procedural import world_from_map_png

        return world_from_map_png(path)
    raise ValueError(f"unknown world spec {spec!r}: use 'real', 'procedural:SEED' or a PNG path")


def with_shadows(world: World, on: bool) -> World:
    """The same scene with cast shadows on or off (the simulator's graphics-quality choice).

    Real recordings differ: test_dataset shows terrain shadows, the 6,150-frame megalphian
    drive shows none (its floor where the twin casts shadow is as bright as sunlit floor).
    """
    if world.cast_shadows == bool(on):
        return world
    return replace(world, cast_shadows=bool(on))


def real_world_available() -> bool:
    return (shared_data.world_dir() / "world.json").exists()


def default_world() -> World:
    """The simulator's real world when ../shared is present, else the procedural canyon 0."""
    if real_world_available():
        return load_real_world()
    log.info("real world not found at %s; using procedural:%d", shared_data.world_dir(),
             DEFAULT_PROCEDURAL_SEED)
    return load_world(f"procedural:{DEFAULT_PROCEDURAL_SEED}")
