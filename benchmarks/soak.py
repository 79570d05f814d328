"""Soak test of the live server: many frames over the real wire, memory watched.

Starts ``drive_rover.py`` on a free port and plays the simulator over a raw
websocket (EIO=4 URL, no ``40``, a ``2`` ping every 20 s) with the Udacity
test_dataset frames as telemetry, forward then backward (one long plausible
mission, no teleports).  Like the simulator it keeps ``--chains`` telemetries
in flight (the real one sends two when the socket opens) and sends the next
only when a reply arrives.  Every ``--every`` frames it prints replies/s,
reply latency percentiles and the server's RSS; at the end the totals, the
replies that never came, and the RSS spread after the first report (warm-up).
Prints, never asserts: timings on a shared machine are noisy.

    python -m benchmarks.soak --frames 100000 [--chains 2] [--every 10000]
"""
from __future__ import annotations

import argparse
import collections
import json
import logging
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import List

import numpy as np
from tqdm import tqdm

log = logging.getLogger("benchmarks.soak")

PROJECT = Path(__file__).resolve().parents[1]
CHAINS = 2  # telemetries in flight, as the simulator after it opens the socket, frames
REPORT_EVERY = 10_000  # frames between report lines
PING_EVERY_S = 20.0  # client ping period (the server drops a client silent for 25 + 5 s), s
REPLY_TIMEOUT_S = 30.0  # a reply not here after this long is lost, s
START_TIMEOUT_S = 60.0  # server start-up allowance, s
RSS_FLAT_MB = 5.0  # the goal: RSS within +-this after warm-up, MB


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def telemetry_frames(log_path=None) -> List[str]:
    """The dataset as ready-to-send ``42["telemetry",{...}]`` frames, forward then back."""
    from benchmarks.frame import dataset_telemetry

    frames = ["42" + json.dumps(["telemetry", t], separators=(",", ":")) for t in dataset_telemetry(log_path)]
    return frames + frames[::-1]


def start_server(port: int, server_log):
    cmd = [sys.executable, str(PROJECT / "drive_rover.py"), "--port", str(port), "--log-level", "WARNING"]
    return subprocess.Popen(cmd, cwd=PROJECT, stdout=server_log, stderr=subprocess.STDOUT)


def connect(port: int, proc):
    import websocket

    url = f"ws://127.0.0.1:{port}/socket.io/?EIO=4&transport=websocket"
    deadline = time.monotonic() + START_TIMEOUT_S
    while True:
        if proc.poll() is not None:
            raise SystemExit(f"drive_rover.py exited with {proc.returncode}")
        try:
            ws = websocket.create_connection(url, timeout=REPLY_TIMEOUT_S)
            break
        except (OSError, websocket.WebSocketException):
            if time.monotonic() > deadline:
                raise SystemExit("drive_rover.py did not accept a connection")
            time.sleep(0.2)
    opening = ws.recv()
    if not opening.startswith("0{"):
        raise SystemExit(f"unexpected handshake {opening[:80]!r}")
    return ws


def soak(frames_total: int, chains: int, every: int, log_path=None, server_log_path=None):
    import websocket

    from sim.wire import free_port

    frames = telemetry_frames(log_path)
    port = free_port()
    server_log = open(server_log_path, "wb") if server_log_path else subprocess.DEVNULL
    proc = start_server(port, server_log)
    ws = connect(port, proc)
    sent_at: "collections.deque[float]" = collections.deque()
    latencies: List[float] = []
    replies = lost = sent = 0
    window_start, window_replies = time.perf_counter(), 0
    last_ping = time.monotonic()
    rss_reports: List[float] = []
    bar = tqdm(total=frames_total, unit="frame", desc="soak", mininterval=2.0)

    def send_next():
        nonlocal sent
        ws.send(frames[sent % len(frames)])
        sent_at.append(time.perf_counter())
        sent += 1

    try:
        for _ in range(min(chains, frames_total)):
            send_next()
        while replies + lost < frames_total:
            if time.monotonic() - last_ping > PING_EVERY_S:
                ws.send("2")
                last_ping = time.monotonic()
            try:
                frame = ws.recv()
            except websocket.WebSocketTimeoutException:
                lost += len(sent_at)  # nothing came for REPLY_TIMEOUT_S: every frame in flight is lost
                tqdm.write(f"timeout: {len(sent_at)} replies lost")
                sent_at.clear()
                for _ in range(min(chains, frames_total - replies - lost)):
                    send_next()
                continue
            if frame == "2":
                ws.send("3")
                continue
            if not frame.startswith("42"):
                continue  # '3' pong, '40'
            latencies.append((time.perf_counter() - sent_at.popleft()) * 1e3)
            replies += 1
            window_replies += 1
            bar.update(1)
            if sent < frames_total:
                send_next()
            if replies % every == 0:
                now = time.perf_counter()
                rss = rss_mb(proc.pid)
                rss_reports.append(rss)
                window = np.asarray(latencies[-window_replies:])
                tqdm.write(f"{replies:>8d} frames  {window_replies / (now - window_start):7.1f} replies/s  "
                           f"latency ms p50 {np.percentile(window, 50):6.2f}  p95 {np.percentile(window, 95):6.2f}  "
                           f"p99 {np.percentile(window, 99):6.2f}  max {window.max():7.2f}  RSS {rss:7.1f} MB  "
                           f"lost {lost}")
                window_start, window_replies = now, 0
    finally:
        bar.close()
        try:
            ws.close()
        finally:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
            if server_log_path:
                server_log.close()
    lat = np.asarray(latencies) if latencies else np.zeros(1)
    print(f"frames sent {sent}, replies {replies}, lost {lost} ({chains} in flight)")
    print(f"latency ms over all: p50 {np.percentile(lat, 50):.2f}  p95 {np.percentile(lat, 95):.2f}  "
          f"p99 {np.percentile(lat, 99):.2f}  max {lat.max():.2f}")
    if len(rss_reports) >= 2:
        after = np.asarray(rss_reports[1:])
        spread = float(np.abs(after - rss_reports[0]).max())
        print(f"RSS after warm-up ({every} frames): {rss_reports[0]:.1f} MB, then {after.min():.1f}-{after.max():.1f} MB "
              f"(max deviation {spread:.1f} MB; goal +-{RSS_FLAT_MB:.0f} MB: {'met' if spread <= RSS_FLAT_MB else 'NOT met'})")
    return dict(sent=sent, replies=replies, lost=lost, rss=rss_reports, latencies=latencies)


def _interrupt(signum, frame):
    """SIGTERM behaves as Ctrl-C, so the finally block stops the server we started."""
    raise KeyboardInterrupt


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m benchmarks.soak", description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=REPORT_EVERY * 2, help="telemetry frames to send")
    p.add_argument("--chains", type=int, default=CHAINS, help="telemetries in flight (the simulator: 2)")
    p.add_argument("--every", type=int, default=REPORT_EVERY, help="frames between report lines")
    p.add_argument("--log", default=None, help="simulator log folder (default: shared test_dataset)")
    p.add_argument("--server-log", default=None, help="write drive_rover.py's output here")
    args = p.parse_args(argv)
    signal.signal(signal.SIGTERM, _interrupt)
    if args.frames < 1 or args.chains < 1 or args.every < 1:
        p.error("--frames, --chains and --every must be positive")
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    soak(args.frames, args.chains, args.every, args.log, args.server_log)


if __name__ == "__main__":
    main()
