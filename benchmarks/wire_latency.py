"""Transport latency of one telemetry -> command round trip over a real websocket.

The twin's wire front end (websocket-client, as `sim.wire`) sends a real twin
telemetry (rendered camera JPEG, string values) to drive_rover.py's own server
stack (python-socketio 4 on eventlet, `drive_rover.build_server`) whose client
answers at once with a real command payload (insets included) computed once up
front; the time from send to the command received is the transport round trip
(JSON encode/decode, Socket.IO framing, loopback), without the client's compute.
This is the number behind sim.timing.WIRE_LATENCY_MS.  Prints, never asserts.

    python -m benchmarks.wire_latency [--count 2000]
"""
from __future__ import annotations

import argparse
import logging
import statistics
import subprocess
import sys
import time

log = logging.getLogger("benchmarks.wire_latency")

COUNT = 2000  # timed round trips
WARMUP = 50  # round trips left out of the statistics
SERVER_START_S = 60.0  # wall s to wait for the echo server


def _telemetry_and_reply():
    """One real twin telemetry and the real client's reply to it (with insets)."""
    from autonomy import AutonomyClient
    from sim.twin import RoverTwin
    from sim.world import default_world

    world = default_world()
    tel = RoverTwin(world, seed=0).reset(0)
    event, payload = AutonomyClient(ground_truth=world.nav_truth, insets=True).handle_telemetry(tel)
    return tel, event, payload


def serve(port: int) -> None:
    """drive_rover.py's server with a client that replies at once with a fixed real command."""
    import eventlet
    import eventlet.wsgi

    from drive_rover import build_server

    _, event, payload = _telemetry_and_reply()

    class InstantClient:
        last_telemetry = None
        rover = None

        def handle_telemetry(self, data):
            return event, payload

    _, app = build_server(InstantClient())
    eventlet.wsgi.server(eventlet.listen(("127.0.0.1", port)), app, log_output=False)


def measure(port: int, count: int) -> list:
    import websocket

    from sim.wire import URL_TEMPLATE, encode_event

    tel, _, _ = _telemetry_and_reply()
    text = encode_event("telemetry", tel)
    ws = websocket.create_connection(URL_TEMPLATE.format(host="127.0.0.1", port=port), timeout=10)
    rtts = []
    try:
        for i in range(count + WARMUP):
            t0 = time.perf_counter()
            ws.send(text)
            while True:
                frame = ws.recv()
                if isinstance(frame, str) and frame.startswith("42"):
                    break
            if i >= WARMUP:
                rtts.append((time.perf_counter() - t0) * 1e3)
    finally:
        ws.close()
    log.info("telemetry frame %d characters", len(text))
    return rtts


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.wire_latency", description=__doc__.split("\n")[0])
    p.add_argument("--count", type=int, default=COUNT)
    p.add_argument("--serve", type=int, default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if a.serve is not None:
        serve(a.serve)
        return 0
    from sim.wire import free_port, stop_process, wait_for_port

    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "benchmarks.wire_latency", "--serve", str(port)])
    try:
        if not wait_for_port(port, proc, timeout=SERVER_START_S):
            log.error("echo server did not start")
            return 1
        rtts = measure(port, max(1, a.count))
    finally:
        stop_process(proc)
    q = statistics.quantiles(rtts, n=20)
    print(f"{len(rtts)} round trips, ms: median {statistics.median(rtts):.2f}, p5 {q[0]:.2f}, "
          f"p95 {q[-1]:.2f}, max {max(rtts):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
