"""The simulator's side of a wire run, shaped like an AutonomyClient for the dashboard's Publisher.

Why: ``python -m sim.wire --dashboard`` drives a client in another process, so
the client's beliefs (its map, mode, plan) are not here; what is here is what
the simulator knows - the camera frame it sends, the true pose, the commands it
received and the samples.  The page then shows those over the ground truth (the
client's own map stays empty: run ``drive_rover.py --dashboard`` for that side).
"""
from __future__ import annotations

import numpy as np

from rover_state import RoverState


class TwinView:
    """``update()`` after each twin frame, then hand it to ``Publisher.observe``."""

    def __init__(self, twin):
        self.twin = twin
        self.rover = RoverState(ground_truth=twin.world.nav_truth)
        self.episodes = 1
        self.last_timings: dict = {}
        self.bad_frames = 0
        self.step_errors = 0

    def update(self) -> "TwinView":
        tw, r = self.twin, self.rover
        tr = tw.truth
        r.total_time, r.frame_count = tr.sim_time, tr.frame
        r.pos, r.yaw, r.vel = (tr.x, tr.y), tr.yaw, tr.v
        c = tw.controls
        r.throttle, r.brake, r.steer = c.throttle, c.brake, c.steer
        r.img = tw.last_rgb
        r.mode = "picking up" if tr.picking_up else "simulator view"
        r.samples_initial, r.samples_remaining = len(tr.initial_samples), len(tr.samples)
        r.samples_pos = (np.array([s.x for s in tr.samples]), np.array([s.y for s in tr.samples]))
        r.start_pos = tr.start_xy
        return self
