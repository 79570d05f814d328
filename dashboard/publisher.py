"""The control loop's side of the dashboard: one cheap call per frame.

``Publisher.observe(client, event)`` notes what changed this frame (mode,
pickups, collections, stuck events, a new mission) and, at most
``PUBLISH_HZ`` times per wall-clock second, copies the few arrays the page
needs into a ``Snapshot`` and drops it into the ``LatestSlot``.  Everything
slow (scoring, drawing, JPEG encoding, sending) happens on the page's threads.
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, List, Optional

import numpy as np

from dashboard.slot import LatestSlot

PUBLISH_HZ = 10.0  # snapshots handed to the page per wall-clock second, at most
TRAIL_STEP_M = 0.25  # a trail point is kept when the rover moved this far from the last, m
EVENT_LOG_LEN = 200  # events kept for the page's log, count
SAMPLE_SAME_M = 0.5  # two reported sample positions closer than this are one sample, m


@dataclass
class Snapshot:
    """What the page shows, copied in the control thread (nothing here is mutated later)."""
    wall: float
    episode: int
    frame: int
    t: float
    pos: tuple
    yaw: float
    speed: float
    throttle: float
    brake: float
    steer: float
    mode: str
    target: Optional[tuple]
    plan_goal: Optional[str]
    img: Optional[np.ndarray]
    vision: Optional[np.ndarray]
    worldmap: np.ndarray
    truth: Optional[np.ndarray]
    plan: np.ndarray
    rocks: list
    samples: np.ndarray  # every sample position reported this mission, (N, 2)
    remaining_xy: np.ndarray  # sample positions still reported on the ground, (M, 2)
    remaining: Optional[int]
    initial: Optional[int]
    stuck: list
    blocked: np.ndarray
    start: Optional[tuple]
    trail: list
    events: list
    timings: dict = field(default_factory=dict)
    counters: dict = field(default_factory=dict)


class Publisher:
    """Per-frame hook for an ``AutonomyClient`` (see module docstring)."""

    def __init__(self, slot: Optional[LatestSlot] = None, hz: float = PUBLISH_HZ,
                 clock: Callable[[], float] = time.monotonic):
        self.slot = slot or LatestSlot()
        self.period = 1.0 / hz if hz > 0 else 0.0
        self.clock = clock
        self.events: deque = deque(maxlen=EVENT_LOG_LEN)
        self._last_pub = -math.inf
        self._episode = None
        self._reset_mission()

    def _reset_mission(self):
        self.trail: List[tuple] = []
        self.samples = np.zeros((0, 2))
        self._mode = None
        self._remaining = None
        self._stuck_n = 0

    def _event(self, t, text):
        self.events.append((round(float(t), 1), text))

    def observe(self, client, event: Optional[str] = None, force: bool = False) -> bool:
        """Call after every telemetry reply; True when a snapshot was published."""
        rover = client.rover
        episode = getattr(client, "episodes", 1)
        t = rover.total_time
        if episode != self._episode:
            if self._episode is not None:
                self._event(t, "simulator restarted: new mission")
            self._episode = episode
            self._reset_mission()
        mode = rover.mode
        if mode != self._mode:
            self._event(t, f"mode {self._mode} -> {mode}" if self._mode else f"mode {mode}")
            self._mode = mode
        if event == "pickup":
            self._event(t, "pickup requested")
        remaining = rover.samples_remaining
        if remaining is not None and self._remaining is not None and remaining < self._remaining:
            got = (rover.samples_initial or 0) - remaining
            self._event(t, f"sample collected ({got}/{rover.samples_initial})")
        self._remaining = remaining
        nav = getattr(rover, "nav", None)
        stuck_events = getattr(nav, "stuck_events", ())
        if len(stuck_events) > self._stuck_n:
            _, x, y = stuck_events[-1][:3]
            self._event(t, f"stuck at ({x:.0f}, {y:.0f}); recovering")
            self._stuck_n = len(stuck_events)
        x, y = rover.pos
        if math.isfinite(x) and math.isfinite(y) and (
                not self.trail or math.hypot(x - self.trail[-1][0], y - self.trail[-1][1]) >= TRAIL_STEP_M):
            self.trail.append((x, y))
        now = self.clock()
        if not force and now - self._last_pub < self.period:
            return False
        self._last_pub = now
        self.slot.put(self._snapshot(client, now))
        return True

    def _remember_samples(self, rover):
        xs, ys = rover.samples_pos
        if not len(xs):
            return
        new = np.column_stack([xs, ys])
        if len(self.samples):
            d = np.abs(new[:, None, :] - self.samples[None, :, :]).max(axis=2)
            new = new[d.min(axis=1) > SAMPLE_SAME_M]
        if len(new):
            self.samples = np.vstack([self.samples, new])

    def _snapshot(self, client, now) -> Snapshot:
        rover = client.rover
        nav = getattr(rover, "nav", None)
        self._remember_samples(rover)
        blocked_at = getattr(nav, "blocked_at", None)
        blocked = (np.argwhere(np.isfinite(blocked_at))[:, ::-1] if isinstance(blocked_at, np.ndarray)
                   else np.zeros((0, 2), int))
        goal = getattr(nav, "path_goal", None)
        plan = getattr(nav, "path_xy", None)
        idx = int(getattr(nav, "path_idx", 0) or 0)
        plan = np.asarray(plan)[idx:] if plan is not None and len(plan) else np.zeros((0, 2))
        target = rover.target
        try:
            target = None if target is None else (float(target[0]), float(target[1]))
        except (TypeError, ValueError, IndexError):
            target = None
        return Snapshot(
            wall=now, episode=self._episode, frame=rover.frame_count, t=rover.total_time,
            pos=tuple(rover.pos), yaw=rover.yaw, speed=rover.vel, throttle=rover.throttle,
            brake=rover.brake, steer=rover.steer, mode=str(rover.mode), target=target,
            plan_goal=goal[0] if goal else None, img=rover.img, vision=rover.vision_image,
            worldmap=np.array(rover.worldmap, copy=True), truth=rover.ground_truth,
            plan=np.array(plan, float, copy=True), rocks=list(rover.rocks_world),
            samples=self.samples, remaining_xy=np.column_stack(rover.samples_pos).reshape(-1, 2),
            remaining=rover.samples_remaining, initial=rover.samples_initial,
            stuck=[tuple(e[1:3]) for e in getattr(nav, "stuck_events", ())], blocked=blocked,
            start=tuple(rover.start_pos) if rover.start_pos is not None else None,
            trail=self.trail[:], events=list(self.events)[-50:], timings=dict(client.last_timings),
            counters={"bad_frames": getattr(client, "bad_frames", 0),
                      "step_errors": getattr(client, "step_errors", 0)})
