"""Turns a ``Snapshot`` into the JSON the page draws (runs on the page's threads).

Scoring, map drawing and JPEG encoding live here, not in the control loop; the
result for a snapshot version is cached, so any number of open pages cost one
render per published snapshot.  The curves keep one point per
``HISTORY_EVERY_S`` of mission time.
"""
from __future__ import annotations

import base64
import json
import math
import threading
from typing import Optional

import cv2
import numpy as np

from dashboard import mapview
from evaluation.metrics import score_map

MAP_SCALE = 2  # page map pixels per metre (400 x 400 px; the page scales it up)
JPEG_QUALITY = 80  # page images, 0..100
HISTORY_EVERY_S = 1.0  # one curve point per this much mission time, s
HISTORY_MAX_POINTS = 1200  # curve points kept (older ones thinned by two), count


def jpeg_data_url(bgr: Optional[np.ndarray]) -> Optional[str]:
    if bgr is None:
        return None
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    return "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode("ascii") if ok else None


def rgb_to_bgr(img) -> Optional[np.ndarray]:
    if not isinstance(img, np.ndarray) or img.ndim != 3 or img.shape[2] != 3:
        return None
    return np.ascontiguousarray(img[:, :, ::-1])


def json_number(v, digits=3):
    """A finite float for JSON (None otherwise), rounded to `digits` (None: sent exactly)."""
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(v):
        return None
    return v if digits is None else round(v, digits)


def shown_number(v):
    # Figures the page prints with fewer digits go out unrounded: rounding here and again in the
    # page (toFixed) can land one step off what the client itself would print (1.149 -> 1.15 -> 1.1).
    return json_number(v, None)


class History:
    """Mission-time curves of mapped / fidelity / located / collected."""

    KEYS = ("t", "mapped", "fidelity", "located", "collected")

    def __init__(self):
        self.reset()

    def reset(self):
        self.data = {k: [] for k in self.KEYS}

    def add(self, t, mapped, fidelity, located, collected):
        ts = self.data["t"]
        if ts and t < ts[-1]:
            self.reset()
        elif ts and t - ts[-1] < HISTORY_EVERY_S:
            return
        for k, v in zip(self.KEYS, (t, mapped, fidelity, located, collected)):
            self.data[k].append(json_number(v, 2))
        if len(ts) > HISTORY_MAX_POINTS:
            for k in self.KEYS:
                self.data[k] = self.data[k][::2]


def map_picture(snap, scale=MAP_SCALE) -> np.ndarray:
    remaining_xy = np.asarray(snap.remaining_xy, float).reshape(-1, 2)
    samples = np.asarray(snap.samples, float).reshape(-1, 2)
    if len(remaining_xy) and len(samples):
        d = np.abs(samples[:, None, :] - remaining_xy[None, :, :]).max(axis=2).min(axis=1)
        collected_xy = samples[d > 0.5]
    else:
        collected_xy = samples if snap.remaining == 0 else samples[:0]
    return mapview.scene(
        snap.worldmap, snap.truth, scale=scale, trail=snap.trail, plan=snap.plan, target=snap.target,
        rocks=snap.rocks, samples=remaining_xy, collected=collected_xy, stuck=snap.stuck,
        blocked=snap.blocked, start=snap.start, pose=(snap.pos[0], snap.pos[1], snap.yaw))


def figures(snap) -> dict:
    """The numbers the page shows, computed from the snapshot exactly as the scorer does."""
    score = score_map(snap.worldmap, snap.truth, [tuple(p) for p in snap.samples])
    collected = (snap.initial - snap.remaining) if snap.initial is not None and snap.remaining is not None \
        else None
    return {"t": shown_number(snap.t), "frame": snap.frame, "mode": snap.mode, "goal": snap.plan_goal,
            "target": None if snap.target is None else [json_number(snap.target[0], 1), json_number(snap.target[1], 1)],
            "x": json_number(snap.pos[0], 2), "y": json_number(snap.pos[1], 2), "yaw": json_number(snap.yaw, 1),
            "speed": shown_number(snap.speed), "throttle": shown_number(snap.throttle), "brake": shown_number(snap.brake),
            "steer": shown_number(snap.steer), "mapped": shown_number(score.mapped_pct),
            "fidelity": shown_number(score.fidelity_pct), "located": score.located, "collected": collected,
            "samples": snap.initial}


class ViewRenderer:
    """Snapshot -> JSON text, cached per version, curves accumulated across versions."""

    def __init__(self, scale: int = MAP_SCALE):
        self.scale = scale
        self.history = History()
        self._lock = threading.Lock()
        self._cache = (None, None)
        self._prev = None  # (wall, frame, episode) of the previous rendered snapshot

    def render(self, version: int, snap) -> str:
        with self._lock:
            if self._cache[0] == version:
                return self._cache[1]
            text = json.dumps(self._state(version, snap), separators=(",", ":"))
            self._cache = (version, text)
            return text

    def _state(self, version, snap) -> dict:
        fig = figures(snap)
        if self._prev is not None and self._prev[2] != snap.episode:
            self.history.reset()
        self.history.add(snap.t, fig["mapped"], fig["fidelity"], fig["located"], fig["collected"])
        rate = None
        if self._prev is not None and snap.wall > self._prev[0] and snap.episode == self._prev[2]:
            rate = (snap.frame - self._prev[1]) / (snap.wall - self._prev[0])
        self._prev = (snap.wall, snap.frame, snap.episode)
        fig["telemetry_hz"] = json_number(rate, 1)
        return {"version": version, "kind": "live", "figures": fig,
                "images": {"camera": jpeg_data_url(rgb_to_bgr(snap.img)),
                           "vision": jpeg_data_url(rgb_to_bgr(snap.vision)),
                           "map": jpeg_data_url(map_picture(snap, self.scale))},
                "history": self.history.data, "events": snap.events,
                "timings": {k: json_number(v) for k, v in snap.timings.items()}, "counters": snap.counters}
