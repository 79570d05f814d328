"""What a replay leaves behind: a scored map PNG, an optional mp4 mosaic, a metrics JSON.

Every file is written atomically (temp file in the same folder + os.replace), so
an interrupted run never leaves a half-written result.
"""
from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

import perception

log = logging.getLogger(__name__)

MAP_SCALE = 4  # map PNG pixels per world metre
LEGEND_H = 86  # legend strip height under the map, px
VIDEO_FPS = 25.0  # mosaic video frame rate (the simulator records at ~25 Hz), fps
VIDEO_FOURCC = "mp4v"  # OpenCV codec tag for .mp4
PANEL_W, PANEL_H = 320, 160  # one mosaic panel, px (the camera frame size)

# map PNG colours (BGR)
COLOR_TRUTH_MISSED = (150, 150, 150)  # ground-truth navigable not (yet) marked
COLOR_GOOD = (255, 160, 40)  # marked navigable and truly navigable
COLOR_WRONG = (40, 40, 255)  # marked navigable but not navigable in the ground truth
COLOR_OBSTACLE = (30, 30, 110)  # marked obstacle
COLOR_ROCK = (0, 230, 255)  # remembered sample rock
COLOR_PATH = (255, 255, 255)  # rover trajectory


def _atomic_write_bytes(path: Path, data: bytes):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")  # same folder: os.replace is atomic
    try:
        with open(tmp, "wb") as fh:  # plain open() keeps the user's umask permissions
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        if tmp.exists():
            tmp.unlink()
        raise


def write_json(path, payload: dict):
    _atomic_write_bytes(Path(path), (json.dumps(payload, indent=2, sort_keys=True) + "\n").encode())


def score_colors(worldmap: np.ndarray, ground_truth: Optional[np.ndarray]) -> np.ndarray:
    """BGR cells of the worldmap scored against the ground truth (one pixel per cell, rows as stored: south up).

    The replay map and dashboard.mapview both colour with this, so every map reads the same."""
    size = worldmap.shape[0]
    img = np.zeros((size, size, 3), np.uint8)
    marked = worldmap[:, :, 2] > 0
    obstacle = (worldmap[:, :, 0] > 0) & ~marked
    img[obstacle] = COLOR_OBSTACLE
    if ground_truth is not None:
        truth = ground_truth > 0
        img[truth & ~marked] = COLOR_TRUTH_MISSED
        img[marked & truth] = COLOR_GOOD
        img[marked & ~truth] = COLOR_WRONG
    else:
        img[marked] = COLOR_GOOD
    return img


def map_image(worldmap: np.ndarray, ground_truth: Optional[np.ndarray], rocks=(), trajectory=None,
              title_lines=()) -> np.ndarray:
    """BGR image of the worldmap scored against the ground truth, north up, with a legend."""
    size = worldmap.shape[0]
    img = score_colors(worldmap, ground_truth)
    big = cv2.resize(img, (size * MAP_SCALE, size * MAP_SCALE), interpolation=cv2.INTER_NEAREST)

    def to_px(x, y):  # world metres -> pixel in the north-up image
        return int(round(x * MAP_SCALE)), int(round((size - y) * MAP_SCALE))

    big = np.ascontiguousarray(big[::-1])  # north up: flip rows (world y grows upward)
    if trajectory is not None and len(trajectory) > 1:
        pts = np.array([to_px(x, y) for x, y in trajectory[:: max(1, len(trajectory) // 4000)]], np.int32)
        cv2.polylines(big, [pts.reshape(-1, 1, 2)], False, COLOR_PATH, 1, cv2.LINE_AA)
    for x, y in rocks:
        cv2.circle(big, to_px(x, y), 2 * MAP_SCALE, COLOR_ROCK, 2, cv2.LINE_AA)
    legend = np.zeros((LEGEND_H, big.shape[1], 3), np.uint8)
    items = [(COLOR_GOOD, "navigable, correct"), (COLOR_WRONG, "navigable, wrong"),
             (COLOR_TRUTH_MISSED, "truth, not mapped"), (COLOR_OBSTACLE, "obstacle"),
             (COLOR_ROCK, "sample rock"), (COLOR_PATH, "rover path")]
    for k, (color, text) in enumerate(items):
        x0, y0 = 8 + (k % 3) * 260, 10 + (k // 3) * 20
        cv2.rectangle(legend, (x0, y0), (x0 + 14, y0 + 12), color, -1)
        cv2.putText(legend, text, (x0 + 20, y0 + 11), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (230, 230, 230), 1,
                    cv2.LINE_AA)
    for k, line in enumerate(title_lines[:2]):
        cv2.putText(legend, line, (8, 60 + 18 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1,
                    cv2.LINE_AA)
    return np.vstack([big, legend])


def write_png(path, bgr: np.ndarray):
    ok, buf = cv2.imencode(".png", bgr)
    if not ok:
        raise OSError(f"cannot encode PNG for {path}")
    _atomic_write_bytes(Path(path), buf.tobytes())


def _grid_panel(grid: Optional[np.ndarray]) -> np.ndarray:
    """Top-down label grid as a BGR panel: forward up, rover at the bottom centre."""
    panel = np.zeros((PANEL_H, PANEL_W, 3), np.uint8)
    if grid is None:
        return panel
    colour = np.zeros(grid.shape + (3,), np.uint8)
    colour[grid == 1] = (40, 40, 200)
    colour[grid == 2] = (230, 160, 60)
    colour = colour[::-1]  # row 0 is nearest: flip so forward is up
    scale = min(PANEL_H / colour.shape[0], PANEL_W / colour.shape[1])
    w, h = int(colour.shape[1] * scale), int(colour.shape[0] * scale)
    small = cv2.resize(colour, (w, h), interpolation=cv2.INTER_NEAREST)
    y0, x0 = PANEL_H - h, (PANEL_W - w) // 2
    panel[y0:y0 + h, x0:x0 + w] = small
    cv2.circle(panel, (PANEL_W // 2, PANEL_H - 2), 3, (255, 255, 255), -1)
    return panel


def _map_panel(worldmap: np.ndarray, pos) -> np.ndarray:
    panel = np.zeros((PANEL_H, PANEL_W, 3), np.uint8)
    side = PANEL_H
    m = cv2.resize(np.ascontiguousarray(worldmap[::-1, :, ::-1]), (side, side), interpolation=cv2.INTER_NEAREST)
    x0 = (PANEL_W - side) // 2
    panel[:, x0:x0 + side] = m
    if pos is not None and np.all(np.isfinite(pos)):
        s = side / worldmap.shape[0]
        cv2.circle(panel, (x0 + int(pos[0] * s), int((worldmap.shape[0] - pos[1]) * s)), 2, (255, 255, 255), -1)
    return panel


def mosaic_frame(rover) -> np.ndarray:
    """2x2 BGR mosaic: camera | thresholds, top-down grid | worldmap."""
    cam = cv2.cvtColor(rover.img, cv2.COLOR_RGB2BGR)
    vision = cv2.cvtColor(rover.vision_image, cv2.COLOR_RGB2BGR)
    mem = perception.get_memory(rover)
    top = np.hstack([cam, vision])
    bottom = np.hstack([_grid_panel(mem.last_grid), _map_panel(rover.worldmap, rover.pos)])
    out = np.vstack([top, bottom])
    label = "mapped" if rover.map_updated else "gated"
    cv2.putText(out, f"t={rover.total_time:6.1f}s pitch={rover.pitch:+.1f} roll={rover.roll:+.1f} {label}",
                (4, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (255, 255, 255), 1, cv2.LINE_AA)
    return out


class MosaicVideo:
    """mp4 (mp4v) writer for mosaic frames; writes to a temp name and renames on close."""

    def __init__(self, path, fps: float = VIDEO_FPS):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = self.path.with_name(f".{self.path.stem}.partial{self.path.suffix or '.mp4'}")
        self.fps = fps
        self.writer = None
        self.frames = 0

    def add(self, rover, frame=None):
        img = mosaic_frame(rover)
        if self.writer is None:
            self.writer = cv2.VideoWriter(str(self.tmp), cv2.VideoWriter_fourcc(*VIDEO_FOURCC), self.fps,
                                          (img.shape[1], img.shape[0]))
            if not self.writer.isOpened():
                raise OSError(f"OpenCV cannot open a {VIDEO_FOURCC} video writer for {self.path}")
        self.writer.write(img)
        self.frames += 1

    def close(self, keep: bool = True):
        if self.writer is not None:
            self.writer.release()
            self.writer = None
        if self.tmp.exists():
            if keep and self.frames:
                os.replace(self.tmp, self.path)
            else:
                self.tmp.unlink()
