"""The wire guards without a socket: which frames reach engineio, how each
Socket.IO packet is classified, the Host check, the session's mailbox
(flood: one reply per telemetry, the newest handled), restart detection near
the start, and writes that fail on a full disk (injected) without litter.
Over the real websocket: tests/test_wire_faults.py."""
import errno
import json
import os

import numpy as np
import pytest

import autonomy
import drive_rover
import safe_write
import wire_guard
import wire_server
from autonomy import AutonomyClient
from replay.log_format import LogWriter, read_log
from tests.test_parsing import telemetry
from wire_guard import IGNORE, TELEMETRY, classify_message
from wire_server import Driver, Mailbox, Session


# --- engine.io frames -------------------------------------------------------------------
@pytest.mark.parametrize("frame", ["2", "3", "42[]", "1", "4"])
def test_engineio_frames_the_simulator_sends_pass(frame):
    assert wire_guard.engineio_frame_verdict(frame) is None


@pytest.mark.parametrize("frame", ["b", "bZZ", "b4AAAA", "", "0", "5", "6", "7", "9abc", "\x00\xff",
                                   b"", b"\x04abc", bytearray(b"\x01")])
def test_engineio_frames_that_break_engineio_are_dropped(frame):
    assert wire_guard.engineio_frame_verdict(frame)


def test_guarded_websocket_skips_dropped_frames():
    class FakeWs:
        frames = ["b", b"\x01\x02", "bZZ", "42[\"telemetry\",{}]", None]
        timeout_set = "yes"

        def wait(self):
            return self.frames.pop(0)

    drops = []
    ws = wire_guard.GuardedWebSocket(FakeWs(), drops.append)
    assert ws.wait() == '42["telemetry",{}]'
    assert ws.wait() is None
    assert drops == ["base64 binary frame", "binary frame", "base64 binary frame"]
    assert ws.timeout_set == "yes"  # everything else is the wrapped websocket


# --- Socket.IO packets --------------------------------------------------------------------
@pytest.mark.parametrize("text", ['2["telemetry",{"speed":"1"}]', '2["telemetry"]',
                                  '2[ "telemetry" ,{}]', '2/,["telemetry",{}]', '27["telemetry",{}]',
                                  '2["telemetry",{"speed":',  # truncated: still owed a reply
                                  '2["telemetry",' + "[" * 5000 + "]" * 5000 + "]",  # too deep to decode
                                  '2["telem\\u0065try",{}]'])
def test_telemetry_is_recognised_even_when_it_does_not_decode(text):
    kind, body = classify_message(text)
    assert kind == TELEMETRY
    assert text.endswith(body)


@pytest.mark.parametrize("text, reason", [
    ("5", "BINARY_EVENT"), ("6", "BINARY_ACK"), ('51-["telemetry",{"_placeholder":true,"num":0}]', "BINARY_EVENT"),
    ("1", "DISCONNECT"), ("0", "CONNECT"), ("0/", "CONNECT"), ("3", "ACK"), ("4", "ERROR"),
    ("9", "type"), ("", "empty"), (b"\x00", "binary"),
    ('2["get_samples",{}]', "unknown event"), ('2[1,2]', "malformed"), ('2"x"', "malformed"), ("2{}", "malformed"),
    ('2/other,["telemetry",{}]', "namespace"), ("2" + "[" * 5000, "malformed"), ("2" + "1" * 40 + "[]", "ack id"),
])
def test_everything_else_is_ignored_with_a_reason(text, reason):
    kind, why = classify_message(text)
    assert kind == IGNORE and reason in why


@pytest.mark.parametrize("body, expected", [('["telemetry",{"a":"1"}]', {"a": "1"}), ('["telemetry"]', None),
                                            ('["telemetry","x","y"]', "x")])
def test_telemetry_argument(body, expected):
    assert wire_guard.telemetry_argument(body) == expected


@pytest.mark.parametrize("body", ['["telemetry",{', '["telemetry",' + "[" * 100000 + "]" * 100000 + "]", "{}", "[]"])
def test_undecodable_telemetry_is_bad(body):
    with pytest.raises(wire_guard.BadTelemetry):
        wire_guard.telemetry_argument(body)


# --- Host names ------------------------------------------------------------------------------
@pytest.mark.parametrize("header, name", [("127.0.0.1:4567", "127.0.0.1"), ("localhost", "localhost"),
                                          ("LocalHost.:4567", "localhost"), ("[::1]:4567", "::1"),
                                          ("[::1]", "::1"), ("evil.example:4567", "evil.example"),
                                          ("", None), (None, None), ("a:b:c", None), ("[::1]x", None),
                                          ("host:port", None)])
def test_host_name(header, name):
    assert wire_guard.host_name(header) == name


def _call(app, host):
    seen = {}
    environ = {} if host is None else {"HTTP_HOST": host}
    body = app(environ, lambda status, headers: seen.setdefault("status", status))
    return seen.get("status", "200 OK"), b"".join(body)


@pytest.mark.parametrize("host, ok", [("127.0.0.1:4567", True), ("localhost:4567", True), ("[::1]:4567", True),
                                      ("rover-box:4567", True), ("evil.example:4567", False),
                                      ("127.0.0.1.evil.example", False), ("", False), (None, False),
                                      ("0.0.0.0:4567", False)])
def test_host_check_serves_loopback_and_bind_names_only(host, ok):
    refused = []
    app = wire_guard.HostCheck(lambda env, sr: [b"served"], wire_guard.allowed_host_names(["rover-box"]),
                               on_refuse=refused.append)
    status, body = _call(app, host)
    assert (body == b"served") == ok
    assert status.startswith("200" if ok else "403")
    assert bool(refused) != ok


def test_bind_address_is_an_allowed_host():
    assert "::1" in wire_guard.allowed_host_names([])
    assert "0.0.0.0" in wire_guard.allowed_host_names(["0.0.0.0"])
    assert "fe80::1" in wire_guard.allowed_host_names(["fe80::1"])


# --- mailbox and session (flood) ----------------------------------------------------------
def test_mailbox_keeps_only_the_newest_frame():
    box = Mailbox()
    assert box.take() is None
    for i in range(1000):
        box.put(f"frame {i}")
    assert box.take() == ("frame 999", 999)
    assert box.take() is None and box.peak == 1000


class CountingClient:
    """An AutonomyClient double that records which frames it was asked to handle."""

    def __init__(self, reply=("data", {"throttle": "0.5000", "brake": "0.0000", "steering_angle": "3.0000",
                                       "inset_image1": "big"})):
        self.handled = []
        self.reply = reply
        self.bad_frames = 0
        self.last_telemetry = None
        self.rover = None

    def handle_telemetry(self, data):
        self.handled.append(data)
        return self.reply


class Wake:
    def set(self):
        pass


def _session(client):
    sent = []
    session = Session("sid", Driver(client), lambda event, payload: sent.append((event, payload)), Wake())
    return session, sent


def _frame(i):
    return "2" + json.dumps(["telemetry", {"frame": str(i)}])


def test_flood_answers_every_telemetry_once_and_handles_only_the_newest():
    client = CountingClient()
    session, sent = _session(client)
    session.on_message(_frame(0))
    assert session.serve_once() == 1
    for i in range(1, 1001):
        session.on_message(_frame(i))
    session.on_message('2["get_samples",{}]')  # not telemetry: no reply
    assert session.serve_once() == 1000
    assert len(sent) == 1001 and session.serve_once() == 0
    assert client.handled == [{"frame": "0"}, {"frame": "1000"}]  # the newest, never the backlog
    stale = sent[1:-1]
    assert all(reply == ("data", {"throttle": "0.5000", "brake": "0.0000", "steering_angle": "3.0000"})
               for reply in stale)  # the last command, without insets
    assert session.telemetry == 1001 and session.full == 2 and session.stale == 999
    assert sum(session.ignored.values()) == 1 and "999 answered with the last command" in session.summary()


def test_stale_frames_never_repeat_a_pickup_and_start_with_a_safe_stop():
    client = CountingClient(reply=("pickup", {}))
    session, sent = _session(client)
    for i in range(3):
        session.on_message(_frame(i))
    session.serve_once()
    assert [event for event, _ in sent] == ["data", "data", "pickup"]
    assert sent[0][1]["brake"] == "1.0000"  # no command yet: a safe stop


def test_undecodable_telemetry_gets_a_safe_stop():
    client = CountingClient()
    session, sent = _session(client)
    session.on_message('2["telemetry",' + "[" * 3000 + "]" * 3000 + "]")
    session.serve_once()
    assert sent == [("data", {"throttle": "0.0000", "brake": "1.0000", "steering_angle": "0.0000"})]
    assert client.handled == [] and client.bad_frames == 1


# --- restart near the start -------------------------------------------------------------
class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def _client(clock):
    return AutonomyClient(clock=clock, insets=False, perception_step=lambda rover: None,
                          decision_step=lambda rover: None)


def test_restart_near_the_start_with_the_same_samples_is_a_new_mission():
    clock = Clock()
    c = _client(clock)
    x = 99.67
    for _ in range(40):  # drive 8 m east at 4 m/s, 20 frames/s
        c.handle_telemetry(telemetry(position=f"{x:.4f};85.5890", speed="4.0000"))
        clock.t += 0.05
        x += 0.2
    assert c.episodes == 1
    c.handle_telemetry(telemetry(position="99.6700;85.5890", speed="0.0000"))  # reloaded: back at the start
    assert c.episodes == 2 and c.rover.start_pos == pytest.approx((99.67, 85.589))


def test_a_long_pause_then_a_plausible_move_is_not_a_restart():
    clock = Clock()
    c = _client(clock)
    c.handle_telemetry(telemetry(position="99.6700;85.5890"))
    clock.t += 3.0  # the client stalled for 3 s while the rover drove on at 4 m/s
    c.handle_telemetry(telemetry(position="111.6700;85.5890"))
    clock.t += 0.05
    c.handle_telemetry(telemetry(position="111.8700;85.5890"))
    assert c.episodes == 1


def test_teleport_limits_are_named_constants():
    assert autonomy.TELEPORT_SPEED_M_S >= 5.0  # never below the simulator's speed clamp
    assert 0 < autonomy.TELEPORT_SLACK_M < autonomy.RESET_JUMP_M


# --- full disk (injected) -----------------------------------------------------------------
class DiskQuota:
    """Replaces safe_write.os_write: writes succeed until ``budget`` bytes are
    used, then the one that crosses it is short and the next raises ENOSPC,
    as a full file system does."""

    def __init__(self, budget):
        self.budget = budget

    def __call__(self, fd, data):
        if self.budget <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        n = min(len(data), self.budget)
        written = os.write(fd, bytes(data[:n]))
        self.budget -= written
        return written


def _litter(folder):
    return sorted(p.name for p in folder.rglob("*") if p.name.endswith(".tmp"))


def test_atomic_write_on_a_full_disk_leaves_the_old_file_and_no_temp(tmp_path, monkeypatch):
    target = tmp_path / "map.npy"
    target.write_bytes(b"old")
    monkeypatch.setattr(safe_write, "os_write", DiskQuota(10))
    with pytest.raises(OSError):
        safe_write.atomic_write(target, b"x" * 100)
    assert target.read_bytes() == b"old" and _litter(tmp_path) == []


def test_append_on_a_full_disk_cuts_back_the_half_line(tmp_path, monkeypatch):
    f = safe_write.AppendFile(tmp_path / "log.csv")
    f.append(b"header\r\n")
    monkeypatch.setattr(safe_write, "os_write", DiskQuota(5))
    with pytest.raises(OSError):
        f.append(b"a long row that does not fit\r\n")
    f.close()
    assert (tmp_path / "log.csv").read_bytes() == b"header\r\n"


def test_recording_on_a_full_disk_leaves_no_temp_files_and_a_readable_log(tmp_path, monkeypatch):
    jpeg = bytes(range(256)) * 20  # 5 KB a frame
    writer = LogWriter(tmp_path / "rec")
    quota = DiskQuota(3 * len(jpeg) + 2000)
    monkeypatch.setattr(safe_write, "os_write", quota)
    failed = 0
    for i in range(400):
        try:
            writer.write(jpeg, 0, 0.2, 0, 1.0, 100 + i * 0.01, 85, 0, 56, 0)
        except OSError as exc:
            assert exc.errno == errno.ENOSPC
            failed += 1
    quota.budget = 10 ** 9  # space freed: recording goes on
    writer.write(jpeg, 0, 0.2, 0, 1.0, 110, 85, 0, 56, 0)
    writer.close()
    assert failed >= 390 and _litter(tmp_path) == []
    data = read_log(writer.folder)
    assert data.skipped == 0 and data.corrupt_rows == 0
    assert len(data.frames) == writer.frames == len(list(writer.img_dir.iterdir()))  # rows and images agree


def test_recorder_thread_survives_a_full_disk(tmp_path, monkeypatch):
    from supporting_functions import parse_telemetry

    rec = drive_rover.Recorder(tmp_path / "rec")
    monkeypatch.setattr(safe_write, "os_write", DiskQuota(0))
    tel = parse_telemetry(telemetry())
    for _ in range(20):
        rec.submit(tel)
    rec.close()
    assert rec.errors + rec.dropped == 20 and _litter(tmp_path) == []


class Rover:
    frame_count = 100
    worldmap = np.full((200, 200, 3), 7, np.uint8)


def test_save_map_on_a_full_disk_leaves_no_temp_and_recovers(tmp_path, monkeypatch):
    saver = drive_rover.MapSaver(tmp_path / "out" / "map.npy")
    quota = DiskQuota(1000)
    monkeypatch.setattr(safe_write, "os_write", quota)
    saver.save(Rover())  # fails: logged, no exception, no litter
    assert _litter(tmp_path) == [] and not saver.path.exists()
    quota.budget = 10 ** 9
    saver.maybe_save(Rover())
    assert np.load(saver.path).shape == (200, 200, 3)


def test_save_map_refuses_a_folder_and_foreign_files(tmp_path):
    with pytest.raises(ValueError, match="is a folder"):
        drive_rover.MapSaver(tmp_path)
    notes = tmp_path / "notes.txt"
    notes.write_text("precious")
    with pytest.raises(ValueError, match=r"\.npy"):
        drive_rover.MapSaver(notes)
    fake = tmp_path / "fake.npy"
    fake.write_text("not numpy")
    with pytest.raises(ValueError, match="not a NumPy"):
        drive_rover.MapSaver(fake)
    assert notes.read_text() == "precious" and fake.read_text() == "not numpy"
    ours = tmp_path / "ours.npy"
    np.save(ours, np.zeros(3))
    drive_rover.MapSaver(ours).save(Rover())  # our own earlier dump is replaced
    assert np.load(ours).shape == (200, 200, 3) and _litter(tmp_path) == []


def test_save_map_target_that_became_a_folder_leaves_no_temp(tmp_path):
    saver = drive_rover.MapSaver(tmp_path / "map.npy")
    (tmp_path / "map.npy").mkdir()  # someone made a folder there while we run
    saver.save(Rover())
    assert _litter(tmp_path) == []


@pytest.mark.parametrize("target, message", [("dir", "is a folder"), ("notes.txt", ".npy")])
def test_save_map_bad_target_exits_with_a_clear_error(tmp_path, monkeypatch, capsys, target, message):
    (tmp_path / "dir").mkdir()
    (tmp_path / "notes.txt").write_text("x")
    monkeypatch.setattr(drive_rover, "require_compatible_versions", lambda: None)
    monkeypatch.setattr(drive_rover, "load_ground_truth_arg", lambda value: None)
    with pytest.raises(SystemExit) as exc:
        drive_rover.main(["--port", "0", "--save-map", str(tmp_path / target)])
    err = capsys.readouterr().err
    assert exc.value.code == 2  # a bad option: one line naming it, exit 2, like every CLI here
    assert "error: --save-map:" in err and message in err


# --- websocket unmasking ------------------------------------------------------------------------
@pytest.mark.filterwarnings("ignore:.*Eventlet is deprecated")
def test_fast_mask_matches_eventlets_byte_loop():
    import random

    from eventlet.websocket import RFC6455WebSocket

    def slow(data, mask, length=None, offset=0):  # eventlet 0.41's loop, for reference
        length = len(data) if length is None else length
        return b"".join(bytes((data[i] ^ mask[(offset + i) % 4],)) for i in range(length))

    rng = random.Random(3)
    for _ in range(200):
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 300)))
        mask = bytes(rng.randrange(256) for _ in range(4)) if rng.random() < 0.5 else \
            [rng.randrange(256) for _ in range(4)]
        offset = rng.randrange(0, 9)
        length = rng.choice([None, len(data), max(0, len(data) - 3)])
        assert wire_guard.fast_apply_mask(data, mask, length, offset) == slow(data, mask, length, offset)
    wire_guard.install_fast_websocket_mask()
    assert RFC6455WebSocket._apply_mask(b"\x00\x01", b"\x0f\x0f\x0f\x0f") == b"\x0f\x0e"


def test_a_flooding_reader_steps_aside_for_the_worker():
    class StepClock:
        t = 0.0

        def __call__(self):
            self.t += 0.005
            return self.t

    pauses = []
    session = Session("sid", Driver(CountingClient()), lambda *a: None, Wake(),
                      pause=lambda: pauses.append(1), clock=StepClock())
    for i in range(100):
        session.on_message(_frame(i))
    expected = 100 * 0.005 / wire_server.READER_SLICE_S  # once per slice of reading, not every frame
    assert expected - 2 <= len(pauses) <= expected + 2


def test_ignore_reasons_do_not_grow_with_invented_names():
    texts = [f'2["event-{i}",{{}}]' for i in range(500)] + [f"{chr(0x4e00 + i)}" for i in range(500)]
    reasons = {classify_message(t)[1] for t in texts}
    frames = {wire_guard.engineio_frame_verdict(chr(0x4e00 + i)) for i in range(500)}
    assert len(reasons) <= 2 and len(frames) == 1


def test_session_worker_survives_an_error_and_keeps_answering():
    sent = []

    def send(event, payload):
        if not sent:
            sent.append("boom")
            raise RuntimeError("socket went away mid-send")
        sent.append(event)

    class ScriptedWake:
        """wait() feeds one frame per call, then closes the session."""

        def __init__(self):
            self.session, self.calls = None, 0

        def wait(self):
            self.calls += 1
            if self.calls > 2:
                self.session.close()
            else:
                self.session.mailbox.put(_frame(self.calls)[1:])

        def clear(self):
            pass

        def set(self):
            pass

    wake = ScriptedWake()
    session = Session("sid", Driver(CountingClient()), send, wake)
    wake.session = session
    session.run()
    assert sent == ["boom", "data"]  # the second frame was answered after the first failed
