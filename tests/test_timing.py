"""The real simulator's loop in-process (sim.timing, sim.mission): late commands act late,
telemetry is captured after the command's frame, no clock is sent, a seed reproduces, and
sim/ has no import circle."""
import ast
from pathlib import Path

import numpy as np
import pytest

from sim.mission import run_inprocess
from sim.timing import Timing, TwinLoop, frame_after, physics_steps_at
from sim.twin import RoverTwin
from twin_worlds import flat_world

SIM_DIR = Path(__file__).resolve().parent.parent / "sim"
DRIVE = {"throttle": "1", "steering_angle": "0", "brake": "0"}


def test_frame_and_physics_arithmetic():
    assert frame_after(0.0, 30) == 1  # strictly after: a reply can never act in its own frame
    assert frame_after(1 / 30, 30) == 2
    assert frame_after(0.034, 30) == 2
    assert physics_steps_at(1 / 30) == 1 and physics_steps_at(0.06) == 3
    with pytest.raises(ValueError):
        Timing("fast")
    with pytest.raises(ValueError):
        Timing(fps=0)
    with pytest.raises(ValueError):
        Timing(latency_ms=-1)


def test_no_sim_time_unless_asked():
    assert "sim_time" not in RoverTwin(flat_world(), render=False).reset(0)
    assert "sim_time" in RoverTwin(flat_world(), render=False, sim_time_field=True).reset(0)
    assert not Timing().sends_sim_time and Timing("lockstep").sends_sim_time


def _drive_once(latency_ms, until_s=0.5):
    """Capture at t=0, answer with full throttle after latency_ms, then let physics run on."""
    twin = RoverTwin(flat_world(), seed=0, render=False)
    loop = TwinLoop(twin, Timing(fps=30, latency_ms=latency_ms, compute_ms=0.0))
    loop.reset(0, start_yaw=0.0)
    tel, dt = loop.step("data", DRIVE)
    acted_at = loop.captured_at
    assert loop.clock() == pytest.approx(acted_at + latency_ms / 2e3)  # read when the telemetry arrives
    at_capture = (twin.sim_time, twin.truth.x)
    twin.advance_to(until_s)
    return tel, acted_at, at_capture, twin.truth.x


def test_a_command_sent_late_acts_late():
    tel_fast, acted_fast, _, x_fast = _drive_once(latency_ms=10.0)
    tel_slow, acted_slow, (t_slow, x_at_slow), x_slow = _drive_once(latency_ms=80.0)
    assert acted_fast == pytest.approx(1 / 30)  # arrived at 10 ms: acts at frame 1
    assert acted_slow == pytest.approx(3 / 30)  # arrived at 80 ms: acts at frame 3 (100 ms)
    assert x_at_slow == pytest.approx(100.0)  # until then the rover sat on the old (zero) inputs
    assert x_slow < x_fast - 0.01  # and so it has covered less ground by the same time


def test_telemetry_is_captured_after_the_commands_frame():
    tel, acted_at, (t_capture, x_capture), _ = _drive_once(latency_ms=40.0)
    assert acted_at == pytest.approx(2 / 30)
    assert t_capture == pytest.approx(physics_steps_at(2 / 30) * 0.02)  # physics caught up to the frame
    assert tel["throttle"] == "1.0000"  # the capture shows the command that just acted
    assert float(tel["position"].split(";")[0]) == pytest.approx(x_capture, abs=1e-4)


def test_the_client_reads_the_virtual_clock_and_the_loop_reproduces_per_seed_and_timing():
    seen = []

    class Recording:
        """A client that drives in a slow circle and notes the clock it was given."""

        def __init__(self, clock):
            self.clock = clock
            self.rover = type("R", (), {"worldmap": np.zeros((200, 200, 3), np.uint8)})()

        def handle_telemetry(self, tel):
            assert "sim_time" not in tel
            seen.append(self.clock())
            return "data", {"throttle": "0.6", "steering_angle": "10", "brake": "0"}

    def run(timing):
        s = run_inprocess(flat_world(), 0, time_limit=3.0, progress=False, render=False,
                          client_factory=Recording, timing=timing)
        return s["traj"], s["twin"].frame, s["reply_delay_ms"]

    a = run(Timing(fps=30, latency_ms=5.0, compute_ms=2.0))
    assert isinstance(seen[0], float) and seen[1] - seen[0] == pytest.approx(1 / 30)
    assert a == run(Timing(fps=30, latency_ms=5.0, compute_ms=2.0))
    slow = run(Timing(fps=15, latency_ms=60.0, compute_ms=2.0))
    assert a[1] == 90 and slow[1] == 45  # one telemetry per render frame when the reply is in time
    assert slow[2] == pytest.approx(1e3 / 15, abs=0.1) and slow[0] != a[0]


def test_lockstep_stays_available_with_its_clock():
    seen = []

    class Lockstep:
        def __init__(self, clock):
            self.rover = type("R", (), {"worldmap": np.zeros((200, 200, 3), np.uint8)})()

        def handle_telemetry(self, tel):
            seen.append(float(tel["sim_time"]))
            return "data", {"throttle": "0.6", "steering_angle": "0", "brake": "0"}

    s = run_inprocess(flat_world(), 0, time_limit=3.0, progress=False, render=False, client_factory=Lockstep,
                      timing=Timing("lockstep"))
    assert s["twin"].frame == 75 and seen[:3] == pytest.approx([0.0, 0.04, 0.08])  # 0.04 s per command


def test_the_real_client_mission_reproduces_exactly():
    pytest.importorskip("sim.render")
    from sim.world import load_world

    world = load_world("procedural:0")
    a = run_inprocess(world, 1, time_limit=4.0, progress=False)
    b = run_inprocess(world, 1, time_limit=4.0, progress=False)
    assert a["traj"] == b["traj"] and np.array_equal(a["worldmap"], b["worldmap"])
    assert a["distance"] > 0.5  # the client drove


def _module_level_imports(path):
    """sim.* modules imported at module level (not inside functions)."""
    found = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("sim."):
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("sim."))
    return found


def _all_imports(path):
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return found


def test_sim_has_no_import_circle():
    graph = {f"sim.{p.stem}": _module_level_imports(p) for p in SIM_DIR.glob("*.py")}

    def visit(mod, stack):
        assert mod not in stack, f"import circle: {' -> '.join(stack + [mod])}"
        for dep in graph.get(mod, ()):
            visit(dep, stack + [mod])

    for mod in graph:
        visit(mod, [])
    # the runners share sim.mission_parts; the wire front end never reaches back into the mission
    assert "sim.mission" not in _all_imports(SIM_DIR / "wire.py")
    assert not {"sim.mission", "sim.wire"} & _all_imports(SIM_DIR / "mission_parts.py")
