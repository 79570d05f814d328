"""Pieces both mission runners share (in-process `sim.mission`, on the wire `sim.wire`).

They live here so that sim/ reads top-down with no import circle: mission.py and
wire.py import this module, and neither imports the other at module level
(mission.py reaches `run_wire_mission` only when asked for a wire mission).
Truth meters (stuck time, distance, trajectory), atomic file writers, the
progress bar and the recorder factory.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from collections import deque
from pathlib import Path

import numpy as np

HOME_RADIUS_M = 3.0  # "returned home": within this of the start after collecting all
STUCK_SPEED = 0.2  # m/s, below this while commanding throttle counts as stuck
STUCK_THROTTLE = 0.05  # |throttle| above this is "commanding throttle"
PROGRESS_WINDOW_S = 10.0  # s, no-progress window
PROGRESS_MIN_M = 0.5  # m, moving less than this over the window (not picking up) = stuck
STUCK_REPORT_MIN_S = 5.0  # s, stuck stretches at least this long are listed (time, place) in the JSON


# ----------------------------------------------------------------------------- files
def write_json_atomic(path, obj) -> None:
    """Write JSON via a temp file + os.replace (never a half-written file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(obj, fh, indent=1, default=_json_default)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def write_png_atomic(path, bgr) -> None:
    import cv2

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(".png", bgr)
    if not ok:
        raise ValueError(f"cannot encode PNG for {path}")
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(buf.tobytes())
    os.replace(tmp, path)


def write_npy_atomic(path, array) -> None:
    """Save an array for later analysis (`np.load`), via a temp file + os.replace."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "wb") as fh:
        np.save(fh, np.asarray(array))
    os.replace(tmp, path)


def nan_to_none(v):
    return None if isinstance(v, float) and not math.isfinite(v) else v


# ----------------------------------------------------------------------------- truth meters
class StuckMeter:
    """Truth-based stuck time: slow while commanding throttle, or no progress over a window."""

    def __init__(self):
        self.total_s = 0.0
        self.longest_s = 0.0
        self.stretches = []  # [t_start, x, y, duration_s] of stretches >= STUCK_REPORT_MIN_S
        self._run_s = 0.0
        self._run_start = None
        self._hist = deque()  # (t, x, y, picking)
        self._picking = 0  # entries of _hist with picking set (kept as they come and go: no scan per frame)

    def update(self, t, dt, x, y, v, throttle, picking):
        self._hist.append((t, x, y, picking))
        self._picking += bool(picking)
        while self._hist and self._hist[0][0] < t - PROGRESS_WINDOW_S:
            self._picking -= bool(self._hist.popleft()[3])
        slow = abs(throttle) > STUCK_THROTTLE and abs(v) < STUCK_SPEED
        no_progress = False
        if t >= PROGRESS_WINDOW_S and not self._picking:
            x0, y0 = self._hist[0][1], self._hist[0][2]
            no_progress = math.hypot(x - x0, y - y0) < PROGRESS_MIN_M
        if (slow or no_progress) and not picking:
            if self._run_s == 0.0:
                self._run_start = (round(t - dt, 2), round(x, 2), round(y, 2))
            self.total_s += dt
            self._run_s += dt
            self.longest_s = max(self.longest_s, self._run_s)
        else:
            self.close_run()

    def close_run(self):
        """End the current stuck stretch (also call at the end of a mission)."""
        if self._run_s >= STUCK_REPORT_MIN_S and self._run_start is not None:
            self.stretches.append([*self._run_start, round(self._run_s, 2)])
        self._run_s = 0.0
        self._run_start = None


class TruthTrack:
    """What really happened along a mission: trajectory, distance and stuck time, from the twin's truth."""

    def __init__(self, twin):
        tr = twin.truth
        self.traj = [(tr.x, tr.y)]
        self.distance = 0.0
        self.stuck = StuckMeter()

    def update(self, twin, dt: float) -> None:
        """Call after the twin advanced dt simulated seconds."""
        tr = twin.truth
        self.distance += math.hypot(tr.x - self.traj[-1][0], tr.y - self.traj[-1][1])
        self.traj.append((tr.x, tr.y))
        self.stuck.update(tr.sim_time, dt, tr.x, tr.y, tr.v, twin.controls.throttle, tr.picking_up)


def all_collected_and_home(truth) -> bool:
    """All samples collected and the rover within HOME_RADIUS_M of its start."""
    return bool(truth.initial_samples and len(truth.collected) == len(truth.initial_samples)
                and math.hypot(truth.x - truth.start_xy[0], truth.y - truth.start_xy[1]) <= HOME_RADIUS_M)


# ----------------------------------------------------------------------------- edges
PROGRESS_FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}]"  # tqdm layout


def progress_bar(total, enabled, desc):
    """tqdm bar counting simulated seconds, shown as whole seconds; it stays on screen at the end
    (callers wrap their run in tqdm's logging_redirect_tqdm so log lines do not break it)."""
    from tqdm import tqdm

    class SimSecondsBar(tqdm):
        def update(self, n=1):  # the last frame may pass the time limit: stop at the total
            return super().update(max(0.0, min(n, self.total - self.n)))

    return SimSecondsBar(total=round(total), unit="sim s", disable=not enabled, desc=desc, leave=True,
                         bar_format=PROGRESS_FORMAT)


def open_recorder(folder):
    """A TwinRecorder writing a simulator-format log into `folder`, or None without one."""
    if not folder:
        return None
    from sim.record import TwinRecorder

    return TwinRecorder(folder)
