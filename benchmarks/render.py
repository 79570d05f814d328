"""Renderer speed: bake time, first frame (JIT), median/p90 per frame, JPEG encode.

    python -m benchmarks.render [--world real|procedural:0|PATH] [--frames 200]

Poses are the logged test_dataset poses when ../shared is present (what the twin
really draws), else random floor poses of the world. Goal: median <= 10 ms per frame
on the 2-core machine (timings are noisy when others use the cores).
"""
import argparse
import logging
import time

import numpy as np

log = logging.getLogger("benchmarks.render")
GOAL_MS = 10.0  # per-frame median goal, ms
SAMPLES_IN_SCENE = 6  # gold samples drawn per frame (the simulator spawns 6)


def _poses(world, count, rng):
    try:
        from sim.realism import read_test_dataset

        if world.name == "real":
            frames = read_test_dataset()
            return [frames[i % len(frames)].pose for i in range(count)]
    except (FileNotFoundError, OSError):
        pass
    rows, cols = np.nonzero(world.nav_truth)
    pick = rng.integers(0, rows.size, count)
    return [(cols[i] + 0.5, rows[i] + 0.5, rng.uniform(0, 360), rng.normal(0, 1), rng.normal(0, 1))
            for i in pick]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", default="default")
    parser.add_argument("--frames", type=int, default=200)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    from sim.render import Renderer, encode_jpeg
    from sim.world import load_world

    t0 = time.perf_counter()
    world = load_world(args.world)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    renderer = Renderer(world)
    t_bake = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    poses = _poses(world, args.frames, rng)
    spots = world.sample_spots[rng.choice(len(world.sample_spots), min(SAMPLES_IN_SCENE, len(world.sample_spots)),
                                          replace=False)]
    samples = [(x, y, 0.43, 0.0) for x, y in spots]
    t0 = time.perf_counter()
    renderer.render(poses[0], samples)
    t_first = time.perf_counter() - t0
    times, jpeg_times = [], []
    for pose in poses:
        t0 = time.perf_counter()
        img = renderer.render(pose, samples)
        times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        encode_jpeg(img)
        jpeg_times.append(time.perf_counter() - t0)
    ms = np.array(times) * 1000
    log.info("world %s: load %.2f s, bake %.2f s, first frame (JIT/cache load) %.2f s", world.name, t_load,
             t_bake, t_first)
    log.info("render  : median %.2f ms  p90 %.2f ms  max %.2f ms over %d frames (goal median <= %.0f ms) %s",
             np.median(ms), np.percentile(ms, 90), ms.max(), ms.size, GOAL_MS,
             "OK" if np.median(ms) <= GOAL_MS else "SLOW")
    log.info("jpeg q75: median %.2f ms", np.median(jpeg_times) * 1000)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
