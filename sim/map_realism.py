"""Does a map built from twin frames score like one built from the real frames?

A simulator log is replayed through the client's perception twice: once with its own camera
frames, once with twin frames rendered at the same logged poses.  The two worldmaps are
scored against map_bw.png, and compared with each other (map IoU: cells the two maps mark
navigable).  Each figure is given over all frames and over the frames where the rover moves
(keys with `moving` in metrics.json), per shadows setting; `places.png` shows the worst
places side by side (real map | twin map | disagreement) and metrics.json lists them.

    python -m sim.map_realism [--log megalphian|test_dataset|PATH] [--stride 2]
                              [--shadows auto|off|on|both] [--tracks on|off] [--out out/map-realism]

Tyre tracks are drawn into the twin frames along the replayed trajectory, as in the real frames.
"""
from __future__ import annotations

import argparse
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

import perception
import shared_data
from evaluation.metrics import load_ground_truth, score_map
from replay.log_format import read_log
from replay.runner import FALLBACK_FRAME_PERIOD_S, apply_frame, decode_frame, signed_angle
from rover_state import RoverState
from sim.cli import parse_with_logging
from sim.render import Renderer
from sim.logs import find_log  # noqa: F401  (the rule for NAME|PATH, re-exported)
from sim.realism import MOVING_MIN_SPEED, jpeg_roundtrip

log = logging.getLogger(__name__)

DEFAULT_LOG = "megalphian"  # folder under ../shared/real-logs (or a path to a log folder)
DEFAULT_STRIDE = 2  # every N-th frame is used (both replays see the same frames)
PLACE_CELLS = 10  # side of a "place" when ranking disagreement, map cells (m)
WORST_PLACES = 5  # places listed in metrics.json and framed in places.png
PLACES_SCALE = 3  # places.png pixels per map cell


@dataclass
class MapRealism:
    frames: int
    real_mapped_pct: float
    real_fidelity_pct: float
    twin_mapped_pct: float
    twin_fidelity_pct: float
    shadows: str
    map_iou: float = float("nan")  # navigable cells of the twin-frame map vs the real-frame map
    moving_frames: int = 0
    real_moving_mapped_pct: float = float("nan")
    real_moving_fidelity_pct: float = float("nan")
    twin_moving_mapped_pct: float = float("nan")
    twin_moving_fidelity_pct: float = float("nan")
    map_iou_moving: float = float("nan")

    @property
    def mapped_gap(self) -> float:
        """Twin minus real mapped %, points (negative: the twin is harder than the recording)."""
        return self.twin_mapped_pct - self.real_mapped_pct


def map_iou(a, b) -> float:
    """IoU of the cells two worldmaps mark navigable (1 when both are empty)."""
    na, nb = a[:, :, 2] > 0, b[:, :, 2] > 0
    union = int(np.count_nonzero(na | nb))
    return 1.0 if union == 0 else int(np.count_nonzero(na & nb)) / union


def compare(log_path, world, stride: int = DEFAULT_STRIDE, progress: bool = False, truth=None, maps=None,
            moving: bool = True, tracks: bool = True):
    """Replay real and twin frames of one log; returns (MapRealism, real worldmap, twin worldmap).

    truth: map_bw as load_ground_truth gives it (read from ../shared when None).
    maps: a dict to receive the moving-frames worldmaps too ("real_moving", "twin_moving").
    moving: also replay the moving frames alone (costs a second perception pass on them).
    tracks: draw the tyre tracks laid along the whole logged drive into the twin frames (the real ones show them).
    """
    data = read_log(log_path)
    if truth is None:
        truth = load_ground_truth(shared_data.ground_truth_map_path())
    renderer = Renderer(world)
    rovers = {k: RoverState() for k in ("real", "twin", "real_moving", "twin_moving")}
    rows = range(0, len(data.frames), max(1, int(stride)))
    frames = [data.frames[i] for i in rows]
    laid = {}
    if tracks:
        from replay.runner import frame_time
        from sim.tracks import replay_quads

        laid = dict(replay_quads([(f.x, f.y, f.yaw) for f in data.frames], [frame_time(f) for f in data.frames],
                                 world, rows))
    it = frames
    if progress:
        from tqdm import tqdm

        it = tqdm(frames, desc="map realism", unit="frame")
    used = moving_used = 0
    for i, frame in enumerate(it):
        real = decode_frame(frame.image_path)
        if real is None:
            continue
        pose = (frame.x, frame.y, frame.yaw, signed_angle(frame.pitch), signed_angle(frame.roll))
        twin = jpeg_roundtrip(renderer.render(pose, tracks=laid.get(rows[i])))
        now = i * FALLBACK_FRAME_PERIOD_S
        is_moving = moving and abs(frame.speed) >= MOVING_MIN_SPEED
        for key, rgb in (("real", real), ("twin", twin)):
            for name in (key, f"{key}_moving") if is_moving else (key,):
                apply_frame(rovers[name], frame, rgb, now)
                perception.perception_step(rovers[name])
        used += 1
        moving_used += is_moving
    if used == 0:
        raise ValueError(f"no readable frames in {log_path}")
    score = {k: score_map(r.worldmap, truth) for k, r in rovers.items()}
    result = MapRealism(
        used, score["real"].mapped_pct, score["real"].fidelity_pct, score["twin"].mapped_pct,
        score["twin"].fidelity_pct, "on" if world.cast_shadows else "off",
        map_iou=map_iou(rovers["real"].worldmap, rovers["twin"].worldmap), moving_frames=moving_used,
        real_moving_mapped_pct=score["real_moving"].mapped_pct,
        real_moving_fidelity_pct=score["real_moving"].fidelity_pct,
        twin_moving_mapped_pct=score["twin_moving"].mapped_pct,
        twin_moving_fidelity_pct=score["twin_moving"].fidelity_pct,
        map_iou_moving=map_iou(rovers["real_moving"].worldmap, rovers["twin_moving"].worldmap))
    if maps is not None:
        maps["real_moving"] = rovers["real_moving"].worldmap
        maps["twin_moving"] = rovers["twin_moving"].worldmap
    return result, rovers["real"].worldmap, rovers["twin"].worldmap


def worst_places(real_map, twin_map, count: int = WORST_PLACES) -> list:
    """PLACE_CELLS squares where the two maps disagree most: dicts with x, y (centre, m) and cells."""
    diff = ((real_map[:, :, 2] > 0) != (twin_map[:, :, 2] > 0)).astype(np.int32)
    n = diff.shape[0] // PLACE_CELLS
    blocks = diff[: n * PLACE_CELLS, : n * PLACE_CELLS].reshape(n, PLACE_CELLS, n, PLACE_CELLS).sum(axis=(1, 3))
    out = []
    for flat in np.argsort(blocks, axis=None)[::-1][:count]:
        r, c = divmod(int(flat), n)
        if blocks[r, c] == 0:
            break
        out.append({"x": (c + 0.5) * PLACE_CELLS, "y": (r + 0.5) * PLACE_CELLS, "disagreeing_cells": int(blocks[r, c])})
    return out


def places_image(real_map, twin_map, truth, places, title: str) -> np.ndarray:
    """BGR: real map | twin map | disagreement (orange real only, cyan twin only), north up, worst places framed."""
    from replay.outputs import map_image

    real_nav, twin_nav = real_map[:, :, 2] > 0, twin_map[:, :, 2] > 0
    diff = np.zeros(real_map.shape, np.uint8)
    diff[(truth > 0)] = (60, 60, 60)
    diff[real_nav & twin_nav] = (200, 200, 200)
    diff[real_nav & ~twin_nav] = (0, 140, 255)
    diff[~real_nav & twin_nav] = (255, 255, 0)
    diff = np.flipud(diff)
    panels = []
    for img in (map_image(real_map, truth), map_image(twin_map, truth), diff):
        img = img[: img.shape[1]]  # the square map, without map_image's legend
        img = cv2.resize(np.ascontiguousarray(img), (diff.shape[1] * PLACES_SCALE, diff.shape[0] * PLACES_SCALE),
                         interpolation=cv2.INTER_NEAREST)
        for p in places:
            x0 = int((p["x"] - PLACE_CELLS / 2) * PLACES_SCALE)
            y0 = int((diff.shape[0] - p["y"] - PLACE_CELLS / 2) * PLACES_SCALE)
            cv2.rectangle(img, (x0, y0), (x0 + PLACE_CELLS * PLACES_SCALE, y0 + PLACE_CELLS * PLACES_SCALE),
                          (0, 0, 255), 1)
        panels.append(img)
    out = np.hstack(panels)
    bar = np.zeros((20, out.shape[1], 3), np.uint8)
    cv2.putText(bar, title, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return np.vstack([bar, out])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim.map_realism", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--log", default=DEFAULT_LOG, help="test_dataset, a real-logs folder name, a log folder or csv")
    p.add_argument("--stride", type=int, default=DEFAULT_STRIDE, help="use every N-th frame")
    p.add_argument("--out", default="out/map-realism", help="folder for metrics.json and the map images")
    p.add_argument("--shadows", choices=("auto", "off", "on", "both"), default="auto",
                   help="twin cast shadows: auto (default: as the log's frames show), off (megalphian), "
                        "on (test_dataset, dimaga, royalejandro) or both")
    p.add_argument("--tracks", choices=("on", "off"), default="on",
                   help="draw tyre tracks along the replayed drive (on, as the real frames show them)")
    a = parse_with_logging(p, argv)
    if a.stride < 1:
        p.error("--stride must be at least 1")
    from sim.world import load_real_world, real_world_available, with_shadows

    if not real_world_available() or not shared_data.ground_truth_map_path().exists():
        log.error("the real world and map_bw.png are needed (set %s)", shared_data.SHARED_ENV_VAR)
        return 2
    from replay.outputs import map_image, write_json, write_png

    out = Path(a.out)
    payload = {"stride": a.stride, "tracks": a.tracks, "moving_min_speed_m_s": MOVING_MIN_SPEED}
    try:
        log_path = find_log(a.log)
        payload["log"] = str(log_path)
        world = load_real_world()
        from sim.realism import shadow_settings

        settings = shadow_settings(a.shadows, log_path, world)
        truth = load_ground_truth(shared_data.ground_truth_map_path())
        results = {}
        for setting in settings:
            maps = {}
            result, real_map, twin_map = compare(log_path, with_shadows(world, setting == "on"), a.stride,
                                                 progress=True, truth=truth, maps=maps, tracks=a.tracks == "on")
            results[setting] = result
            places = worst_places(real_map, twin_map)
            payload[f"shadows_{setting}"] = {**asdict(result), "mapped_gap": result.mapped_gap,
                                             "moving_mapped_gap": result.twin_moving_mapped_pct
                                             - result.real_moving_mapped_pct,
                                             "worst_places": places}
            title = (f"{log_path.parent.name}, shadows {setting}: real {result.real_mapped_pct:.1f}/"
                     f"{result.real_fidelity_pct:.1f}  twin {result.twin_mapped_pct:.1f}/{result.twin_fidelity_pct:.1f}"
                     f"  map IoU {result.map_iou:.3f}  (real | twin | orange real only, cyan twin only)")
            write_png(out / f"places_shadows_{setting}.png", places_image(real_map, twin_map, truth, places, title))
            for name, worldmap, mapped, fidelity in (
                    ("real", real_map, result.real_mapped_pct, result.real_fidelity_pct),
                    ("twin", twin_map, result.twin_mapped_pct, result.twin_fidelity_pct)):
                lines = [f"{name} frames, shadows {setting}", f"{mapped:.1f}% mapped {fidelity:.1f}% fidelity"]
                write_png(out / f"{name}_map_shadows_{setting}.png", map_image(worldmap, truth, title_lines=lines))
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    write_json(out / "metrics.json", payload)
    print(f"map realism of {log_path}, every {a.stride}. frame (mapped / fidelity %, twin minus real in points)")
    print(f"{'shadows':<8} {'frames':>13} {'real all':>12} {'twin all':>12} {'gap':>11} {'IoU':>6}"
          f" {'real moving':>12} {'twin moving':>12} {'gap moving':>11} {'IoU mov':>7}")
    for setting, r in results.items():
        print(f"{setting:<8} {r.frames:>6}/{r.moving_frames:<6} {r.real_mapped_pct:>5.1f}/{r.real_fidelity_pct:<5.1f} "
              f"{r.twin_mapped_pct:>5.1f}/{r.twin_fidelity_pct:<5.1f} {r.mapped_gap:>+5.1f}/"
              f"{r.twin_fidelity_pct - r.real_fidelity_pct:<+5.1f} {r.map_iou:>6.3f} "
              f"{r.real_moving_mapped_pct:>5.1f}/{r.real_moving_fidelity_pct:<5.1f} "
              f"{r.twin_moving_mapped_pct:>5.1f}/{r.twin_moving_fidelity_pct:<5.1f} "
              f"{r.twin_moving_mapped_pct - r.real_moving_mapped_pct:>+5.1f}/"
              f"{r.twin_moving_fidelity_pct - r.real_moving_fidelity_pct:<+5.1f} {r.map_iou_moving:>7.3f}")
    print(f"metrics.json, maps and places images in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
