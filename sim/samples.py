"""Sample rocks: seeded spawning, the near_sample capsule rule and the pickup arm.

Mirrors ObjectiveSpawner.cs / RoverController.cs as described in the fact sheet:
6 of the world's candidate spots per scene load (without replacement), random
yaw and scale 0.36-0.5; near_sample when a sample centre is within ~0.55 m
(horizontal) of the point 0.84 m ahead of the rover origin; pickup freezes the
rover for 10 s of game time, then removes the sample, and picking_up drops one
frame later.  A pickup with nothing near leaves picking_up stuck at 1 and the
rover frozen forever (the real one hits a null reference).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

SPAWN_COUNT = 6  # samples activated per scene load
SCALE_RANGE = (0.36, 0.5)  # uniform sample prefab scale
NEAR_AHEAD_M = 0.84  # m, capsule centre ahead of the rover origin
NEAR_RADIUS_M = 0.55  # m, horizontal reach of the capsule test
PICKUP_DURATION_S = 10.0  # s of game time the arm sequence takes


@dataclass
class Sample:
    x: float
    y: float
    scale: float
    yaw: float  # deg, random visual yaw

    def render_tuple(self):
        return (self.x, self.y, self.scale, self.yaw)


def spawn_samples(spots, rng: np.random.Generator, count: int = SPAWN_COUNT) -> list:
    """`count` distinct candidate spots with random scale and yaw."""
    spots = np.asarray(spots, dtype=np.float64).reshape(-1, 2)
    count = min(count, len(spots))
    idx = rng.choice(len(spots), size=count, replace=False) if count else []
    out = []
    for i in idx:
        out.append(Sample(float(spots[i, 0]), float(spots[i, 1]),
                          float(rng.uniform(*SCALE_RANGE)), float(rng.uniform(0.0, 360.0))))
    return out


def near_index(samples, x: float, y: float, yaw_deg: float):
    """Index of the closest sample inside the pickup capsule, or None."""
    if not samples:
        return None
    cx = x + NEAR_AHEAD_M * math.cos(math.radians(yaw_deg))
    cy = y + NEAR_AHEAD_M * math.sin(math.radians(yaw_deg))
    xy = np.array([(s.x, s.y) for s in samples])
    d = np.hypot(xy[:, 0] - cx, xy[:, 1] - cy)
    i = int(np.argmin(d))
    return i if d[i] <= NEAR_RADIUS_M else None


@dataclass
class PickupArm:
    """The arm's state machine, advanced in game time by the twin."""

    active: bool = False  # picking_up reported as 1
    target: int | None = None  # index of the sample being picked (None = blind pickup)
    remaining_s: float = 0.0  # game time left in the sequence
    release_pending: bool = False  # sample removed; picking_up drops on the next frame
    stuck: bool = False  # blind pickup: frozen forever
    collected: list = field(default_factory=list)  # collected Samples, in order

    @property
    def freezes_rover(self) -> bool:
        return self.active

    def start(self, target) -> bool:
        """Begin a pickup; ignored while one is running (as the arm is busy)."""
        if self.active:
            return False
        self.active = True
        self.target = target
        self.remaining_s = PICKUP_DURATION_S
        self.stuck = target is None
        return True

    def advance(self, dt: float, samples: list) -> None:
        """Advance game time; removes the sample from `samples` when the arm finishes."""
        if not self.active or self.stuck or self.release_pending:
            return
        self.remaining_s -= dt
        if self.remaining_s <= 1e-9:
            if self.target is not None and 0 <= self.target < len(samples):
                self.collected.append(samples.pop(self.target))
            self.target = None
            self.release_pending = True

    def end_of_frame(self) -> None:
        """Called after a telemetry frame was produced: picking_up drops one frame late."""
        if self.release_pending:
            self.release_pending = False
            self.active = False
