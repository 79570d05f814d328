"""Test helpers: ``drive_rover.py`` in a subprocess and a raw-frame client that
behaves like the Unity simulator (websocket straight to the EIO=4 URL, never
``40``, pings ``2``, retries a refused connection every 5 ms as the simulator
does).  Shared by tests/test_wire*.py."""
import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import websocket

PROJECT = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 60.0  # server start-up allowance (imports on a busy 2-core box), s
RECV_TIMEOUT_S = 20.0  # wait for one reply, s
QUIET_S = 0.5  # silence that proves "no extra reply", s
CONNECT_RETRY_S = 10.0  # keep retrying a refused (401) connection this long, s
RECONNECT_DELAY_S = 0.005  # the simulator's reconnect period, s
PING_EVERY_S = 10.0  # ping period while receiving (engineio drops a client silent for 25 + 5 s), s


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``python drive_rover.py`` in a subprocess; always shut down."""

    def __init__(self, tmp_path, *extra):
        self.port = free_port()
        self.log_path = tmp_path / f"server-{self.port}.log"
        self._log = open(self.log_path, "wb")
        self.proc = subprocess.Popen(
            [sys.executable, str(PROJECT / "drive_rover.py"), *extra, "--port", str(self.port),
             "--log-level", "INFO"], cwd=PROJECT, stdout=self._log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            if self.proc.poll() is not None:
                raise AssertionError(f"server exited early:\n{self.output()}")
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    self.stop()
                    raise AssertionError(f"server did not start:\n{self.output()}")
                time.sleep(0.1)

    def output(self, tail=5000):
        self._log.flush()
        text = self.log_path.read_text(errors="replace")
        return text[-tail:] if tail else text

    def wait_for_log(self, text, timeout=RECV_TIMEOUT_S):
        deadline = time.monotonic() + timeout
        while text not in self.output(tail=0):
            if time.monotonic() > deadline:
                raise AssertionError(f"{text!r} not logged:\n{self.output()}")
            time.sleep(0.05)

    def rss_kib(self):
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        raise AssertionError("no VmRSS")

    def alive(self):
        return self.proc.poll() is None

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self._log.close()


def sim_url(port, host="127.0.0.1"):
    return f"ws://{host}:{port}/socket.io/?EIO=4&transport=websocket"


class FakeSimulator:
    """The simulator's side of the socket, frame by frame."""

    def __init__(self, port, retry_s=CONNECT_RETRY_S, **options):
        deadline = time.monotonic() + retry_s
        while True:
            try:
                self.ws = websocket.create_connection(sim_url(port), timeout=RECV_TIMEOUT_S, **options)
                break
            except websocket.WebSocketBadStatusException as exc:
                # 401: another simulator connection is still open (one at a time);
                # the real simulator retries every 5 ms
                if exc.status_code != 401 or time.monotonic() > deadline:
                    raise
                time.sleep(RECONNECT_DELAY_S)
        opening = self.ws.recv()
        assert opening.startswith("0{"), opening
        self.handshake = json.loads(opening[1:])
        self.pongs = 0
        self._last_ping = time.monotonic()

    def send_telemetry(self, data):
        self.ws.send("42" + json.dumps(["telemetry", data]))

    def recv_frame(self, timeout=RECV_TIMEOUT_S):
        self.ws.settimeout(timeout)
        return self.ws.recv()

    def recv_event(self, timeout=RECV_TIMEOUT_S):
        """Next event (name, payload); answers pings and skips 40/3 as the sim does."""
        deadline = time.monotonic() + timeout
        while True:
            if time.monotonic() - self._last_ping > PING_EVERY_S:  # as the simulator does (every 25 s)
                self.ws.send("2")
                self._last_ping = time.monotonic()
            try:
                frame = self.recv_frame(max(0.01, min(PING_EVERY_S, deadline - time.monotonic())))
            except websocket.WebSocketTimeoutException:
                if time.monotonic() >= deadline:
                    raise
                continue
            if frame == "2":
                self.ws.send("3")
            elif frame == "3":
                self.pongs += 1
            elif frame.startswith("42"):
                name, *args = json.loads(frame[2:])
                return name, (args[0] if args else None)
            # '40' (namespace connect) and anything else are ignored, like the sim

    def drain(self, quiet=QUIET_S):
        """Every event that arrives until ``quiet`` s pass without one."""
        events = []
        while True:
            try:
                events.append(self.recv_event(timeout=quiet))
            except websocket.WebSocketTimeoutException:
                return events

    def assert_quiet(self, quiet=QUIET_S):
        """No further event arrives (lockstep: exactly one reply per telemetry)."""
        with pytest.raises(websocket.WebSocketTimeoutException):
            self.recv_event(timeout=quiet)

    def close(self, polite=True):
        try:
            if polite:
                self.ws.send("41")
                self.ws.send("1")
        except (websocket.WebSocketException, OSError):
            pass
        finally:
            self.ws.close()


def server_and_sim_fixtures(tmp_name):
    """The (server, sim) fixture pair wire test files share: one drive_rover.py per module, a fresh simulator per test.

    Use as ``server, sim = server_and_sim_fixtures("name")`` at a test module's top level.
    """

    @pytest.fixture(scope="module")
    def server(tmp_path_factory):
        srv = Server(tmp_path_factory.mktemp(tmp_name))
        yield srv
        srv.stop()

    @pytest.fixture
    def sim(server):
        s = FakeSimulator(server.port)
        yield s
        s.close(polite=False)

    return server, sim


def assert_command(name, payload):
    assert name in ("data", "pickup", "manual"), name
    assert isinstance(payload, dict)
    for key, value in payload.items():
        assert isinstance(value, str), (key, value)
    if name == "data":
        for key in ("throttle", "brake", "steering_angle"):
            text = payload[key]
            assert "," not in text
            assert float(text) == float(text)  # parses, not NaN
        assert abs(float(payload["steering_angle"])) <= 15.0
    else:
        assert payload == {}
