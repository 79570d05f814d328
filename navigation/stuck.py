"""Lack-of-progress detection and a scripted back-off-and-turn recovery.

Progress is judged from pose alone (position over a time window while the
rover is commanded to drive), because wheel speed lies when the rover is
wedged on a rock or spinning on a slope.
"""
from collections import deque

import numpy as np

STUCK_WINDOW_S = 3.0  # driving this long without progress means stuck, s
STUCK_MIN_PROGRESS_M = 0.4  # ...progress less than this over the window, m
BACK_OFF_S = 1.3  # reverse phase duration, s
BACK_OFF_THROTTLE = -1.0  # reverse throttle
SETTLE_S = 0.5  # braking to a standstill before turning, s
SETTLE_BRAKE = 3.0  # brake while settling
TURN_S = 1.6  # turn-in-place phase (45 deg/s at full lock), s
ESCALATE_BACK_S = 0.6  # extra reverse time per repeated stuck at the same place, s
ESCALATE_RADIUS_M = 3.0  # stuck events within this distance count as the same place, m
ESCALATE_WINDOW_S = 40.0  # ...and within this time, s
MAX_ESCALATION = 4  # cap on the repeat count used for escalation
AHEAD_THROTTLE = 0.6  # forward escape throttle (used when reversing cannot free the rover)


class ProgressMonitor:
    """Says 'stuck' after STUCK_WINDOW_S of commanded driving with too little displacement."""

    def __init__(self):
        self.samples = deque()  # (t, x, y) while driving

    def reset(self):
        self.samples.clear()

    def update(self, t, pos, driving):
        if not driving or not (np.isfinite(t) and np.isfinite(pos[0]) and np.isfinite(pos[1])):
            self.samples.clear()
            return False
        self.samples.append((t, float(pos[0]), float(pos[1])))
        while len(self.samples) > 1 and t - self.samples[1][0] >= STUCK_WINDOW_S:
            self.samples.popleft()
        t0, x0, y0 = self.samples[0]
        if t - t0 < STUCK_WINDOW_S:
            return False
        moved = np.hypot(pos[0] - x0, pos[1] - y0)
        return bool(moved < STUCK_MIN_PROGRESS_M)


class Recovery:
    """Scripted escape: reverse (steering so the nose swings toward turn_sign), stop, turn in place.

    With ``ahead`` the first phase drives forward at full lock instead: a rover
    wedged with its tail on a rock can neither reverse nor turn in place, but
    can still pull away nose first.
    """

    def __init__(self, t0, turn_sign, repeat=0, ahead=False):
        self.t0 = float(t0)
        self.turn_sign = 1.0 if turn_sign >= 0 else -1.0
        back = BACK_OFF_S + ESCALATE_BACK_S * min(repeat, MAX_ESCALATION)
        turn = TURN_S * (1.0 + 0.25 * min(repeat, MAX_ESCALATION))
        first = (("ahead", back, AHEAD_THROTTLE, 0.0, 15.0 * self.turn_sign) if ahead
                 else ("back", back, BACK_OFF_THROTTLE, 0.0, -15.0 * self.turn_sign))
        self.phases = [
            first,
            ("settle", SETTLE_S, 0.0, SETTLE_BRAKE, 0.0),
            ("turn", turn, 0.0, 0.0, 15.0 * self.turn_sign),
        ]

    def command(self, t):
        """(phase, throttle, brake, steer) for time t, or None when the recovery is over."""
        el = t - self.t0
        for name, dur, thr, brk, st in self.phases:
            if el < dur:
                return name, thr, brk, st
            el -= dur
        return None


def count_recent_nearby(events, t, pos):
    """How many earlier stuck events happened close by, recently (for escalation)."""
    n = 0
    for et, ex, ey in events:
        if t - et <= ESCALATE_WINDOW_S and np.hypot(ex - pos[0], ey - pos[1]) <= ESCALATE_RADIUS_M:
            n += 1
    return n


def blocked_cells_ahead(pos, yaw_deg, near_m=0.8, far_m=1.8, half_width_m=0.6, step_m=0.3):
    """World cells (row, col) just ahead of the rover, to remember as blocked after a stuck."""
    yaw = np.radians(yaw_deg)
    fwd = np.arange(near_m, far_m + 1e-9, step_m)
    lat = np.arange(-half_width_m, half_width_m + 1e-9, step_m)
    f, l = np.meshgrid(fwd, lat)
    x = pos[0] + f * np.cos(yaw) - l * np.sin(yaw)
    y = pos[1] + f * np.sin(yaw) + l * np.cos(yaw)
    cells = np.unique(np.stack([np.floor(y).ravel(), np.floor(x).ravel()], axis=1).astype(int), axis=0)
    keep = (cells[:, 0] >= 0) & (cells[:, 0] < 200) & (cells[:, 1] >= 0) & (cells[:, 1] < 200)
    return cells[keep]
