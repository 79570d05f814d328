"""Turning in place with the simulator's fixed_turn (navigation.fixed_turn, decision.mode_stop):
the payload is strings with matching signs, a stopped rover on the twin turns to the target and
stops there, a refused fixed turn falls back to steering, and the gym baseline never sends one."""
import json

import numpy as np

import pytest

import decision
from autonomy import AutonomyClient
from navigation import fixed_turn
from sim.timing import Timing, TwinLoop
from sim.twin import RoverTwin
from twin_worlds import flat_world

START_YAW = 10.0  # the twin's start heading in these tests, degrees
FRAMES = 150  # telemetry frames per test turn (5 s at 30 fps: a steered 150 deg turn takes ~4 s)


@pytest.mark.parametrize("ccw", [30.0, -150.0, 250.0])
def test_payload_is_strings_clockwise_positive_with_the_angles_sign(ccw):
    p = fixed_turn.payload(ccw)
    assert set(p) == {"angle", "time"} and all(isinstance(v, str) for v in p.values())
    assert json.loads(json.dumps(p)) == p  # JSON strings on the wire, never numbers
    angle, time_s = float(p["angle"]), float(p["time"])
    assert angle == pytest.approx(-ccw)  # the simulator turns clockwise for a positive angle
    assert time_s * angle > 0  # opposite signs would spin for good
    assert angle / time_s == pytest.approx(fixed_turn.FIXED_TURN_RATE_DPS, rel=1e-3)


def test_payload_refuses_an_angle_it_cannot_send():
    for bad in (0.0, float("nan"), float("inf")):
        with pytest.raises(ValueError):
            fixed_turn.payload(bad)


class TurnOnly:
    """decision_step double: only the turn in place to `target` (decision's own functions), then hold."""

    def __init__(self, target):
        self.target = target

    def __call__(self, rover):
        nav = rover.nav if isinstance(getattr(rover, "nav", None), decision.NavMemory) else decision.NavMemory()
        rover.nav = nav
        s = decision._read_inputs(rover)
        nav.lead.update(s.t, s.yaw)
        if self.target is not None:
            decision._start_rotation(nav, s, self.target, "test")
            self.target = None
        cmd = decision._fixed_turn_step(nav, s) if nav.fixed is not None else None
        if cmd is None and nav.rotate_heading is not None:
            cmd = decision.mode_stop(nav, s)
        decision._apply(rover, nav, "stop", cmd or decision.Command(0.0, decision.BRAKE_STOP, 0.0), s.t)
        return rover


def _turn_on_twin(target, drop_fixed_turns=False, fixed_turns=True):
    """Run the client's turn on the flat twin (unity timing, 15 fps, 60 ms); returns (client, events, yaw)."""
    twin = RoverTwin(flat_world(), seed=0, render=False)
    loop = TwinLoop(twin, Timing(fps=15, latency_ms=60.0))
    tel = loop.reset(0, start_yaw=START_YAW)
    client = AutonomyClient(insets=False, clock=loop.clock, perception_step=lambda rover: None,
                            decision_step=TurnOnly(target), fixed_turns=fixed_turns)
    events = []
    for _ in range(FRAMES):
        event, payload = client.handle_telemetry(tel)
        events.append(event)
        if drop_fixed_turns and event == "fixed_turn":  # a simulator that ignores it, as when a brake is held
            event, payload = "data", {"throttle": "0", "brake": "0", "steering_angle": "0"}
        tel, _ = loop.step(event, payload)
    return client, events, twin.truth.yaw


@pytest.mark.parametrize("target", [START_YAW + 150.0, START_YAW - 70.0])
def test_a_stopped_rover_turns_to_the_target_with_one_fixed_turn(target):
    client, events, yaw = _turn_on_twin(target % 360.0)
    assert events.count("fixed_turn") == 1
    assert abs(decision.predict.wrap_deg(yaw - target)) < 1.0  # stopped exactly at the target
    assert client.rover.nav.fixed is None and client.rover.nav.rotate_heading is None


def test_a_refused_fixed_turn_falls_back_to_steering():
    target = START_YAW + 120.0
    client, events, yaw = _turn_on_twin(target, drop_fixed_turns=True)
    nav = client.rover.nav
    assert events.count("fixed_turn") == 1 and nav.fixed_refused == 1
    assert abs(decision.predict.wrap_deg(yaw - target)) <= decision.ROTATE_EXIT_DEG + 5.0  # steered there


def test_fixed_turns_off_steers_and_never_sends_one():
    target = START_YAW + 120.0
    client, events, yaw = _turn_on_twin(target, fixed_turns=False)
    assert "fixed_turn" not in events
    assert abs(decision.predict.wrap_deg(yaw - target)) <= decision.ROTATE_EXIT_DEG + 5.0


def test_only_the_arc_a_turn_sweeps_counts_as_swept():
    from navigation import explore

    unsearched = np.zeros((200, 200), bool)
    unsearched[105:107, 100:102] = True  # a nook 5 m north of a rover at (100.5, 100.5) facing east
    pos = (100.5, 100.5)
    assert explore.arc_swept_cells(unsearched, pos, 0.0, 180.0) == 4  # turning left sweeps past north
    assert explore.arc_swept_cells(unsearched, pos, 0.0, -180.0) == 0  # turning right does not
    assert explore.arc_swept_cells(unsearched, pos, 0.0, 60.0) == 0  # the start and end views overlap
    assert explore.arc_swept_cells(None, pos, 0.0, 180.0) == 0
