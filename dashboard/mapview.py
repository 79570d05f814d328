"""The map picture shared by the live dashboard, the mission viewer and mission.png.

One renderer, so the three views use the same colours as the replay map
(`replay.outputs`): the client's worldmap scored against the ground truth, then
the trail, the planned path, the target, remembered rocks, the samples and the
places the rover got stuck.  North up, 1 m = ``scale`` pixels.
"""
from __future__ import annotations

import math
from typing import Iterable, Optional, Sequence

import cv2
import numpy as np

from replay.outputs import (COLOR_GOOD, COLOR_OBSTACLE, COLOR_PATH, COLOR_ROCK, COLOR_TRUTH_MISSED,
                            COLOR_WRONG, score_colors)

COLOR_PLAN = (255, 0, 255)  # planned path (BGR magenta)
COLOR_TARGET = (0, 140, 255)  # decision target (BGR orange)
COLOR_SAMPLE = (0, 255, 0)  # a sample still on the ground (truth or telemetry), BGR green
COLOR_COLLECTED = (0, 120, 0)  # a sample already collected, dark green
COLOR_STUCK = (0, 0, 255)  # where the rover got stuck, red cross
COLOR_BLOCKED = (60, 60, 200)  # cells the planner marked blocked, dim red
COLOR_ROVER = (255, 255, 255)  # rover body and heading
COLOR_START = (200, 200, 200)  # start ("home") cross
LEGEND_ROW_PX = 20  # legend row height, px
LEGEND_COLUMN_PX = 200  # legend column width, px
FONT = cv2.FONT_HERSHEY_SIMPLEX
LEGEND_ITEMS = (  # (colour, label, kind) in legend order
    (COLOR_GOOD, "navigable, correct", "box"), (COLOR_WRONG, "navigable, wrong", "box"),
    (COLOR_TRUTH_MISSED, "truth, not mapped", "box"), (COLOR_OBSTACLE, "obstacle", "box"),
    (COLOR_PATH, "trail", "line"), (COLOR_PLAN, "planned path", "line"),
    (COLOR_TARGET, "target", "dot"), (COLOR_ROCK, "rock seen", "ring"),
    (COLOR_SAMPLE, "sample", "ring"), (COLOR_COLLECTED, "sample collected", "ring"),
    (COLOR_STUCK, "stuck", "cross"), (COLOR_START, "start (home)", "cross"),
)


def base_map(worldmap: np.ndarray, truth: Optional[np.ndarray], scale: int) -> np.ndarray:
    """Worldmap over truth as BGR, north up, ``scale`` px per metre (no overlays)."""
    size = worldmap.shape[0]
    img = np.ascontiguousarray(score_colors(worldmap, truth)[::-1])
    return cv2.resize(img, (size * scale, size * scale), interpolation=cv2.INTER_NEAREST)


def _finite_points(points) -> np.ndarray:
    a = np.asarray(points if points is not None else [], dtype=float).reshape(-1, 2)
    return a[np.isfinite(a).all(axis=1)]


def scene(worldmap: np.ndarray, truth: Optional[np.ndarray] = None, *, scale: int = 3,
          trail: Sequence = (), plan: Sequence = (), target=None, rocks: Iterable = (),
          samples: Iterable = (), collected: Iterable = (), stuck: Iterable = (),
          blocked: Optional[np.ndarray] = None, start=None, pose=None) -> np.ndarray:
    """The full map picture (BGR).  ``blocked`` is an (N, 2) array of (x, y) cells;
    ``pose`` is (x, y, yaw_deg)."""
    img = base_map(worldmap, truth, scale)
    size = worldmap.shape[0]

    def px(pts):
        pts = _finite_points(pts)
        return np.stack([np.round(pts[:, 0] * scale), np.round((size - pts[:, 1]) * scale)],
                        axis=1).astype(np.int32)

    if blocked is not None and len(blocked):
        for x, y in px(np.asarray(blocked, float) + 0.5):
            cv2.rectangle(img, (x - scale // 2, y - scale // 2), (x + scale // 2, y + scale // 2),
                          COLOR_BLOCKED, -1)
    trail_px = px(trail)
    if len(trail_px) > 1:
        cv2.polylines(img, [trail_px.reshape(-1, 1, 2)], False, COLOR_PATH, 1, cv2.LINE_AA)
    plan_px = px(plan)
    if len(plan_px) > 1:
        cv2.polylines(img, [plan_px.reshape(-1, 1, 2)], False, COLOR_PLAN, 2, cv2.LINE_AA)
    for x, y in px(rocks):
        cv2.circle(img, (x, y), 2 * scale, COLOR_ROCK, 2, cv2.LINE_AA)
    for x, y in px(samples):
        cv2.circle(img, (x, y), 3 * scale, COLOR_SAMPLE, 2, cv2.LINE_AA)
    for x, y in px(collected):
        cv2.circle(img, (x, y), 3 * scale, COLOR_COLLECTED, 2, cv2.LINE_AA)
    for x, y in px(stuck):
        cv2.drawMarker(img, (x, y), COLOR_STUCK, cv2.MARKER_TILTED_CROSS, 4 * scale, 2)
    if start is not None:
        for x, y in px([start]):
            cv2.drawMarker(img, (x, y), COLOR_START, cv2.MARKER_CROSS, 5 * scale, 2)
    if target is not None:
        for x, y in px([target]):
            cv2.circle(img, (x, y), 2 * scale, COLOR_TARGET, -1, cv2.LINE_AA)
    if pose is not None:
        pts = px([pose[:2]])
        if len(pts) and math.isfinite(pose[2]):
            x, y = pts[0]
            a = math.radians(pose[2])
            tip = (int(x + 4 * scale * math.cos(a)), int(y - 4 * scale * math.sin(a)))
            cv2.circle(img, (x, y), max(3, scale + 1), COLOR_ROVER, -1, cv2.LINE_AA)
            cv2.line(img, (x, y), tip, COLOR_ROVER, 2, cv2.LINE_AA)
    return img


def legend(width: int, columns: int = 3) -> np.ndarray:
    """A strip naming every colour used by ``scene``."""
    rows = math.ceil(len(LEGEND_ITEMS) / columns)
    col_w = width // columns
    strip = np.full((rows * LEGEND_ROW_PX + 8, width, 3), 24, np.uint8)
    for k, (color, text, kind) in enumerate(LEGEND_ITEMS):
        x0, y0 = 8 + (k % columns) * col_w, 6 + (k // columns) * LEGEND_ROW_PX
        c = (x0 + 7, y0 + 6)
        if kind == "box":
            cv2.rectangle(strip, (x0, y0), (x0 + 14, y0 + 12), color, -1)
        elif kind == "line":
            cv2.line(strip, (x0, y0 + 6), (x0 + 14, y0 + 6), color, 2)
        elif kind == "dot":
            cv2.circle(strip, c, 5, color, -1)
        elif kind == "ring":
            cv2.circle(strip, c, 6, color, 2)
        else:
            cv2.drawMarker(strip, c, color, cv2.MARKER_TILTED_CROSS, 12, 2)
        cv2.putText(strip, text, (x0 + 20, y0 + 11), FONT, 0.45, (230, 230, 230), 1, cv2.LINE_AA)
    return strip


def titled(img: np.ndarray, title: str, lines: Sequence[str] = ()) -> np.ndarray:
    """``img`` with a title bar and a few lines of figures above it, and the legend below."""
    w = img.shape[1]
    head = np.full((34 + 20 * len(lines), w, 3), 24, np.uint8)
    cv2.putText(head, title, (8, 24), FONT, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
    for k, line in enumerate(lines):
        cv2.putText(head, line, (8, 50 + 20 * k), FONT, 0.5, (230, 230, 230), 1, cv2.LINE_AA)
    return np.vstack([head, img, legend(w, columns=max(2, w // LEGEND_COLUMN_PX))])
