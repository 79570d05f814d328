"""AutonomyClient: one reply per telemetry, the pickup safety gate, safe stops
on bad frames and crashing steps, clamping, and no NaN on the wire.

Perception and decision are replaced by small doubles defined here, so these
tests pin the client's own behaviour whatever the real modules do."""
import math

import pytest

import autonomy
from autonomy import AutonomyClient, pickup_allowed
from rover_state import RoverState
from tests.test_parsing import telemetry

SAFE = {"throttle": "0.0000", "brake": "1.0000", "steering_angle": "0.0000"}


def no_perception(rover):
    return rover


class Decider:
    """Decision double: sets a fixed command and optionally asks for a pickup."""

    def __init__(self, throttle=0.2, brake=0.0, steer=5.0, pickup=False):
        self.throttle, self.brake, self.steer, self.pickup = throttle, brake, steer, pickup
        self.calls = 0

    def __call__(self, rover):
        self.calls += 1
        rover.throttle, rover.brake, rover.steer = self.throttle, self.brake, self.steer
        rover.send_pickup = self.pickup
        rover.mode = "test"
        return rover


def boom(rover):
    raise RuntimeError("step exploded")


class FakeClock:
    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        return self.t


def client(decider=None, perception=no_perception, insets=False, clock=None):
    return AutonomyClient(clock=clock or FakeClock(), insets=insets,
                          perception_step=perception, decision_step=decider or Decider())


def assert_all_strings(payload):
    assert isinstance(payload, dict)
    for k, v in payload.items():
        assert isinstance(k, str) and isinstance(v, str), (k, v)


# --- reply types ------------------------------------------------------------------
def test_normal_frame_gives_data_with_strings():
    event, payload = client().handle_telemetry(telemetry())
    assert event == "data"
    assert payload == {"throttle": "0.2000", "brake": "0.0000", "steering_angle": "5.0000"}
    assert_all_strings(payload)


@pytest.mark.parametrize("data", [None, {}, "", []])
def test_empty_telemetry_gives_manual(data):
    c = client()
    assert c.handle_telemetry(data) == ("manual", {})


@pytest.mark.parametrize("bad", [
    {"speed": "NaN"}, {"image": "###"}, {"position": "garbage"}, {"yaw": None},
])
def test_bad_frame_gives_safe_stop(bad):
    d = Decider()
    c = client(d)
    event, payload = c.handle_telemetry(telemetry(**bad))
    assert (event, payload) == ("data", SAFE)
    assert d.calls == 0 and c.bad_frames == 1 and not c.rover.telemetry_ok


@pytest.mark.parametrize("data", ["a string", [1, 2, 3], 42, {"unknown": "1"}])
def test_garbage_telemetry_gives_safe_stop(data):
    assert client().handle_telemetry(data) == ("data", SAFE)


def test_crashing_perception_or_decision_gives_safe_stop():
    c = client(perception=boom)
    assert c.handle_telemetry(telemetry()) == ("data", SAFE)
    c = client(decider=boom)
    assert c.handle_telemetry(telemetry()) == ("data", SAFE)
    assert c.step_errors == 1
    # and the next frame is handled normally again once the step recovers
    c.decision_step = Decider()
    assert c.handle_telemetry(telemetry())[0] == "data"


def test_exactly_one_reply_per_call_over_a_mixed_stream():
    c = client(Decider(pickup=True))
    stream = [telemetry(), None, telemetry(speed="NaN"), telemetry(near_sample="1", speed="0.0000"),
              {}, "junk", telemetry()]
    replies = [c.handle_telemetry(d) for d in stream]
    assert len(replies) == len(stream)
    for event, payload in replies:
        assert event in ("data", "pickup", "manual")
        assert_all_strings(payload)
        if event != "data":
            assert payload == {}


# --- clamping / NaN -----------------------------------------------------------------
@pytest.mark.parametrize("steer, sent", [(40.0, "15.0000"), (-99.0, "-15.0000"), (14.5, "14.5000")])
def test_steering_is_clamped(steer, sent):
    _, payload = client(Decider(steer=steer)).handle_telemetry(telemetry())
    assert payload["steering_angle"] == sent


def test_throttle_and_brake_are_clamped():
    _, payload = client(Decider(throttle=7.0, brake=-3.0)).handle_telemetry(telemetry())
    assert payload["throttle"] == "1.0000" and payload["brake"] == "0.0000"


@pytest.mark.parametrize("field", ["throttle", "brake", "steer"])
@pytest.mark.parametrize("value", [math.nan, math.inf, None, "x"])
def test_non_finite_command_becomes_safe_stop(field, value):
    d = Decider()
    setattr(d, field, value)
    event, payload = client(d).handle_telemetry(telemetry())
    assert (event, payload) == ("data", SAFE)


def test_numbers_are_plain_dot_decimals():
    assert autonomy.format_number(-0.0) == "0.0000"
    assert autonomy.format_number(-1e-9) == "0.0000"
    assert autonomy.format_number(0.2) == "0.2000"
    assert autonomy.format_number(-12.34567) == "-12.3457"


# --- pickup gate --------------------------------------------------------------------
def _rover(near=True, vel=0.0, picking=False, total=10.0, last=None):
    r = RoverState()
    r.near_sample, r.vel, r.picking_up, r.total_time, r.pickup_sent_at = near, vel, picking, total, last
    return r


def test_pickup_gate_allows_near_and_stopped():
    assert pickup_allowed(_rover())
    assert pickup_allowed(_rover(vel=autonomy.PICKUP_MAX_SPEED / 2))


@pytest.mark.parametrize("kwargs", [
    dict(near=False), dict(vel=0.5), dict(vel=-0.5), dict(vel=math.nan), dict(picking=True),
    dict(last=9.8),  # just asked
])
def test_pickup_gate_refuses(kwargs):
    assert not pickup_allowed(_rover(**kwargs))


def test_pickup_gate_allows_retry_after_pause():
    assert pickup_allowed(_rover(last=10.0 - autonomy.PICKUP_RETRY_S - 0.1))


def test_client_sends_pickup_only_when_near_and_stopped():
    c = client(Decider(pickup=True))
    # not near -> data (decision's command), never pickup
    assert c.handle_telemetry(telemetry(near_sample="0", speed="0.0000"))[0] == "data"
    # near but moving -> data
    assert c.handle_telemetry(telemetry(near_sample="1", speed="0.8000"))[0] == "data"
    # near, stopped, already picking up -> data
    assert c.handle_telemetry(telemetry(near_sample="1", speed="0.0000", picking_up="1"))[0] == "data"
    # near, stopped, idle -> pickup with an empty payload
    assert c.handle_telemetry(telemetry(near_sample="1", speed="0.0000")) == ("pickup", {})
    # the very next frame (same clock, the sim has not flagged picking_up yet) -> no repeat
    assert c.handle_telemetry(telemetry(near_sample="1", speed="0.0000"))[0] == "data"


def test_no_pickup_unless_decision_asks():
    c = client(Decider(pickup=False))
    assert c.handle_telemetry(telemetry(near_sample="1", speed="0.0000"))[0] == "data"


def test_pickup_never_on_a_bad_frame():
    c = client(Decider(pickup=True))
    event, _ = c.handle_telemetry(telemetry(near_sample="1", speed="0.0000", image="bad"))
    assert event == "data"


# --- clock, first-frame bookkeeping ---------------------------------------------------
def test_sim_time_is_the_clock_when_present():
    clock = FakeClock(1000.0)
    c = client(clock=clock)
    c.handle_telemetry(telemetry(sim_time="2.0000"))
    c.handle_telemetry(telemetry(sim_time="5.5000"))
    assert c.rover.total_time == pytest.approx(3.5)


def test_wall_clock_used_without_sim_time():
    clock = FakeClock(50.0)
    c = client(clock=clock)
    c.handle_telemetry(telemetry(speed="NaN"))  # bad first frame does not start the clock
    clock.t = 51.0
    c.handle_telemetry(telemetry())
    clock.t = 53.5
    c.handle_telemetry(telemetry(sample_count="4"))
    r = c.rover
    assert r.start_time == 51.0 and r.total_time == pytest.approx(2.5)
    assert r.samples_initial == 6 and r.samples_remaining == 4
    assert r.start_pos == pytest.approx((99.67, 85.589))
    assert r.frame_count == 3


def test_timing_hook_reports_stages():
    c = client(insets=True)
    c.handle_telemetry(telemetry())
    assert set(c.last_timings) == set(autonomy.STAGES)
    assert c.last_timings["total"] >= c.last_timings["decode"] >= 0.0


def test_insets_are_added_to_data_replies():
    event, payload = client(insets=True).handle_telemetry(telemetry())
    assert event == "data"
    assert payload["inset_image1"] and payload["inset_image2"]
    assert_all_strings(payload)


def test_failing_insets_still_send_the_command(monkeypatch):
    import supporting_functions

    monkeypatch.setattr(supporting_functions, "create_output_images", boom)
    c = client(insets=True)
    event, payload = c.handle_telemetry(telemetry())
    assert event == "data" and payload["throttle"] == "0.2000" and "inset_image1" not in payload


# --- simulator restart ----------------------------------------------------------------
@pytest.mark.parametrize("restart, why", [
    (dict(position="10.0000;10.0000"), "teleport"),
    (dict(sample_count="6"), "sample count rose"),
    (dict(samples_x="50.00;104.56", samples_y="50.00;80.78"), "new sample position"),
])
def test_simulator_restart_starts_a_new_mission(restart, why):
    c = client()
    c.handle_telemetry(telemetry(sample_count="6"))
    c.handle_telemetry(telemetry(sample_count="5"))
    old = c.rover
    old.worldmap[0, 0, 2] = 255
    assert c.handle_telemetry(telemetry(**restart))[0] == "data"
    assert c.rover is not old, why
    assert c.episodes == 2 and c.rover.worldmap[0, 0, 2] == 0


def test_twin_clock_going_back_is_a_restart():
    c = client()
    c.handle_telemetry(telemetry(sim_time="30.0000"))
    c.handle_telemetry(telemetry(sim_time="0.0000"))
    assert c.episodes == 2 and c.rover.total_time == 0.0


def test_normal_progress_is_not_a_restart():
    c = client()
    c.handle_telemetry(telemetry(sim_time="0.0000"))
    c.handle_telemetry(telemetry(position="100.5000;85.7000", sim_time="0.1000"))
    # a sample collected: fewer samples, lower count
    c.handle_telemetry(telemetry(samples_x="104.56", samples_y="80.78", sample_count="5",
                                 sim_time="0.2000"))
    # garbage sample list then valid again
    c.handle_telemetry(telemetry(samples_x="zz", samples_y="", sample_count="5", sim_time="0.3000"))
    c.handle_telemetry(telemetry(samples_x="104.56", samples_y="80.78", sample_count="5",
                                 sim_time="0.4000"))
    assert c.episodes == 1


def test_return_deadline_reaches_every_mission_and_is_checked_on_the_command_line():
    import drive_rover

    c = AutonomyClient(perception_step=no_perception, decision_step=boom, insets=False, home_by_s=870.0)
    assert c.rover.home_by_s == 870.0
    c.handle_telemetry(telemetry(sim_time="30.0000"))
    c.handle_telemetry(telemetry(sim_time="0.0000"))  # the simulator restarted: a new RoverState
    assert c.episodes == 2 and c.rover.home_by_s == 870.0
    assert AutonomyClient(perception_step=no_perception, decision_step=boom).rover.home_by_s is None
    assert drive_rover.parse_args(["--home-by", "870"]).home_by == 870.0
    assert drive_rover.parse_args([]).home_by is None
    for bad in ("0", "-1", "nan", "inf", "soon"):
        with pytest.raises(SystemExit):
            drive_rover.parse_args(["--home-by", bad])


def test_warm_up_compiles_the_kernels_and_leaves_the_client_untouched():
    import perception
    from navigation import reactive

    client = AutonomyClient()
    rover = client.rover
    seconds = client.warm_up()
    assert seconds >= 0.0
    assert client.rover is rover and rover.frame_count == 0 and getattr(rover, "perception_memory", None) is None
    assert perception._pixel_labels_kernel.signatures and perception._vote_kernel.signatures
    assert reactive._bin_extremes.signatures  # the driving frame's binning too
