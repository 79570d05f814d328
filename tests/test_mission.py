"""Mission runner: a short in-process mission writes metrics JSON + PNG and moves the rover."""
import json

import pytest

from sim.mission import StuckMeter, run_mission

MISSION_S = 40.0  # simulated seconds: long enough to drive and map, short for CI


@pytest.fixture(scope="module")
def world():
    pytest.importorskip("sim.render")
    from sim.world import default_world

    return default_world()  # real world when ../shared is present, else the procedural one


def test_short_mission_writes_metrics_and_png(world, tmp_path):
    r = run_mission(seed=1, world=world, time_limit=MISSION_S, out=tmp_path / "m", progress=False)
    data = json.loads((tmp_path / "m" / "mission.json").read_text())
    assert data == json.loads(json.dumps(r))
    png = (tmp_path / "m" / "mission.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    for key in ("mapped_pct", "fidelity_pct", "located", "collected", "returned_home", "time_s",
                "stuck_time_s", "longest_stuck_s", "frames"):
        assert key in data
    assert data["mode"] == "inprocess" and data["samples"] == 6
    assert data["frames"] > 0 and 0 < data["time_s"] <= MISSION_S + 0.05
    assert data["distance_m"] > 2.0  # the client drove
    assert data["mapped_pct"] > 0.5  # and mapped something
    assert data["rejected_commands"] == 0
    assert data["longest_stuck_s"] <= data["stuck_time_s"] <= data["time_s"]


def test_stuck_meter_counts_throttle_without_motion():
    m = StuckMeter()
    t = 0.0
    for _ in range(100):  # 4 s pushing against something
        t += 0.04
        m.update(t, 0.04, 10.0, 10.0, 0.0, 1.0, False)
    for _ in range(50):  # 2 s driving
        t += 0.04
        m.update(t, 0.04, 10.0 + t, 10.0, 1.0, 1.0, False)
    assert m.total_s == pytest.approx(4.0, abs=0.05)
    assert m.longest_s == pytest.approx(4.0, abs=0.05)
    for _ in range(50):  # picking up is not stuck
        t += 0.04
        m.update(t, 0.04, 12.0, 10.0, 0.0, 1.0, True)
    assert m.total_s == pytest.approx(4.0, abs=0.05)
