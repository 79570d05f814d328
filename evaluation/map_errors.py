"""Where an evaluation's maps go wrong, across its missions: ``python -m evaluation.map_errors RUN [RUN ...]``.

Why: a mission's mapped and fidelity figures are a few dozen wrong cells out of ~2,000.  Whether driving,
looking or perception could win them back depends on whether they are the same cells in every mission (the
world decides them: how the cell looks from the floor, and how map_bw's hand-drawn edge cuts it) or different
ones each time (the route decides them).  This tool counts, per cell, in how many missions of each condition the
cell was a false navigable cell or missed truth (split into mapped obstacle and never seen), calls the cells wrong
in at least ``--min-share`` of the missions *systematic*, and on the real world sorts those by what the terrain
holds there (``sim.ceiling.cell_features``): a rock or raised ground, floor whose sand is too dim to pass the
light-sand threshold, or light floor.  It also prints what mapped and fidelity would be if the systematic errors
were the only ones left: the figures no change of route can beat while perception reads those cells as it does.

RUN is a folder written by ``python -m sim.evaluate`` (``seed-N/worldmap.npy``), or by ``--matrix`` (one such
folder per condition).  Writes ``map-errors-<condition>.png`` (truth grey; false navigable red and missed truth
blue, brighter the more missions got the cell wrong; systematic cells dotted white) and ``map-errors.json``
to ``--out``.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

import cv2
import numpy as np

log = logging.getLogger(__name__)

SYSTEMATIC_SHARE = 0.5  # a cell wrong in at least this share of a condition's missions is systematic, 0..1
IMAGE_SCALE = 5  # pixels per map cell in the PNG
CROP_MARGIN_CELLS = 8  # map cells kept around the canyon in the PNG
TRUTH_GREY = 70  # grey level of truth floor in the PNG, 0..255


class MapErrorsError(ValueError):
    """The folders hold no missions this tool can read."""


@dataclass
class ConditionErrors:
    """Per-cell error counts of one condition's missions (maps [y, x], 1 cell = 1 m)."""

    condition: str
    world: str
    missions: int
    truth: np.ndarray  # bool, map_bw's navigable cells
    false_nav: np.ndarray  # int, missions that marked the cell navigable where truth is not
    missed_obstacle: np.ndarray  # int, missions that marked a truth cell obstacle
    missed_unseen: np.ndarray  # int, missions that never marked a truth cell at all
    per_mission: List[dict] = field(default_factory=list)  # seed, false, missed_obstacle, missed_unseen

    @property
    def missed(self) -> np.ndarray:
        """int, missions that missed the truth cell either way."""
        return self.missed_obstacle + self.missed_unseen


def count_errors(worldmaps, truth: np.ndarray):
    """(false_nav, missed_obstacle, missed_unseen, per-mission counts) over worldmaps ([y, x] RGB, blue = navigable)."""
    truth = np.asarray(truth) > 0
    false_nav = np.zeros(truth.shape, np.int32)
    missed_obstacle = np.zeros(truth.shape, np.int32)
    missed_unseen = np.zeros(truth.shape, np.int32)
    rows = []
    for wm in worldmaps:
        nav = wm[:, :, 2] > 0
        obstacle = (wm[:, :, 0] > 0) & ~nav
        f, mo, mu = nav & ~truth, truth & obstacle, truth & ~nav & ~obstacle
        false_nav += f
        missed_obstacle += mo
        missed_unseen += mu
        rows.append({"false": int(f.sum()), "missed_obstacle": int(mo.sum()), "missed_unseen": int(mu.sum())})
    return false_nav, missed_obstacle, missed_unseen, rows


def systematic(counts: np.ndarray, missions: int, share: float = SYSTEMATIC_SHARE) -> np.ndarray:
    """Cells wrong in at least ``share`` of the missions."""
    return (counts >= share * missions) & (counts > 0)


def remaining_scores(truth: np.ndarray, sys_false: np.ndarray, sys_missed: np.ndarray):
    """(mapped %, fidelity %) of a map whose only errors are the systematic ones."""
    n_truth = int(truth.sum())
    good = n_truth - int((sys_missed & truth).sum())
    marked = good + int((sys_false & ~truth).sum())
    return 100.0 * good / n_truth, 100.0 * good / marked


def terrain_classes(mask: np.ndarray, floor_centre: np.ndarray, sand_centre: np.ndarray, light_sand: float) -> dict:
    """Counts of the masked cells by what the terrain holds at their centre: raised (a rock or a slope), dim floor, light floor."""
    raised = mask & ~floor_centre
    dim = mask & floor_centre & (sand_centre < light_sand)
    light = mask & floor_centre & (sand_centre >= light_sand)
    return {"rock or raised ground": int(raised.sum()), "floor, sand too dim for the light-sand threshold": int(dim.sum()),
            "floor, light sand": int(light.sum())}


def find_conditions(run: Path) -> Dict[str, Path]:
    """Folders under ``run`` (itself included) that hold ``seed-N/worldmap.npy``, by condition name."""
    run = Path(run)
    if not run.is_dir():
        raise MapErrorsError(f"{run}: no such folder")
    found = {}
    for folder in sorted({p.parent.parent for p in run.glob("**/seed-*/worldmap.npy")}):
        name = run.name if folder == run else str(folder.relative_to(run))
        found[name] = folder
    if not found:
        raise MapErrorsError(f"{run}: no seed-N/worldmap.npy (a folder written by python -m sim.evaluate)")
    return found


def _mission_truth(seed_dir: Path) -> Optional[np.ndarray]:
    timeline = seed_dir / "timeline.npz"
    if timeline.exists():
        with np.load(timeline) as z:
            if "truth" in z.files:
                return z["truth"] > 0
    return None


def load_condition(name: str, folder: Path, fallback_truth: Optional[np.ndarray]) -> ConditionErrors:
    """Count one condition's errors; every mission must share one truth map (one world)."""
    maps, seeds, truth, world = [], [], None, None
    for seed_dir in sorted(folder.glob("seed-*"), key=lambda p: (len(p.name), p.name)):
        wm_path = seed_dir / "worldmap.npy"
        if not wm_path.exists():
            continue
        wm = np.load(wm_path)
        if wm.ndim != 3 or wm.shape[2] != 3:
            log.warning("%s: not an RGB worldmap; skipped", wm_path)
            continue
        t = _mission_truth(seed_dir)
        t = fallback_truth if t is None else t
        if t is None or t.shape != wm.shape[:2]:
            log.warning("%s: no ground truth of the map's size; skipped", seed_dir)
            continue
        if truth is not None and not np.array_equal(t, truth):
            raise MapErrorsError(f"{folder}: missions on different worlds; give each world's folder on its own")
        try:
            meta = json.loads((seed_dir / "mission.json").read_text())
        except (OSError, ValueError):
            meta = {}
        truth, world = t, world or meta.get("world", "unknown")
        maps.append(wm)
        seeds.append(meta.get("seed", seed_dir.name))
    if not maps:
        raise MapErrorsError(f"{folder}: no mission with a worldmap and a ground truth")
    false_nav, m_obs, m_unseen, rows = count_errors(maps, truth)
    for row, seed in zip(rows, seeds):
        row["seed"] = seed
    return ConditionErrors(name, world, len(maps), truth, false_nav, m_obs, m_unseen, rows)


def summary(ce: ConditionErrors, share: float, cell_features=None) -> dict:
    """The condition's figures: errors per mission, systematic cells by kind and terrain, the remaining-error scores."""
    missed = ce.missed
    sys_false, sys_missed = systematic(ce.false_nav, ce.missions, share), systematic(missed, ce.missions, share)
    med = lambda key: float(np.median([r[key] for r in ce.per_mission]))  # noqa: E731
    out = {
        "condition": ce.condition, "world": ce.world, "missions": ce.missions, "truth_cells": int(ce.truth.sum()),
        "median_false": med("false"), "median_missed_obstacle": med("missed_obstacle"),
        "median_missed_unseen": med("missed_unseen"),
        "systematic_share": share,
        "systematic_false": int(sys_false.sum()), "systematic_missed": int(sys_missed.sum()),
        "systematic_missed_unseen": int((sys_missed & systematic(ce.missed_unseen, ce.missions, share)).sum()),
        "false_share_systematic": float(ce.false_nav[sys_false].sum() / max(1, ce.false_nav.sum())),
        "missed_share_systematic": float(missed[sys_missed].sum() / max(1, missed.sum())),
    }
    out["remaining_mapped_pct"], out["remaining_fidelity_pct"] = remaining_scores(ce.truth, sys_false, sys_missed)
    if cell_features is not None:
        floor_centre, sand_centre, light_sand = cell_features
        out["systematic_false_terrain"] = terrain_classes(sys_false, floor_centre, sand_centre, light_sand)
        out["systematic_missed_terrain"] = terrain_classes(sys_missed, floor_centre, sand_centre, light_sand)
    for key, counts, mask in (("false_cells", ce.false_nav, sys_false), ("missed_cells", missed, sys_missed)):
        ys, xs = np.nonzero(mask)
        order = np.argsort(-counts[ys, xs], kind="stable")  # most often wrong first
        out[key] = [[int(xs[i]), int(ys[i]), int(counts[ys[i], xs[i]])] for i in order]
    return out


def error_image(ce: ConditionErrors, share: float) -> np.ndarray:
    """BGR picture, north up: truth grey, false navigable red, missed truth blue (brighter = more missions)."""
    n = max(1, ce.missions)
    img = np.zeros(ce.truth.shape + (3,), np.uint8)
    img[ce.truth] = TRUTH_GREY
    missed = ce.missed
    for counts, channel in ((ce.false_nav, 2), (missed, 0)):
        wrong = counts > 0
        level = (90 + 165 * counts / n).clip(0, 255).astype(np.uint8)
        img[wrong] = 0
        img[..., channel][wrong] = level[wrong]
    big = cv2.resize(img, None, fx=IMAGE_SCALE, fy=IMAGE_SCALE, interpolation=cv2.INTER_NEAREST)
    half = IMAGE_SCALE // 2
    for counts in (ce.false_nav, missed):
        for y, x in zip(*np.nonzero(systematic(counts, ce.missions, share))):
            cx, cy = int(x) * IMAGE_SCALE + half, int(y) * IMAGE_SCALE + half
            big[cy - 1:cy + 1, cx - 1:cx + 1] = 255
    ys, xs = np.nonzero(ce.truth | (ce.false_nav > 0))
    if ys.size:  # crop to the canyon, with a margin for the caption
        y0, y1 = max(0, ys.min() - CROP_MARGIN_CELLS), min(img.shape[0], ys.max() + 1 + CROP_MARGIN_CELLS)
        x0, x1 = max(0, xs.min() - CROP_MARGIN_CELLS), min(img.shape[1], xs.max() + 1 + CROP_MARGIN_CELLS)
        big = big[y0 * IMAGE_SCALE:y1 * IMAGE_SCALE, x0 * IMAGE_SCALE:x1 * IMAGE_SCALE]
    big = np.ascontiguousarray(big[::-1])  # row 0 is y = 0 (south): flip so north is up
    cv2.putText(big, f"{ce.condition}: {ce.missions} missions; red false floor, blue missed floor, white dot: "
                f"wrong in >= {share:.0%}", (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return big


def markdown(summaries: List[dict]) -> str:
    lines = ["| condition | missions | false / missed (obstacle + unseen) per mission, median | systematic false / missed "
             "| share of all errors that is systematic (false / missed) | mapped / fidelity with only those left |",
             "|---|---|---|---|---|---|"]
    for s in summaries:
        lines.append(f"| {s['condition']} | {s['missions']} | {s['median_false']:g} / {s['median_missed_obstacle']:g} + "
                     f"{s['median_missed_unseen']:g} | {s['systematic_false']} / {s['systematic_missed']} | "
                     f"{s['false_share_systematic']:.0%} / {s['missed_share_systematic']:.0%} | "
                     f"{s['remaining_mapped_pct']:.2f} / {s['remaining_fidelity_pct']:.2f} % |")
    for s in summaries:
        if "systematic_missed_terrain" in s:
            lines.append("")
            lines.append(f"{s['condition']}, systematic cells by the terrain at their centre: missed "
                         + ", ".join(f"{k} {v}" for k, v in s["systematic_missed_terrain"].items()) + "; false "
                         + ", ".join(f"{k} {v}" for k, v in s["systematic_false_terrain"].items()) + ".")
    return "\n".join(lines)


def _real_cell_features():
    """(floor centre, sand centre, light-sand weight) of the real world, or None where it is absent."""
    from sim.world import load_real_world, real_world_available

    if not real_world_available():
        return None
    from sim.ceiling import BRIGHT_SAND_WEIGHT, cell_features

    floor_centre, sand_centre, _ = cell_features(load_real_world())
    return floor_centre, sand_centre, BRIGHT_SAND_WEIGHT


def _fallback_truth():
    import shared_data
    from evaluation.metrics import load_ground_truth

    path = shared_data.ground_truth_map_path()
    return load_ground_truth(path) > 0 if path.exists() else None


def main(argv=None) -> int:
    from sim.cli import parse_with_logging

    p = argparse.ArgumentParser(prog="python -m evaluation.map_errors", description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", type=Path, help="folders written by python -m sim.evaluate")
    p.add_argument("--min-share", type=float, default=SYSTEMATIC_SHARE,
                   help=f"a cell wrong in at least this share of the missions is systematic (default {SYSTEMATIC_SHARE})")
    p.add_argument("--out", type=Path, default=Path("out/map-errors"), help="folder for the PNGs and map-errors.json")
    a = parse_with_logging(p, argv)
    if not 0.0 < a.min_share <= 1.0:
        log.error("--min-share must lie in (0, 1], got %s", a.min_share)
        return 2
    from replay.outputs import write_json, write_png

    try:
        fallback = _fallback_truth()
        conditions = []
        for run in a.runs:
            for name, folder in find_conditions(run).items():
                label = name if len(a.runs) == 1 or name == run.name else f"{run.name}/{name}"
                conditions.append(load_condition(label, folder, fallback))
    except MapErrorsError as exc:
        log.error("%s", exc)
        return 2
    features = _real_cell_features() if any(c.world == "real" for c in conditions) else None
    summaries = [summary(c, a.min_share, features if c.world == "real" else None) for c in conditions]
    a.out.mkdir(parents=True, exist_ok=True)
    for c in conditions:
        write_png(a.out / f"map-errors-{c.condition.replace('/', '-')}.png", error_image(c, a.min_share))
    write_json(a.out / "map-errors.json", {"conditions": summaries})
    sys.stdout.write(markdown(summaries) + "\n")
    log.info("wrote %s", a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
