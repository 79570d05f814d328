"""Watch the rover think: a live browser dashboard and a finished-mission viewer.

Live: ``python drive_rover.py --dashboard`` or ``python -m sim.mission --dashboard``
serve http://127.0.0.1:4568/ with the camera, the perception overlay, the map
over the ground truth (trail, planned path, target, rocks, samples, stuck
places), the mode and commands, the scores and their curves, and an event log.
Finished missions: ``python -m dashboard out/mission-seed0`` scrubs through a
mission folder (mission.json + timeline.npz, and its recording when there is one).

The control loop only ever calls ``Publisher.observe`` (cheap, never blocks on
a page); see ``publisher.py`` and ``server.py`` for why.
"""
from __future__ import annotations

import argparse

from dashboard.server import DEFAULT_HOST, DEFAULT_PORT
from sim.cli import port_number


def add_dashboard_options(parser: argparse.ArgumentParser):
    """--dashboard, --dashboard-port: the same options on every tool that can show the page."""
    parser.add_argument("--dashboard", action="store_true",
                        help=f"serve a live dashboard on http://{DEFAULT_HOST}:<--dashboard-port>/")
    parser.add_argument("--dashboard-port", type=port_number, default=DEFAULT_PORT, metavar="PORT",
                        help="dashboard port (default %(default)s; 0 = any free port)")


class LiveDashboard:
    """Publisher + server in one object: ``observe(client, event)`` per frame, ``close()`` at the end."""

    def __init__(self, port=DEFAULT_PORT, host=DEFAULT_HOST, title="rover"):
        from dashboard.publisher import Publisher
        from dashboard.server import DashboardServer, LiveSource
        from dashboard.view import ViewRenderer

        self.publisher = Publisher()
        self.server = DashboardServer(LiveSource(self.publisher.slot, ViewRenderer(), title), host, port)
        self.url = self.server.url

    def start(self):
        self.server.start()
        return self

    def observe(self, client, event=None, force=False):
        return self.publisher.observe(client, event, force)

    def close(self):
        self.server.stop()
