"""From where the camera shows each of the canyon's sample spots: the twin draws a sample at every spot and looks
at it from every side.  ``python -m sim.spot_views [--out navigation/spot_views.json]``

Why: the sample search checks the canyon's 33 spots (navigation.sample_spots).  A spot seen "from close along a
clear line of sight" on the 1 m map is not always seen by the camera: a rock smaller than a cell, or a slot's
wall, hides the sample from most sides (the east nook shows only from 150-165 and 240 deg, docs/autonomy.md,
fourteenth round).  This tool records, per spot, bearing (from the spot to the camera, every BEARING_STEP_DEG)
and range, how many gold pixels the client's own gold threshold finds in the twin's JPEG of a sample there (scale
SAMPLE_SCALE, the fewest over SAMPLE_YAWS_DEG, in the sun and in the canyon's shadows), with the rover standing on
floor clear of rocks and facing the spot; -1 where it cannot stand.  The client reads the table it ships with
(navigation/spot_views.json) against its own pixel lines (navigation.sample_spots): a spot counts as checked only
from where it shows well, and the search's stand for it is where it shows best.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

import numpy as np

import perception
from safe_write import atomic_write

log = logging.getLogger(__name__)

BEARING_STEP_DEG = 10  # bearings from the spot to the camera, every this many degrees
RANGES_M = tuple(np.round(np.arange(2.0, 7.01, 0.5), 2))  # camera distances from the spot, m
SAMPLE_SCALE = 0.40  # prefab scale drawn (spawns are 0.36-0.5; smaller shows fewer pixels)
SAMPLE_YAWS_DEG = (0.0, 45.0)  # the sample's yaw, both drawn: it shows only when it shows at both
STAND_MAX_HEIGHT_M = 0.05  # a camera stand must be floor: terrain at most this high, m
STAND_ROCK_CLEAR_M = 0.6  # ...with no rock this close (the body would stand on it), m
DEFAULT_OUT = Path(__file__).resolve().parent.parent / "navigation" / "spot_views.json"


def stand_ok(world, x, y) -> bool:
    """Whether the rover can stand at (x, y): floor height, no rock within STAND_ROCK_CLEAR_M."""
    if not (0.0 <= x < world.size_m and 0.0 <= y < world.size_m):
        return False
    if float(world.height_at(np.float32(x), np.float32(y))) > STAND_MAX_HEIGHT_M:
        return False
    cell = world.rock_cell_m
    r = int(math.ceil(STAND_ROCK_CLEAR_M / cell))
    row, col = int(round(y / cell)), int(round(x / cell))
    top = world.rock_top[max(row - r, 0):row + r + 1, max(col - r, 0):col + r + 1]
    return not (top > 0).any()


def gold_px(renderer, pose, spot, yaw_deg) -> int:
    """Gold pixels the client's threshold finds in the twin's JPEG of a sample at ``spot`` seen from ``pose``."""
    from sim.realism import jpeg_roundtrip

    rgb = renderer.render(pose, samples=[(spot[0], spot[1], SAMPLE_SCALE, yaw_deg)])
    return int(perception.rock_mask(jpeg_roundtrip(rgb)).sum())


def spot_view_table(worlds, spots, progress=True) -> np.ndarray:
    """int16 (n spots, n bearings, n ranges): the fewest gold pixels a sample at each spot shows from there over
    ``worlds`` (the canyon with and without shadows) and SAMPLE_YAWS_DEG; -1 where the rover cannot stand."""
    from sim.render import Renderer

    bearings = np.arange(0, 360, BEARING_STEP_DEG)
    table = np.full((len(spots), len(bearings), len(RANGES_M)), -1, np.int16)
    renderers = [Renderer(w) for w in worlds]
    todo = [(k, i, j) for k in range(len(spots)) for i in range(len(bearings)) for j in range(len(RANGES_M))]
    try:
        from tqdm import tqdm
        todo = tqdm(todo, desc="spot views", disable=not progress)
    except ImportError:
        pass
    for k, i, j in todo:
        sx, sy = spots[k]
        b = math.radians(bearings[i])
        x, y = sx + RANGES_M[j] * math.cos(b), sy + RANGES_M[j] * math.sin(b)
        if not stand_ok(worlds[0], x, y):
            continue
        pose = (x, y, (bearings[i] + 180.0) % 360.0, 0.0, 0.0)
        table[k, i, j] = min(gold_px(r, pose, (sx, sy), yaw) for r in renderers for yaw in SAMPLE_YAWS_DEG)
    return table


def to_json(spots, table) -> dict:
    """The table as the client reads it: per spot, one line per bearing of the pixel counts over RANGES_M."""
    return {"about": "navigation/spot_views.json: gold pixels the twin's camera shows of a sample at each of the "
                     "canyon's spots, per bearing (rows) and range (columns); -1 = no floor to stand on; "
                     "written by python -m sim.spot_views",
            "bearing_step_deg": BEARING_STEP_DEG, "ranges_m": [float(r) for r in RANGES_M],
            "sample_scale": SAMPLE_SCALE,
            "spots": [{"x": float(x), "y": float(y), "px": [" ".join(str(int(v)) for v in row) for row in table[k]]}
                      for k, (x, y) in enumerate(spots)]}


def main(argv=None) -> int:
    from sim.cli import parse_with_logging
    from sim.world import load_world, with_shadows

    p = argparse.ArgumentParser(prog="python -m sim.spot_views", description=__doc__.split("\n")[0])
    p.add_argument("--out", default=str(DEFAULT_OUT), help="JSON to write (default: the one the client ships)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parse_with_logging(p, argv)
    try:
        world = load_world("real")
    except (OSError, ValueError) as exc:
        log.error("the real world's export is needed (../shared/udacity-rover/world): %s", exc)
        return 2
    from navigation.sample_spots import CANYON_SPOTS

    spots = CANYON_SPOTS  # the client's list: the table is read against it (the export's differ by millimetres)
    if len(world.sample_spots) != len(spots) or np.abs(np.asarray(world.sample_spots) - spots).max() > 0.05:
        log.error("the world export's sample spots are not navigation.sample_spots.CANYON_SPOTS")
        return 2
    table = spot_view_table([with_shadows(world, False), with_shadows(world, True)], spots, not args.no_progress)
    atomic_write(Path(args.out), (json.dumps(to_json(spots, table), indent=1) + "\n").encode())
    shown = (table >= perception.ROCK_MIN_PIXELS).any(axis=2).sum(axis=1)
    log.info("wrote %s: %d spots; bearings a spot shows from (>= %d px): min %d, median %.0f, max %d of %d", args.out,
             len(spots), perception.ROCK_MIN_PIXELS, shown.min(), np.median(shown), shown.max(), table.shape[1])
    for k in np.argsort(shown)[:5]:
        log.info("  fewest: spot %d (%.2f, %.2f) shows from %d bearings", k, *spots[k], shown[k])
    return 0


if __name__ == "__main__":
    sys.exit(main())
