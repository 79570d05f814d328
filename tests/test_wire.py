"""drive_rover.py on the wire, against a raw-frame client that behaves exactly
like the Unity simulator: websocket straight to
``/socket.io/?EIO=4&transport=websocket`` (no polling), never sends ``40``,
pings with ``2``, sends ``42["telemetry",{...}]`` with string values built
from real test_dataset frames.  A python-socketio client would not do: it
connects to servers the simulator cannot use (see socketio-compat.md)."""
import base64
import time
import urllib.request
from pathlib import Path

import pytest

websocket = pytest.importorskip("websocket")

import drive_rover  # noqa: E402
from benchmarks.frame import sim_telemetry  # noqa: E402
from wire_client import RECV_TIMEOUT_S, FakeSimulator, Server, assert_command, server_and_sim_fixtures  # noqa: E402

N_FRAMES = 12  # real frames sent per lockstep test


@pytest.fixture(scope="module")
def frames(test_dataset_dir):
    from replay.log_format import read_log

    data = read_log(test_dataset_dir)
    picked = data.frames[:: max(1, len(data.frames) // N_FRAMES)][:N_FRAMES]
    return [(f, Path(f.image_path).read_bytes()) for f in picked]


server, sim = server_and_sim_fixtures("wire")


# --- protocol ------------------------------------------------------------------------
def test_handshake_is_engineio3(sim):
    assert sim.handshake["pingInterval"] == 25000
    assert "sid" in sim.handshake


def test_ping_pong(sim):
    sim.ws.send("2")
    deadline = time.monotonic() + RECV_TIMEOUT_S
    while sim.pongs == 0 and time.monotonic() < deadline:
        frame = sim.recv_frame()
        if frame == "3":
            sim.pongs += 1
    assert sim.pongs == 1


@pytest.mark.parametrize("locale", ["en-US", "de-DE"])
def test_lockstep_real_frames(sim, frames, locale):
    """Each telemetry gets exactly one reply before the next is sent."""
    for i, (frame, jpeg) in enumerate(frames):
        sim.send_telemetry(sim_telemetry(frame, jpeg, locale))
        name, payload = sim.recv_event()
        assert_command(name, payload)
        if name == "data" and i == 0:
            for key in ("inset_image1", "inset_image2"):
                raw = base64.b64decode(payload[key], validate=True)
                assert raw[:2] == b"\xff\xd8"
    sim.assert_quiet()


def test_pipelined_telemetry_gets_one_reply_each(sim, frames):
    for frame, jpeg in frames[:3]:
        sim.send_telemetry(sim_telemetry(frame, jpeg))
    for _ in range(3):
        assert_command(*sim.recv_event())
    sim.assert_quiet()


@pytest.mark.parametrize("data", [None, {}])
def test_empty_telemetry_gets_manual(sim, data):
    sim.send_telemetry(data)
    assert sim.recv_event() == ("manual", {})
    sim.assert_quiet()


def test_telemetry_without_argument_still_answered(sim):
    sim.ws.send('42["telemetry"]')
    assert sim.recv_event() == ("manual", {})


# --- bad input ---------------------------------------------------------------------
@pytest.mark.parametrize("override", [
    {"speed": "NaN"}, {"speed": "Infinity"}, {"image": "not-an-image"}, {"position": "x;y"},
    {"yaw": 12.5},  # a JSON number instead of a string: tolerated
])
def test_bad_values_get_a_safe_answer(sim, frames, override):
    frame, jpeg = frames[0]
    data = sim_telemetry(frame, jpeg)
    data.update(override)
    sim.send_telemetry(data)
    name, payload = sim.recv_event()
    assert_command(name, payload)
    if "yaw" not in override:
        assert payload == {"throttle": "0.0000", "brake": "1.0000", "steering_angle": "0.0000"}


def test_wrong_image_size_is_answered(sim, frames):
    import cv2
    import numpy as np

    frame, _ = frames[0]
    ok, buf = cv2.imencode(".jpg", np.zeros((100, 100, 3), np.uint8))
    sim.send_telemetry(sim_telemetry(frame, buf.tobytes()))
    name, payload = sim.recv_event()
    assert name == "data" and payload["brake"] == "1.0000"


@pytest.mark.parametrize("garbage", ['42["telemetry",{"speed":', '42[1,2]', '42"x"', '42{}',
                                     '4x', '49', '42["telemetry","a","b"]'])
def test_socketio_garbage_keeps_the_connection(server, sim, frames, garbage):
    sim.ws.send(garbage)
    frame, jpeg = frames[0]
    sim.send_telemetry(sim_telemetry(frame, jpeg))
    name, payload = sim.recv_event()
    assert_command(name, payload)
    assert server.alive()


def test_unknown_event_gets_no_reply(server, sim, frames):
    sim.ws.send('42["get_samples",{}]')
    sim.assert_quiet()
    frame, jpeg = frames[0]
    sim.send_telemetry(sim_telemetry(frame, jpeg))
    assert_command(*sim.recv_event())
    assert "unknown event" in server.output()


@pytest.mark.parametrize("garbage", ["x", "", "9abc", "\x00\xff"])
def test_engineio_garbage_does_not_kill_the_server(server, frames, garbage):
    sim = FakeSimulator(server.port)
    try:
        sim.ws.send(garbage)
    finally:
        sim.close(polite=False)
    assert server.alive()
    again = FakeSimulator(server.port)
    try:
        frame, jpeg = frames[0]
        again.send_telemetry(sim_telemetry(frame, jpeg))
        assert_command(*again.recv_event())
    finally:
        again.close()


# --- connections ----------------------------------------------------------------------
@pytest.mark.parametrize("polite", [True, False])
def test_disconnect_and_reconnect(server, frames, polite):
    frame, jpeg = frames[1]
    for _ in range(3):
        sim = FakeSimulator(server.port)
        sim.send_telemetry(sim_telemetry(frame, jpeg))
        assert_command(*sim.recv_event())
        sim.close(polite=polite)
    assert server.alive()


def test_http_fingerprint_engineio3(server):
    """socketio-compat test A: the polling handshake uses EIO3 length-prefixed
    framing and the server adds the namespace CONNECT by itself."""
    url = f"http://127.0.0.1:{server.port}/socket.io/?EIO=4&transport=polling&b64=1"
    with urllib.request.urlopen(url, timeout=RECV_TIMEOUT_S) as resp:
        assert resp.status == 200
        body = resp.read().decode()
    length, _, rest = body.partition(":")
    assert length.isdigit() and rest.startswith("0{"), body
    assert body.endswith("2:40"), body


# --- recording ----------------------------------------------------------------------
def test_recording_never_overwrites_and_reads_back(tmp_path, frames):
    from replay.log_format import read_log

    folder = tmp_path / "rec"
    folder.mkdir()
    keep = folder / "precious.txt"
    keep.write_text("do not delete")
    srv = Server(tmp_path, str(folder))
    try:
        sim = FakeSimulator(srv.port)
        for frame, jpeg in frames[:5]:
            sim.send_telemetry(sim_telemetry(frame, jpeg))
            assert_command(*sim.recv_event())
        sim.send_telemetry(sim_telemetry(frames[0][0], frames[0][1], locale="de-DE") | {"speed": "NaN"})
        sim.recv_event()  # bad frame: answered, not recorded
        sim.close()
    finally:
        srv.stop()
    assert keep.read_text() == "do not delete"
    runs = [p for p in folder.iterdir() if p.is_dir()]
    assert len(runs) == 1, list(folder.iterdir())
    data = read_log(runs[0])
    assert len(data.frames) == 5 and data.skipped == 0
    for (frame, jpeg), got in zip(frames[:5], data.frames):
        assert Path(got.image_path).read_bytes() == jpeg  # stored exactly as received
        assert got.x == pytest.approx(frame.x, abs=1e-3)
        assert got.yaw == pytest.approx(frame.yaw, abs=1e-3)


# --- versions -------------------------------------------------------------------------
def test_installed_versions_are_accepted():
    assert drive_rover.check_versions(drive_rover.installed_version("python-socketio"),
                                      drive_rover.installed_version("python-engineio")) is None


@pytest.mark.parametrize("sio, eio", [("5.18.1", "4.15.1"), ("4.6.1", "3.14.2"),
                                      ("4.6.1", "4.0.0"), ("4.6.1", None), ("3.1.0", "3.13.2"),
                                      ("4.6.1", "3.8.0")])
def test_wrong_versions_exit_with_the_fix(sio, eio, monkeypatch):
    monkeypatch.setattr(drive_rover, "installed_version", lambda dist: None)
    message = drive_rover.check_versions(sio, eio)
    assert message and "python-engineio==3.13.2" in message and "python-socketio==4.6.1" in message
    with pytest.raises(SystemExit) as exc:
        drive_rover.require_compatible_versions(sio, eio or "0")
    assert isinstance(exc.value.code, str) and "Fix:" in exc.value.code  # exit status 1


@pytest.mark.parametrize("sio, eio", [("4.6.1", "3.13.2"), ("4.6.0", "3.13.0"), ("4.4.0", "3.11.2")])
def test_working_versions_pass(sio, eio):
    assert drive_rover.check_versions(sio, eio) is None
