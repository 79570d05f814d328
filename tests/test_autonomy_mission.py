"""Short closed-loop missions on the twin: the real client (perception + decision) drives.

These check behaviour, not speed: in 90 s of simulated time from the start the
rover must leave the start area, map a meaningful part of the canyon with good
fidelity and never sit stuck for long. Full missions live in `sim.evaluate`.
"""
import math

import numpy as np
import pytest

from sim.mission import run_inprocess
from evaluation.metrics import score_map

SHORT_MISSION_S = 90.0  # simulated seconds per test mission
MAX_STUCK_S = 15.0  # longest stuck stretch allowed, s
MIN_TRAVEL_M = 40.0  # distance the rover must cover, m
MIN_MAPPED_REAL_PCT = 15.0  # share of the real canyon floor mapped in the short mission, %
MIN_FIDELITY_PCT = 85.0  # fidelity of what was mapped, %


def _short_mission(world, seed):
    summary = run_inprocess(world, seed, time_limit=SHORT_MISSION_S, progress=False)
    score = score_map(summary["worldmap"], world.nav_truth)
    traj = np.asarray(summary["traj"])
    far = float(np.max(np.hypot(traj[:, 0] - world.start_xy[0], traj[:, 1] - world.start_xy[1])))
    return summary, score, far


def test_short_mission_on_the_real_world_explores_without_getting_stuck(world_dir):
    from sim.world import load_world

    world = load_world("real")
    summary, score, far = _short_mission(world, seed=3)
    assert summary["fixed_turns"] > 0 and summary["fixed_turns_refused"] == 0  # turns in place are fixed turns
    assert summary["stuck"].longest_s <= MAX_STUCK_S
    assert summary["distance"] >= MIN_TRAVEL_M
    assert far >= 15.0, "the rover must leave the start area"
    assert score.mapped_pct >= MIN_MAPPED_REAL_PCT
    assert score.fidelity_pct >= MIN_FIDELITY_PCT


def test_short_mission_on_a_procedural_world_explores():
    from sim.world import load_world

    world = load_world("procedural:1")
    summary, score, far = _short_mission(world, seed=0)
    assert summary["stuck"].longest_s <= MAX_STUCK_S
    assert summary["distance"] >= MIN_TRAVEL_M
    assert score.good_cells >= 150, "a meaningful area of true floor is mapped"
    assert score.fidelity_pct >= MIN_FIDELITY_PCT
