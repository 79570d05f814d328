"""Replay throughput: frames per second of JPEG decode + perception over a real log.

Reads every frame's bytes into memory first (disk speed is not what we measure),
then times, per frame, ``cv2.imdecode`` + BGR->RGB and ``perception_step`` on a
RoverState fed like the live client.  Prints, never asserts: the machine is
shared and timings are noisy.  Goal: >= 500 frames/s on one core.

    python -m benchmarks.replay_fps [LOG] [--limit N]

LOG defaults to the megalphian log in ../shared (6,150 frames).
"""
from __future__ import annotations

import argparse
import logging
import sys
import time

import cv2
import numpy as np
from tqdm import tqdm

import perception
import shared_data
from replay.log_format import LogFormatError, read_log
from replay.runner import apply_frame
from rover_state import RoverState

log = logging.getLogger("benchmarks.replay_fps")

TARGET_FPS = 500.0  # goal for decode + perception, frames per second


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.replay_fps", description=__doc__.splitlines()[0])
    p.add_argument("log", nargs="?", default=str(shared_data.real_logs_dir() / "megalphian"))
    p.add_argument("--limit", type=int, default=0, help="use only the first N frames (0 = all)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cv2.setNumThreads(1)  # one core, like the live client's budget
    try:
        data = read_log(args.log)
    except LogFormatError as exc:
        log.error("%s", exc)
        return 2
    frames = data.frames[: args.limit] if args.limit > 0 else data.frames
    blobs = [np.fromfile(str(f.image_path), np.uint8) for f in tqdm(frames, desc="load", unit="frame")]
    rover = RoverState()
    dec_ms, perc_ms = [], []
    t_all = time.perf_counter()
    for i, (frame, blob) in enumerate(zip(tqdm(frames, desc="replay", unit="frame"), blobs)):
        t0 = time.perf_counter()
        bgr = cv2.imdecode(blob, cv2.IMREAD_COLOR)
        if bgr is None:
            continue
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        t1 = time.perf_counter()
        apply_frame(rover, frame, rgb, i * 0.04)
        t2 = time.perf_counter()
        perception.perception_step(rover)
        t3 = time.perf_counter()
        dec_ms.append((t1 - t0) * 1e3)
        perc_ms.append((t3 - t2) * 1e3)
    wall = time.perf_counter() - t_all
    n = len(perc_ms)
    if n == 0:
        log.error("no decodable frames in %s", args.log)
        return 2
    dec, perc = np.array(dec_ms), np.array(perc_ms)
    both = dec + perc
    log.info("log: %s (%d frames timed)", data.log_path, n)
    log.info("%-22s %8s %8s %8s", "stage", "median", "p95", "mean")
    for name, a in (("decode ms", dec), ("perception ms", perc), ("decode+perception ms", both)):
        log.info("%-22s %8.3f %8.3f %8.3f", name, np.median(a), np.percentile(a, 95), a.mean())
    log.info("decode+perception: %.0f frames/s from the mean, %.0f frames/s from the median (target >= %.0f)",
             1e3 / both.mean(), 1e3 / np.median(both), TARGET_FPS)
    log.info("whole loop incl. state update and progress bar: %.0f frames/s (%.1f s)", n / wall, wall)
    return 0


if __name__ == "__main__":
    sys.exit(main())
