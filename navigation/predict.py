"""Latency lead: where the rover will be when this frame's command starts to act.

The real simulator is not lockstep: physics runs on at 0.02 s steps while the
client thinks, and a command sent for frame N is applied at the next rendered
frame, so the rover the command meets has moved on by about one telemetry
interval.  The client has no simulator clock, only its own; it measures that
interval (and the yaw rate) from consecutive frames and predicts the pose
forward by it where a late command costs most: the end of a turn in place, the
last metres to a sample, and the pursuit point on a path.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Tuple

LEAD_MAX_S = 0.25  # never predict further ahead than this (a stalled frame is not latency), s
LEAD_EMA = 0.2  # weight of the newest frame interval in the running estimate, 0..1
FRAME_GAP_MAX_S = 1.0  # a longer gap between frames is a pause, not a frame interval: ignored, s
YAW_RATE_MAX_DPS = 90.0  # the simulator turns in place at 45 deg/s; faster readings are noise or wraps, deg/s


def wrap_deg(a: float) -> float:
    """Degrees wrapped to [-180, 180)."""
    return (float(a) + 180.0) % 360.0 - 180.0


@dataclass
class LeadEstimator:
    """Running frame interval and yaw rate from the client's own clock (no simulator time)."""

    interval_s: float = 0.0  # smoothed time between telemetry frames, s (0 until two frames were seen)
    yaw_rate_dps: float = 0.0  # yaw rate between the last two frames, deg/s (CCW +)
    _t: Optional[float] = None
    _yaw: Optional[float] = None

    def update(self, t: float, yaw_deg: float) -> None:
        """Feed one frame's time (client clock, s) and yaw (deg)."""
        if not (math.isfinite(t) and math.isfinite(yaw_deg)):
            return
        if self._t is not None:
            dt = t - self._t
            if 0.0 < dt <= FRAME_GAP_MAX_S:
                self.interval_s = dt if self.interval_s <= 0.0 else (
                    (1.0 - LEAD_EMA) * self.interval_s + LEAD_EMA * dt)
                rate = wrap_deg(yaw_deg - self._yaw) / dt
                self.yaw_rate_dps = max(-YAW_RATE_MAX_DPS, min(YAW_RATE_MAX_DPS, rate))
            elif dt > FRAME_GAP_MAX_S or dt < 0.0:
                self.yaw_rate_dps = 0.0  # a pause or a clock jump: the last rate is stale
        self._t, self._yaw = t, yaw_deg

    @property
    def lead_s(self) -> float:
        """How far ahead to predict: one telemetry interval, capped."""
        return min(max(self.interval_s, 0.0), LEAD_MAX_S)


def predict_pose(x: float, y: float, yaw_deg: float, speed: float, yaw_rate_dps: float,
                 lead_s: float) -> Tuple[float, float, float]:
    """(x, y, yaw_deg) after `lead_s` seconds at constant speed (m/s, forward +) and yaw rate (deg/s).

    Integrates along the arc (exact for constant speed and turn rate); non-finite
    inputs give the pose back unchanged.
    """
    vals = (x, y, yaw_deg, speed, yaw_rate_dps, lead_s)
    if not all(math.isfinite(float(v)) for v in vals) or lead_s <= 0.0:
        return float(x), float(y), float(yaw_deg)
    dyaw = math.radians(yaw_rate_dps * lead_s)
    yaw0 = math.radians(yaw_deg)
    dist = speed * lead_s
    if abs(dyaw) < 1e-6:
        dx, dy = dist * math.cos(yaw0), dist * math.sin(yaw0)
    else:
        r = dist / dyaw
        dx = r * (math.sin(yaw0 + dyaw) - math.sin(yaw0))
        dy = -r * (math.cos(yaw0 + dyaw) - math.cos(yaw0))
    return float(x + dx), float(y + dy), float((yaw_deg + math.degrees(dyaw)) % 360.0)


def heading_error_at_lead(target_deg: float, yaw_deg: float, yaw_rate_dps: float, lead_s: float) -> float:
    """Heading still to turn (deg, CCW +) once the command now being chosen takes effect.

    Ending a turn in place on the error measured now overshoots by rate x lead;
    judging it on the predicted yaw stops the turn in time.  Only a rate that
    moves toward the target shortens the error; one moving away is ignored (a
    turn that has not started yet must not look finished).
    """
    err = wrap_deg(target_deg - yaw_deg)
    if not all(math.isfinite(float(v)) for v in (yaw_rate_dps, lead_s)) or lead_s <= 0.0:
        return err
    turned = yaw_rate_dps * lead_s
    if turned * err <= 0.0:
        return err
    if abs(turned) >= abs(err):
        return 0.0
    return err - turned


def distance_at_lead(dist_m: float, speed: float, lead_s: float) -> float:
    """Distance (m) still to go to a point ahead once the command takes effect (never below 0)."""
    if not all(math.isfinite(float(v)) for v in (dist_m, speed, lead_s)):
        return dist_m
    return max(0.0, dist_m - max(speed, 0.0) * max(lead_s, 0.0))
