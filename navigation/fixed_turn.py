"""Turning in place with the simulator's `fixed_turn` command instead of steering at full lock.

Why: a steered turn in place runs at the simulator's 45 deg/s (less where the last degrees are
softened) and stops wherever the latency leaves it; ~24 turns of ~112 deg each cost a mission
~82 s (matrix at 2ec3495). `fixed_turn` turns the body kinematically at angle/time deg/s and
stops exactly at its target, whatever the latency.

The simulator accepts it only from a standstill (|speed| < 0.01 m/s) with no motor and no
steering input in the last (sticky) `data` command and no fixed turn running; otherwise it
ignores it without a word. So a turn is: brake to a standstill, one frame of data 0/0/0 (brake
released), the `fixed_turn` itself, then data 0/0/0 until the yaw has arrived. A turn whose yaw
has not moved FIXED_TURN_REFUSED_S (plus the latency) after it was sent was refused: the caller
steers that turn instead, and after FIXED_TURN_MAX_REFUSALS refusals in a row stops asking.

Sign conventions: the client thinks in CCW degrees (telemetry yaw grows to the left); the
simulator's angle is clockwise-positive, and its time must carry the same sign as the angle
(opposite signs give a negative speed and a turn that never ends).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional

from navigation.predict import wrap_deg

FIXED_TURN_RATE_DPS = 180.0  # turn speed asked of the simulator (time = angle / this), deg/s (90 was slower overall, docs/autonomy.md)
FIXED_TURN_SWEEP_RATE_DPS = 45.0  # ...for a turn whose arc sweeps what the camera still has to look at (decision._fixed_turn_rate), deg/s
FIXED_TURN_SLOW_FOR_UNSEARCHED = True  # ...slow: the long way round, or an arc over unsearched wall feet with samples missing (180 deg/s there missed seed 0's north-tip sample)
FIXED_TURN_SLOW_FOR_FRONTIER = True  # ...slow: an arc over frontier cells (mapped floor beside unmapped ground: cells need several votes)
FIXED_TURN_MIN_DEG = 15.0  # turns smaller than this are steered (release + send frames cost more than they save), degrees
FIXED_TURN_STILL_MPS = 0.005  # |telemetry speed| below this counts as the standstill the simulator needs (< 0.01), m/s
FIXED_TURN_STOP_WAIT_S = 2.0  # braking this long without reaching that standstill: steer this turn instead, s
FIXED_TURN_REFUSED_S = 0.3  # the yaw has not moved this long (+ latency) after sending: the simulator refused it, s
FIXED_TURN_MOVED_DEG = 1.0  # ...has not moved by at least this much, degrees
FIXED_TURN_DONE_DEG = 1.0  # the turn has arrived when this close to its full angle, degrees
FIXED_TURN_MARGIN_S = 0.5  # wait at most the turn's own time + this (+ latency) for it to arrive, s
FIXED_TURN_MAX_REFUSALS = 3  # this many refusals in a row: the simulator does not do fixed turns, steer from then on
ANGLE_FORMAT = "{:.4f}"  # plain decimal with '.', as the simulator's float.Parse expects


def duration_s(ccw_deg: float, rate_dps: Optional[float] = None) -> float:
    """Seconds the simulator takes for a turn of this many degrees at rate_dps (default FIXED_TURN_RATE_DPS)."""
    return abs(float(ccw_deg)) / (FIXED_TURN_RATE_DPS if rate_dps is None else rate_dps)


def payload(ccw_deg: float, rate_dps: Optional[float] = None) -> Dict[str, str]:
    """The `fixed_turn` payload for a CCW turn (client convention) at rate_dps (default
    FIXED_TURN_RATE_DPS): JSON strings (a JSON number stalls the simulator), angle
    clockwise-positive, time with the angle's sign."""
    rate_dps = FIXED_TURN_RATE_DPS if rate_dps is None else rate_dps
    cw = -float(ccw_deg)
    if not math.isfinite(cw) or cw == 0.0 or not (math.isfinite(rate_dps) and rate_dps > 0):
        raise ValueError(f"no fixed turn for angle {ccw_deg!r} at {rate_dps!r} deg/s")
    time_s = math.copysign(duration_s(cw, rate_dps), cw)
    return {"angle": _fmt(cw), "time": _fmt(time_s)}


def _fmt(v: float) -> str:
    return ANGLE_FORMAT.format(float(v) + 0.0).replace("-0.0000", "0.0000")


def still(vel: float) -> bool:
    """Is the rover at the standstill the simulator accepts a fixed turn from?"""
    return math.isfinite(vel) and abs(vel) < FIXED_TURN_STILL_MPS


@dataclass
class FixedTurn:
    """One fixed turn in flight: released (the frame of data 0/0/0), then sent."""

    ccw_deg: float  # the whole turn, CCW +, may exceed 180 (the long way round)
    released_at: float  # client clock when the brake was released, s
    rate_dps: float = FIXED_TURN_RATE_DPS  # the turn's speed, deg/s
    sent_at: Optional[float] = None  # client clock when the fixed_turn was sent, s (None: not yet)
    turned_deg: float = 0.0  # yaw change seen since sending, CCW +, accumulated frame by frame
    last_yaw: Optional[float] = None  # yaw at the last frame, degrees

    def observe(self, yaw_deg: float) -> None:
        """Accumulate this frame's yaw change (turns longer than 180 deg need the running sum)."""
        if self.last_yaw is not None:
            self.turned_deg += wrap_deg(yaw_deg - self.last_yaw)
        self.last_yaw = yaw_deg

    def arrived(self) -> bool:
        return abs(self.turned_deg - self.ccw_deg) <= FIXED_TURN_DONE_DEG

    def refused(self, t: float, latency_s: float) -> bool:
        """No yaw change long after sending: the simulator ignored it."""
        return (self.sent_at is not None and abs(self.turned_deg) < FIXED_TURN_MOVED_DEG
                and t - self.sent_at > FIXED_TURN_REFUSED_S + latency_s)

    def overdue(self, t: float, latency_s: float) -> bool:
        """Longer than the turn's own time plus a margin since sending: stop waiting for it."""
        return (self.sent_at is not None
                and t - self.sent_at > duration_s(self.ccw_deg, self.rate_dps) + FIXED_TURN_MARGIN_S + latency_s)
