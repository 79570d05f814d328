"""Run the baseline policy (our AutonomyClient) in `RoverTwin-v0` and save what it saw.

    python -m rover_gym.demo [--steps 1500] [--world default] [--seed 0] [--shadows off|on]
                             [--out out/gym-demo.png]

Prints the episode's reward, the truth floor the camera saw (the mapping reward's
measure) beside the mapped / fidelity figures of the client's own map, and writes the env's
`render()` image (camera | map of the floor seen so far and the path) at the end.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

log = logging.getLogger(__name__)

DEFAULT_STEPS = 1500  # env steps (one 1/30 s render frame each under unity timing, 0.04 s under lockstep)
DEFAULT_OUT = "out/gym-demo.png"  # where the final render() image goes


def run_demo(steps=DEFAULT_STEPS, world="default", seed=0, shadows=False, timing="unity", progress=True):
    """Run the baseline for up to `steps` steps; returns (summary dict, final render image)."""
    import gymnasium
    from tqdm import tqdm

    import rover_gym  # noqa: F401  (registers the id)
    from rover_gym.baseline import AutonomyPolicy

    env = gymnasium.make(rover_gym.ENV_ID, world=world, seed=seed, timing=timing, shadows=shadows,
                         render_mode="rgb_array")
    policy = AutonomyPolicy.for_env(env)
    obs, info = env.reset()
    total, n = 0.0, 0
    terminated = truncated = False
    for n in tqdm(range(1, steps + 1), unit="step", disable=not progress, leave=False):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += reward
        if terminated or truncated:
            break
    image = env.render()
    env.close()
    from evaluation.metrics import score_map

    client_map = score_map(policy.worldmap, env.unwrapped.world.nav_truth)
    summary = {"timing": env.unwrapped.timing.model, "steps": n, "sim_time_s": round(info["sim_time"], 2),
               "reward": round(total, 2),
               "seen_truth_pct": round(info["seen_truth_pct"], 1),
               "client_mapped_pct": round(client_map.mapped_pct, 1), "client_fidelity_pct": round(client_map.fidelity_pct, 1),
               "collected": info["collected"],
               "samples": info["samples"], "terminated": terminated, "truncated": truncated,
               "end_reason": info["end_reason"] or "step budget"}
    return summary, image


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m rover_gym.demo", description="Baseline policy in the RoverTwin-v0 Gymnasium env.")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS, help="env steps (one render frame each)")
    p.add_argument("--world", default="default", help="real | procedural:K | PATH.png")
    p.add_argument("--seed", type=int, default=0, help="scene seed")
    from sim.cli import add_shadows_option

    add_shadows_option(p)
    from sim.timing import add_timing_options, timing_from_args

    add_timing_options(p)
    p.add_argument("--out", default=DEFAULT_OUT, help="PNG of the final render()")
    p.add_argument("--no-progress", action="store_true")
    from sim.cli import parse_with_logging

    a = parse_with_logging(p, argv)
    if a.steps <= 0:
        p.error("--steps must be positive")
    try:
        summary, image = run_demo(a.steps, a.world, a.seed, a.shadows == "on", timing_from_args(a),
                                  not a.no_progress)
    except (ValueError, FileNotFoundError, NotImplementedError) as exc:
        log.error("%s", exc)
        return 2
    from sim.mission import write_png_atomic

    write_png_atomic(Path(a.out), image[:, :, ::-1])
    print(" ".join(f"{k}={v}" for k, v in summary.items()))
    log.info("wrote %s", a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
