"""Where a twin frame goes: the renderer stage by stage, and an in-process mission part by part (CPU ms per frame).

    python -m benchmarks.stages [--world default] [--shadows off|on] [--frames 283] [--mission-s 60]

Renderer stages, on the logged test_dataset poses (random floor poses without ../shared), each pose drawn
whole once and then stage by stage (each stage timed alone, in the order render() runs them): camera pose,
raymarch kernel, back-scatter column gains, floor look (far-floor mipmaps and lobe), the fill of the shared
pixels, gold samples. Mission parts: the same calls wrapped with CPU timers during one in-process mission
(seed 0): render, JPEG encode, the rest of the telemetry (base64, number formatting), the client's
handle_telemetry (of which perception_step), physics. Prints, never asserts.
"""
from __future__ import annotations

import argparse
import collections
import contextlib
import logging
import time

import numpy as np

log = logging.getLogger("benchmarks.stages")
SAMPLES_IN_SCENE = 6  # gold samples drawn per frame


def render_stages(world, poses, samples):
    """{stage: [CPU ms per pose]} for the renderer's stages (see the module docstring)."""
    from sim import render as R
    from sim import shading

    r = R.Renderer(world)
    r.render(poses[0], samples)
    out = collections.defaultdict(list)
    pc = time.process_time
    for pose in poses:
        t0 = pc()
        r.render(pose, samples)
        out["whole render()"].append(pc() - t0)
        t0 = pc()
        origin, rot = r.camera(pose)
        out["camera pose"].append(pc() - t0)
        rot = np.ascontiguousarray(rot)
        img = np.empty((R.IMAGE_H, R.IMAGE_W, 3), np.uint8)
        depth = np.empty((R.IMAGE_H, R.IMAGE_W), np.float32)
        shared = np.zeros((R.IMAGE_H, R.IMAGE_W), np.uint8)
        b = r.baked
        t0 = pc()
        R._render_kernel(img, depth, rot, r.ray_a, r.ray_b, r._terrain, 1.0 / float(world.terrain_cell_m), b["tex"],
                         b["tex_u"], b["slab"], r._rock64(), b["coarse"], b["bmax"], R.BLOCK_CELLS * R.COARSE_CELL_M,
                         float(world.rock_cell_m), R.COARSE_CELL_M, origin, R.FAR_M, R.FINE_STEP_MIN_M,
                         R.FINE_STEP_PER_M, R.REFINE_ITERS, r.zmax, r.sky_rgb, r.far_rgb, R.UNDERSIDE_SHADE,
                         R.UNDERSIDE_BAND_M, R.UNDERSIDE_RAMP_M, float(world.size_m), r._dark_lut, R.DARK_LUT_STEP_M,
                         r.column_share_m, R.COLUMN_SHARE_RATIO, R.COLUMN_SHARE_LEVELS, r.share_rock, r._col_order,
                         r._col_offset,
                         shared, r.share_rock_ratio, r._col_min_m)
        out["raymarch kernel"].append(pc() - t0)
        t0 = pc()
        shading.backscatter_columns(rot, r.ray_a, R.SUN_AZIMUTH_DEG)
        out["back-scatter gains (NumPy)"].append(pc() - t0)
        t0 = pc()
        r._draw_floor_look(img, depth, origin, rot, shared)  # computes the gains again inside (subtract the line above)
        out["floor look incl. gains"].append(pc() - t0)
        t0 = pc()
        R._fill_shared_pixels(img, shared, r._col_order, r._col_offset)
        out["fill of shared pixels"].append(pc() - t0)
        t0 = pc()
        r.draw_samples(img, depth, origin, rot, samples)
        out["gold samples"].append(pc() - t0)
    return {k: np.array(v) * 1e3 for k, v in out.items()}


@contextlib.contextmanager
def _timers(acc):
    """CPU timers around the mission's parts (module attributes patched for the duration)."""
    import autonomy
    import perception
    from sim import render as R
    from sim import twin as T

    patched = []

    def wrap(owner, name, key):
        original = getattr(owner, name)

        def timed(*args, **kwargs):
            t0 = time.process_time()
            try:
                return original(*args, **kwargs)
            finally:
                acc[key] += time.process_time() - t0

        patched.append((owner, name, original))
        setattr(owner, name, timed)

    wrap(R.Renderer, "render", "render")
    wrap(R, "encode_jpeg", "JPEG encode")
    wrap(T.RoverTwin, "telemetry", "telemetry (render, JPEG, base64, numbers)")
    wrap(autonomy.AutonomyClient, "handle_telemetry", "client handle_telemetry")
    wrap(perception, "perception_step", "  of which perception_step")
    wrap(T.RoverTwin, "advance_to", "physics (advance_to)")
    try:
        yield
    finally:
        for owner, name, original in reversed(patched):
            setattr(owner, name, original)


def mission_parts(world, seconds, seed=0):
    """(frames, CPU ms per frame in all, {part: CPU ms per frame}) of one in-process mission."""
    from sim.mission import run_inprocess

    acc = collections.defaultdict(float)
    with _timers(acc):
        c0 = time.process_time()
        summary = run_inprocess(world, seed, time_limit=seconds, progress=False)
        cpu = time.process_time() - c0
    frames = summary["twin"].frame
    return frames, cpu / frames * 1e3, {k: v / frames * 1e3 for k, v in acc.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.stages", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", default="default")
    parser.add_argument("--shadows", choices=("off", "on"), default=None, help="cast shadows (default: the world's)")
    parser.add_argument("--frames", type=int, default=283)
    parser.add_argument("--mission-s", type=float, default=60.0, help="simulated seconds of the mission (0: none)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    import cv2

    cv2.setNumThreads(1)  # as sim.evaluate's workers (one mission per core): OpenCV's helper threads only add CPU time
    import os

    from benchmarks.render import _poses
    from sim.world import load_world, with_shadows

    world = load_world(args.world)
    if args.shadows:
        world = with_shadows(world, args.shadows == "on")
    rng = np.random.default_rng(0)
    poses = _poses(world, args.frames, rng)
    spots = world.sample_spots[rng.choice(len(world.sample_spots), min(SAMPLES_IN_SCENE, len(world.sample_spots)),
                                          replace=False)]
    samples = [(x, y, 0.43, 0.0) for x, y in spots]
    log.info("world %s, cast shadows %s, %d poses, load average %.1f", world.name, world.cast_shadows, len(poses),
             os.getloadavg()[0])
    for stage, ms in render_stages(world, poses, samples).items():
        log.info("  %-28s median %6.3f  mean %6.3f ms", stage, np.median(ms), ms.mean())
    if args.mission_s > 0:
        frames, per_frame, parts = mission_parts(world, args.mission_s)
        log.info("in-process mission (seed 0, %.0f s simulated, %d frames): %.3f ms CPU per frame, %.0f frames/s per "
                 "core; load average %.1f", args.mission_s, frames, per_frame, 1e3 / per_frame, os.getloadavg()[0])
        for part, ms in parts.items():
            log.info("  %-42s %6.3f ms per frame", part, ms)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
