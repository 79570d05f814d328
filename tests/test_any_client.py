"""Third-party clients on the twin: the hook's pieces, a tiny starter-style client, and the Udacity starter."""
import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

import shared_data
from sim import client_hook
from sim.any_client import read_worldmap, run_client_mission

STARTER = shared_data.shared_dir() / "clients" / "udacity-starter" / "drive_rover.py"
WORLD = "procedural:0"  # the hook tests need no ../shared


def test_find_worldmap_prefers_the_rover_global_and_ignores_classes_and_modules():
    class RoverState:
        worldmap = np.ones((200, 200, 3))  # a class attribute: not a rover

    class Other:
        def __init__(self, m):
            self.worldmap = m

    rover_map = np.zeros((200, 200, 3))
    ns = {"np": np, "RoverState": RoverState, "helper": Other(np.ones((5, 5))), "Rover": Other(rover_map)}
    assert client_hook.find_worldmap(ns) is rover_map
    assert client_hook.find_worldmap({"RoverState": RoverState, "x": 3}) is None


def test_snapshot_round_trip_scores_any_positive_value_like_the_starter(tmp_path):
    m = np.zeros((200, 200, 3), np.float64)
    m[10, 20, 2] = 0.5  # starter maps count hits: any positive value is marked
    m[11, 20, 0] = 7.0
    path = tmp_path / "worldmap.npy"
    client_hook.write_snapshot(m, str(path))
    got = read_worldmap(path)
    assert got.dtype == np.uint8 and got[10, 20, 2] == 255 and got[11, 20, 0] == 255 and got.sum() == 2 * 255
    np.save(tmp_path / "bad.npy", np.zeros((10, 10)))
    assert read_worldmap(tmp_path / "bad.npy") is None and read_worldmap(tmp_path / "missing.npy") is None


# A starter-shaped client written for this test: eventlet + python-socketio server hard-wired to
# port 4567 (the hook moves it), np.float (the hook's shim), a global Rover with a worldmap that
# marks the cells it drives over.
TINY_CLIENT = textwrap.dedent('''
    import eventlet, eventlet.wsgi, numpy as np, socketio
    from flask import Flask

    sio = socketio.Server()

    class RoverState:
        def __init__(self):
            self.worldmap = np.zeros((200, 200, 3), dtype=np.float)

    Rover = RoverState()

    @sio.on("telemetry")
    def telemetry(sid, data):
        if data:
            x, y = (float(v) for v in data["position"].split(";"))
            Rover.worldmap[int(y) - 1:int(y) + 2, int(x) - 1:int(x) + 2, 2] += 1
        sio.emit("data", {"throttle": "0.5", "brake": "0", "steering_angle": "0"}, skip_sid=True)

    if __name__ == "__main__":
        app = socketio.Middleware(sio, Flask(__name__))
        eventlet.wsgi.server(eventlet.listen(("", 4567)), app)
''')


def test_a_starter_style_client_runs_unchanged_and_its_worldmap_is_scored(tmp_path):
    from sim.world import load_world

    client = tmp_path / "tiny" / "drive_rover.py"
    client.parent.mkdir()
    client.write_text(TINY_CLIENT)
    world = load_world(WORLD)
    r = run_client_mission(world, 0, client, time_limit=4.0, out=tmp_path / "out", progress=False)
    # counts, not rates: the wire runs in real time, so a loaded machine sends fewer frames in the same seconds
    assert r["mode"] == "client" and r["end_reason"] == "time limit" and r["client_commands"] >= 3
    assert r["distance_m"] > 0.5  # it drove on its commands
    assert r["mapped_pct"] is not None and r["mapped_pct"] > 0  # the hook's snapshot reached the scorer
    assert np.load(tmp_path / "out" / "worldmap.npy")[:, :, 2].any()
    assert (tmp_path / "out" / "client.log").exists()


@pytest.mark.skipif(not STARTER.exists(), reason=f"Udacity starter client not found at {STARTER} "
                                                 f"(set {shared_data.SHARED_ENV_VAR} to the shared folder)")
def test_udacity_starter_client_evaluates_on_the_twin_unchanged(tmp_path):
    from sim.evaluate import main

    # 12 s of simulated time is 12 s of wall time (the wire runs in real time): enough to drive off and score
    rc = main(["--seeds", "0", "--client", str(STARTER), "--time-limit", "12", "--world", WORLD,
               "--out", str(tmp_path), "--no-progress", "--log-level", "WARNING"])
    assert rc == 0
    row = json.loads((tmp_path / "evaluation.json").read_text())["missions"][0]
    assert row["mode"] == "client" and row["end_reason"] == "time limit" and row["frames"] >= 20
    assert row["client_commands"] >= 0.5 * row["frames"]  # it answered telemetry all along (numpy, matplotlib, OpenCV shims held)
    assert row["distance_m"] > 1.0  # the starter drives ahead at throttle 0.2
    assert row["mapped_pct"] == 0.0  # its perception_step is a TODO: readable map, nothing mapped
    assert row["collected"] == 0 and row["returned_home"] is False
    assert Path(row["files"]["worldmap"]).exists() and Path(row["files"]["client_log"]).exists()
