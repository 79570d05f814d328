"""Hostile input over the raw websocket against ``drive_rover.py``: stray
Socket.IO packets, deep nesting, binary and oversized frames, a telemetry
flood, DNS-rebinding Host headers, two simulators at once, and a seeded fuzz
of corrupted frames.  Every case ends with the session (or the simulator's
reconnect) answering a valid telemetry.  Rules: docs/wire-hardening.md."""
import json
import random
import re
import threading
import time
import urllib.error
import urllib.request

import pytest

websocket = pytest.importorskip("websocket")

import supporting_functions as sf  # noqa: E402
from tests.test_parsing import telemetry  # noqa: E402
import wire_guard  # noqa: E402
from wire_client import (QUIET_S, FakeSimulator, assert_command, server_and_sim_fixtures,  # noqa: E402
                         sim_url)

FUZZ_SEED = 26  # the number; any seed must pass
FUZZ_FRAMES = 1200  # corrupted frames per run
FLOOD_FRAMES = 600  # telemetry frames sent without waiting for replies
FLOOD_RSS_GROWTH_KIB = 30 * 1024  # allowed server RSS growth over a flood (was ~40 MB per 10 s unbounded), KiB
MAX_FRAME_BYTES = 8 << 20  # eventlet's websocket frame limit, bytes
REPLY_GAP_S = 60.0  # longest silence tolerated while replies are owed (a loaded 2-core box), s


server, sim = server_and_sim_fixtures("faults")


def valid():
    return telemetry()


def flat_image_b64():
    import base64

    import cv2
    import numpy as np

    ok, buf = cv2.imencode(".jpg", np.full((160, 320, 3), 120, np.uint8))
    return base64.b64encode(buf.tobytes()).decode("ascii")


def assert_answers_valid_telemetry(sim):
    sim.send_telemetry(valid())
    name, payload = sim.recv_event()
    assert_command(name, payload)
    return name, payload


def session_summaries(server):
    """(messages, telemetry, full, stale, unanswered, ignored) per closed session, from the log."""
    pattern = re.compile(r"simulator disconnected \(\S+\): (\d+) messages, (\d+) telemetry \((\d+) handled, "
                         r"(\d+) answered with the last command, (\d+) unanswered at close\), ignored (\d+)")
    return [tuple(int(g) for g in m.groups()) for m in pattern.finditer(server.output(tail=0))]


def close_and_summary(server, sim):
    before = len(session_summaries(server))
    sim.close(polite=False)
    deadline = time.monotonic() + 20
    while len(session_summaries(server)) == before:
        assert time.monotonic() < deadline, server.output()
        time.sleep(0.05)
    return session_summaries(server)[-1]


# --- stray packets (defects 1 and 2) --------------------------------------------------------
@pytest.mark.parametrize("stray", ["45", "46", '451-["telemetry",{"_placeholder":true,"num":0}]',
                                   '461-[{"_placeholder":true,"num":0}]', "41", "41/", "43", "44", "40"])
def test_stray_socketio_packets_do_not_wedge_the_session(server, sim, stray):
    sim.ws.send(stray)
    for _ in range(3):  # not just the next one: every later telemetry is answered
        assert_answers_valid_telemetry(sim)
    sim.assert_quiet()
    assert server.alive()


def test_binary_attachment_after_stray_binary_event_is_ignored(server, sim):
    sim.ws.send("451-" + json.dumps(["telemetry", {"_placeholder": True, "num": 0}]))
    sim.ws.send(b"\x04attachment", opcode=websocket.ABNF.OPCODE_BINARY)
    assert_answers_valid_telemetry(sim)
    sim.assert_quiet()


# --- deep nesting (defect 3) --------------------------------------------------------------------
@pytest.mark.parametrize("depth", [950, 980, 1200, 100000])
def test_deeply_nested_telemetry_is_answered(server, sim, depth):
    sim.ws.send('42["telemetry",{"image":' + "[" * depth + "]" * depth + "}]")
    name, payload = sim.recv_event()
    assert name == "data" and payload["brake"] == "1.0000"  # a safe stop, not silence
    assert_answers_valid_telemetry(sim)


def test_deeply_nested_unknown_event_is_ignored(server, sim):
    sim.ws.send("42" + "[" * 5000 + "]" * 5000)
    assert_answers_valid_telemetry(sim)
    sim.assert_quiet()


# --- engine.io-level garbage (defect 4) -------------------------------------------------------
@pytest.mark.parametrize("frame, binary", [("b", False), ("bZZ", False), ("b4AAAA", False), ("", False),
                                           ("6", False), ("5", False), (b"", True), (b"\x01", True),
                                           (bytes(range(256)), True), (b"\x04" + b"\xff" * 100, True)])
def test_binary_and_base64_frames_are_ignored_and_the_connection_stays(server, sim, frame, binary):
    opcode = websocket.ABNF.OPCODE_BINARY if binary else websocket.ABNF.OPCODE_TEXT
    sim.ws.send(frame, opcode=opcode)
    assert_answers_valid_telemetry(sim)
    sim.assert_quiet()


def test_oversized_frame_closes_and_the_reconnect_works(server):
    big = FakeSimulator(server.port)
    try:
        with pytest.raises((websocket.WebSocketConnectionClosedException, ConnectionError, OSError)):
            # the server closes (1009) once it reads the frame header: the send
            # itself may fail, or the next receive sees the close
            big.ws.send('42["telemetry",{"image":"' + "A" * (MAX_FRAME_BYTES + 1024) + '"}]')
            for _ in range(10):
                big.recv_frame(timeout=10)
    finally:
        big.close(polite=False)
    again = FakeSimulator(server.port)  # the simulator reconnects every 5 ms
    try:
        assert_answers_valid_telemetry(again)
    finally:
        again.close()
    assert server.alive()


def test_engineio_close_then_reconnect(server):
    first = FakeSimulator(server.port)
    assert_answers_valid_telemetry(first)
    first.ws.send("1")  # engine.io CLOSE: what the simulator says on quit
    second = FakeSimulator(server.port)
    try:
        assert_answers_valid_telemetry(second)
    finally:
        second.close()
        first.close(polite=False)


# --- flood (defect 5) ---------------------------------------------------------------------------
class Collector(threading.Thread):
    """Reads the events of a FakeSimulator on a thread while the test sends:
    ``expected`` of them (a silence of REPLY_GAP_S is an error), then any
    extra that arrives within QUIET_S."""

    def __init__(self, sim, expected):
        super().__init__(daemon=True)
        self.sim, self.expected, self.events, self.error = sim, expected, [], None

    def run(self):
        try:
            while len(self.events) < self.expected:
                self.events.append(self.sim.recv_event(timeout=REPLY_GAP_S))
            self.events.extend(self.sim.drain(QUIET_S))
        except Exception as exc:  # reported by the test
            self.error = exc


def test_flood_every_telemetry_answered_memory_bounded(server):
    sim = FakeSimulator(server.port)
    for _ in range(20):  # warm up (imports, caches) before measuring memory
        assert_answers_valid_telemetry(sim)
    rss_before = server.rss_kib()
    image = flat_image_b64()  # small frames: the sender easily outpaces the full pipeline
    frames = ["42" + json.dumps(["telemetry", telemetry(position=f"{99.67 + i * 0.001:.4f};85.5890", image=image)])
              for i in range(FLOOD_FRAMES)]
    reader = Collector(sim, FLOOD_FRAMES)
    reader.start()
    for frame in frames:
        sim.ws.send(frame)
    reader.join()
    rss_after = server.rss_kib()
    assert reader.error is None, reader.error
    assert len(reader.events) == FLOOD_FRAMES  # exactly one reply each, none lost
    for event in reader.events:
        assert_command(*event)
    messages, tel, full, stale, unanswered, ignored = close_and_summary(server, sim)
    assert tel == FLOOD_FRAMES + 20 and full + stale == tel and unanswered == 0 and ignored == 0
    assert stale > 0  # the backlog was answered cheaply, not run through the pipeline
    assert sum(1 for _, p in reader.events if "inset_image1" in p) <= full  # insets only on handled frames
    assert rss_after - rss_before < FLOOD_RSS_GROWTH_KIB


# --- DNS rebinding (defect 6) ----------------------------------------------------------------
@pytest.mark.parametrize("host", ["evil.example", "127.0.0.1.nip.io", "attacker.test"])
def test_foreign_host_header_is_refused_on_websocket_and_http(server, host):
    with pytest.raises(websocket.WebSocketBadStatusException) as exc:
        websocket.create_connection(sim_url(server.port), timeout=10, host=f"{host}:{server.port}",
                                    origin=f"http://{host}:{server.port}")
    assert exc.value.status_code == 403
    request = urllib.request.Request(f"http://127.0.0.1:{server.port}/", headers={"Host": f"{host}:{server.port}"})
    with pytest.raises(urllib.error.HTTPError) as http:
        urllib.request.urlopen(request, timeout=10)
    assert http.value.code == 403
    assert "DNS-rebinding guard" in server.output()
    sim = FakeSimulator(server.port)  # the simulator itself is still served
    try:
        assert_answers_valid_telemetry(sim)
    finally:
        sim.close()


@pytest.mark.parametrize("host", ["localhost", "[::1]", "127.0.0.1"])
def test_loopback_host_headers_are_served(server, host):
    ws = websocket.create_connection(sim_url(server.port), timeout=10, host=f"{host}:{server.port}",
                                     origin=f"http://{host}:{server.port}")
    try:
        assert ws.recv().startswith("0{")
    finally:
        ws.close()
    request = urllib.request.Request(f"http://127.0.0.1:{server.port}/", headers={"Host": f"{host}:{server.port}"})
    with urllib.request.urlopen(request, timeout=10) as resp:
        assert resp.status == 200


# --- two simulators (defect 8) -------------------------------------------------------------
def test_second_simulator_is_refused_while_the_first_drives(server):
    first = FakeSimulator(server.port)
    try:
        assert_answers_valid_telemetry(first)
        with pytest.raises(websocket.WebSocketBadStatusException) as exc:
            FakeSimulator(server.port, retry_s=0)
        assert exc.value.status_code == 401
        assert "refused a second simulator connection" in server.output()
        for _ in range(3):  # the first one is undisturbed
            assert_answers_valid_telemetry(first)
    finally:
        first.close()
    second = FakeSimulator(server.port)  # gets in once the first has gone
    try:
        assert_answers_valid_telemetry(second)
    finally:
        second.close()
    assert "new mission" not in server.output()


# --- seeded fuzz ------------------------------------------------------------------------------------
_JUNK = "\"'[]{},:;0123456789.-eE\\ntrufalsNaI\x00\u00e9\u4e2d\U0001f680 "
_PREFIXES = ["40", "41", "43", "44", "45", "46", "451-", "4", "49", "4x", "42/", "42/other,", "421", "42/,",
             "42", "42", "42", "42"]
_ENGINEIO_JUNK = ["b", "bZZ", "b4", "", "0", "5", "6", "7", "9abc", "2probe", "3"]


def _mutate(rng, text):
    """One corrupted frame built from a valid telemetry frame ``text``."""
    op = rng.randrange(9)
    body = text[2:]
    if op == 0:  # replace some characters
        chars = list(body)
        for _ in range(rng.randint(1, 8)):
            chars[rng.randrange(len(chars))] = rng.choice(_JUNK)
        return "42" + "".join(chars)
    if op == 1:  # truncate
        return text[:rng.randrange(len(text))]
    if op == 2:  # insert junk
        i = rng.randrange(len(body))
        return "42" + body[:i] + "".join(rng.choice(_JUNK) for _ in range(rng.randint(1, 20))) + body[i:]
    if op == 3:  # another packet type / namespace / ack id in front
        return rng.choice(_PREFIXES) + body
    if op == 4:  # deep nesting somewhere
        depth = rng.choice([10, 500, 950, 980, 1000, 2000, 20000])
        return '42["telemetry",{"speed":' + "[" * depth + "]" * depth + "}]"
    if op == 5:  # one field gets a value of the wrong type
        data = json.loads(body)[1]
        key = rng.choice(sorted(data))
        data[key] = rng.choice([1.5, None, True, [], {}, {"a": ["b"]}, "NaN", "-1e309", "9" * 400, "", "1;2;3"])
        return "42" + json.dumps(["telemetry", data])
    if op == 6:  # engine.io-level junk
        return rng.choice(_ENGINEIO_JUNK)
    if op == 7:  # binary frame
        return bytes(rng.randrange(256) for _ in range(rng.randint(0, 64)))
    return "42" + json.dumps(["telemetry"] + [rng.choice([None, 1, "x", [], {}]) for _ in range(rng.randint(0, 3))])


def _is_telemetry(frame):
    """Whether the server owes this frame a reply (engineio's own ping/pong excluded)."""
    if wire_guard.engineio_frame_verdict(frame) is not None or frame[0] in "23":
        return False
    return wire_guard.classify_message(frame[1:])[0] == wire_guard.TELEMETRY


def _could_pick_up(frame):
    """True when this frame, if handled, may legitimately be answered by a pickup."""
    if not isinstance(frame, str) or not frame.startswith("42["):
        return False
    try:
        message = json.loads(frame[2:])
        tel = sf.parse_telemetry(message[1])
    except Exception:
        return False
    return bool(tel.ok and tel.near_sample and abs(tel.speed) < 0.05 and not tel.picking_up)


def test_seeded_fuzz_every_frame_answered_or_ignored(server):
    rng = random.Random(FUZZ_SEED)
    # near a sample but moving, or stopped but not near: a pickup for either would be blind
    bases = ["42" + json.dumps(["telemetry", telemetry(near_sample="1", speed="1.5000")]),
             "42" + json.dumps(["telemetry", telemetry(near_sample="0", speed="0.0000")])]
    frames = [_mutate(rng, rng.choice(bases)) for _ in range(FUZZ_FRAMES)]
    frames = [f if not (isinstance(f, str) and f.startswith("1")) else "4" + f for f in frames]  # '1' = quit
    allowed_pickups = sum(_could_pick_up(f) for f in frames)
    sim = FakeSimulator(server.port)
    # how many replies to wait for (the server's own count is checked against it below)
    reader = Collector(sim, sum(_is_telemetry(f) for f in frames) + 1)
    reader.start()
    for frame in frames:
        opcode = websocket.ABNF.OPCODE_BINARY if isinstance(frame, bytes) else websocket.ABNF.OPCODE_TEXT
        sim.ws.send(frame, opcode=opcode)
    sim.send_telemetry(valid())  # the session still answers a valid frame afterwards
    reader.join()
    assert reader.error is None, reader.error
    for event in reader.events:
        assert_command(*event)
    pickups = sum(1 for name, _ in reader.events if name == "pickup")
    assert pickups <= allowed_pickups
    messages, tel, full, stale, unanswered, ignored = close_and_summary(server, sim)
    pings = sum(1 for f in frames if isinstance(f, str) and f and f[0] in "23")  # engineio's own
    assert tel + ignored == FUZZ_FRAMES + 1 - pings  # every frame answered or deliberately ignored
    assert len(reader.events) == tel and unanswered == 0  # exactly one reply per telemetry
    assert server.alive()
