"""drive_rover.py's first-contact monitor: what it says, and when."""
import logging

from link_status import NO_CONNECTION_S, NO_TELEMETRY_S, STATUS_EVERY_S, TELEMETRY_GAP_S, LinkStatus
from rover_state import RoverState


def _messages(lines):
    return [m for _, m in lines]


def test_connected_but_silent_says_what_to_check_once():
    s = LinkStatus(0.0, "127.0.0.1:4567", "python-socketio 5.0, python-engineio 4.0")
    s.on_connect(1.0)
    assert s.tick(1.0 + NO_TELEMETRY_S - 0.1) == []
    lines = s.tick(1.0 + NO_TELEMETRY_S)
    assert [lvl for lvl, _ in lines] == [logging.WARNING]
    text = lines[0][1]
    assert "no telemetry" in text and "Autonomous Mode" in text and "python-socketio 5.0" in text
    assert s.tick(30.0) == []  # said once per connection


def test_status_line_while_driving_then_gap_then_resume():
    s = LinkStatus(0.0)
    rover = RoverState()
    rover.samples_initial, rover.samples_remaining = 6, 4
    s.on_connect(0.0)
    t = 0.0
    while t < STATUS_EVERY_S + 0.01:
        s.on_telemetry(t, 2.0)
        t += 0.04
    lines = s.tick(t, rover)
    assert len(lines) == 1 and lines[0][0] == logging.INFO
    assert "25.0 telemetry/s" in lines[0][1] and "reply 2.0 ms median" in lines[0][1]
    assert "mode forward" in lines[0][1] and "collected 2/6" in lines[0][1] and "mapped n/a" in lines[0][1]
    gap = s.tick(t + TELEMETRY_GAP_S, rover)
    assert len(gap) == 1 and "no telemetry for 3 s" in gap[0][1]
    assert s.tick(t + 10, rover) == []  # once per gap
    s.on_telemetry(t + 11, 2.0)  # resumes: the next gap is reported again
    assert s.tick(t + 11 + TELEMETRY_GAP_S, rover)
    s.on_telemetry(t + 20, 2.0)
    s.on_disconnect(t + 20)  # a closed simulator is not a stalled one
    assert s.tick(t + 30, rover) == []


def test_nothing_connects():
    s = LinkStatus(0.0, "127.0.0.1:4567")
    assert s.tick(NO_CONNECTION_S - 1) == []
    (level, text), = s.tick(NO_CONNECTION_S)
    assert level == logging.WARNING and "127.0.0.1:4567" in text and "firewall" in text
