"""Byte-identity check of the camera renderer: save a tree's frames, then compare another tree's to them.

    python -m benchmarks.render_identity --save DIR     # on the tree before a change (keeps DIR/draws.pkl if there)
    python -m benchmarks.render_identity --check DIR    # on the tree after it: exit 1 on any differing byte

Why: the raymarch kernel is compiled with fastmath, so any edit may change its output bytes; a speed
change that claims "same images" needs evidence over many poses. The pose set (fixed, reproducible):
the 283 logged test_dataset poses, 120 random floor poses with pitch and roll of the real world, and
the frames of a 40-s in-process mission (seed 3, every 4th frame, with its gold samples and tyre tracks
as the twin drew them), each with cast shadows on and off. Needs ../shared (the real world).
"""
from __future__ import annotations

import argparse
import hashlib
import logging
import sys
from pathlib import Path

import numpy as np

log = logging.getLogger("benchmarks.render_identity")
RANDOM_POSES = 120  # random floor poses (rough pitch and roll) per shadows setting, count
MISSION_SEED = 3  # seed of the mission whose frames are replayed
MISSION_S = 40.0  # simulated seconds of that mission, s
MISSION_EVERY = 4  # every N-th mission frame is kept, count
SAMPLES_IN_SCENE = 6  # gold samples drawn at the fixed poses
NAV_THRESHOLD = 160  # the starter pipeline's navigable threshold (all channels above), grey level


def _random_floor_poses(world, count, rng):
    rows, cols = np.nonzero(world.nav_truth)
    pick = rng.integers(0, rows.size, count)
    return [(cols[i] + rng.uniform(0, 1), rows[i] + rng.uniform(0, 1), rng.uniform(0, 360), rng.normal(0, 3),
             rng.normal(0, 3)) for i in pick]


def _mission_draws(world):
    """(pose, samples, track quads) of every MISSION_EVERY-th frame an in-process mission draws."""
    from sim import render as render_mod
    from sim.mission import run_inprocess

    draws = []
    original = render_mod.Renderer.render

    def recording(self, pose, samples=(), tracks=None):
        quads = None if tracks is None else np.array(getattr(tracks, "quads", tracks), np.float64, copy=True)
        draws.append((tuple(float(v) for v in pose), [tuple(s) for s in samples], quads))
        return original(self, pose, samples, tracks)

    render_mod.Renderer.render = recording
    try:
        run_inprocess(world, MISSION_SEED, time_limit=MISSION_S, progress=False)
    finally:
        render_mod.Renderer.render = original
    return draws[::MISSION_EVERY]


def draw_set(world):
    """Every (pose, samples, quads) the check renders, for one world."""
    rng = np.random.default_rng(25)
    spots = world.sample_spots[rng.choice(len(world.sample_spots), SAMPLES_IN_SCENE, replace=False)]
    samples = [(x, y, 0.43, 0.0) for x, y in spots]
    from sim.realism import read_test_dataset

    fixed = [f.pose for f in read_test_dataset()] + _random_floor_poses(world, RANDOM_POSES, rng)
    return [(tuple(p), samples, None) for p in fixed] + _mission_draws(world)


def render_all(draws, world):
    from sim.render import Renderer

    renderer = Renderer(world)
    frames = np.empty((len(draws), 160, 320, 3), np.uint8)
    depths = np.empty((len(draws), 160, 320), np.float32)
    for i, (pose, samples, quads) in enumerate(draws):
        frames[i] = renderer.render(pose, samples, quads)
        depths[i] = renderer.last_depth
    return frames, depths


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m benchmarks.render_identity", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--save", type=Path, help="write this tree's frames (and the draw list) here")
    group.add_argument("--check", type=Path, help="compare this tree's frames with the ones saved here")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    import pickle

    from sim.world import load_world, with_shadows

    world = load_world("real")
    folder = args.save or args.check
    draws_file = folder / "draws.pkl"
    if args.save and not draws_file.exists():  # a draw list already there is kept (compare trees on one list)
        folder.mkdir(parents=True, exist_ok=True)
        draws = draw_set(with_shadows(world, False))
        tmp = draws_file.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps(draws))
        tmp.replace(draws_file)
    else:
        draws = pickle.loads(draws_file.read_bytes())
    failed = False
    for shadows in (False, True):
        frames, depths = render_all(draws, with_shadows(world, shadows))
        name = folder / f"frames_shadows_{'on' if shadows else 'off'}.npz"
        digest = hashlib.sha256(frames.tobytes()).hexdigest()[:16]
        if args.save:
            np.savez(name, frames=frames, depths=depths)
            log.info("shadows %s: %d frames saved, sha256 %s", shadows, len(frames), digest)
            continue
        ref = np.load(name)
        same = np.all(frames == ref["frames"], axis=(1, 2, 3))
        diff = np.abs(frames.astype(np.int16) - ref["frames"]).max()
        depth_same = np.array_equal(depths, ref["depths"], equal_nan=True)
        log.info("shadows %s: %d of %d frames byte-identical (max |diff| %d levels, %d pixels differ); depth "
                 "identical: %s; sha256 %s", shadows, same.sum(), len(same), diff,
                 int(np.any(frames != ref["frames"], axis=3).sum()), depth_same, digest)
        if not same.all():
            d = np.abs(frames.astype(np.int16) - ref["frames"]).max(axis=3)
            nav = np.all(frames > NAV_THRESHOLD, axis=3) == np.all(ref["frames"] > NAV_THRESHOLD, axis=3)
            log.info("  pixels within 1 / 2 / 8 levels: %.3f / %.3f / %.3f %%; navigable mask (RGB > %d) the same "
                     "on %.4f %% of pixels (worst frame %.3f %%)", 100 * (d <= 1).mean(), 100 * (d <= 2).mean(),
                     100 * (d <= 8).mean(), NAV_THRESHOLD, 100 * nav.mean(), 100 * nav.mean(axis=(1, 2)).min())
        failed |= not same.all()
    return 1 if failed and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
