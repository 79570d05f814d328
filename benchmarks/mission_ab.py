"""Whole-code A/B of in-process mission speed: the current tree against a git revision, missions alternating.

    python -m benchmarks.mission_ab --baseline REV [--seconds 60] [--rounds 2] [--seed 0] [--world default]

`benchmarks.render --baseline REV` swaps in only the renderer's modules of REV, so a change to the client,
the physics or the mission loop is in both of its arms. This benchmark checks REV out whole (`git worktree`
in a temporary folder, removed afterwards) and runs the same in-process mission in a fresh Python process per
run, in the current tree and in REV's, alternating. Each run first drives a short warm-up mission (numba
compiles and the renderer's rasters bake there) and then times one mission of --seconds simulated on the same
world, OpenCV on one thread as `sim.evaluate`'s workers: CPU frames/s per core of the timed mission. Also
prints whether the two trees' timed missions ended with the same figures and the same world map bytes (a
speed change that is meant to be behaviour-identical shows "same"). Prints, never asserts.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import tempfile
from pathlib import Path

log = logging.getLogger("benchmarks.mission_ab")
WARMUP_S = 2.0  # simulated seconds of the untimed warm-up mission in each run, s
GOAL_MISSION_FPS = 300.0  # issue 25: in-process mission frames/s per core of CPU

# run inside each tree's folder: warm-up, then the timed mission; prints one JSON line
_RUNNER = r"""
import hashlib, json, sys, time
import cv2
cv2.setNumThreads(1)
from sim.mission import run_inprocess
from sim.world import load_world
world_spec, seed, seconds, warmup = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
world = load_world(world_spec)
run_inprocess(world, seed, time_limit=warmup, progress=False)
c0 = time.process_time()
s = run_inprocess(world, seed, time_limit=seconds, progress=False)
cpu = time.process_time() - c0
tr = s["twin"].truth
print(json.dumps({"frames": s["twin"].frame, "cpu_s": cpu, "wall_s": s["wall"],
                  "pose": [tr.x, tr.y, tr.yaw], "collected": len(tr.collected), "distance": s["distance"],
                  "worldmap_sha1": hashlib.sha1(s["worldmap"].tobytes()).hexdigest()}))
"""


def run_once(tree: Path, world: str, seed: int, seconds: float) -> dict:
    """One fresh-process run in `tree`: {frames, cpu_s, wall_s, pose, collected, distance, worldmap_sha1}."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", _RUNNER, world, str(seed), str(seconds), str(WARMUP_S)], cwd=tree,
                         env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _repo_root() -> Path:
    return Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.mission_ab", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--baseline", required=True, metavar="REV", help="git revision to compare against")
    parser.add_argument("--seconds", type=float, default=60.0, help="simulated seconds of each timed mission")
    parser.add_argument("--rounds", type=int, default=2, help="timed runs per tree, alternating")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--world", default="default")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    root = _repo_root()
    rev = subprocess.run(["git", "rev-parse", "--short", args.baseline], cwd=root, capture_output=True, text=True,
                         check=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix=f"mission-ab-{rev}-") as tmp:
        base_tree = Path(tmp) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(base_tree), rev], cwd=root, check=True)
        try:
            log.info("in-process missions, seed %d, %.0f s simulated, %d rounds alternating; load average %.1f",
                     args.seed, args.seconds, args.rounds, os.getloadavg()[0])
            runs = {"baseline": [], "current": []}
            for i in range(args.rounds):
                order = ("baseline", "current") if i % 2 == 0 else ("current", "baseline")
                for who in order:
                    r = run_once(base_tree if who == "baseline" else root, args.world, args.seed, args.seconds)
                    runs[who].append(r)
                    log.info("  %-8s %5d frames  %.1f CPU s  %.0f frames/s per core", who, r["frames"], r["cpu_s"],
                             r["frames"] / r["cpu_s"])
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base_tree)], cwd=root, check=False)
    fps = {k: [r["frames"] / r["cpu_s"] for r in v] for k, v in runs.items()}
    keys = ("frames", "pose", "collected", "distance", "worldmap_sha1")
    same = all({k: r[k] for k in keys} == {k: runs["baseline"][0][k] for k in keys}
               for r in runs["baseline"] + runs["current"])
    mean = {k: sum(v) / len(v) for k, v in fps.items()}
    log.info("frames/s per core of CPU: baseline %s: %s; current: %s; ratio of means %.3f (goal >= %.0f); missions "
             "%s; load average %.1f", rev, ", ".join(f"{v:.0f}" for v in fps["baseline"]),
             ", ".join(f"{v:.0f}" for v in fps["current"]), mean["current"] / mean["baseline"], GOAL_MISSION_FPS,
             "the same (frames, final pose, collected, distance, world map bytes)" if same else "DIFFERENT",
             os.getloadavg()[0])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
