"""Run the live client's perception over a recorded log, frame by frame.

Each frame goes through the same path as live telemetry: a ``Telemetry`` built
from the log row is applied with ``supporting_functions.update_rover`` (so
``RoverState`` gets exactly what the live client would give it), then
``perception.perception_step`` runs.  Only the JPEG decode differs: frames come
from files instead of base64.
"""
from __future__ import annotations

import datetime as _dt
import logging
import math
import re
import time
from dataclasses import dataclass, field
from typing import Callable, List, Optional

import cv2
import numpy as np

import perception
from evaluation.metrics import score_map
from replay.log_format import LogData, LogFrame
from rover_state import RoverState

log = logging.getLogger(__name__)

FALLBACK_FRAME_PERIOD_S = 0.04  # frame spacing assumed when names carry no time stamp, s (25 Hz)
_STAMP_RE = re.compile(r"(\d{4})_(\d{2})_(\d{2})_(\d{2})_(\d{2})_(\d{2})_(\d{3})")

try:  # the live client's parser/updater, when present
    import supporting_functions as _sf
except Exception:  # pragma: no cover - only while the client module is missing/broken
    _sf = None


def frame_time(frame: LogFrame) -> Optional[float]:
    """Seconds since the epoch encoded in a robocam_YYYY_MM_DD_HH_MM_SS_fff.jpg name, or None."""
    m = _STAMP_RE.search(frame.image_path.name)
    if not m:
        return None
    y, mo, d, h, mi, s, ms = (int(g) for g in m.groups())
    try:
        return _dt.datetime(y, mo, d, h, mi, s, ms * 1000).timestamp()
    except ValueError:
        return None


def decode_frame(path) -> Optional[np.ndarray]:
    """RGB uint8 (160, 320, 3) from a JPEG file, or None when unreadable or the wrong size."""
    try:
        raw = np.fromfile(str(path), dtype=np.uint8)
    except OSError:
        return None
    if raw.size == 0:
        return None
    bgr = cv2.imdecode(raw, cv2.IMREAD_COLOR)
    if bgr is None or bgr.shape != (perception.IMAGE_H, perception.IMAGE_W, 3):
        return None
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def signed_angle(deg: float) -> float:
    d = float(deg) % 360.0
    return d - 360.0 if d > 180.0 else d


def apply_frame(rover: RoverState, frame: LogFrame, rgb: np.ndarray, now: float) -> RoverState:
    """Load one log row into the rover as live telemetry would."""
    if _sf is not None and hasattr(_sf, "Telemetry") and hasattr(_sf, "update_rover"):
        tel = _sf.Telemetry()
        tel.ok = True
        tel.steer, tel.throttle, tel.brake, tel.speed = frame.steer, frame.throttle, frame.brake, frame.speed
        tel.pos = (frame.x, frame.y)
        tel.yaw = frame.yaw % 360.0
        tel.pitch, tel.roll = signed_angle(frame.pitch), signed_angle(frame.roll)
        tel.image = rgb
        return _sf.update_rover(rover, tel, now)
    # fallback: the same fields set directly
    rover.frame_count += 1
    rover.telemetry_ok = True
    if rover.start_time is None:
        rover.start_time = now
    rover.total_time = max(0.0, now - rover.start_time)
    if rover.start_pos is None:
        rover.start_pos = (frame.x, frame.y)
    rover.img = rgb
    rover.pos = (frame.x, frame.y)
    rover.yaw, rover.pitch, rover.roll = frame.yaw % 360.0, signed_angle(frame.pitch), signed_angle(frame.roll)
    rover.vel = frame.speed
    rover.steer_telemetry, rover.throttle_telemetry, rover.brake_telemetry = frame.steer, frame.throttle, frame.brake
    return rover


@dataclass
class ReplayResult:
    log_path: str
    frames_total: int  # rows in the log
    frames_used: int  # frames that went through perception
    frames_skipped_log: int  # rows the reader skipped (corrupt, duplicate, missing image)
    frames_unreadable: int  # images that failed to decode
    frames_mapped: int  # frames that passed the tilt gate
    mapped_pct: float
    fidelity_pct: float
    marked_cells: int
    good_cells: int
    rocks_located: int  # rocks remembered by perception
    rocks_world: List[List[float]] = field(default_factory=list)
    perception_ms_median: float = float("nan")
    perception_ms_p95: float = float("nan")
    wall_s: float = 0.0
    used_update_rover: bool = False

    def as_dict(self):
        d = dict(self.__dict__)
        for k, v in d.items():
            if isinstance(v, float) and not math.isfinite(v):
                d[k] = None  # JSON has no nan
        return d


def replay(data: LogData, ground_truth=None, on_frame: Optional[Callable] = None,
           progress: bool = True) -> tuple:
    """Run perception over every usable frame; returns (ReplayResult, rover, trajectory (N, 2))."""
    from tqdm import tqdm

    rover = RoverState(ground_truth=ground_truth)
    unreadable = 0
    times_ms = []
    trajectory = []
    t_start = time.perf_counter()
    base_time = None
    for i, frame in enumerate(tqdm(data.frames, desc="replay", unit="frame", disable=not progress)):
        rgb = decode_frame(frame.image_path)
        if rgb is None:
            unreadable += 1
            if unreadable <= 10:
                log.warning("unreadable image %s (row %d); skipped", frame.image_path, frame.row_number)
            continue
        stamp = frame_time(frame)
        if stamp is None:
            now = i * FALLBACK_FRAME_PERIOD_S
        else:
            base_time = stamp if base_time is None else base_time
            now = stamp - base_time
        apply_frame(rover, frame, rgb, now)
        t0 = time.perf_counter()
        perception.perception_step(rover)
        times_ms.append((time.perf_counter() - t0) * 1e3)
        trajectory.append((frame.x, frame.y))
        if on_frame is not None:
            on_frame(rover, frame)
    wall = time.perf_counter() - t_start
    used = len(times_ms)
    score = score_map(rover.worldmap, ground_truth)
    mem = perception.get_memory(rover)
    result = ReplayResult(
        log_path=str(data.log_path), frames_total=data.rows, frames_used=used,
        frames_skipped_log=data.skipped, frames_unreadable=unreadable, frames_mapped=mem.frames_mapped,
        mapped_pct=score.mapped_pct, fidelity_pct=score.fidelity_pct, marked_cells=score.marked_cells,
        good_cells=score.good_cells, rocks_located=len(rover.rocks_world),
        rocks_world=[[round(x, 2), round(y, 2)] for x, y in rover.rocks_world],
        perception_ms_median=float(np.median(times_ms)) if times_ms else float("nan"),
        perception_ms_p95=float(np.percentile(times_ms, 95)) if times_ms else float("nan"),
        wall_s=wall, used_update_rover=_sf is not None and hasattr(_sf, "update_rover"))
    return result, rover, np.array(trajectory, dtype=float).reshape(-1, 2)
