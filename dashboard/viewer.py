"""The finished-mission viewer: the dashboard page scrubbing through a mission folder.

Reads ``mission.json`` and ``timeline.npz`` (written by ``sim.mission``) and,
when the mission was recorded (``--record``), the camera frames of that
recording; the perception overlay is recomputed from each frame with the
client's own ``perception`` module.  One slider step = one timeline row
(one simulated second).
"""
from __future__ import annotations

import datetime as dt
import json
import logging
import math
import re
import threading
from functools import lru_cache
from pathlib import Path
from typing import Optional

import numpy as np

from dashboard import mapview
from dashboard.view import MAP_SCALE, jpeg_data_url, json_number, rgb_to_bgr, shown_number

log = logging.getLogger(__name__)

FRAME_TIME_RE = re.compile(r"(\d{4})_(\d\d)_(\d\d)_(\d\d)_(\d\d)_(\d\d)_(\d{3})")  # robocam_Y_M_D_h_m_s_ms
CACHE_FRAMES = 64  # rendered viewer frames kept in memory, count


class MissionFolderError(ValueError):
    """The folder is not a finished mission the viewer can read."""


def frame_time_s(name: str) -> Optional[float]:
    m = FRAME_TIME_RE.search(name)
    if not m:
        return None
    y, mo, d, h, mi, s, ms = (int(g) for g in m.groups())
    return dt.datetime(y, mo, d, h, mi, s).timestamp() + ms / 1000.0


class MissionSource:
    """A finished mission served to the dashboard page (``kind: viewer``)."""

    def __init__(self, folder, record=None):
        folder = Path(folder).expanduser()
        self.folder = folder
        mission_json = folder / "mission.json"
        timeline = folder / "timeline.npz"
        if not mission_json.is_file():
            raise MissionFolderError(f"{folder} has no mission.json (run python -m sim.mission --out {folder})")
        if not timeline.is_file():
            raise MissionFolderError(f"{folder} has no timeline.npz (missions written before the viewer "
                                     "existed cannot be scrubbed; run the mission again)")
        self.mission = json.loads(mission_json.read_text())
        with np.load(timeline) as z:
            fields = [str(f) for f in z["fields"]]
            table = z["table"]
            self.cols = {f: table[:, k] for k, f in enumerate(fields)}
            self.modes = [str(m) for m in z["modes"]]
            self.maps, self.map_t = z["maps"], z["map_t"]
            self.events = json.loads(str(z["events"]))
            self.samples = z["samples"]
            self.truth = z["truth"] if z["truth"].size else None
            self.samples_initial = int(z["samples_initial"]) if int(z["samples_initial"]) >= 0 else None
        self.n = len(self.modes)
        if self.n == 0:
            raise MissionFolderError(f"{timeline} is empty")
        record = record or (self.mission.get("files") or {}).get("record")
        self.frames, self.frame_t = self._load_recording(record)
        self._lock = threading.Lock()
        self.render_frame = lru_cache(maxsize=CACHE_FRAMES)(self._render_frame)

    def _load_recording(self, record):
        if not record:
            return [], np.zeros(0)
        from replay.log_format import LogFormatError, read_log

        try:
            data = read_log(record)
        except (LogFormatError, OSError) as exc:
            log.warning("recording %s not usable (%s): the viewer shows no camera", record, exc)
            return [], np.zeros(0)
        frames = [f for f in data.frames if frame_time_s(Path(f.image_path).name) is not None]
        if not frames:
            return [], np.zeros(0)
        t = np.array([frame_time_s(Path(f.image_path).name) for f in frames])
        return frames, t - t[0]

    def info(self):
        m = self.mission
        return {"kind": "viewer", "frames": self.n, "recording": bool(self.frames),
                "title": f"seed {m.get('seed')} on {m.get('world')}: {m.get('end_reason', '')}"}

    def state_json(self):
        return self.frame_json(self.n - 1)

    def frame_json(self, index: int) -> Optional[str]:
        if not 0 <= index < self.n:
            return None
        with self._lock:
            return self.render_frame(index)

    def _camera(self, t, k):
        """(camera RGB, perception overlay RGB) of the recorded frame nearest ``t``, or (None, None)."""
        if not len(self.frames):
            return None, None
        j = int(np.clip(np.searchsorted(self.frame_t, t), 0, len(self.frames) - 1))
        f = self.frames[j]
        import cv2
        import perception
        from rover_state import RoverState

        bgr = cv2.imread(str(f.image_path))
        if bgr is None:
            return None, None
        rover = RoverState(ground_truth=self.truth)
        rover.img = bgr[:, :, ::-1].copy()
        rover.pos, rover.yaw = (f.x, f.y), f.yaw
        rover.pitch = f.pitch if f.pitch <= 180 else f.pitch - 360
        rover.roll = f.roll if f.roll <= 180 else f.roll - 360
        try:
            perception.perception_step(rover)
            vision = rover.vision_image
        except Exception:  # the viewer must show the frame even if perception fails on it
            log.exception("perception failed on %s", f.image_path)
            vision = None
        return rover.img, vision

    def _render_frame(self, i: int) -> str:
        c = self.cols
        t = float(c["t"][i])
        k = int(np.searchsorted(self.map_t, t, side="right")) - 1
        worldmap = self.maps[max(0, k)] if len(self.maps) else np.zeros((200, 200, 3), np.uint8)
        trail = np.column_stack([c["x"][:i + 1], c["y"][:i + 1]])
        stuck = [(s[1], s[2]) for s in self.mission.get("stuck_stretches", []) if s[0] <= t]
        target = (c["target_x"][i], c["target_y"][i]) if math.isfinite(c["target_x"][i]) else None
        start = tuple(trail[0]) if len(trail) else None
        img = mapview.scene(worldmap, self.truth, scale=MAP_SCALE, trail=trail, target=target,
                            samples=self.samples, stuck=stuck, start=start,
                            pose=(c["x"][i], c["y"][i], c["yaw"][i]))
        camera, vision = self._camera(t, i)
        fig = {key: shown_number(c[key][i]) for key in ("t", "x", "y", "yaw", "speed", "throttle", "brake",
                                                           "steer", "mapped", "fidelity")}
        for key in ("located", "collected"):
            v = c[key][i]
            fig[key] = int(v) if math.isfinite(v) else None
        fig.update(frame=i, mode=self.modes[i], goal=None, samples=self.samples_initial,
                   target=None if target is None else [json_number(target[0], 1), json_number(target[1], 1)],
                   telemetry_hz=None)
        hist = {"t": [json_number(v, 2) for v in c["t"][:i + 1]]}
        for key in ("mapped", "fidelity", "located", "collected"):
            hist[key] = [json_number(v, 2) for v in c[key][:i + 1]]
        state = {"version": i + 1, "kind": "viewer", "figures": fig,
                 "images": {"camera": jpeg_data_url(rgb_to_bgr(camera)), "vision": jpeg_data_url(rgb_to_bgr(vision)),
                            "map": jpeg_data_url(img)},
                 "history": hist, "events": [e for e in self.events if e[0] <= t][-50:]}
        return json.dumps(state, separators=(",", ":"))
