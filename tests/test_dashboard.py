"""The live dashboard: newest-state slot, per-frame publisher, port check, and the page in a real browser."""
import json
import os
import socket
import threading
import urllib.request

import numpy as np
import pytest

from dashboard.publisher import Publisher
from dashboard.server import DashboardServer, LiveSource, port_problem
from dashboard.slot import LatestSlot
from dashboard.view import ViewRenderer


class FakeClock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_slot_keeps_only_the_newest_item():
    slot = LatestSlot()
    for k in range(5):
        slot.put(k)
    assert slot.latest() == (5, 4)
    assert slot.wait_newer(5, timeout=0.01) is None  # nothing newer: the reader waits, no backlog
    slot.put("x")
    assert slot.wait_newer(5, timeout=0.01) == (6, "x")


def _client():
    from autonomy import AutonomyClient

    return AutonomyClient(insets=False, perception_step=lambda r: r, decision_step=lambda r: r)


def _jpeg_b64():
    import base64

    import cv2

    return base64.b64encode(cv2.imencode(".jpg", np.full((160, 320, 3), 120, np.uint8))[1].tobytes()).decode()


JPEG_B64 = _jpeg_b64()


def _telemetry(x, sample_count=3, t=0.0):
    return {"steering_angle": "0", "throttle": "0", "brake": "0", "speed": "1.0", "position": f"{x};80",
            "pitch": "0", "yaw": "90", "roll": "0", "near_sample": "0", "picking_up": "0",
            "sample_count": str(sample_count), "samples_x": ";".join(["90"] * sample_count),
            "samples_y": ";".join(str(70 + k) for k in range(sample_count)), "sim_time": str(t), "image": JPEG_B64}


def test_publisher_is_rate_limited_and_logs_what_changed():
    clock = FakeClock()
    pub = Publisher(hz=10, clock=clock)
    client = _client()
    published = 0
    for k in range(20):  # 20 frames in 0.2 s of wall clock: 10 Hz allows 2 snapshots (t=0 and t=0.1)
        clock.t = k * 0.01
        client.handle_telemetry(_telemetry(100 + k * 0.1, t=k * 0.04))
        client.rover.mode = "forward" if k < 10 else "rock"
        published += pub.observe(client, "data")
    client.handle_telemetry(_telemetry(102, sample_count=2, t=1.0))
    pub.observe(client, "data", force=True)
    assert published == 2
    version, snap = pub.slot.latest()
    assert version == 3
    texts = [e[1] for e in snap.events]
    assert texts == ["mode forward", "mode forward -> rock", "sample collected (1/3)"]
    assert snap.frame == client.rover.frame_count and snap.remaining == 2
    snap.worldmap[0, 0] = 7  # a copy: the client's map is untouched
    assert client.rover.worldmap[0, 0, 0] == 0


def test_port_problem_sees_a_server_that_shares_its_port():
    holder = socket.socket()
    holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)  # as eventlet.listen does
    holder.bind(("127.0.0.1", 0))
    holder.listen(1)
    try:
        port = holder.getsockname()[1]
        assert "already in use" in port_problem("127.0.0.1", port)
    finally:
        holder.close()
    assert "0-65535" in port_problem("127.0.0.1", 70000)
    assert port_problem("127.0.0.1", 0) is None


def test_a_stalled_page_never_blocks_the_publisher():
    """A client that opens the stream and never reads: publishing goes on (no timing assertion:
    the publisher thread must simply finish)."""
    pub = Publisher(hz=0)
    client = _client()
    client.handle_telemetry(_telemetry(100))
    server = DashboardServer(LiveSource(pub.slot, ViewRenderer()), port=0).start()
    stalled = socket.create_connection((server.host, server.port))
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1024)
    stalled.sendall(b"GET /api/stream HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    done = threading.Event()

    def publish_many():
        for k in range(300):
            client.handle_telemetry(_telemetry(100 + k * 0.01, t=k * 0.04))
            pub.observe(client, "data")
        done.set()

    worker = threading.Thread(target=publish_many, daemon=True)
    worker.start()
    try:
        assert done.wait(60), "publishing stalled behind a page that does not read"
        state = json.load(urllib.request.urlopen(server.url + "api/state", timeout=10))
        assert state["figures"]["frame"] == client.rover.frame_count
    finally:
        stalled.close()
        server.stop()


def test_a_page_under_a_foreign_host_name_is_refused():
    """DNS rebinding: a page served as evil.example that resolves to 127.0.0.1 must not read the view."""
    pub = Publisher(hz=0)
    server = DashboardServer(LiveSource(pub.slot, ViewRenderer()), port=0).start()
    try:
        for host, status in (("evil.example", b" 403 "), (f"localhost:{server.port}", b" 200 ")):
            with socket.create_connection((server.host, server.port), timeout=10) as conn:
                conn.sendall(f"GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
                status_line = conn.makefile("rb").readline()
            assert status in status_line, (host, status_line)
    finally:
        server.stop()


# ------------------------------------------------------------------------------ real browser
def _chromium_or_skip():
    from dashboard.browser import find_chromium

    path = find_chromium()
    if path is None:
        pytest.skip("chromium is not installed (apt-get install chromium): the dashboard page test needs a browser")
    return path


def test_dashboard_page_in_headless_chromium(tmp_path):
    """Loads the live page, waits for the map to change, checks the figures against the
    client's own state, saves a screenshot; then the page hands over to the mission viewer."""
    chromium = _chromium_or_skip()
    from autonomy import AutonomyClient
    from dashboard import LiveDashboard
    from dashboard.browser import Browser
    from dashboard.timeline import Timeline
    from dashboard.viewer import MissionSource
    from evaluation.metrics import score_map
    from sim.twin import RoverTwin
    from sim.world import default_world

    world = default_world()
    twin = RoverTwin(world, seed=3)
    client = AutonomyClient(ground_truth=world.nav_truth, insets=False)
    dash = LiveDashboard(port=0, title="test").start()
    timeline = Timeline()
    pause, paused = threading.Event(), threading.Event()

    def drive():
        tel = twin.reset(3)
        while not pause.is_set() and twin.sim_time < 300:
            event, payload = client.handle_telemetry(tel)
            dash.observe(client, event)
            timeline.observe(client, event)
            tel = twin.step(event, payload)
        paused.set()

    loop = threading.Thread(target=drive, daemon=True)
    try:
        with Browser(chromium) as b:
            b.open(dash.url)
            loop.start()
            first = b.wait_for("document.body.dataset.version > 0 && document.getElementById('img-map').src", 60)
            b.wait_for(f"document.getElementById('img-map').src !== {json.dumps(first)}", 120)  # the map changed
            b.wait_for("Number(document.body.dataset.frame) > 100", 120)
            pause.set()
            assert paused.wait(60)
            dash.observe(client, None, force=True)
            timeline.observe(client, None, force=True)
            version = dash.publisher.slot.latest()[0]
            b.wait_for(f"Number(document.body.dataset.version) === {version}", 30)
            shown = b.eval("Object.fromEntries([...document.querySelectorAll('[id^=fig-]')]"
                           ".map(e => [e.id.slice(4), e.textContent]))")
            rover = client.rover
            score = score_map(rover.worldmap, world.nav_truth, [tuple(p) for p in dash.publisher.samples])
            assert shown["t"] == f"{rover.total_time:.1f} s"
            assert shown["mapped"] == f"{score.mapped_pct:.1f} %"
            assert shown["fidelity"] == f"{score.fidelity_pct:.1f} %"
            collected = rover.samples_initial - rover.samples_remaining
            assert shown["collected"] == f"{collected} / {rover.samples_initial}"
            assert shown["mode"] == rover.mode
            assert shown["speed"] == f"{rover.vel:.2f} m/s"
            assert shown["steer"] == f"{rover.steer:.1f} °"
            shot = b.screenshot(os.environ.get("DASHBOARD_SCREENSHOT") or tmp_path / "dashboard.png")
            assert shot.stat().st_size > 10_000

            # the same page, now over the finished mission's timeline
            timeline.save(tmp_path / "timeline.npz")
            (tmp_path / "mission.json").write_text(json.dumps({"seed": 3, "world": world.name,
                                                               "end_reason": "test", "stuck_stretches": []}))
            source = MissionSource(tmp_path)
            dash.server.show(source)
            b.wait_for("document.getElementById('kind').textContent === 'mission viewer'", 30)
            assert int(b.eval("document.getElementById('scrub').max")) == source.n - 1
            b.wait_for(f"document.getElementById('fig-t').textContent === '{rover.total_time:.1f} s'", 30)
            b.eval("(() => { const s = document.getElementById('scrub'); s.value = '0';"
                   " s.dispatchEvent(new Event('input')); })()")
            b.wait_for("document.getElementById('fig-t').textContent === '0.0 s'", 30)
    finally:
        pause.set()
        dash.close()


def test_twin_view_shows_the_simulator_side():
    """sim.wire --dashboard: the twin's camera, true pose, commands and samples reach the page's figures."""
    from dashboard.twin_view import TwinView
    from dashboard.view import figures
    from sim.twin import RoverTwin
    from sim.world import load_world

    twin = RoverTwin(load_world("procedural:0"), seed=1)
    twin.reset(1)
    for _ in range(10):
        twin.step("data", {"throttle": "1.0", "brake": "0", "steering_angle": "5.0"})
    pub = Publisher(hz=0)
    pub.observe(TwinView(twin).update())
    _, snap = pub.slot.latest()
    fig = figures(snap)
    tr = twin.truth
    assert (fig["x"], fig["y"]) == (round(tr.x, 2), round(tr.y, 2)) and fig["throttle"] == 1.0
    assert fig["collected"] == 0 and fig["samples"] == len(tr.initial_samples)
    assert snap.img is twin.last_rgb and fig["mapped"] == 0.0  # the client's map lives in the client
