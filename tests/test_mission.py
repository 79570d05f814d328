"""Mission runner: a short in-process mission writes metrics JSON + PNG and moves the rover."""
import json

import pytest

from sim.mission import StuckMeter, run_mission
from sim.timing import WIRE_LATENCY_MS

MISSION_S = 30.0  # simulated seconds: long enough to drive and map, short for CI


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
    assert isinstance(data["stuck_stretches"], list)
    assert data["shadows"] is False  # the default twin casts no shadows (the held-out real drives show none)
    # the real simulator's loop by default, and the result says so
    assert (data["timing"], data["fps"], data["latency_ms"]) == ("unity", 30.0, WIRE_LATENCY_MS)
    assert data["telemetry_hz"] == pytest.approx(30.0, abs=0.5)


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
    assert m.stretches == []  # shorter than STUCK_REPORT_MIN_S
    for _ in range(50):  # picking up is not stuck
        t += 0.04
        m.update(t, 0.04, 12.0, 10.0, 0.0, 1.0, True)
    assert m.total_s == pytest.approx(4.0, abs=0.05)
    for _ in range(200):  # 8 s against a wall at (12, 10)
        t += 0.04
        m.update(t, 0.04, 12.0, 10.0, 0.0, 1.0, False)
    m.close_run()
    assert len(m.stretches) == 1 and m.stretches[0][1:3] == [12.0, 10.0]
    assert m.stretches[0][3] == pytest.approx(8.0, abs=0.05)


def test_parse_seeds_and_summary():
    from sim.evaluate import markdown_table, parse_seeds, summarise

    assert parse_seeds("0-3") == [0, 1, 2, 3]
    assert parse_seeds("5, 1,1,8-9") == [1, 5, 8, 9]
    from sim.evaluate import format_seeds
    assert format_seeds(parse_seeds("40-49,90-99")) == "40-49,90-99", "not 40-99: fifty seeds never run"
    assert format_seeds([9, 1, 2, 3, 5, 5]) == "1-3,5,9"
    assert parse_seeds(format_seeds([0, 7, 8, 200])) == [0, 7, 8, 200]
    with pytest.raises(ValueError):
        parse_seeds("9-2")
    with pytest.raises(ValueError):
        parse_seeds("x")
    with pytest.raises(ValueError):
        parse_seeds("-3")
    rows = [{"seed": 0, "mapped_pct": 40.0, "returned_home": True, "fidelity_pct": None},
            {"seed": 1, "mapped_pct": 60.0, "returned_home": False, "fidelity_pct": 70.0}]
    s = summarise(rows)
    assert s["mapped_pct"] == {"median": 50.0, "min": 40.0, "max": 60.0}
    assert s["returned_home"]["min"] == 0.0 and s["fidelity_pct"]["median"] == 70.0
    assert s["returned_home"]["yes"] == 1
    md = markdown_table(rows, s)
    assert "| median |" in md and "n/a" in md
    assert "| 1/2 yes |" in md and "mapped_pct" not in md  # yes/no counted, headings for people


def test_record_mode_writes_a_log_the_replay_reader_reads(world, tmp_path):
    from replay.log_format import read_log

    r = run_mission(seed=2, world=world, time_limit=2.0, out=tmp_path / "m", record=tmp_path / "rec",
                    progress=False)
    data = read_log(tmp_path / "rec")
    assert len(data.frames) == r["frames"] and data.skipped == 0
    first = data.frames[0]
    assert (first.x, first.y) == pytest.approx(tuple(world.start_xy), abs=1e-3)
    assert all(0.0 <= f.yaw <= 360.0 for f in data.frames)


def test_evaluate_runs_seeds_on_two_workers(tmp_path):
    """The CLI as users run it: two worker processes, every output, and a clean exit."""
    pytest.importorskip("sim.render")
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "sim.evaluate", "--seeds", "0-1", "--world", "procedural:0",
                           "--jobs", "2", "--time-limit", "1", "--out", str(tmp_path), "--no-progress",
                           "--shadows", "off", "--home-by", "870", "--fps", "15", "--latency-ms", "60"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "leaked" not in proc.stderr, "worker processes were killed instead of joined"
    res = json.loads((tmp_path / "evaluation.json").read_text())
    assert [m["seed"] for m in res["missions"]] == [0, 1]
    assert all("mapped_pct" in m for m in res["missions"]), res["missions"]
    assert res["meta"]["shadows"] == "off" and not any(m["shadows"] for m in res["missions"])
    assert "shadows off" in (tmp_path / "evaluation.md").read_text()
    assert res["meta"]["home_by_s"] == 870.0 and all(m["home_by_s"] == 870.0 for m in res["missions"])
    assert "client home by 870 s" in (tmp_path / "evaluation.md").read_text()
    assert (res["meta"]["timing"], res["meta"]["fps"], res["meta"]["latency_ms"]) == ("unity", 15.0, 60.0)
    assert all(m["fps"] == 15.0 and m["latency_ms"] == 60.0 for m in res["missions"])
    assert "unity 15 fps, 60 ms latency" in (tmp_path / "evaluation.md").read_text()
    for name in ("evaluation.json", "evaluation.csv", "evaluation.md"):
        assert (tmp_path / name).stat().st_size > 0
    assert (tmp_path / "seed-1" / "mission.png").exists()


def test_matrix_runs_every_condition_and_prints_one_table(tmp_path):
    pytest.importorskip("sim.render")
    from sim.evaluate import MATRIX_CONDITIONS, MissionOptions, run_matrix

    res = run_matrix([0], "procedural:0", jobs=1, out=tmp_path, progress=False,
                     options=MissionOptions(time_limit=1.0))
    assert [r["condition"] for r in res["rows"]] == [c.name for c in MATRIX_CONDITIONS]
    assert [(r["shadows"], r["fps"], r["latency_ms"]) for r in res["rows"]] == [
        ("off", 30.0, WIRE_LATENCY_MS), ("on", 30.0, WIRE_LATENCY_MS), ("off", 15.0, 60.0)]
    assert all(r["errors"] == 0 and r["mapped_median"] is not None for r in res["rows"])
    md = (tmp_path / "matrix.md").read_text()
    assert md == res["markdown"] and md.count("\n| shadows-") == 3
    for cond in MATRIX_CONDITIONS:
        meta = json.loads((tmp_path / cond.name / "evaluation.json").read_text())["meta"]
        assert meta["shadows"] == ("on" if cond.shadows else "off") and meta["fps"] == cond.timing.fps
