"""``python -m dashboard OUT_DIR [--record DIR] [--port 4568]``: scrub through a finished mission."""
from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from dashboard import port_number
from dashboard.server import DEFAULT_HOST, DEFAULT_PORT

log = logging.getLogger("dashboard")


def main(argv=None) -> int:
    from sim.cli import parse_with_logging

    p = argparse.ArgumentParser(prog="python -m dashboard",
                                description="Open a finished mission (mission.json + timeline.npz, and its "
                                            "recording if any) in the dashboard page and scrub through it.")
    p.add_argument("mission", help="mission folder written by python -m sim.mission (e.g. out/mission-seed0)")
    p.add_argument("--record", default=None, help="the mission's recording folder (default: the one named "
                                                  "in mission.json, if any)")
    p.add_argument("--port", type=port_number, default=DEFAULT_PORT, help="page port (default %(default)s)")
    a = parse_with_logging(p, argv)
    from dashboard.server import DashboardServer
    from dashboard.viewer import MissionFolderError, MissionSource

    try:
        source = MissionSource(a.mission, a.record)
        server = DashboardServer(source, DEFAULT_HOST, a.port)
    except MissionFolderError as exc:
        p.error(f"mission: {exc}")
    except OSError as exc:
        p.error(f"--port: {exc}")
    server.start()
    log.info("%d timeline rows%s; Ctrl-C to quit", source.n,
             f", {len(source.frames)} recorded frames" if source.frames else ", no recording")
    done = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: done.set())
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    done.wait()
    server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
