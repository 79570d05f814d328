"""Which sample rock to go for, and what the rover remembers about rocks it went for.

A rock the camera shows close by comes first, then the nearest rock perception remembers on the
map; collected rocks, rocks given up for a while, and rocks refuted by a close look that did not
show them (navigation.rockmem) are left out. This memory grew rule by rule (phantom sightings,
a target lost at close range, another rock in view); it lives here so decision.py's state machine
only asks "is there a rock to approach?" (choose_rock) and "drop this one" (give_up_rock).
Functions take the rover, its `nav` memory (decision.NavMemory) and the frame's sanitised inputs
`s` (decision.Inputs).
"""
import logging
import math

import numpy as np

from navigation import rockmem

log = logging.getLogger(__name__)

ROCK_MIN_PIXELS = 3  # rock pixels needed to trust a rock in the current frame
ROCK_CHASE_M = 10.0  # chase a rock seen in the camera closer than this, m
ROCK_DETOUR_M = 25.0  # go for a remembered rock closer than this (straight line) while exploring, m
ROCK_SAME_M = 2.0  # rock positions closer than this are the same rock, m
COLLECTED_CLEAR_M = 3.0  # remembered rocks this close to a collected one are echoes of it, m (samples lie >= 5 m apart)
ROCK_SKIP_S = 60.0  # a given-up rock is ignored for this long, s
SAMPLE_VISUAL_M = 3.5  # closer than this the approach steers by the camera, farther it follows a planned path, m
SAMPLE_VISION_MEMORY_S = 1.0  # keep steering by vision this long after the rock left the frame, s
TURN_SIGHTING_KEEP_S = 10.0  # a rock the camera showed during a fixed turn is gone back for when the turn (and any turn chained to it) ends within this, s


def choose_rock(rover, nav, s):
    """Pick (or keep) the rock to approach: visible ones first, then remembered ones. True if any."""
    if s.samples_remaining == 0:
        nav.rock_target = None
        return False
    sighting = camera_sighting(s)
    if sighting is not None:
        xy, dist, ang, pixels = sighting
        same = nav.rock_target is not None and math.hypot(xy[0] - nav.rock_target[0],
                                                          xy[1] - nav.rock_target[1]) < ROCK_SAME_M
        target_d = math.hypot(nav.rock_target[0] - s.pos[0], nav.rock_target[1] - s.pos[1]) \
            if nav.rock_target is not None else math.inf
        nearer = dist < target_d - ROCK_SAME_M
        # the rover is (nearly) at the remembered spot and the camera does not show the rock there:
        # the estimate was off (a far sighting can be 2-3 m out), so trust the rock the camera sees
        lost = target_d <= SAMPLE_VISUAL_M and s.t - nav.rock_seen_time > SAMPLE_VISION_MEMORY_S
        if dist <= ROCK_CHASE_M and not _camera_rock_refuted(nav, xy, pixels, dist) \
                and not _rock_is_known_done(nav, xy, s.t) and (nav.rock_target is None or same or nearer or lost):
            if nav.rock_target is None:
                nav.rock_since = s.t
                nav.rock_close_since = None
                _new_rock_attempt(nav)
            elif not same:
                _switch_rock(nav, s, xy, lost)
            nav.rock_target = xy
            nav.rock_seen_time = s.t
            nav.rock_best_px = max(nav.rock_best_px, pixels)
            nav.rock_seen_close |= dist <= SAMPLE_VISUAL_M
            nav.rock_bearing, nav.rock_dist = ang, dist
            nav.turn_sighting = None
            return True
    if nav.rock_target is not None:
        if _rock_is_known_done(nav, nav.rock_target, s.t):
            nav.rock_target = None
        else:
            nav.turn_sighting = None
            return True
    if _go_back_for_turn_sighting(nav, s):
        return True
    best, best_d = None, math.inf
    for xy in list(getattr(rover, "rocks_world", []) or []):
        try:
            xy = (float(xy[0]), float(xy[1]))
        except (TypeError, ValueError, IndexError):
            continue
        if not (math.isfinite(xy[0]) and math.isfinite(xy[1])) or _rock_is_known_done(nav, xy, s.t):
            continue
        d = math.hypot(xy[0] - s.pos[0], xy[1] - s.pos[1])
        if d < best_d:
            best, best_d = xy, d
    if best is not None and (best_d <= ROCK_DETOUR_M or nav.explored):
        _target_unseen_rock(nav, s, best)
        return True
    return False


def _target_unseen_rock(nav, s, xy):
    """Start a fresh attempt at a rock the camera does not show now (remembered, or glimpsed in a turn): the
    approach plans a path there until the camera picks it up."""
    _new_rock_attempt(nav)
    nav.rock_target = xy
    nav.rock_since = s.t
    nav.rock_close_since = None
    nav.rock_seen_time = -math.inf


def camera_sighting(s):
    """The nearest rock blob in this frame as (world xy, distance m, bearing rad off the heading,
    pixels), or None when the camera shows fewer than ROCK_MIN_PIXELS rock pixels."""
    if s.rock_angles.size < ROCK_MIN_PIXELS:
        return None
    dist = float(np.min(s.rock_dists))
    near = s.rock_dists <= dist + ROCK_SAME_M / 2  # nearest blob only
    ang = float(np.mean(s.rock_angles[near]))
    yaw = math.radians(s.yaw)
    xy = (s.pos[0] + dist * math.cos(yaw + ang), s.pos[1] + dist * math.sin(yaw + ang))
    return xy, dist, ang, int(np.count_nonzero(near))


def note_turn_sighting(nav, s):
    """During a fixed turn the state machine only waits for the yaw, so a rock that flashes past the
    camera is not chosen; keep the strongest such sighting (within ROCK_CHASE_M, not collected,
    skipped or refuted) for _go_back_for_turn_sighting once the turn is over.

    Seed 0 at 10 fps: braking at the north tip, the sample 4.2 m ahead showed 3-4 px (a blob needs 4),
    then 16 px in the first frame of the 180 deg/s turn back; the rover drove away and the search
    did not return to the tip before the time limit."""
    if s.samples_remaining == 0:
        return
    sighting = camera_sighting(s)
    if sighting is None:
        return
    xy, dist, _ang, pixels = sighting
    if dist > ROCK_CHASE_M or _rock_is_known_done(nav, xy, s.t):  # collected, skipped or refuted
        return
    best = nav.turn_sighting
    if best is None or s.t - best[2] > TURN_SIGHTING_KEEP_S or pixels > best[3]:
        nav.turn_sighting = (xy[0], xy[1], s.t, pixels)


def _go_back_for_turn_sighting(nav, s):
    """Make a rock seen during a fixed turn that just ended the target (the approach turns back to it
    and the camera takes over). True if it did."""
    seen = nav.turn_sighting
    nav.turn_sighting = None
    if seen is None or s.t - seen[2] > TURN_SIGHTING_KEEP_S or _rock_is_known_done(nav, seen[:2], s.t):
        return False
    log.info("rock glimpsed at (%.1f, %.1f) during a turn (%d px): going back for it", seen[0], seen[1], seen[3])
    _target_unseen_rock(nav, s, (seen[0], seen[1]))
    nav.rock_best_px = seen[3]
    return True


def _rock_is_known_done(nav, xy, t):
    for c in nav.collected:
        if math.hypot(xy[0] - c[0], xy[1] - c[1]) < COLLECTED_CLEAR_M:
            return True
    for x, y, until in nav.rock_skip:
        if t < until and math.hypot(xy[0] - x, xy[1] - y) < ROCK_SAME_M:
            return True
    return rockmem.nearest_refuted(nav.rock_refuted, xy, ROCK_SAME_M) is not None


def _new_rock_attempt(nav):
    """Forget the camera evidence gathered for the previous target (see give_up_rock)."""
    nav.rock_came_close = nav.rock_seen_close = False
    nav.rock_best_px = 0
    nav.rock_backed_off = False


def give_up_rock(nav, s):
    """Drop the target rock: refuted for good when the rover came close and the camera never showed
    it there (a misprojected far sighting: seed 5's phantom was chosen 7 times on a 60 s skip), else
    skipped for ROCK_SKIP_S (a real rock that was hard to reach is tried again)."""
    xy = nav.rock_target
    close = nav.rock_came_close or math.hypot(xy[0] - s.pos[0], xy[1] - s.pos[1]) <= SAMPLE_VISUAL_M
    if rockmem.was_refuted(close, nav.rock_seen_close):
        log.info("rock at (%.1f, %.1f) approached and not found: refuted", *xy)
        nav.rock_refuted = rockmem.add_refuted(nav.rock_refuted, xy, nav.rock_best_px, ROCK_SAME_M)
    nav.rock_skip.append((xy[0], xy[1], s.t + ROCK_SKIP_S))
    nav.rock_target = None
    _new_rock_attempt(nav)


def _camera_rock_refuted(nav, xy, pixels, dist):
    """Is this camera sighting at a refuted spot without stronger evidence? A sighting close by
    with more pixels than the refuting attempt saw lifts the refutation."""
    k = rockmem.nearest_refuted(nav.rock_refuted, xy, ROCK_SAME_M)
    if k is None:
        return False
    if rockmem.revives(nav.rock_refuted[k][2], pixels, dist, SAMPLE_VISUAL_M):
        log.info("rock at (%.1f, %.1f) seen again from %.1f m with %d px: no longer refuted", *xy, dist, pixels)
        nav.rock_refuted = nav.rock_refuted[:k] + nav.rock_refuted[k + 1:]
        return False
    return True


def _switch_rock(nav, s, xy, lost):
    """The camera shows another rock than the target: when the rover stood at the target and never
    saw it there ('lost'), the camera found the real rock elsewhere and the target is refuted."""
    old = nav.rock_target
    if lost and not nav.rock_seen_close and math.hypot(xy[0] - old[0], xy[1] - old[1]) >= ROCK_SAME_M:
        log.info("rock at (%.1f, %.1f) not there, the camera shows one at (%.1f, %.1f): refuted", *old, *xy)
        nav.rock_refuted = rockmem.add_refuted(nav.rock_refuted, old, nav.rock_best_px, ROCK_SAME_M)
    _new_rock_attempt(nav)
