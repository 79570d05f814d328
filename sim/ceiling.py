"""How well could any map score against map_bw.png? Oracle maps built from the world's own data.

map_bw.png is not simply "the canyon floor": hundreds of 1 m cells at floor height along
the walls are left out of it. A client only sees colours, so it can at best call a cell
navigable from what the cell looks like: whether it is floor, and how much light floor
sand (the texture the simulator blends out towards the walls) covers it. This tool builds
such maps with perfect knowledge of the terrain and the sand texture and scores them, so the
best mapped / fidelity pair any camera-based client can hope for is a number, not a guess.

    python -m sim.ceiling [--json out/ceiling.json]

Needs the real world (../shared/udacity-rover/world) and map_bw.png.
"""
from __future__ import annotations

import argparse
import logging
from dataclasses import asdict, dataclass

import numpy as np

from evaluation.metrics import load_ground_truth, score_map
from sim.cli import parse_with_logging
from sim.world import FLOOR_TOLERANCE_M, World

log = logging.getLogger(__name__)

SUB_CELLS = 10  # samples per metre along each axis when measuring a cell's floor and sand cover
BRIGHT_SAND_WEIGHT = 0.735  # sand weight at which sunlit floor crosses the RGB > 160 threshold (twin colour table)
CENTRE_SAND_STEPS = np.round(np.arange(0.55, 0.901, 0.01), 3)  # centre sand-weight thresholds tried
BRIGHT_SHARE_STEPS = np.round(np.arange(0.0, 0.951, 0.05), 3)  # bright-floor share thresholds tried
FIDELITY_FLOORS = (95.0, 96.0, 97.0, 98.0)  # report the best mapped at fidelity at least these, %


@dataclass
class CeilingPoint:
    rule: str
    mapped_pct: float
    fidelity_pct: float


@dataclass
class Ceiling:
    truth_cells: int
    floor_cells: int  # cells whose centre is at floor height with no rock on it
    floor_not_truth: int  # of those, cells map_bw leaves out
    truth_not_floor: int
    points: list  # CeilingPoint: every floor cell, and the best oracle rule per fidelity floor


def cell_features(world: World):
    """Per 1 m cell [y, x]: centre is floor, centre sand weight, share of the cell that is bright floor."""
    n = int(world.size_m)
    centre = np.mgrid[0:n, 0:n].astype(np.float64) + 0.5
    cy, cx = centre
    floor_centre = world.is_floor(cx, cy)
    sand_centre = world.sand_at(cx, cy)
    k = SUB_CELLS
    fine = (np.arange(n * k) + 0.5) / k
    fx, fy = np.meshgrid(fine, fine)
    bright = (np.asarray(world.height_at(fx, fy)) <= FLOOR_TOLERANCE_M) & (
        world.sand_at(fx, fy) >= BRIGHT_SAND_WEIGHT)
    bright_share = bright.reshape(n, k, n, k).mean(axis=(1, 3))
    return floor_centre, sand_centre, bright_share


def _as_worldmap(nav: np.ndarray) -> np.ndarray:
    wm = np.zeros(nav.shape + (3,), np.uint8)
    wm[..., 2] = np.where(nav, 255, 0)
    return wm


def ceiling(world: World, truth: np.ndarray) -> Ceiling:
    """Score the oracle maps: all floor, then the best (centre sand, bright share) rule per fidelity floor."""
    truth = np.asarray(truth) > 0
    floor, sand, bright = cell_features(world)
    score = lambda nav: score_map(_as_worldmap(nav), truth)  # noqa: E731
    whole = score(floor)
    points = [CeilingPoint("every floor cell", whole.mapped_pct, whole.fidelity_pct)]
    trials = []
    for a in CENTRE_SAND_STEPS:
        for b in BRIGHT_SHARE_STEPS:
            s = score(floor & (sand >= a) & (bright > b))
            trials.append((s.mapped_pct, s.fidelity_pct, a, b))
    for fid in FIDELITY_FLOORS:
        ok = [t for t in trials if t[1] >= fid]
        if ok:
            m, f, a, b = max(ok, key=lambda t: (t[0], t[1]))
            points.append(CeilingPoint(f"floor, centre sand >= {a:.2f}, bright share > {b:.2f} "
                                       f"(best mapped at fidelity >= {fid:.0f} %)", m, f))
    return Ceiling(int(truth.sum()), int(floor.sum()), int((floor & ~truth).sum()), int((truth & ~floor).sum()),
                   points)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim.ceiling", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--json", help="also write the figures here")
    a = parse_with_logging(p, argv)
    import shared_data
    from sim.world import load_real_world, real_world_available

    truth_path = shared_data.ground_truth_map_path()
    if not real_world_available() or not truth_path.exists():
        log.error("the real world and map_bw.png are needed (set %s)", shared_data.SHARED_ENV_VAR)
        return 2
    result = ceiling(load_real_world(), load_ground_truth(truth_path))
    log.info("map_bw: %d navigable cells; floor-height cells: %d (%d of them not in map_bw, %d map_bw cells not floor)",
             result.truth_cells, result.floor_cells, result.floor_not_truth, result.truth_not_floor)
    for pt in result.points:
        log.info("  %5.1f %% mapped  %5.1f %% fidelity  %s", pt.mapped_pct, pt.fidelity_pct, pt.rule)
    if a.json:
        from replay.outputs import write_json

        write_json(a.json, {**asdict(result), "points": [asdict(pt) for pt in result.points]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
