"""Where do a map's wrong cells come from?  ``python -m replay.vote_sources LOG [--timeline T] [--out DIR]``.

Replays a log through the client's perception (as ``python -m replay`` does) and keeps every
map vote, grouped by frame, world cell and range band.  The scored map is then rebuilt from those
votes with one class of votes left out at a time (a range band, standing still, turning fast,
close to a wall, a mission mode), so each class's effect on mapped / fidelity is measured, not
guessed.  Per class it also gives the light-sand share of the votes landing on the false
navigable cells and on the correctly mapped edge cells: a class worth gating is one whose
votes call the false cells floor much more often than the true edge cells.  Last, the
near-confirmation check (a cell whose views from within 5 m see mostly no sand is not floor,
whatever the far views say) against the curve the scored light share alone draws, and the wrong
cells by the rule that decided them and by how much cast shadow their votes saw.

Written for issue 27 (why twin missions mapped at ~95 % fidelity); findings in docs/perception.md.
Outputs in --out: ``errors.png`` (north up; grey mapped floor, red false navigable, blue missed
floor, green the rover path) and ``vote_sources.json``.
"""
from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Optional

import cv2
import numpy as np

import perception

log = logging.getLogger(__name__)

RANGE_BANDS_M = (0.0, *perception.SCORED_BAND_EDGES_M, perception.MAP_RANGE_M + 0.01)  # vote range bands (the scored map's), m
SPEED_BANDS_M_S = (0.0, 0.2, 1.0, np.inf)  # |speed| bands, m/s (below 0.2: standing, turning in place, picking up)
YAW_RATE_BANDS_DEG_S = (0.0, 5.0, 30.0, np.inf)  # |yaw rate| bands, deg/s
WALL_BANDS_M = (0.0, 1.5, 3.0, np.inf)  # rover's distance to the nearest non-floor cell of the truth, m
ERROR_SCALE = 4  # errors.png pixels per map cell
PATH_EVERY = 10  # errors.png draws every Nth rover position
# The near-confirmation check (issue 27, fourth round; not in perception: see docs/perception.md).  Sand h above
# the floor seen from d metres projects d*h/(H-h) too far, so a sunlit wall foot seen from afar lands a cell
# outwards; the check turns down a cell whose near views see mostly no sand, whatever the far ones say.
NEAR_CONFIRM_RANGE_M = 5.0  # votes from ground nearer than this to the rover are near views, m
NEAR_CONFIRM_MIN_VOTES = 2.0  # weighted near votes a cell needs before the check applies to it
# The curve and the checks vary what decides the scored map: since round 8 the cell model's probability
# threshold (SCORED_CELL_MIN_P: 0.375 in round 8, 0.4 since round 9); rounds 4-7 varied the band-mean share
# (SCORED_BAND_SHARE), which now only decides which neighbours count as floor.
NEAR_CHECKS = ((0.3, 0.5), (0.375, 0.4), (0.375, 0.5), (0.45, 0.5))  # (cell model probability, near sand share) reported
CURVE_SHARES = tuple(np.round(np.arange(0.2, 0.651, 0.025), 3))  # cell model probabilities of the reference curve
# Wrong cells by the rule that decided them and by how much cast shadow their votes saw (issue 27, round 6)
SHADE_SEEN_SHARES = (0.05, 0.2)  # a wrong cell counts as in shadow when shadowed-sand votes make more than this share


@dataclass
class VoteLog:
    """Every map vote of a replay, summed per (frame, cell, range band).

    frame: int32 (N,) index into ``features``; cell: int32 (N,) = y * 200 + x; band: int8 (N,) range band;
    votes: float32 (N, 7) light sand, everything else (as obs_votes), sand in shadow, darker sand in shadow,
        and of all these the part from ground within NEAR_CONFIRM_RANGE_M: all, and light plus shadowed sand;
        last, near-hue sand (perception.NEAR_SAND_MIN_*).
    features: float64 (frames, 7) t s, x m, y m, yaw deg, pitch deg, roll deg, speed m/s.
    """
    frame: np.ndarray
    cell: np.ndarray
    band: np.ndarray
    votes: np.ndarray
    features: np.ndarray
    worldmap: np.ndarray  # the replay's final scored map, to check a rebuild against

    def yaw_rate(self) -> np.ndarray:
        """|yaw rate| per frame, deg/s."""
        t, yaw = self.features[:, 0], np.unwrap(np.radians(self.features[:, 3]))
        if len(t) < 2:
            return np.zeros(len(t))
        return np.abs(np.degrees(np.gradient(yaw)) / np.maximum(np.gradient(t), 1e-3))


def _frame_votes(mem, x: float, y: float, yaw: float):
    """The cells, range bands, weights, labels and near flags ``perception._vote`` used for the last frame."""
    labels = mem.last_grid.ravel()[perception._MAP_CELLS]
    hidden = mem.last_occluded.ravel()[perception._MAP_CELLS] != 0
    idx = np.flatnonzero(labels != perception._LABEL_UNKNOWN)
    xw, yw = perception.rover_to_world(perception._MAP_X[idx], perception._MAP_Y[idx], x, y, yaw)
    ix, iy = np.floor(xw).astype(np.int64), np.floor(yw).astype(np.int64)
    n = perception.WORLD_SIZE
    ok = (ix >= 0) & (ix < n) & (iy >= 0) & (iy < n)
    idx = idx[ok]
    band = np.clip(np.digitize(perception._MAP_DIST[idx], RANGE_BANDS_M) - 1, 0, len(RANGE_BANDS_M) - 2)
    near = perception._MAP_DIST[idx] < NEAR_CONFIRM_RANGE_M
    weight = perception._MAP_WEIGHT[idx]
    weight = np.where(hidden[idx], weight * perception.OCCLUDED_VOTE_WEIGHT, weight)
    return iy[ok] * n + ix[ok], band, weight, labels[idx], near


def collect(log_path, ground_truth=None, progress: bool = False) -> VoteLog:
    """Replay ``log_path`` and keep its votes (perception is not changed, only observed)."""
    from replay.log_format import read_log
    from replay.runner import frame_time, replay

    nb = len(RANGE_BANDS_M) - 1
    parts, feats = [], []

    def on_frame(rover, frame):
        t = frame_time(frame)
        feats.append((len(feats) * 0.04 if t is None else t, frame.x, frame.y, rover.yaw,
                      float(rover.pitch), float(rover.roll), frame.speed))
        if not rover.map_updated:
            return
        cell, band, w, lab, near = _frame_votes(perception.get_memory(rover), float(rover.pos[0]), float(rover.pos[1]),
                                                float(rover.yaw))
        uk, inv = np.unique(cell * nb + band, return_inverse=True)
        sand = (lab == perception._LABEL_NAV) | (lab == perception._LABEL_SHADE) | (lab == perception._LABEL_DIM_SHADE)
        cols = [lab == perception._LABEL_NAV, lab != perception._LABEL_NAV,
                lab == perception._LABEL_SHADE, lab == perception._LABEL_DIM_SHADE, near, near & sand,
                lab == perception._LABEL_NEAR_SAND]
        votes = np.stack([np.bincount(inv, w * c, len(uk)) for c in cols], 1).astype(np.float32)
        parts.append((np.full(len(uk), len(feats) - 1, np.int32), uk, votes))

    _, rover, _ = replay(read_log(log_path), ground_truth, on_frame=on_frame, progress=progress)
    if not parts:
        raise ValueError(f"no frame of {log_path} voted on the map")
    key = np.concatenate([p[1] for p in parts])
    feats = np.array(feats, np.float64)
    feats[:, 0] -= feats[0, 0]
    return VoteLog(np.concatenate([p[0] for p in parts]), (key // nb).astype(np.int32), (key % nb).astype(np.int8),
                   np.concatenate([p[2] for p in parts]), feats, np.array(rover.worldmap, copy=True))


def _memory(votes: VoteLog, keep: Optional[np.ndarray] = None):
    """(perception memory, near votes, near sand votes) of the kept votes."""
    mem = perception.PerceptionMemory()
    n = perception.WORLD_SIZE
    w = np.ones(len(votes.cell)) if keep is None else keep.astype(np.float64)
    sums = [np.bincount(votes.cell, votes.votes[:, col] * w, n * n).reshape(n, n).astype(np.float32)
            for col in range(votes.votes.shape[1])]
    for arr, col in ((mem.nav_votes, 0), (mem.obs_votes, 1), (mem.shade_votes, 2), (mem.dim_shade_votes, 3),
                     (mem.near_sand_votes, 6)):
        arr += sums[col]
    for b in range(perception.SCORED_BANDS):  # the scored map's per-band light shares
        in_band = (votes.band == b) * w
        mem.band_nav_votes[b] += np.bincount(votes.cell, votes.votes[:, 0] * in_band, n * n).reshape(n, n).astype(
            np.float32)
        mem.band_votes[b] += np.bincount(votes.cell, (votes.votes[:, 0] + votes.votes[:, 1]) * in_band,
                                         n * n).reshape(n, n).astype(np.float32)
    return mem, sums[4], sums[5]


def _render(mem, min_p: Optional[float] = None) -> np.ndarray:
    """perception.render_worldmap, with the cell model's threshold (SCORED_CELL_MIN_P) set to ``min_p`` for this
    call only."""
    if min_p is None:
        return perception.render_worldmap(mem)
    saved = perception.SCORED_CELL_MIN_P
    perception.SCORED_CELL_MIN_P = min_p
    try:
        return perception.render_worldmap(mem)
    finally:
        perception.SCORED_CELL_MIN_P = saved


def near_veto(worldmap: np.ndarray, near: np.ndarray, near_sand: np.ndarray, min_sand_share: float) -> np.ndarray:
    """The map with the near-confirmation check applied: a navigable cell with at least NEAR_CONFIRM_MIN_VOTES
    near votes of which less than ``min_sand_share`` are sand becomes obstacle."""
    out = worldmap.copy()
    veto = (out[:, :, 2] > 0) & (near >= NEAR_CONFIRM_MIN_VOTES) & (near_sand < min_sand_share * near)
    out[:, :, 2][veto] = 0
    out[:, :, 0][veto] = 255
    return out


def rebuild(votes: VoteLog, keep: Optional[np.ndarray] = None) -> np.ndarray:
    """The scored worldmap the kept votes (bool per vote row; None = all) give, by perception's own rules."""
    return _render(_memory(votes, keep)[0])


def near_confirmation(votes: VoteLog, truth: np.ndarray) -> Dict:
    """The threshold curve (``share_curve``: the cell model's probability threshold, mapped, fidelity), and each
    NEAR_CHECKS pair's mapped / fidelity and its fidelity gain over the curve at equal mapped (the curve
    interpolated at the check's mapped figure)."""
    from evaluation.metrics import score_map

    mem, near, near_sand = _memory(votes)
    curve = []
    for share in CURVE_SHARES:
        s = score_map(_render(mem, share), truth)
        curve.append((float(share), round(s.mapped_pct, 2), round(s.fidelity_pct, 2)))
    pts = np.array([c[1:] for c in curve])
    order = np.argsort(pts[:, 0])
    checks = []
    for share, min_sand in NEAR_CHECKS:
        s = score_map(near_veto(_render(mem, share), near, near_sand, min_sand), truth)
        gain = s.fidelity_pct - float(np.interp(s.mapped_pct, pts[order, 0], pts[order, 1]))
        checks.append({"share": share, "near_sand_share": min_sand, "mapped_pct": round(s.mapped_pct, 2),
                       "fidelity_pct": round(s.fidelity_pct, 2), "gain_at_equal_mapped": round(gain, 2)})
    return {"share_curve": curve, "checks": checks}


def wrong_cells_by_rule(mem, truth: np.ndarray) -> Dict:
    """Why each wrong cell of the scored map is wrong, by perception's own rules.

    False navigable cells by the vote-share rule that calls them floor too (``light``: the light-sand share,
    ``shade``: only the light-plus-shadowed-sand majority, ``model``: neither, only the cell model, from sand
    short of those rules and floor around it); missed floor cells by whether any
    vote saw them.  For both, how many have more than each SHADE_SEEN_SHARES share of shadowed-sand votes:
    wrong cells in cast shadow are a shadow problem, the others a lighting/edge one.
    """
    n = perception.WORLD_SIZE
    floor = truth > 0
    seen, majority = perception._majority_navigable(mem, 0, n, 0, n, scored=True)
    share, spoken = perception.band_light_share(mem)
    total = mem.nav_votes + mem.obs_votes
    light = seen & np.where(spoken, share > perception.SCORED_BAND_SHARE,
                            mem.nav_votes > perception.SCORED_NAV_MAJORITY * total)
    marked = perception.render_worldmap(mem)[:, :, 2] > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        shaded = np.where(total > 0, (mem.shade_votes + mem.dim_shade_votes) / total, 0.0)

    def in_shadow(sel):
        return {f"shadow_share_over_{t:g}": int(np.count_nonzero(sel & (shaded > t))) for t in SHADE_SEEN_SHARES}

    false, missed = marked & ~floor, floor & ~marked
    return {"false": {"cells": int(false.sum()), "light": int(np.count_nonzero(false & light)),
                      "shade": int(np.count_nonzero(false & majority & ~light)),
                      "model": int(np.count_nonzero(false & ~majority)), **in_shadow(false)},
            "missed": {"cells": int(missed.sum()), "seen": int(np.count_nonzero(missed & seen)), **in_shadow(missed & seen)}}


def _bands(values, edges, unit):
    codes = np.clip(np.digitize(values, edges) - 1, 0, len(edges) - 2)
    names = [f"{a:g}-{b:g} {unit}" if np.isfinite(b) else f">= {a:g} {unit}" for a, b in zip(edges, edges[1:])]
    return codes, names


def mode_per_frame(features: np.ndarray, timeline_path) -> np.ndarray:
    """The mission mode at each frame's time, from a mission's timeline.npz (1 s rows)."""
    tl = np.load(timeline_path)
    t, modes = tl["table"][:, 0], tl["modes"]
    return modes[np.clip(np.searchsorted(t, features[:, 0], side="right") - 1, 0, len(t) - 1)]


def attribute(votes: VoteLog, truth: np.ndarray, modes: Optional[np.ndarray] = None) -> Dict:
    """Per vote class: share of votes, light share on false / true-edge cells, score without it."""
    from evaluation.metrics import score_map

    floor = truth > 0
    base = rebuild(votes)
    marked = base[:, :, 2] > 0
    false_cells = (marked & ~floor).ravel()[votes.cell]
    wall_near = cv2.dilate((~floor).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    edge_cells = (marked & floor & wall_near).ravel()[votes.cell]
    total = votes.votes[:, 0] + votes.votes[:, 1]
    wall_dist = cv2.distanceTransform(floor.astype(np.uint8), cv2.DIST_L2, 5)
    fx = np.clip(votes.features[:, 1].astype(int), 0, floor.shape[1] - 1)
    fy = np.clip(votes.features[:, 2].astype(int), 0, floor.shape[0] - 1)
    factors = {"range": (votes.band, [f"{a:g}-{b:.3g} m" for a, b in zip(RANGE_BANDS_M, RANGE_BANDS_M[1:])])}
    for name, values, edges, unit in (("speed", np.abs(votes.features[:, 6]), SPEED_BANDS_M_S, "m/s"),
                                      ("yaw rate", votes.yaw_rate(), YAW_RATE_BANDS_DEG_S, "deg/s"),
                                      ("wall distance", wall_dist[fy, fx], WALL_BANDS_M, "m")):
        codes, names = _bands(values, edges, unit)
        factors[name] = (codes[votes.frame], names)
    if modes is not None:
        names, codes = np.unique(modes, return_inverse=True)
        factors["mode"] = (codes[votes.frame], [str(n) for n in names])

    def light_share(sel):
        t = total[sel].sum()
        return round(float(votes.votes[sel, 0].sum() / t), 3) if t > 0 else None

    s0 = score_map(base, truth)
    out = {"all": {"mapped_pct": round(s0.mapped_pct, 2), "fidelity_pct": round(s0.fidelity_pct, 2),
                   "false_cells": int((marked & ~floor).sum()), "missed_cells": int((~marked & floor).sum()),
                   "light_share_false": light_share(false_cells), "light_share_edge": light_share(edge_cells)},
           "factors": {}}
    for factor, (codes, names) in factors.items():
        rows = []
        for k, name in enumerate(names):
            sel = codes == k
            if not sel.any():
                continue
            s = score_map(rebuild(votes, ~sel), truth)
            rows.append({"band": name, "votes_pct": round(float(100.0 * total[sel].sum() / total.sum()), 1),
                         "light_share_false": light_share(sel & false_cells),
                         "light_share_edge": light_share(sel & edge_cells),
                         "without_mapped_pct": round(s.mapped_pct, 2), "without_fidelity_pct": round(s.fidelity_pct, 2)})
        out["factors"][factor] = rows
    out["near_confirmation"] = near_confirmation(votes, truth)
    out["wrong_cells"] = wrong_cells_by_rule(_memory(votes)[0], truth)
    return out


def error_image(worldmap: np.ndarray, truth: np.ndarray, features: Optional[np.ndarray] = None) -> np.ndarray:
    """BGR, north up: grey mapped floor, red false navigable, blue missed floor, green the rover path."""
    floor, marked = truth > 0, worldmap[:, :, 2] > 0
    img = np.zeros(worldmap.shape, np.uint8)
    img[floor & marked] = (110, 110, 110)
    img[~floor & marked] = (0, 0, 255)
    img[floor & ~marked] = (255, 80, 0)
    if features is not None and len(features):
        px = np.clip(features[::PATH_EVERY, 1].astype(int), 0, img.shape[1] - 1)
        py = np.clip(features[::PATH_EVERY, 2].astype(int), 0, img.shape[0] - 1)
        img[py, px] = (0, 200, 0)
    return cv2.resize(np.flipud(img), None, fx=ERROR_SCALE, fy=ERROR_SCALE, interpolation=cv2.INTER_NEAREST)


def main(argv=None) -> int:
    from evaluation.metrics import load_ground_truth
    from replay.outputs import write_json, write_png
    import shared_data

    p = argparse.ArgumentParser(prog="python -m replay.vote_sources", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", help="robot_log.csv or its folder (a real drive, or a mission's --record)")
    p.add_argument("--timeline", help="the mission's timeline.npz, to split the votes by mission mode")
    p.add_argument("--out", default="out/vote-sources", help="folder for errors.png and vote_sources.json")
    p.add_argument("--ground-truth", help="ground-truth map (default: the shared map_bw.png)")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    gt = Path(a.ground_truth) if a.ground_truth else shared_data.ground_truth_map_path()
    try:
        truth = load_ground_truth(gt)
        votes = collect(a.log, truth, progress=True)
        modes = mode_per_frame(votes.features, a.timeline) if a.timeline else None
    except (OSError, ValueError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    report = attribute(votes, truth, modes)
    out = Path(a.out)
    write_png(out / "errors.png", error_image(votes.worldmap, truth, votes.features))
    write_json(out / "vote_sources.json", report)
    r = report["all"]
    print(f"{a.log}: mapped {r['mapped_pct']:.2f} %, fidelity {r['fidelity_pct']:.2f} %, {r['false_cells']} false "
          f"navigable cells (light share {r['light_share_false']}), true edge cells' light share {r['light_share_edge']}")
    print(f"{'factor':14} {'band':16} {'votes %':>8} {'share false':>12} {'share edge':>11} {'without it: mapped / fidelity %':>32}")
    for factor, rows in report["factors"].items():
        for row in rows:
            print(f"{factor:14} {row['band']:16} {row['votes_pct']:8.1f} {str(row['light_share_false']):>12} "
                  f"{str(row['light_share_edge']):>11} {row['without_mapped_pct']:>21.2f} / {row['without_fidelity_pct']:.2f}")
    nc = report["near_confirmation"]
    print("threshold curve (cell model probability: mapped / fidelity %): "
          + ", ".join(f"{s:g}: {m:.2f} / {f:.2f}" for s, m, f in nc["share_curve"]))
    print(f"near confirmation (within {NEAR_CONFIRM_RANGE_M:g} m): share, near sand share -> mapped / fidelity %, "
          "fidelity gain over the share curve at equal mapped")
    for c in nc["checks"]:
        print(f"  {c['share']:.3g}, {c['near_sand_share']:.3g} -> {c['mapped_pct']:.2f} / {c['fidelity_pct']:.2f}, "
              f"{c['gain_at_equal_mapped']:+.2f}")
    w = report["wrong_cells"]
    f, m = w["false"], w["missed"]
    lo, hi = (f"shadow_share_over_{t:g}" for t in SHADE_SEEN_SHARES)
    print(f"false cells {f['cells']}: light share {f['light']}, shadowed-sand majority {f['shade']}, cell model only {f['model']}; "
          f"in shadow (shadowed-sand votes > {SHADE_SEEN_SHARES[0]:g} / > {SHADE_SEEN_SHARES[1]:g}) {f[lo]} / {f[hi]}")
    print(f"missed floor cells {m['cells']}: seen {m['seen']}, of them in shadow {m[lo]} / {m[hi]}")
    print(f"errors.png and vote_sources.json in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
