"""The map-score ceiling: oracle maps from the world's own geometry and sand texture."""
import os
import subprocess
import sys

import pytest

from sim import ceiling


@pytest.fixture(scope="module")
def procedural_world():
    from sim.world import load_world

    return load_world("procedural:0")


def test_a_world_whose_truth_is_its_floor_scores_perfectly(procedural_world):
    r = ceiling.ceiling(procedural_world, procedural_world.nav_truth)
    every = r.points[0]
    assert r.floor_not_truth == 0 and r.truth_not_floor == 0
    assert every.mapped_pct == pytest.approx(100.0) and every.fidelity_pct == pytest.approx(100.0)
    assert all(p.fidelity_pct >= 95.0 for p in r.points[1:])


def test_cell_features_are_per_metre_and_bounded(procedural_world):
    floor, sand, bright = ceiling.cell_features(procedural_world)
    assert floor.shape == sand.shape == bright.shape == (200, 200)
    assert 0.0 <= sand.min() and sand.max() <= 1.0 and 0.0 <= bright.min() and bright.max() <= 1.0
    assert bright[floor].mean() > bright[~floor].mean()  # light floor sand lies on the floor


def test_map_bw_leaves_out_edge_floor_but_an_oracle_reaches_the_goal(world_dir, ground_truth):
    from sim.world import load_real_world

    r = ceiling.ceiling(load_real_world(), ground_truth)
    assert r.truth_cells == 1993
    assert r.floor_not_truth > 300  # hundreds of floor-height cells along the walls are not in map_bw
    assert r.points[0].fidelity_pct < 90  # so mapping every floor cell costs fidelity
    best = max((p for p in r.points[1:] if p.fidelity_pct >= 95.0), key=lambda p: p.mapped_pct)
    assert best.mapped_pct >= 98.0  # knowing geometry and sand texture would meet 98 / 95
    strict = [p for p in r.points[1:] if p.fidelity_pct >= 98.0]
    assert strict and max(p.mapped_pct for p in strict) >= 98.0  # ... even 98 / 98: the lines are in reach


def test_cli_needs_the_real_world(tmp_path):
    env = dict(os.environ, ROVER_SHARED=str(tmp_path / "absent"))
    out = subprocess.run([sys.executable, "-m", "sim.ceiling"], cwd=os.path.dirname(os.path.dirname(ceiling.__file__)),
                         env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert "needed" in out.stderr
