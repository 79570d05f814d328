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
from dataclasses import replace
from pathlib import Path

import numpy as np

import shared_data
from sim.contact import load_collider_shapes
from sim.procedural import canyon_world, world_from_map_png
from sim.scene import (FLOOR_TOLERANCE_M, MAP_CELLS, ROCK_CELL_M, ROCK_SAMPLES, SAND_CELL_M, SAND_TEXELS,  # noqa: F401
                       TERRAIN_CELL_M, TERRAIN_SAMPLES, WORLD_SIZE_M, World, nav_truth_from_geometry)

log = logging.getLogger(__name__)

HEIGHT_M_PER_UNIT_REAL = 300.0 / 32766.0  # real terrain PNG value -> metres (Unity constant)
ROCK_M_PER_UNIT_REAL = 0.01  # real rock PNG value -> metres (centimetres)
DEFAULT_PROCEDURAL_SEED = 0  # seed of the embedded default world


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
    colliders = load_collider_shapes(world_dir) or None
    world = World(
        terrain_height=terrain, sand_weight=sand, rock_top=rock_top, rock_bottom=rock_bottom,
        nav_truth=np.zeros((MAP_CELLS, MAP_CELLS), np.uint8), sample_spots=samples,
        start_xy=(float(start["position_m"]["x"]), float(start["position_m"]["y"])),
        start_yaw_training=float(start["training_mode"]["telemetry_yaw_deg"]),
        name="real", obstacles=obstacles, rock_colliders=colliders,
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
        _, _, seed_text = spec.partition(":")
        try:
            seed = int(seed_text) if seed_text else DEFAULT_PROCEDURAL_SEED
        except ValueError:
            raise ValueError(f"bad procedural seed in world spec {spec!r}") from None
        return canyon_world(seed)
    path = Path(spec).expanduser()
    if path.suffix.lower() == ".png" or path.exists():
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
