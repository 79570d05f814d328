"""From how far the client's gold threshold finds a sample: the twin's JPEG against a real drive.

For the logged frames of a real drive taken level (|pitch|, |roll| <= LEVEL_DEG), the twin draws a sample
of scale SAMPLE_SCALE at each sample spot that drive really had (ACTIVE_MIN_HITS one-blob detections within
ACTIVE_RADIUS_M, every ACTIVE_STRIDE-th frame) when the spot lies 3-7 m ahead, within AHEAD_HALF_DEG of the
heading, and the raw render shows it (at least perception.ROCK_MIN_PIXELS gold px). The frame is then
scored twice with `perception.rock_mask`:

- real: gold px of the logged frame in a window around where the twin drew the sample;
- twin: gold px of the twin's frame after the simulator's JPEG (`sim.render.encode_jpeg`).

Frames are chosen by the twin's raw view, not by what the real frame shows, so the real column is not
biased towards detections. Per 1 m range band it prints both medians and the share of frames with at least
ROCK_MIN_PIXELS px (docs/twin-realism.md, rounds 8 and 9).

    python -m sim.sample_range [LOG] [--stride 2] [--json out/sample_range.json]

LOG is a folder under ../shared/real-logs (default megalphian), test_dataset, or a path.
"""
from __future__ import annotations

import argparse
import logging
import math
import sys
from pathlib import Path

import numpy as np

import perception
import shared_data
from replay.runner import decode_frame, signed_angle
from sim.realism import jpeg_roundtrip
from sim.render import Renderer

log = logging.getLogger(__name__)

LEVEL_DEG = 3.0  # frames count only while |pitch| and |roll| are at most this, deg
ACTIVE_STRIDE = 4  # the drive's sample spots are found on every this-th frame
ACTIVE_RADIUS_M = 1.5  # a one-blob detection this close to a spot counts for it, m
ACTIVE_MIN_HITS = 10  # a spot is in the drive when it has at least this many detections
SAMPLE_SCALE = 0.43  # prefab scale the twin draws (the spawn range is 0.36-0.5; the real ones are unknown)
AHEAD_HALF_DEG = 30.0  # the spot must lie this close to the heading, deg
BANDS_M = ((3.0, 4.0), (4.0, 5.0), (5.0, 6.0), (6.0, 7.0))  # range bands of the table, m
WINDOW_ROWS_PX = 8  # the real frame's window reaches this far above and below the twin's blob, px
WINDOW_COLS_PX = 12  # ...and this far to either side, px


def _level(frame):
    return abs(signed_angle(frame.pitch)) <= LEVEL_DEG and abs(signed_angle(frame.roll)) <= LEVEL_DEG


def active_spots(frames, spots):
    """Indices of the sample spots the drive really had: one-blob real detections near them."""
    hits = np.zeros(len(spots), int)
    for frame in frames[::ACTIVE_STRIDE]:
        if not _level(frame):
            continue
        rgb = decode_frame(frame.image_path)
        if rgb is None:
            continue
        mask = perception.rock_mask(rgb)
        if mask.sum() < perception.ROCK_MIN_PIXELS:
            continue
        points, _, _ = perception._rock_detections(mask.astype(np.uint8) * 255, signed_angle(frame.pitch),
                                                   signed_angle(frame.roll))
        for fx, fy in points:
            wx, wy = perception.rover_to_world(np.array([fx]), np.array([fy]), frame.x, frame.y, frame.yaw)
            d = np.hypot(spots[:, 0] - wx[0], spots[:, 1] - wy[0])
            k = int(np.argmin(d))
            if d[k] < ACTIVE_RADIUS_M:
                hits[k] += 1
    return [k for k in range(len(spots)) if hits[k] >= ACTIVE_MIN_HITS]


def measure(frames, world, stride=2):
    """(range m, real px, twin JPEG px, twin raw px) per chosen frame and active spot; the active spots."""
    spots = np.asarray(world.sample_spots, float)
    active = active_spots(frames, spots)
    renderer = Renderer(world)
    rows = []
    for frame in frames[::stride]:
        if not _level(frame):
            continue
        real = None
        for k in active:
            sx, sy = spots[k]
            dist = math.hypot(sx - frame.x, sy - frame.y)
            off = (math.degrees(math.atan2(sy - frame.y, sx - frame.x)) - frame.yaw + 180.0) % 360.0 - 180.0
            if not (BANDS_M[0][0] <= dist < BANDS_M[-1][1] and abs(off) < AHEAD_HALF_DEG):
                continue
            raw = renderer.render((frame.x, frame.y, frame.yaw, 0.0, 0.0), samples=[(sx, sy, SAMPLE_SCALE, 0.0)])
            raw_mask = perception.rock_mask(raw)
            if raw_mask.sum() < perception.ROCK_MIN_PIXELS:
                continue
            real = decode_frame(frame.image_path) if real is None else real
            if real is None:
                break
            vs, us = np.nonzero(raw_mask)
            window = perception.rock_mask(real)[max(vs.min() - WINDOW_ROWS_PX, 0):vs.max() + WINDOW_ROWS_PX + 1,
                                                max(us.min() - WINDOW_COLS_PX, 0):us.max() + WINDOW_COLS_PX + 1]
            rows.append((dist, int(window.sum()), int(perception.rock_mask(jpeg_roundtrip(raw)).sum()), int(raw_mask.sum())))
    return np.array(rows, float).reshape(-1, 4), active


def table(rows):
    """Per band: frames, real px median and share >= ROCK_MIN_PIXELS, twin JPEG the same, twin raw median."""
    out = []
    for lo, hi in BANDS_M:
        band = rows[(rows[:, 0] >= lo) & (rows[:, 0] < hi)]
        if not len(band):
            continue
        seen = perception.ROCK_MIN_PIXELS
        out.append({"band_m": [lo, hi], "frames": int(len(band)),
                    "real_px_median": float(np.median(band[:, 1])), "real_seen_share": float(np.mean(band[:, 1] >= seen)),
                    "twin_jpeg_px_median": float(np.median(band[:, 2])),
                    "twin_seen_share": float(np.mean(band[:, 2] >= seen)),
                    "twin_raw_px_median": float(np.median(band[:, 3]))})
    return out


def _log_path(name):
    if name in ("", "test_dataset"):
        return shared_data.test_dataset_dir()
    candidate = shared_data.real_logs_dir() / name
    return candidate if candidate.exists() else Path(name)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim.sample_range", description=__doc__.split("\n")[0])
    p.add_argument("log", nargs="?", default="megalphian", help="a folder under ../shared/real-logs, "
                                                                 "test_dataset, or a path (default megalphian)")
    p.add_argument("--stride", type=int, default=2, help="use every N-th logged frame (default 2)")
    p.add_argument("--json", metavar="OUT.json", help="also write the table as JSON")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    from replay.log_format import LogFormatError, read_log
    from sim.world import load_world

    if a.stride < 1:
        log.error("--stride must be at least 1")
        return 2
    try:
        data = read_log(_log_path(a.log))
        world = load_world("real")
    except (LogFormatError, OSError, ValueError) as exc:
        log.error("%s", exc)
        return 2
    rows, active = measure(data.frames, world, a.stride)
    spots = np.asarray(world.sample_spots, float)
    log.info("%s: active spots %s; %d frames show one 3-7 m ahead in the twin's raw render", data.log_path,
             [(round(float(spots[k][0]), 1), round(float(spots[k][1]), 1)) for k in active], len(rows))
    result = table(rows)
    for band in result:
        log.info("%g-%g m: %3d frames | real px median %3.0f, >= %d px in %3.0f %% | twin JPEG median %3.0f, "
                 "in %3.0f %% | twin raw %3.0f", *band["band_m"], band["frames"], band["real_px_median"],
                 perception.ROCK_MIN_PIXELS, 100 * band["real_seen_share"], band["twin_jpeg_px_median"],
                 100 * band["twin_seen_share"], band["twin_raw_px_median"])
    if a.json:
        from sim.mission_parts import write_json_atomic

        try:
            write_json_atomic(a.json, {"log": str(data.log_path), "bands": result})
        except OSError as exc:
            log.error("cannot write %s: %s", a.json, exc)
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
