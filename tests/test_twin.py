"""RoverTwin: telemetry exactly like the simulator, samples/pickup, commands, bad input."""
import math

import numpy as np
import pytest

from sim.samples import NEAR_AHEAD_M, PICKUP_DURATION_S
from sim.twin import CommandError, RoverTwin, format_angle_0_360, format_n
from sim.world import World

FIELDS = ["steering_angle", "throttle", "brake", "speed", "position", "pitch", "yaw", "roll",
          "near_sample", "picking_up", "sample_count", "samples_x", "samples_y", "image"]  # as the real one


def _flat_world():
    spots = np.array([[100.0 + 10 * i, 60.0 + 5 * i] for i in range(10)])
    return World(terrain_height=np.zeros((513, 513), np.float32),
                 sand_weight=np.ones((512, 512), np.float32),
                 rock_top=np.zeros((2001, 2001), np.float32),
                 rock_bottom=np.zeros((2001, 2001), np.float32),
                 nav_truth=np.full((200, 200), 255, np.uint8), sample_spots=spots,
                 start_xy=(100.0, 100.0), start_yaw_training=0.0, name="flat-test")


@pytest.fixture(scope="module")
def world():
    return _flat_world()


@pytest.fixture()
def twin(world):
    return RoverTwin(world, seed=3, render=False)


def _data(throttle="0", steer="0", brake=None):
    d = {"throttle": throttle, "steering_angle": steer}
    if brake is not None:
        d["brake"] = brake
    return d


def _run(twin, seconds, event="manual", payload=None):
    tel = None
    for _ in range(int(round(seconds / twin.frame_dt))):
        tel = twin.step(event, payload if payload is not None else {})
    return tel


def test_number_formatting_mirrors_dotnet_n4():
    assert format_n(1.23456) == "1.2346"
    assert format_n(1234.56789) == "1,234.5679"
    assert format_n(-0.00001) == "0.0000"
    assert format_n(-1.5) == "-1.5000"
    assert format_n(3.14159, 2) == "3.14"
    assert format_angle_0_360(-0.5) == "359.5000"
    assert format_angle_0_360(370.25) == "10.2500"


def test_telemetry_fields_are_strings_in_simulator_order(twin):
    tel = twin.reset(3)
    assert list(tel) == FIELDS
    assert all(isinstance(v, str) for v in tel.values())
    assert tel["sample_count"] == "6"
    assert len(tel["samples_x"].split(";")) == 6
    assert tel["speed"] == "0.0000" and tel["picking_up"] == "0"
    x, y = (float(v) for v in tel["position"].split(";"))
    assert (x, y) == (100.0, 100.0)
    assert tel["image"] and "sim_time" not in tel  # the real simulator sends no clock


def test_seed_sets_samples_and_start_yaw(world):
    a, b, c = (RoverTwin(world, seed=s, render=False) for s in (1, 1, 2))
    assert a.reset(1) == b.reset(1)
    ta, tc = a.truth, c.truth
    assert ta.yaw != tc.yaw
    xy = {(s.x, s.y) for s in ta.samples}
    assert len(xy) == 6 and xy <= {tuple(p) for p in world.sample_spots}
    assert all(0.36 <= s.scale <= 0.5 for s in ta.samples)


def test_driving_reverse_and_sticky_commands(twin):
    twin.reset(3, start_yaw=0.0)
    twin.step("data", _data("1"))
    tel = _run(twin, 2.0)  # `manual` sends nothing: the throttle stays applied
    assert float(tel["speed"]) > 1.0 and tel["throttle"] == "1.0000"
    assert twin.sim_time == pytest.approx(2.04, abs=1e-6)
    twin.step("data", _data("0", brake="10"))
    tel = _run(twin, 1.0)
    assert tel["speed"] == "0.0000"
    tel = _run(twin, 1.0, "data", _data("-1"))
    assert float(tel["speed"]) < -0.3  # negative in reverse
    tel = twin.step("data", _data("0", steer="40", brake="1"))
    assert tel["steering_angle"] == "15.0000"  # echoed clamped


def test_pickup_freezes_ten_seconds_then_removes_sample(twin):
    twin.reset(3, start_yaw=0.0)
    smp = twin.samples[0]
    st = twin.physics.state
    st.x, st.y, st.yaw = smp.x - NEAR_AHEAD_M - 0.2, smp.y, 0.0
    tel = twin.step("manual", {})
    assert tel["near_sample"] == "1"
    twin.step("data", _data("1"))
    tel = twin.step("pickup", {})
    assert tel["picking_up"] == "1" and tel["speed"] == "0.0000"
    x0 = twin.truth.x
    frames, tel = 1, None
    while True:
        tel = twin.step("manual", {})
        frames += 1
        if tel["sample_count"] == "5":
            break
        assert tel["picking_up"] == "1" and frames < 400
    assert frames * twin.frame_dt == pytest.approx(PICKUP_DURATION_S, abs=2 * twin.frame_dt)
    assert twin.truth.x == pytest.approx(x0)  # frozen although throttle was 1
    assert tel["picking_up"] == "1" and tel["near_sample"] == "0"
    assert len(tel["samples_x"].split(";")) == 5
    tel = twin.step("manual", {})
    assert tel["picking_up"] == "0"
    assert len(twin.truth.collected) == 1
    tel = _run(twin, 1.0)
    assert float(tel["speed"]) > 0.3  # sticky throttle drives again


def test_blind_pickup_freezes_forever(twin):
    twin.reset(3)
    twin.step("data", _data("1"))
    tel = twin.step("pickup", {})
    assert tel["picking_up"] == "1"
    x0 = twin.truth.x
    tel = _run(twin, 30.0, "data", _data("1"))
    assert tel["picking_up"] == "1" and tel["speed"] == "0.0000" and tel["sample_count"] == "6"
    assert twin.truth.x == x0 and twin.truth.pickup_stuck


def test_fixed_turn_only_when_still_and_clockwise(twin):
    twin.reset(3, start_yaw=90.0)
    twin.step("fixed_turn", {"angle": "45", "time": "1"})
    tel = _run(twin, 1.5)
    assert float(tel["yaw"]) == pytest.approx(45.0, abs=0.01)
    twin.step("data", _data("1"))
    _run(twin, 1.0)
    yaw = twin.truth.yaw
    twin.step("fixed_turn", {"angle": "90"})  # moving: ignored, but answered
    assert twin.truth.yaw == pytest.approx(yaw, abs=0.01)


def test_fixed_turn_refused_while_the_brake_is_held(twin):
    """Unity counts a nonzero brake as motor input, and FixedTurn wants none."""
    twin.reset(3, start_yaw=90.0)
    twin.step("data", _data(brake="1"))
    twin.step("fixed_turn", {"angle": "45", "time": "1"})
    assert float(_run(twin, 1.5)["yaw"]) == pytest.approx(90.0, abs=0.01)
    twin.step("data", _data())
    twin.step("fixed_turn", {"angle": "45", "time": "1"})
    assert float(_run(twin, 1.5)["yaw"]) == pytest.approx(45.0, abs=0.01)


def test_fixed_turn_ignores_data_while_it_runs_and_signs_need_to_match(twin):
    twin.reset(3, start_yaw=90.0)
    twin.step("fixed_turn", {"angle": "-90", "time": "-0.5"})  # counter-clockwise at 180 deg/s
    tel = _run(twin, 0.2, "data", _data("1"))  # ignored while turning
    assert float(tel["speed"]) == 0.0 and 90.0 < float(tel["yaw"]) < 180.0
    twin.step("data", _data())
    assert float(_run(twin, 0.6)["yaw"]) == pytest.approx(180.0, abs=0.01)
    # angle and time of opposite signs: a negative speed that never reaches its target
    twin.step("fixed_turn", {"angle": "-90", "time": "1"})
    for _ in range(3):
        yaw = float(_run(twin, 2.0)["yaw"])
        assert abs(((yaw - 270.0) + 180.0) % 360.0 - 180.0) > 45.0
    assert twin.physics.state.fixed_turning


@pytest.mark.parametrize("event,payload", [
    ("data", {"throttle": 0.5, "steering_angle": "0"}),  # JSON number
    ("data", {"throttle": "abc", "steering_angle": "0"}),
    ("data", {"throttle": "NaN", "steering_angle": "0"}),
    ("data", {"throttle": "1", "steering_angle": "inf"}),
    ("data", {"throttle": "1"}),  # steering missing
    ("data", {"throttle": "1", "steering_angle": "0", "brake": None}),
    ("data", ["1", "0"]),
    ("data", "garbage"),
    ("fixed_turn", {"angle": 30}),
    ("get_samples", {}),
    (None, None),
])
def test_bad_commands_raise_and_leave_state_unchanged(twin, event, payload):
    twin.reset(3)
    twin.step("data", _data("1"))
    before = (twin.sim_time, twin.frame, twin.truth.x, twin.controls)
    with pytest.raises(CommandError):
        twin.step(event, payload)
    assert (twin.sim_time, twin.frame, twin.truth.x, twin.controls) == before
    assert twin.rejected_commands == 1
    tel = twin.step("manual", {})  # and the twin carries on
    assert float(tel["speed"]) > 0


def test_brake_is_optional_and_comma_thousands_parse_like_dotnet(twin):
    twin.reset(3)
    tel = twin.step("data", {"throttle": " 0.5 ", "steering_angle": "-3"})
    assert tel["brake"] == "0.0000" and tel["throttle"] == "0.5000"
    tel = twin.step("data", {"throttle": "0", "steering_angle": "0", "brake": "1,0"})
    assert tel["brake"] == "10.0000"  # en-US float.Parse reads ',' as a group separator


def test_rendered_frame_is_a_jpeg(world_dir):
    pytest.importorskip("sim.render")
    import base64

    import cv2

    from sim.world import load_world

    twin = RoverTwin(load_world("real"), seed=0)
    tel = twin.step("data", _data("0.5"))
    img = cv2.imdecode(np.frombuffer(base64.b64decode(tel["image"]), np.uint8), cv2.IMREAD_COLOR)
    assert img is not None and img.shape == (160, 320, 3)
    assert not math.isnan(float(tel["pitch"]))


def test_fuzzed_commands_never_crash_and_telemetry_stays_finite(twin):
    rng = np.random.default_rng(0)
    values = ["1e308", "-1e308", "0", "1", "-1", "15", "1e-320", "", " ", "nan", "1,5", "0x10",
              "\u0661", "--1", 1, None, [], {}, True, "1e400"]
    events = ["data", "pickup", "manual", "fixed_turn", "steer", "", None, 5]
    twin.reset(0)
    for _ in range(400):
        event = events[rng.integers(len(events))]
        payload = {k: values[rng.integers(len(values))]
                   for k in ("throttle", "steering_angle", "brake", "angle", "time")
                   if rng.random() < 0.8}
        try:
            tel = twin.step(event, payload)
        except CommandError:
            continue
        assert all(isinstance(v, str) for v in tel.values())
        for key in ("speed", "pitch", "yaw", "roll"):
            assert math.isfinite(float(tel[key].replace(",", "")))
        x, y = (float(v.replace(",", "")) for v in tel["position"].split(";"))
        assert 0.0 <= x <= 200.0 and 0.0 <= y <= 200.0
