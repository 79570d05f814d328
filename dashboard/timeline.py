"""A mission's story at one point per simulated second, for the finished-mission viewer.

Recorded in the mission loop (one cheap call per frame; the work happens once
per ``EVERY_S`` of mission time) and saved as ``timeline.npz`` beside
mission.json: pose, commands, mode, target, the four scores, the client's
worldmap every ``MAP_EVERY_S`` and its event log.  Scores are computed exactly
as the scorer does, on the client's map at that moment.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

from collections import deque

import numpy as np

from evaluation.metrics import score_map

EVERY_S = 1.0  # one timeline row per this much mission time, s
EVENTS_MAX = 20000  # events kept for the viewer's log, count
MAP_EVERY_S = 5.0  # one worldmap copy per this much mission time, s
FIELDS = ("t", "x", "y", "yaw", "speed", "throttle", "brake", "steer", "target_x", "target_y",
          "mapped", "fidelity", "located", "collected")  # float columns, in order


class Timeline:
    def __init__(self, every_s: float = EVERY_S, map_every_s: float = MAP_EVERY_S):
        from dashboard.publisher import Publisher

        self.every_s, self.map_every_s = every_s, map_every_s
        self.rows, self.modes, self.maps, self.map_t = [], [], [], []
        self.samples_initial = None
        self._last_t = self._last_map_t = -math.inf
        self._events = Publisher(hz=0.0)  # reuses its change detection; never publishes
        self._events.period = math.inf
        self._events.events = deque(maxlen=EVENTS_MAX)
        self.truth = None

    def observe(self, client, event=None, force=False):
        self._events.observe(client, event)
        rover = client.rover
        t = rover.total_time
        if not force and t - self._last_t < self.every_s:
            return
        self._last_t = t
        self._events._remember_samples(rover)
        score = score_map(rover.worldmap, rover.ground_truth, [tuple(p) for p in self._events.samples])
        tgt = rover.target if rover.target is not None else (math.nan, math.nan)
        collected = (rover.samples_initial - rover.samples_remaining
                     if rover.samples_initial is not None and rover.samples_remaining is not None else math.nan)
        self.samples_initial = rover.samples_initial
        if self.truth is None and rover.ground_truth is not None:
            self.truth = np.asarray(rover.ground_truth, np.uint8)
        try:
            tx, ty = float(tgt[0]), float(tgt[1])
        except (TypeError, ValueError, IndexError):
            tx = ty = math.nan
        self.rows.append((t, rover.pos[0], rover.pos[1], rover.yaw, rover.vel, rover.throttle, rover.brake,
                          rover.steer, tx, ty, score.mapped_pct, score.fidelity_pct, score.located, collected))
        self.modes.append(str(rover.mode))
        if force or t - self._last_map_t >= self.map_every_s:
            self._last_map_t = t
            self.maps.append(np.array(rover.worldmap, copy=True))
            self.map_t.append(t)

    def save(self, path) -> Path:
        """Write ``timeline.npz`` atomically (temp file + os.replace)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        table = np.asarray(self.rows, float).reshape(-1, len(FIELDS))
        maps = np.asarray(self.maps, np.uint8).reshape(-1, 200, 200, 3)
        tmp = path.with_name(f".{path.name}.tmp")
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, table=table, fields=np.array(FIELDS), modes=np.array(self.modes, dtype=str),
                                maps=maps, map_t=np.asarray(self.map_t, float),
                                events=np.array(json.dumps(list(self._events.events))),
                                truth=(self.truth if self.truth is not None else np.zeros((0, 0), np.uint8)),
                                samples=np.asarray(self._events.samples, float).reshape(-1, 2),
                                samples_initial=np.array(-1 if self.samples_initial is None
                                                         else self.samples_initial))
        os.replace(tmp, path)
        return path
