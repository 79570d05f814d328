"""Lack-of-progress detection and a free-settle-turn recovery.

Progress is judged from pose alone (position over a time window while the
rover is commanded to drive), because wheel speed lies when the rover is
wedged on a rock or spinning on a slope. For the same reason the recovery
watches the pose: a freeing move that does not budge the rover is swapped
for another.
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
PROBE_S = 0.6  # a freeing move that has not budged the rover after this long is swapped for the next, s
PROBE_MIN_MOVE_M = 0.08  # ...budged = moved at least this far, m
PROBE_MIN_TURN_DEG = 4.0  # ...or turned at least this much, degrees
TURN_BLOCKED_S = 0.8  # the recovery turn ends early when the heading has not changed for this long, s


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
    """Escape: free the rover (reverse or pull away), stop, turn in place.

    The freeing move starts by reversing (steering so the nose swings toward
    turn_sign), or with ``ahead`` by driving forward at full lock: a rover
    wedged with its tail on a rock can neither reverse nor turn in place, but
    can still pull away nose first. Given the pose, a move that does not
    budge the rover within PROBE_S is swapped for the next one in
    `escape_moves` (a wedge blocks some directions, rarely all), and a turn
    that does not change the heading ends early.
    """

    def __init__(self, t0, turn_sign, repeat=0, ahead=False):
        self.t0 = float(t0)
        self.turn_sign = 1.0 if turn_sign >= 0 else -1.0
        self.free_s = BACK_OFF_S + ESCALATE_BACK_S * min(repeat, MAX_ESCALATION)
        self.turn_s = TURN_S * (1.0 + 0.25 * min(repeat, MAX_ESCALATION))
        self.moves = escape_moves(self.turn_sign, ahead)
        self.move = 0
        self.phase, self.phase_t0 = "free", self.t0
        self.ref = None  # (t, x, y, yaw) where the current move or turn was last seen to make progress
        self.moved = False  # the current freeing move has budged the rover

    def command(self, t, pose=None):
        """(phase, throttle, brake, steer) for time t, or None when the recovery is over.

        pose: (x, y, yaw_deg) of the rover now, or None for a purely timed script.
        """
        if self.phase == "free":
            out = self._free(t, pose)
            if out is not None:
                return out
            self._enter("settle", t)
        if self.phase == "settle":
            if t - self.phase_t0 < SETTLE_S:
                return "settle", 0.0, SETTLE_BRAKE, 0.0
            self._enter("turn", t)
        if self.phase == "turn":
            if t - self.phase_t0 < self.turn_s and not self._turn_blocked(t, pose):
                return "turn", 0.0, 0.0, 15.0 * self.turn_sign
            self._enter("over", t)
        return None

    def _enter(self, phase, t):
        self.phase, self.phase_t0, self.ref = phase, t, None

    def _free(self, t, pose):
        name, throttle, steer = self.moves[self.move]
        if pose is not None and not self.moved:
            if self.ref is None:
                self.ref = (t, *pose)
            elif _budged(self.ref, pose):
                self.moved = True
            elif t - self.ref[0] >= PROBE_S:
                if self.move + 1 >= len(self.moves):
                    return None
                self.move += 1
                self.phase_t0, self.ref = t, (t, *pose)
                name, throttle, steer = self.moves[self.move]
        if t - self.phase_t0 >= self.free_s:
            return None
        return name, throttle, 0.0, steer

    def _turn_blocked(self, t, pose):
        if pose is None:
            return False
        if self.ref is None or abs(heading_diff_deg(pose[2], self.ref[3])) >= PROBE_MIN_TURN_DEG:
            self.ref = (t, *pose)
            return False
        return t - self.ref[0] >= TURN_BLOCKED_S


def escape_moves(turn_sign, ahead=False):
    """Freeing moves in the order they are tried: (name, throttle, steer)."""
    back = [("back", BACK_OFF_THROTTLE, -15.0 * turn_sign), ("back", BACK_OFF_THROTTLE, 0.0)]
    fwd = [("ahead", AHEAD_THROTTLE, 15.0 * turn_sign), ("ahead", AHEAD_THROTTLE, -15.0 * turn_sign)]
    last = [("back", BACK_OFF_THROTTLE, 15.0 * turn_sign)]
    return fwd + back + last if ahead else back + fwd + last


def heading_diff_deg(a, b):
    """a - b in degrees, wrapped to [-180, 180)."""
    return (a - b + 180.0) % 360.0 - 180.0


def _budged(ref, pose):
    """The rover moved or turned noticeably since `ref` (t, x, y, yaw)."""
    return (np.hypot(pose[0] - ref[1], pose[1] - ref[2]) >= PROBE_MIN_MOVE_M
            or abs(heading_diff_deg(pose[2], ref[3])) >= PROBE_MIN_TURN_DEG)


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
