"""Behaviour: one mode state machine that explores, collects samples and returns home.

`decision_step(rover)` is called once per telemetry frame. It reads the
telemetry and perception fields of `RoverState`, keeps its own memory in
`rover.nav` (a `NavMemory`, created lazily) and writes the commands
(`throttle`, `brake`, `steer`, `send_pickup`) plus `mode` and `target` for the
vision inset.

Modes (one handler function each):
- forward: explore - follow a planned path to the best frontier (unmapped
  ground) with pure pursuit, corrected by the current frame's free space;
- stop:    brake and turn in place toward a heading the rover cannot steer to
  while moving (the path doubles back, or the way ahead is blocked);
- stuck:   scripted back-off and turn after no progress while driving; the
  cells ahead are remembered as blocked so the planner avoids them;
- sample:  approach a seen (camera) or remembered (map) sample rock slowly;
- pickup:  stop, request the pickup once when near_sample and stopped, wait;
- search:  map complete but samples missing: peek into shadowed floor the
  camera never saw from close (dark pockets hide small samples) and visit
  mapped floor far from the trail (pockets at the arms' tips) and wall feet
  beside the trail the camera never faced from close (nooks), and drive into
  faint pockets (slots whose shadowed floor was voted wall), nearest first,
  turning to face unsearched wall feet at each goal reached;
- home:    plan back to the start and stop there;
- done:    parked at home with everything collected (or time is up).

Exploration resumes by itself after a sample because the frontier target is
re-derived from the map, not from a script.

This module is the state machine: which mode runs, and how each mode drives.
What to drive to is planned beside it in navigation/: `exploration_plan`
(frontier goals, when the map is complete), `search_plan` (the sample search's
goals, faint pockets among them), `rock_choice` (which rock, and the memory of rocks given
up or refuted) and `paths` (the maps planned on and the path in `nav`). Each
holds its own tunable constants at its top.
"""
import logging
import math
import operator
from collections import deque
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

import perception
from interrupts import reraise_interrupt
from navigation import (approach, exploration_plan, explore, fixed_turn, grid, paths, predict, pursuit, reactive,
                        rock_choice, sample_spots, search_plan, stuck, turning)

log = logging.getLogger(__name__)

# --- speeds and the longitudinal controller ---------------------------------------
CRUISE_SPEED_MPS = 4.5  # target speed on a clear, straight path, m/s
MIN_DRIVE_SPEED_MPS = 0.6  # target speed floor while driving somewhere, m/s
THROTTLE_GAIN = 1.2  # throttle per m/s of speed deficit
MAX_THROTTLE = 1.0  # forward throttle cap
BRAKE_GAIN = 1.5  # brake per m/s of speed excess beyond the deadband
BRAKE_DEADBAND_MPS = 0.3  # coast (no throttle, no brake) within this excess, m/s
BRAKE_STOP = 5.0  # brake used to stop / hold still
MAX_BRAKE = 10.0  # brake command clamp
STEER_LIMIT_DEG = 15.0  # steering command clamp, degrees
STOPPED_SPEED_MPS = 0.2  # below this the rover counts as stopped, m/s
TURN_IN_PLACE_SPEED_MPS = 0.3  # the simulator turns in place only below 0.316 m/s

# --- heading / turning ----------------------------------------------------------------
ROTATE_ENTER_DEG = 90.0  # a wanted heading further off than this is reached by turning in place, degrees
LEAVE_PICKUP_ROTATE_DEG = 30.0  # leaving a pickup spot (samples lie at wall feet), turn in place first when the way on is further off than this, degrees
SWEEP_REASONS = ("path-behind", "leave-pickup")  # long turns in place that may go the long way round to sweep the camera over unsearched wall feet (explore.sweep_direction)
GLANCE_REASONS = ("path-behind",)  # turns in place that may glance first at unsearched wall feet (explore.glance_heading): a path doubling back, not leaving a pickup (samples lie >= 5 m apart; glancing there too cost seeds 0, 3, 7 time)
GLANCE_DEAD_END_REACH_M = 5.0  # ...and only at a dead end: no rover-wide corridor this long in the camera's view, m
GLANCE_HOLD_S = 0.5  # ...and holds still facing them this long, so a rock there is chosen before the turn back (turning straight on missed the east nook on seeds 51 and 52), s
GLANCE_DONE_M = 3.0  # a turn back glances at unsearched wall feet once per place: not again this close, m
GLANCE_RETURN_S = 3.0  # a turn back starting this soon after a glance against its way, where the glance began, goes back through the glance's start, s
GLANCE_RETURN_MAX_DEG = 300.0  # ...when that turn is at most this long, degrees
SWEEP_COMMIT_DEG = 90.0  # ...the long way is kept while the heading error, on the far side, is larger than this, degrees
ROTATE_EXIT_DEG = 12.0  # turning in place ends within this of the wanted heading, degrees
SPIN_WINDOW_S = 20.0  # window for detecting endless turning in place, s
SPIN_STOP_FRACTION = 0.6  # ...share of it spent turning in place
SPIN_MAX_SPAN_M = 2.0  # ...while staying within a box this size, m
ROTATE_TIMEOUT_S = 6.0  # give up a turn in place after this long, s
ROTATE_BLOCKED_S = 2.0  # turning in place that has not changed the heading for this long means wedged, s
ROTATE_BLOCKED_DEG = 5.0  # ...has not changed it by at least this much, degrees
SLOW_TURN_DEG = 50.0  # speed falls linearly to MIN_DRIVE_SPEED at this heading error, degrees
REACH_SPEED_GAIN = 1.0  # allowed speed per metre of clear corridor beyond REACH_STOP_M, 1/s
REACH_STOP_M = 1.0  # clear corridor below which the rover will not drive forward, m
CREEP_SPEED_MPS = 0.5  # speed along a planned path when the camera view looks blocked, m/s
BLOCKED_TURN_DEG = 60.0  # turn this far when the way ahead is blocked, degrees
WALL_BIAS_STD = 0.6  # fallback wall hugging: steer to mean + this x std of nav angles (left wall)
FALLBACK_MIN_NAV_PIXELS = 50  # fallback needs this many nav pixels to drive, pixels

# --- sample search (mode_search) and path ends ----------------------------------------
SEARCH_FACES_PER_GOAL = 2  # turns to face unsearched wall feet at one reached search goal, at most
SEARCH_FACE_KINDS = ("peek", "look")  # ...those reached only to look at something beside them: the rover turns to face it
SEARCH_GOALS_PER_FRAME = 3  # search goals one frame may tick off as reached (a goal under the rover's wheels) before it plans the next one
PATH_END_SLOW_M = 3.0  # slow down over the last metres of a path to a sample or home, m

# --- samples -----------------------------------------------------------------------------
SAMPLE_STOP_M = 0.9  # rock distance (rover origin) where approach speed reaches its floor, m
SAMPLE_SPEED_GAIN = 0.5  # approach speed per metre of rock distance, 1/s
SAMPLE_MIN_SPEED_MPS = 0.35  # creeping speed near a rock, m/s
SAMPLE_MAX_SPEED_MPS = 1.5  # fastest approach speed, m/s
SAMPLE_ROTATE_DEG = 35.0  # turn in place toward a rock further off than this (when slow), degrees
SAMPLE_STEER_GAIN = 1.0  # steering command per degree of rock bearing
SAMPLE_TIMEOUT_S = 90.0  # give up a rock after this long in sample mode, s
SAMPLE_CLOSE_TIMEOUT_S = 30.0  # ...or after this long within rock_choice.SAMPLE_VISUAL_M of it, s
ROCK_BESIDE_BACK_S = 3.0  # reverse straight at most this long when a rock the camera showed from close is now beside the rover, s
ROCK_BESIDE_CLEAR_M = 1.5  # ...or until the rock is this far from the rover, m
SAMPLE_PATH_SPEED_MPS = 3.0  # top speed on the way to a rock, m/s
PICKUP_STOP_SPEED_MPS = 0.04  # request pickup only below this speed (autonomy's gate is 0.05), m/s
PICKUP_RETRY_S = 2.0  # re-request a pickup if picking_up did not start within this, s
PICKUP_REACH_M = 0.84  # pickup point ahead of the rover origin, m
STAGE_DECIDE_M = 7.0  # a rock this close gets its approach decided: straight in, or via a staging point, m
STAGE_REACHED_M = 0.6  # the staging point counts as reached this close, m
STAGE_BEHIND_REACHED_M = 1.2  # ...or this close when it lies behind the rover (no 180 deg turn to face a point a metre off; seed 23), m
STAGE_FACE_DEG = 15.0  # at the staging point, turn in place when the rock is further off than this (above ROTATE_EXIT_DEG, so a finished turn never restarts), degrees
COLLECT_DEBOUNCE_S = 3.0  # pickup-finished and count-dropped within this time are one collection, s

# --- mission -----------------------------------------------------------------------------
HOME_STOP_M = 1.5  # parked when this close to the start, m
HOME_BY_S = 570.0  # head home when the estimated arrival would be later than this, s
SEARCH_HOME_BY_S = 870.0  # ...stretched to this while the map is incomplete or samples are missing and there is ground to search, s
HOME_SPEED_ESTIMATE_MPS = 2.0  # speed used to estimate the time to get home, m/s
HOME_DETOUR_FACTOR = 1.5  # the way home is taken to be this many times the straight line, ratio
SECOND_SWEEP = True  # with samples missing and no frontier left, clear ignored frontiers once


@dataclass
class Inputs:
    """Sanitised per-frame view of the rover state (never NaN where it matters)."""

    t: float
    pos: tuple  # (x, y) or None when unknown
    yaw: float
    vel: float
    nav_angles: np.ndarray
    nav_dists: np.ndarray
    obs_angles: np.ndarray
    obs_dists: np.ndarray
    rock_angles: np.ndarray
    rock_dists: np.ndarray
    near_sample: bool
    picking_up: bool
    samples_remaining: object  # int or None
    home_by: Optional[float] = None  # return deadline set for this mission (RoverState.home_by_s), s; None: the default
    fixed_turns: bool = False  # the link can send the simulator's fixed_turn (RoverState.fixed_turns)
    reach: Optional[np.ndarray] = field(default=None, repr=False, compare=False)  # _frame_reach's, once computed
    rover: object = field(default=None, repr=False, compare=False)  # the RoverState read (for maps a rule needs now and then)


@dataclass
class Command:
    throttle: float = 0.0
    brake: float = 0.0
    steer: float = 0.0
    pickup: bool = False
    fixed_turn: Optional[tuple] = None  # send the simulator's fixed_turn instead of data: (degrees CCW +, deg/s)


class NavMemory:
    """Everything the decision layer remembers between frames (lives in rover.nav)."""

    def __init__(self):
        self.mode = "forward"
        self.mode_since = 0.0
        self.home = None  # (x, y) start position
        self.last_cmd = Command()
        # stuck
        self.progress = stuck.ProgressMonitor()
        self.recovery = None
        self.stuck_events = []  # (t, x, y)
        self.stuck_since = None  # start of the current unbroken stuck spell
        self.blocked_at = np.full((grid.GRID_SIZE, grid.GRID_SIZE), -np.inf, np.float32)  # when a cell was blocked
        # turning in place
        self.rotate_heading = None  # world yaw to turn to, degrees
        self.rotate_since = 0.0
        self.spin_hist = deque()  # (t, turning in place?, x, y) over SPIN_WINDOW_S
        self.spin_events = []  # (t, x, y) of every spin detection, for alternating the escape
        self.turn_ref = None  # (t, yaw) since when turning in place has not changed the heading
        self.rotate_dir = None  # +1 / -1: this turn goes the long way round (sweeping unsearched wall feet); None: the short way
        self.rotate_via = None  # world yaw to turn to once rotate_heading (a glance at unsearched wall feet) is reached, or None
        self.glance_hold_until = -math.inf  # a glance holds the rover still, facing the wall feet, until then, s
        self.glance_return = None  # (way +1/-1, (x, y), until t): the turn back after a glance against its way goes this way (_glance_first)
        self.glanced = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # places a turn in place already glanced at unsearched wall feet
        self.unsearched = None  # unsearched wall feet (explore.unsearched_wall_feet) at the last plan with samples missing, or None
        self.search_began = None  # (t, (x, y)) when and where the sample search first planned, or None
        self.pocket_goal = None  # bool map of the faint pocket the search's current pocket goal drives into (search_plan._pocket_goal), or None
        self.pocket_reached = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # faint pockets driven into (or given up); kept through the second sweep
        self.spots = None  # (n, 2) world (x, y) of the sample spots this mission can hold (navigation.sample_spots), set once home is known
        self.spot_done = None  # bool (n,): spots checked (seen from close, faced from their stand, held a collected sample, or given up)
        self.spot_goal = None  # index of the spot the search's "spot" goal is the stand of, or None
        self.spots_taken_checked = 0  # collections the spots were last ruled out against (sample_spots.taken_spots)
        self.spot_faced = None  # the spot index the rover last turned at its stand to face
        self.spot_hold_until = None  # ...and until when it holds still facing it, s
        self.lead = predict.LeadEstimator()  # frame interval and yaw rate on the client's clock (latency lead)
        self.fixed = None  # the fixed_turn.FixedTurn in flight, or None
        self.fixed_steer = False  # this turn in place is steered: its fixed turn was refused
        self.fixed_refusals = 0  # fixed turns refused in a row (fixed_turn.FIXED_TURN_MAX_REFUSALS: stop asking)
        self.fixed_refused = 0  # fixed turns the simulator refused this mission (each then steered)
        # planning
        self.path_xy = np.zeros((0, 2))
        self.path_idx = 0
        self.path_goal = None  # ("frontier" | "rock" | "home", (row, col))
        self.plan_time = -math.inf
        self.frontier_ignored = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)
        self.frontier_abandoned = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # ignored because given up, not reached
        self.vanished = None  # (goal cell, stand cell): a frontier goal voted wall before it was seen from close, still driven to
        self.frontier_count = None  # reachable frontier clusters at the last explore plan
        self.explored = False
        self.no_frontier_plans = 0  # consecutive explore plans that found no frontier
        self.hidden_frontiers = 0  # reachable frontier clusters only the ignore mask hides (last plan without any)
        self.second_sweep_done = False
        self.search_left = True  # sample search still has places to visit
        self.search_done = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # places the search has visited
        self.search_faced_goal = None  # the search goal the rover last turned at to face unsearched wall feet
        self.search_faces = 0  # ...and how many turns it made there
        self.in_sight = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # cells a clear line of sight reached within SEARCH_LOOK_M (explore.mark_in_sight)
        self.look_stand_done = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # look stands already reached
        self.look_done = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # wall feet given up (faced LOOK_TRIES times unseen, or a stuck beside them)
        self.look_tries = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), np.int16)  # look stands each unsearched wall foot was faced from
        self.goal_best = math.inf
        self.goal_best_time = 0.0
        self.goal_since = 0.0  # when the current path goal was chosen, s
        self.goal_from = None  # where the rover stood when it chose the current path goal, world (x, y)
        self.loops = explore.LoopDetector()
        self.visits = explore.VisitMap((grid.GRID_SIZE, grid.GRID_SIZE))
        self.seen_close = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # cells looked at from close
        self.seen_near = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)  # ...from SEEN_CLOSE_SAMPLES_M (frontiers while samples are missing)
        # samples
        self.rock_target = None  # world (x, y) of the rock being approached
        self.rock_since = 0.0  # when the current rock target was chosen, s
        self.rock_close_since = None  # when the rover first came within rock_choice.SAMPLE_VISUAL_M of it, s
        self.rock_seen_time = -math.inf  # last time the target was seen in the camera
        self.rock_bearing = 0.0  # last camera bearing of the target, rad
        self.rock_dist = math.inf  # last camera distance of the target, m
        self.stage = None  # (x, y, heading) to line up at before the final run to the rock, or None: straight in
        self.stage_for = None  # the rock target (x, y) the approach was decided for, or None: not decided
        self.stage_done = False  # the staging point was reached and the rover faced the rock
        self.stages_wedged = []  # (rock x, y, stage x, y): staging points whose approach wedged (not chosen again for that rock)
        self.collected = []  # world (x, y) of collected samples
        self.rock_skip = []  # (x, y, until_t)
        self.rock_refuted = []  # (x, y, best_pixels): approached and not found (navigation.rockmem)
        self.rock_came_close = False  # this attempt brought the rover within rock_choice.SAMPLE_VISUAL_M of the target
        self.rock_seen_close = False  # ...and the camera showed the target within rock_choice.SAMPLE_VISUAL_M
        self.rock_best_px = 0  # most rock pixels of any camera sighting matched to the target this attempt
        self.rock_backed_off = False  # this attempt already reversed away from the rock once (mode_sample)
        self.rock_back_until = -math.inf  # reversing away from a rock beside the rover until then, s
        self.turn_sighting = None  # (x, y, t, pixels): a rock the camera showed during a fixed turn (rock_choice.note_turn_sighting)
        self.pickup_sent_at = -math.inf
        self.was_picking = False
        self.last_collect_t = -math.inf  # when the last collection was registered, s
        self.leaving_pickup = False  # the rover has not driven off since its last collection
        self.last_remaining = None
        self.done = False


# ============================== entry point ===========================================

def decision_step(rover):
    """Choose this frame's commands; never raises, never writes NaN."""
    nav = getattr(rover, "nav", None)
    if not isinstance(nav, NavMemory):
        nav = NavMemory()
        rover.nav = nav
    rover.send_pickup = False
    try:
        s = _read_inputs(rover)
        _update_memory(rover, nav, s)
        mode, cmd = _select_and_run(rover, nav, s)
        if s.pos is not None and mode in ("stop", "forward", "sample", "home", "search"):
            _check_spinning(nav, s, mode)
    except Exception as exc:  # a server must keep running: stop safely and log
        reraise_interrupt(exc)  # ...but a Ctrl-C wrapped by a compiled kernel still stops it
        log.exception("decision_step failed; holding still")
        mode, cmd = "stop", Command(0.0, BRAKE_STOP, 0.0)
    _apply(rover, nav, mode, cmd, getattr(rover, "total_time", 0.0))
    return rover


def _finite(x, default=0.0):
    try:
        x = float(x)
    except (TypeError, ValueError):
        return default
    return x if math.isfinite(x) else default


def _array(x):
    try:
        a = np.asarray(x, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        return np.zeros(0)
    return a


def _pair(a_name, d_name, rover):
    a, d = _array(getattr(rover, a_name, ())), _array(getattr(rover, d_name, ()))
    if a.size == d.size:  # the usual frame: equal lengths, all finite -> the arrays as they are, no masked copies
        ok = np.isfinite(a)
        ok &= np.isfinite(d)
        return (a, d) if ok.all() else (a[ok], d[ok])
    n = min(a.size, d.size)
    a, d = a[:n], d[:n]
    ok = np.isfinite(a) & np.isfinite(d)
    return a[ok], d[ok]


def _read_inputs(rover):
    t = _finite(getattr(rover, "total_time", 0.0))
    pos = getattr(rover, "pos", None)
    try:
        px, py = float(pos[0]), float(pos[1])
        pos = (px, py) if math.isfinite(px) and math.isfinite(py) else None
    except (TypeError, ValueError, IndexError):
        pos = None
    nav_a, nav_d = _pair("nav_angles", "nav_dists", rover)
    obs_a, obs_d = _pair("obs_angles", "obs_dists", rover)
    rock_a, rock_d = _pair("rock_angles", "rock_dists", rover)
    remaining = getattr(rover, "samples_remaining", None)
    try:
        remaining = None if remaining is None else int(remaining)
    except (TypeError, ValueError):
        remaining = None
    return Inputs(
        t=t, pos=pos, yaw=_finite(getattr(rover, "yaw", 0.0)) % 360.0, vel=_finite(getattr(rover, "vel", 0.0)),
        nav_angles=nav_a, nav_dists=nav_d, obs_angles=obs_a, obs_dists=obs_d,
        rock_angles=rock_a, rock_dists=rock_d,
        near_sample=bool(getattr(rover, "near_sample", False)), picking_up=bool(getattr(rover, "picking_up", False)),
        samples_remaining=remaining, home_by=_given_home_by(rover),
        fixed_turns=bool(getattr(rover, "fixed_turns", False)), rover=rover,
    )


def _frame_reach(s):
    """This frame's reactive.reach_profile of the camera's pixels, read-only, computed once per Inputs (the
    line-of-sight bookkeeping and the driving modes both ask for it)."""
    if s.reach is None:
        s.reach = reactive.reach_profile(s.nav_angles, s.nav_dists, s.obs_angles, s.obs_dists)
        s.reach.flags.writeable = False
    return s.reach


def _given_home_by(rover):
    """The rover's own return deadline when it has a usable one (a positive number), else None."""
    v = _finite(getattr(rover, "home_by_s", None))
    return v if v > 0 else None


def _deadline(nav, s):
    """The return deadline now: a given one as it is; the default (HOME_BY_S) stretches to SEARCH_HOME_BY_S
    while the map is not complete, or samples are missing and the search still has places to
    visit (an unmapped arm or a sample is worth more than five minutes; once both are done, the
    rover goes home)."""
    if s.home_by is not None:
        return s.home_by
    missing = s.samples_remaining is not None and s.samples_remaining > 0
    return SEARCH_HOME_BY_S if not nav.explored or (missing and nav.search_left) else HOME_BY_S


def _update_memory(rover, nav, s):
    """Bookkeeping that does not depend on the mode: home, visits, loops, collections."""
    if nav.home is None:
        start = getattr(rover, "start_pos", None)
        try:
            if start is not None and all(math.isfinite(float(v)) for v in start[:2]):
                nav.home = (float(start[0]), float(start[1]))
        except (TypeError, ValueError, IndexError):
            pass
        if nav.home is None and s.pos is not None:
            nav.home = s.pos
    nav.lead.update(s.t, s.yaw)
    if abs(s.vel) > 1.0:
        nav.leaving_pickup = False  # driving off already (e.g. by camera toward the next rock)
    if s.pos is not None:
        nav.visits.update(s.t, grid.world_to_cell(s.pos))
        nav.loops.update(s.t, s.pos, s.yaw)
        explore.mark_seen_close(nav.seen_close, s.pos, s.yaw)
        if search_plan.samples_missing(s):
            explore.mark_seen_close(nav.seen_near, s.pos, s.yaw, explore.SEEN_CLOSE_SAMPLES_M)
            explore.mark_in_sight(nav.in_sight, getattr(rover, "worldmap", None), s.pos, s.yaw,
                                  explore.SEARCH_LOOK_M, perception.LOOK_HALF_ANGLE_DEG,
                                  _frame_reach(s))
            _check_spots(rover, nav, s)
    # a pickup that just finished, or a sample count that dropped, means a collection
    finished = nav.was_picking and not s.picking_up
    dropped = (nav.last_remaining is not None and s.samples_remaining is not None
               and s.samples_remaining < nav.last_remaining)
    if (finished or dropped) and s.t - nav.last_collect_t > COLLECT_DEBOUNCE_S:
        nav.last_collect_t = s.t
        _register_collection(nav, s)
    nav.was_picking = s.picking_up
    if s.samples_remaining is not None:
        nav.last_remaining = s.samples_remaining


def _check_spots(rover, nav, s):
    """Rule out the sample spots (navigation.sample_spots) the camera has faced from where they show (in_view), or
    glimpsed along a clear line of sight on the map from a bearing they show from, and those that held a collected
    sample, from the mission's start on: the search later drives only to those still open."""
    if nav.spots is None and nav.home is not None:
        search_plan.init_spots(nav)
    if nav.spots is None or len(nav.spots) == 0 or nav.spot_done.all():
        return
    was = nav.spot_done.copy()
    if len(nav.collected) != nav.spots_taken_checked:
        nav.spot_done |= sample_spots.taken_spots(nav.spots, nav.collected)
        nav.spots_taken_checked = len(nav.collected)
    if not sample_spots.open_spots_near(nav.spots, nav.spot_done, s.pos):  # the usual frame: nothing to look at
        _log_spots_seen(nav, s, was)
        return
    nav.spot_done |= sample_spots.in_view(nav.spots, s.pos, s.yaw, sample_spots.VIEWS)
    maybe = sample_spots.glimpse_candidates(nav.spots, s.pos, sample_spots.VIEWS) & ~nav.spot_done
    if maybe.any():  # a line of sight on the map only when a spot is near
        sight = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)
        explore.mark_in_sight(sight, getattr(rover, "worldmap", None), s.pos, s.yaw, sample_spots.SPOT_GLIMPSE_M,
                              perception.LOOK_HALF_ANGLE_DEG, _frame_reach(s))
        cells = sample_spots.spot_cells(nav.spots)
        nav.spot_done |= maybe & sight[cells[:, 0], cells[:, 1]]
    _log_spots_seen(nav, s, was)


def _log_spots_seen(nav, s, was):
    for k in np.nonzero(nav.spot_done & ~was)[0]:
        log.info("spot %d (%.1f, %.1f) seen from (%.1f, %.1f) heading %.0f deg, t=%.1f", k, *nav.spots[k], s.pos[0],
                 s.pos[1], s.yaw, s.t)


def _register_collection(nav, s):
    # a collection is progress: the turns that lined the rover up for it are no spin (seed 23's
    # spin detector fired as the nook pickup ended and backed the rover into the rocks twice)
    nav.spin_hist.clear()
    nav.leaving_pickup = True
    if nav.rock_target is not None:
        where = nav.rock_target
    elif s.pos is not None:
        yaw = math.radians(s.yaw)
        where = (s.pos[0] + PICKUP_REACH_M * math.cos(yaw), s.pos[1] + PICKUP_REACH_M * math.sin(yaw))
    else:
        return
    if not any(math.hypot(where[0] - c[0], where[1] - c[1]) < 0.5 for c in nav.collected):
        nav.collected.append(where)
        log.info("sample collected at (%.1f, %.1f), %d so far", where[0], where[1], len(nav.collected))
    nav.rock_target = None
    nav.rock_seen_time = -math.inf
    nav.path_goal = None


def _apply(rover, nav, mode, cmd, t):
    """Clamp, de-NaN and write the commands; remember them for the stuck monitor."""
    throttle = pursuit.clamp(_finite(cmd.throttle), -1.0, 1.0)
    brake = pursuit.clamp(_finite(cmd.brake, BRAKE_STOP), 0.0, MAX_BRAKE)
    steer = pursuit.clamp(_finite(cmd.steer), -STEER_LIMIT_DEG, STEER_LIMIT_DEG)
    rover.throttle, rover.brake, rover.steer = throttle, brake, steer
    rover.send_pickup = bool(cmd.pickup)
    rover.fixed_turn = cmd.fixed_turn
    if mode != nav.mode:
        log.debug("mode %s -> %s at t=%.1f", nav.mode, mode, _finite(t))
        nav.mode = mode
        nav.mode_since = _finite(t)
    rover.mode = mode
    rover.target = _display_target(nav)
    rover.mission_complete = bool(nav.done)
    nav.last_cmd = Command(throttle, brake, steer, bool(cmd.pickup), rover.fixed_turn)


def _display_target(nav):
    if nav.rock_target is not None and nav.mode in ("sample", "pickup"):
        return (round(float(nav.rock_target[0]), 1), round(float(nav.rock_target[1]), 1))
    if nav.path_goal is not None:
        x, y = grid.cell_to_world(*nav.path_goal[1])
        return (round(x, 1), round(y, 1))
    return None


# ============================== arbitration ==========================================

def _select_and_run(rover, nav, s):
    """Highest-priority applicable mode wins; each mode is one function below."""
    if s.pos is None:
        return "stop", Command(0.0, BRAKE_STOP if abs(s.vel) > STOPPED_SPEED_MPS else 0.0, 0.0)
    if nav.fixed is not None:
        rock_choice.note_turn_sighting(nav, s)
        cmd = _fixed_turn_step(nav, s)  # the simulator ignores data commands while it turns: wait for the yaw
        if cmd is not None:
            return "stop", cmd
    if nav.mode in ("sample", "pickup", "stuck"):
        paths.reset_goal_progress(nav, s)  # time spent on a rock or a recovery is no stall of the frontier goal
    if s.picking_up or s.near_sample:
        nav.recovery = None
        nav.rotate_heading = nav.rotate_via = None
        return "pickup", mode_pickup(nav, s)
    if nav.recovery is not None or _check_stuck(nav, s) or _check_turn_blocked(nav, s):
        cmd = mode_stuck(nav, s)
        if cmd is not None:
            return "stuck", cmd
    nav.stuck_since = None if nav.recovery is None else nav.stuck_since
    if nav.done:
        return "done", mode_done(nav, s)
    if nav.rotate_heading is not None:
        cmd = mode_stop(nav, s)
        if cmd is not None:
            return "stop", cmd
    if rock_choice.choose_rock(rover, nav, s):
        return _with_rotation("sample", mode_sample(rover, nav, s), nav)
    if s.t < nav.glance_hold_until:
        return "stop", Command(0.0, BRAKE_STOP, 0.0)  # a glance: the camera faces a nook for a moment
    if _should_search(nav, s):
        cmd = mode_search(rover, nav, s)
        if cmd is not None:
            return _with_rotation("search", cmd, nav)
    if _should_go_home(rover, nav, s):
        cmd = mode_home(rover, nav, s)
        return ("done", cmd) if nav.done else _with_rotation("home", cmd, nav)
    return _with_rotation("forward", mode_forward(rover, nav, s), nav)


def _home_eta(nav, s):
    """Estimated arrival time at home if the rover turned back now, s (canyon paths are not straight)."""
    home_dist = math.hypot(nav.home[0] - s.pos[0], nav.home[1] - s.pos[1])
    return s.t + home_dist * HOME_DETOUR_FACTOR / HOME_SPEED_ESTIMATE_MPS


def _should_search(nav, s):
    """After the map is complete, with samples still missing and time left, search the far corners."""
    if not (nav.explored and nav.second_sweep_done and nav.search_left):
        return False
    if s.samples_remaining is None or s.samples_remaining <= 0 or nav.home is None:
        return False
    if nav.path_goal is not None and nav.path_goal[0] == "home":
        return False
    return _home_eta(nav, s) <= _deadline(nav, s)


def _should_go_home(rover, nav, s):
    """Home when all samples are in and the map is done, or when time is running out."""
    if nav.home is None:
        return False
    if nav.path_goal is not None and nav.path_goal[0] == "home":
        return True
    if _home_eta(nav, s) > _deadline(nav, s):
        log.info("time is running out at t=%.1f: going home", s.t)
        return True
    if not nav.explored:
        return False
    missing = s.samples_remaining is not None and s.samples_remaining > 0
    if (missing or nav.hidden_frontiers) and SECOND_SWEEP and not nav.second_sweep_done:
        # an abandoned frontier that is still reachable (often behind cells remembered as stuck)
        # means the map is not complete, even with every sample in
        log.info("map complete with %d samples missing and %d abandoned frontiers reachable: second sweep",
                 s.samples_remaining or 0, nav.hidden_frontiers)
        nav.second_sweep_done = True
        nav.frontier_ignored[:] = False
        nav.frontier_abandoned[:] = False
        nav.hidden_frontiers = 0
        nav.explored = False
        return False
    if exploration_plan.frontier_reachable(rover, nav, s):
        # the way into an arm was mapped as wall when the map was called complete; driving near it
        # later for a sample opened it (seed 15, shadows on: the west arm was never entered)
        log.info("a reachable frontier appeared after the map was called complete, t=%.1f: exploring on", s.t)
        nav.explored = False
        nav.no_frontier_plans = 0
        nav.plan_time = -math.inf
        return False
    return True


def _check_spinning(nav, s, mode):
    """Turning in place again and again without getting anywhere: drop the goal and back off
    (or, when that already failed here, drive ahead)."""
    nav.spin_hist.append((s.t, mode == "stop", s.pos[0], s.pos[1]))
    while nav.spin_hist and s.t - nav.spin_hist[0][0] > SPIN_WINDOW_S:
        nav.spin_hist.popleft()
    if s.t - nav.spin_hist[0][0] < SPIN_WINDOW_S - 1.0 or nav.recovery is not None:
        return
    if _stop_share(nav.spin_hist) < SPIN_STOP_FRACTION or _span(nav.spin_hist, 2, 3) > SPIN_MAX_SPAN_M:
        return
    repeat = stuck.count_recent_nearby(nav.spin_events, s.t, s.pos)
    nav.spin_events.append((s.t, s.pos[0], s.pos[1]))
    ahead = repeat % 2 == 1  # backing off did not free it last time here: pull away forward
    log.info("turning in place without progress at (%.1f, %.1f) t=%.1f: dropping goal %s, %s",
             s.pos[0], s.pos[1], s.t, nav.path_goal, "driving ahead" if ahead else "backing off")
    _abandon_goal(nav, s)
    nav.rotate_heading = nav.rotate_via = None
    nav.recovery = stuck.Recovery(s.t, _escape_side(nav, s), 1, ahead=ahead)
    nav.spin_hist.clear()


_SECOND = operator.itemgetter(1)  # an entry's turning-in-place flag


def _stop_share(hist):
    """Share of (t, turning in place?, x, y) entries turning in place (plain Python on the ~600 entries:
    the same float64 value as the NumPy mean of the 0/1 column, without building an array every frame)."""
    return sum(map(_SECOND, hist)) / len(hist)  # True counts 1 (a C-level pass over the deque)


def _span(hist, col_x, col_y):
    """The larger of the x and y extents (max - min) of the entries' two position columns, m."""
    xs = [entry[col_x] for entry in hist]
    ys = [entry[col_y] for entry in hist]
    return max(max(xs) - min(xs), max(ys) - min(ys))


def _abandon_goal(nav, s):
    """Give up whatever the rover is heading for (the planner will pick something else)."""
    if nav.rock_target is not None:
        rock_choice.give_up_rock(nav, s)
    elif nav.path_goal is not None and nav.path_goal[0] == "frontier" and nav.path_goal[1] is not None:
        exploration_plan.give_up_frontier(nav)
    nav.path_goal = None
    nav.plan_time = -math.inf


def _with_rotation(mode, cmd, nav):
    """A driving mode may have asked to turn in place this frame: show that as 'stop'."""
    return ("stop", cmd) if nav.rotate_heading is not None else (mode, cmd)


def _check_stuck(nav, s):
    driving = nav.last_cmd.throttle > 0.05 and nav.last_cmd.brake == 0.0
    if not nav.progress.update(s.t, s.pos, driving):
        return False
    _begin_recovery(nav, s, "stuck", stuck.STUCK_WINDOW_S)
    for r, c in stuck.blocked_cells_ahead(s.pos, s.yaw):
        if math.hypot(c + 0.5 - s.pos[0], r + 0.5 - s.pos[1]) > 0.7:
            nav.blocked_at[r, c] = s.t
    search_plan.give_up_search_goal_near(nav, s)
    return True


def _check_turn_blocked(nav, s):
    """Turning in place while wedged (a rock at a corner) leaves the heading unchanged: escape at once
    instead of waiting for the turn to time out again and again."""
    cmd = nav.last_cmd
    if nav.rotate_heading is None or cmd.throttle != 0.0 or cmd.brake != 0.0 or cmd.steer == 0.0:
        nav.turn_ref = None
        return False
    if nav.turn_ref is None or abs(stuck.heading_diff_deg(s.yaw, nav.turn_ref[1])) >= ROTATE_BLOCKED_DEG:
        nav.turn_ref = (s.t, s.yaw)
        return False
    if s.t - nav.turn_ref[0] < ROTATE_BLOCKED_S:
        return False
    nav.turn_ref = None
    _begin_recovery(nav, s, "turn blocked", ROTATE_BLOCKED_S)
    return True


def _begin_recovery(nav, s, why, noticed_after_s):
    """Start an escape; a repeat at the same place escapes to the other side and for longer.

    noticed_after_s: how long the rover had been stuck when this was noticed, s.
    """
    if nav.stuck_since is None:
        nav.stuck_since = s.t - noticed_after_s
    repeat = stuck.count_recent_nearby(nav.stuck_events, s.t, s.pos)
    nav.stuck_events.append((s.t, s.pos[0], s.pos[1]))
    sign = _escape_side(nav, s)
    if repeat % 2 == 1:
        sign = -sign
    nav.recovery = stuck.Recovery(s.t, sign, repeat)
    nav.progress.reset()
    nav.rotate_heading = nav.rotate_via = None
    nav.plan_time = -math.inf  # replan around the blocked cells
    if nav.stage is not None and nav.stage_for is not None and nav.mode == "sample":
        nav.stages_wedged.append((*nav.stage_for, *nav.stage[:2]))
    nav.stage_for = None  # a rock approach that wedged is decided again, around the stuck cells
    log.info("%s at (%.1f, %.1f) t=%.1f, repeat %d, escaping %s", why, s.pos[0], s.pos[1], s.t, repeat,
             "left" if sign > 0 else "right")


def _escape_side(nav, s):
    """Turn toward the goal if it is off to one side, else toward the more open side of the view."""
    if len(nav.path_xy):
        pt = nav.path_xy[min(nav.path_idx + 3, len(nav.path_xy) - 1)]
        a = pursuit.bearing(s.pos, s.yaw, pt)
        if abs(a) > math.radians(10):
            return 1.0 if a > 0 else -1.0
    if s.nav_angles.size:
        return 1.0 if float(np.mean(s.nav_angles)) >= 0 else -1.0
    return 1.0


# ============================== modes =================================================

def mode_pickup(nav, s):
    """Stop; request the pickup once when near_sample and stopped; wait while the arm works."""
    if s.picking_up:
        return Command(0.0, 0.0, 0.0)
    if abs(s.vel) > PICKUP_STOP_SPEED_MPS:
        return Command(0.0, BRAKE_STOP, 0.0)
    if s.near_sample and s.t - nav.pickup_sent_at >= PICKUP_RETRY_S:
        nav.pickup_sent_at = s.t
        if nav.rock_target is None:
            yaw = math.radians(s.yaw)
            nav.rock_target = (s.pos[0] + PICKUP_REACH_M * math.cos(yaw), s.pos[1] + PICKUP_REACH_M * math.sin(yaw))
        log.info("pickup requested at (%.1f, %.1f) t=%.1f", s.pos[0], s.pos[1], s.t)
        return Command(0.0, BRAKE_STOP, 0.0, pickup=True)
    return Command(0.0, BRAKE_STOP, 0.0)


def mode_stuck(nav, s):
    """Run the scripted recovery; None when it has finished (the caller picks the next mode)."""
    if nav.recovery is None:
        return None
    out = nav.recovery.command(s.t, (s.pos[0], s.pos[1], s.yaw))
    if out is None:
        nav.recovery = None
        nav.progress.reset()
        return None
    _phase, thr, brk, st = out
    return Command(thr, brk, st)


def mode_stop(nav, s):
    """Brake, then turn in place toward nav.rotate_heading; None when aligned (or timed out).

    With the simulator's fixed_turn (s.fixed_turns) the turn is one kinematic turn that stops
    exactly at the heading (_fixed_turn_angle); otherwise, or when it was refused, steered at
    full lock, the error judged where the heading will be when this command acts (latency lead).
    """
    turn, sweep = _fixed_turn_angle(nav, s)
    if turn is not None:
        if abs(turn) <= ROTATE_EXIT_DEG:
            return _end_rotation(nav, s)
        if abs(turn) >= fixed_turn.FIXED_TURN_MIN_DEG:
            return _begin_fixed_turn(nav, s, turn, sweep)
    err = predict.heading_error_at_lead(nav.rotate_heading, s.yaw, nav.lead.yaw_rate_dps, nav.lead.lead_s)
    if nav.rotate_dir is not None and err * nav.rotate_dir < 0 and abs(err) > SWEEP_COMMIT_DEG:
        if abs(s.vel) > TURN_IN_PLACE_SPEED_MPS:
            return Command(0.0, BRAKE_STOP, 0.0)
        return Command(0.0, 0.0, nav.rotate_dir * STEER_LIMIT_DEG)  # the long way round, until past the far side
    if abs(err) <= ROTATE_EXIT_DEG or s.t - nav.rotate_since > ROTATE_TIMEOUT_S:
        return _end_rotation(nav, s)
    if abs(s.vel) > TURN_IN_PLACE_SPEED_MPS:
        return Command(0.0, BRAKE_STOP, 0.0)
    steer = STEER_LIMIT_DEG if err > 0 else -STEER_LIMIT_DEG
    if abs(err) < 20.0:
        steer *= 0.6  # soften the last degrees to limit overshoot at 45 deg/s
    return Command(0.0, 0.0, steer)


def _end_rotation(nav, s):
    """The turn in place is over: None (the caller picks the next mode)."""
    if nav.rotate_via is not None:  # facing the unsearched wall feet: hold still and let a rock there be chosen
        nav.glance_hold_until = s.t + GLANCE_HOLD_S
    nav.rotate_heading = nav.rotate_via = None
    return None


def _fixed_turn_angle(nav, s):
    """(turn, sweep): the whole turn still wanted, degrees CCW, and whether it goes the long way round
    to sweep the camera over unsearched wall feet, when this turn is to be a fixed turn; (None, False)
    when it is to be steered (no fixed turns on this link, this one was refused, the simulator refused
    them again and again, or the turn timed out)."""
    if (not s.fixed_turns or nav.fixed_steer or nav.fixed_refusals >= fixed_turn.FIXED_TURN_MAX_REFUSALS
            or s.t - nav.rotate_since > ROTATE_TIMEOUT_S):
        return None, False
    if not fixed_turn.still(s.vel) and s.t - nav.rotate_since > fixed_turn.FIXED_TURN_STOP_WAIT_S:
        nav.fixed_steer = True  # not coming to a standstill (rocking on a rock): steer as before
        return None, False
    err = predict.wrap_deg(nav.rotate_heading - s.yaw)
    if nav.rotate_dir is not None and err * nav.rotate_dir < 0 and abs(err) > SWEEP_COMMIT_DEG:
        return err + 360.0 * nav.rotate_dir, True
    return err, False


def _fixed_turn_rate(nav, s, turn, sweep):
    """deg/s for this fixed turn: slow (FIXED_TURN_SWEEP_RATE_DPS) when it goes the long way round to
    sweep unsearched wall feet, or when its arc alone sweeps at least explore.SWEEP_MIN_CELLS of them
    with samples missing (FIXED_TURN_SLOW_FOR_UNSEARCHED) or of frontier cells
    (FIXED_TURN_SLOW_FOR_FRONTIER): a rock is remembered only after several frames show it
    (perception.ROCK_MIN_HITS) and a cell is mapped only after several votes, and a fast sweep missed
    the north-tip sample on seed 0; fast (FIXED_TURN_RATE_DPS) otherwise."""
    if sweep or (fixed_turn.FIXED_TURN_SLOW_FOR_UNSEARCHED and search_plan.samples_missing(s)
                 and explore.arc_swept_cells(nav.unsearched, s.pos, s.yaw, turn) >= explore.SWEEP_MIN_CELLS):
        return fixed_turn.FIXED_TURN_SWEEP_RATE_DPS
    if fixed_turn.FIXED_TURN_SLOW_FOR_FRONTIER and s.rover is not None:
        free, obstacle, unknown = paths.grids(s.rover)
        frontier = explore.frontier_mask(free, unknown, obstacle=obstacle,
                                         seen_close=exploration_plan.seen_for_frontiers(nav, s))
        if explore.arc_swept_cells(frontier, s.pos, s.yaw, turn) >= explore.SWEEP_MIN_CELLS:
            return fixed_turn.FIXED_TURN_SWEEP_RATE_DPS
    return fixed_turn.FIXED_TURN_RATE_DPS


def _begin_fixed_turn(nav, s, turn, sweep):
    """Brake to the standstill the simulator needs, then release the brake for one frame (it refuses
    a fixed turn while the last data command brakes); the next frame sends it (_fixed_turn_step)."""
    if not fixed_turn.still(s.vel):
        return Command(0.0, BRAKE_STOP, 0.0)
    nav.fixed = fixed_turn.FixedTurn(ccw_deg=float(turn), released_at=s.t, rate_dps=_fixed_turn_rate(nav, s, turn, sweep))
    return Command(0.0, 0.0, 0.0)


def _fixed_turn_step(nav, s):
    """Send the released fixed turn, then hold data 0/0/0 until the yaw has arrived; None once it is
    over (arrived, overdue, refused: then this turn is steered) or the rover rolled off the standstill."""
    ft = nav.fixed
    latency = 2.0 * nav.lead.interval_s  # a reply acts at the next frame and shows in the one after
    if ft.sent_at is None:
        if not fixed_turn.still(s.vel):
            nav.fixed = None
            return None
        ft.sent_at, ft.last_yaw = s.t, s.yaw
        log.debug("fixed turn %+.0f deg at t=%.1f", ft.ccw_deg, s.t)
        return Command(0.0, 0.0, 0.0, fixed_turn=(ft.ccw_deg, ft.rate_dps))
    ft.observe(s.yaw)
    if ft.arrived() or ft.overdue(s.t, latency):
        nav.fixed = None
        nav.fixed_refusals = 0
        return None
    if ft.refused(s.t, latency):
        nav.fixed = None
        nav.fixed_refusals += 1
        nav.fixed_refused += 1
        nav.fixed_steer = True
        log.info("fixed turn refused at t=%.1f (%d in a row): steering this turn", s.t, nav.fixed_refusals)
        return None
    return Command(0.0, 0.0, 0.0)


def mode_done(nav, s):
    """Parked: hold the brake."""
    return Command(0.0, BRAKE_STOP, 0.0)


def mode_forward(rover, nav, s):
    """Explore: follow a path to the best frontier; without a plan, hug the left wall."""
    if nav.path_goal is None or nav.path_goal[0] != "frontier" or paths.needs_replan(nav, s):
        exploration_plan.plan_explore(rover, nav, s)
    if nav.path_goal is not None and nav.path_goal[0] == "frontier" and len(nav.path_xy) >= 2:
        goal_xy = grid.cell_to_world(*nav.path_goal[1])
        if math.hypot(goal_xy[0] - s.pos[0], goal_xy[1] - s.pos[1]) < exploration_plan.FRONTIER_REACHED_M:
            explore.ignore_disc(nav.frontier_ignored, nav.path_goal[1])
            nav.plan_time = -math.inf
        if paths.goal_stalled(nav, s):
            log.info("frontier %s not getting closer: ignoring it", nav.path_goal[1])
            exploration_plan.give_up_frontier(nav)
            nav.plan_time = -math.inf
        return _follow_path(nav, s, CRUISE_SPEED_MPS, slow_at_end=False)
    return _wall_follow(nav, s)


def mode_search(rover, nav, s):
    """Map complete, samples missing: peek into shadowed pockets and visit mapped floor far from
    the trail, nearest first; None when nothing is left."""
    frame_maps = {}  # maps this frame's replan and face turn share (see search_plan.unsearched_wall_feet)
    for _goal in range(SEARCH_GOALS_PER_FRAME):
        if nav.path_goal is None or nav.path_goal[0] not in search_plan.SEARCH_GOAL_KINDS or paths.needs_replan(nav, s):
            search_plan.plan_search(rover, nav, s, frame_maps)
        if not nav.search_left or nav.path_goal is None:
            return None
        kind, goal = nav.path_goal
        goal_xy = grid.cell_to_world(*goal)
        near_m = sample_spots.SPOT_STAND_REACHED_M if kind == "spot" else exploration_plan.FRONTIER_REACHED_M
        reached = (len(nav.path_xy) < 2 or paths.goal_stalled(nav, s)
                   or math.hypot(goal_xy[0] - s.pos[0], goal_xy[1] - s.pos[1]) < near_m)
        if not reached:
            return _follow_path(nav, s, CRUISE_SPEED_MPS, slow_at_end=False)
        if kind in SEARCH_FACE_KINDS and _face_unsearched(rover, nav, s, goal, frame_maps):
            return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
        if kind == "spot" and _face_spot(nav, s):
            return (mode_stop(nav, s) if nav.rotate_heading is not None else None) or Command(0.0, BRAKE_STOP, 0.0)
        if kind == "spot":
            search_plan.spot_done(nav, s)
        elif kind == "look":
            search_plan.leave_look_stand(rover, nav, s, goal, frame_maps)
        elif kind == "pocket":
            search_plan.pocket_done(nav, goal)
        else:
            explore.ignore_disc(nav.search_done, goal, search_plan.search_done_radius(kind))
        nav.plan_time = -math.inf
    # goals under the rover's wheels were ticked off; the next frame plans on (an empty path here
    # once sent seed 15 home with two samples missing)
    return Command(0.0, BRAKE_STOP if abs(s.vel) > STOPPED_SPEED_MPS else 0.0, 0.0)


def _face_spot(nav, s):
    """At a reached spot stand, turn once to face the spot, then hold still for sample_spots.SPOT_HOLD_S so
    the camera's frames show it (a rock there becomes the target); True while turning or holding."""
    if nav.spot_goal is None or nav.spots is None:
        return False
    if nav.spot_faced != nav.spot_goal:
        nav.spot_faced, nav.spot_hold_until = nav.spot_goal, None
        heading = sample_spots.face_heading(nav.spots[nav.spot_goal], s.pos, s.yaw)
        if heading is not None:
            log.info("sample search: facing spot %d (%.1f, %.1f) at %.0f deg, t=%.1f", nav.spot_goal,
                     *nav.spots[nav.spot_goal], heading, s.t)
            _start_rotation(nav, s, heading, "spot-face")
            return True
    if nav.spot_hold_until is None:
        nav.spot_hold_until = s.t + sample_spots.SPOT_HOLD_S
    return s.t < nav.spot_hold_until


def _face_unsearched(rover, nav, s, goal, frame_maps=None):
    """At a reached peek or look goal, turn to face nearby wall feet the camera never saw from close by
    (see explore.face_heading) before calling the place searched; True when a turn was started.
    At most SEARCH_FACES_PER_GOAL turns per goal, so a cell the camera cannot see never holds it.
    Far-floor goals do not turn: their path already faces the floor they were chosen for, and turning
    at each of them cost seed 5 twelve turns and 49 s."""
    if nav.search_faced_goal != goal:
        nav.search_faced_goal, nav.search_faces = goal, 0
    if nav.search_faces >= SEARCH_FACES_PER_GOAL:
        return False
    free, obstacle, _unknown = paths.grids(rover)
    heading = explore.face_heading(search_plan.unsearched_wall_feet(rover, nav, frame_maps, free, obstacle),
                                   s.pos, s.yaw)
    if heading is None:
        return False
    nav.search_faces += 1
    log.info("sample search: facing %.0f deg at (%.1f, %.1f), t=%.1f", heading, s.pos[0], s.pos[1], s.t)
    _start_rotation(nav, s, heading, "search-face")
    return True


def mode_sample(rover, nav, s):
    """Approach the target rock: along a planned path while far, by camera bearing for the last metres."""
    dist = math.hypot(nav.rock_target[0] - s.pos[0], nav.rock_target[1] - s.pos[1])
    if dist <= rock_choice.SAMPLE_VISUAL_M and nav.rock_close_since is None:
        nav.rock_close_since = s.t
    nav.rock_came_close |= dist <= rock_choice.SAMPLE_VISUAL_M
    close_for = s.t - nav.rock_close_since if nav.rock_close_since is not None else 0.0
    if s.t - nav.rock_since > SAMPLE_TIMEOUT_S or close_for > SAMPLE_CLOSE_TIMEOUT_S:
        log.info("giving up rock at (%.1f, %.1f) for now", *nav.rock_target)
        rock_choice.give_up_rock(nav, s)
        nav.path_goal = None
        return Command(0.0, BRAKE_STOP, 0.0)
    if s.t < nav.rock_back_until and dist < ROCK_BESIDE_CLEAR_M:
        return Command(stuck.BACK_OFF_THROTTLE, 0.0, 0.0)
    staged = _stage_approach(rover, nav, s, dist)
    if staged is not None:
        return staged
    if dist > rock_choice.SAMPLE_VISUAL_M:
        # far: the planner knows the walls, a straight line at the rock may not
        goal = grid.world_to_cell(nav.rock_target)
        if nav.path_goal != ("rock", goal) or paths.needs_replan(nav, s):
            paths.plan_to(rover, nav, s, "rock", goal)
        if len(nav.path_xy) >= 2:
            return _follow_path(nav, s, SAMPLE_PATH_SPEED_MPS, slow_at_end=True)
    if s.t - nav.rock_seen_time <= rock_choice.SAMPLE_VISION_MEMORY_S:
        alpha, dist = nav.rock_bearing, nav.rock_dist
        reason = "sample-vision"
    else:
        if not turning.bearing_usable(dist):
            if nav.rock_seen_close and not nav.rock_backed_off:
                # the camera showed this rock from close: it is beside the rover, where near_sample stays off and
                # the camera cannot see (held-out seed 89, shadows on, gave the east-nook rock up 0.5 m off it).
                # Reverse straight once (until ROCK_BESIDE_CLEAR_M, above), so it comes back into view ahead
                log.info("rock at (%.1f, %.1f) is beside the rover: backing off to see it again", *nav.rock_target)
                nav.rock_backed_off = True
                nav.rock_back_until = s.t + ROCK_BESIDE_BACK_S
                return Command(stuck.BACK_OFF_THROTTLE, 0.0, 0.0)
            # the remembered spot is under the rover, the camera does not show a rock and near_sample is
            # off: it is not there (seed 16 at 15 fps turned nine times toward such a spot, 0.1-0.4 m off)
            log.info("rock at (%.1f, %.1f) is under the rover and not in view: giving it up", *nav.rock_target)
            rock_choice.give_up_rock(nav, s)
            nav.path_goal = None
            return Command(0.0, BRAKE_STOP, 0.0)
        alpha = pursuit.bearing(s.pos, s.yaw, nav.rock_target)
        reason = "sample-near"
    if abs(math.degrees(alpha)) > SAMPLE_ROTATE_DEG and abs(s.vel) < 1.0:
        _start_rotation(nav, s, s.yaw + math.degrees(alpha), reason)
        return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
    dist = predict.distance_at_lead(dist, s.vel, nav.lead.lead_s)  # where the rover is when this command acts
    speed = float(np.clip(SAMPLE_SPEED_GAIN * (dist - SAMPLE_STOP_M) + SAMPLE_MIN_SPEED_MPS,
                          SAMPLE_MIN_SPEED_MPS, SAMPLE_MAX_SPEED_MPS))
    steer = float(np.clip(SAMPLE_STEER_GAIN * math.degrees(alpha), -STEER_LIMIT_DEG, STEER_LIMIT_DEG))
    thr, brk = _speed_control(s.vel, speed)
    return Command(thr, brk, steer)


def _arrival_point(nav, s):
    """Where the rover will come from on its final run to the rock: the planned path's point
    approach.FINAL_RUN_M before its end (the path curves round walls), else the rover itself."""
    if nav.path_goal is None or nav.path_goal[0] != "rock" or len(nav.path_xy) < 2:
        return s.pos
    steps = np.hypot(*np.diff(nav.path_xy[::-1], axis=0).T)
    k = int(np.searchsorted(np.cumsum(steps), approach.FINAL_RUN_M))
    return tuple(nav.path_xy[::-1][min(k + 1, len(nav.path_xy) - 1)])


def _stage_approach(rover, nav, s, dist):
    """Command toward the rock's staging point (see navigation.approach), or None to approach normally.

    Decided once per rock when it is within STAGE_DECIDE_M, and again after each stuck: a rock
    whose straight final run from the rover is not mapped floor (a nook), or runs over cells
    the rover got stuck on, is approached from a staging point with a clear run in, whatever
    the heading the rover arrives with.
    """
    if nav.stage_for is None or math.hypot(nav.rock_target[0] - nav.stage_for[0],
                                           nav.rock_target[1] - nav.stage_for[1]) > rock_choice.ROCK_SAME_M:
        if dist > STAGE_DECIDE_M:
            return None
        free = paths.grids(rover)[0]
        nav.stage_for, nav.stage_done = nav.rock_target, False
        # each decided approach gets its own SAMPLE_CLOSE_TIMEOUT_S (SAMPLE_TIMEOUT_S still bounds the
        # rock): seed 37 (15 fps) wedged twice at the east nook, and the close timer ran out as it drove
        # to the third staging point, the one that works; it came back 70 s later and collected from there
        nav.rock_close_since = None
        wedged = [(x, y) for rx, ry, x, y in nav.stages_wedged
                  if math.hypot(rx - nav.rock_target[0], ry - nav.rock_target[1]) <= rock_choice.ROCK_SAME_M]
        nav.stage = approach.plan_approach(free, paths.blocked_cells(nav, s), nav.rock_target, _arrival_point(nav, s),
                                           wedged_stages=wedged)
        if nav.stage is not None:
            log.info("rock at (%.1f, %.1f): lining up at (%.1f, %.1f) first", *nav.rock_target, *nav.stage[:2])
    if nav.stage is None or nav.stage_done:
        return None
    sx, sy, _heading = nav.stage
    d_stage = math.hypot(sx - s.pos[0], sy - s.pos[1])
    behind = abs(math.degrees(pursuit.bearing(s.pos, s.yaw, (sx, sy)))) > ROTATE_ENTER_DEG
    if d_stage > (STAGE_BEHIND_REACHED_M if behind else STAGE_REACHED_M):
        goal = grid.world_to_cell((sx, sy))
        if d_stage > PATH_END_SLOW_M / 2:
            if nav.path_goal != ("stage", goal) or paths.needs_replan(nav, s):
                paths.plan_to(rover, nav, s, "stage", goal)
            if len(nav.path_xy) >= 2:
                return _follow_path(nav, s, SAMPLE_PATH_SPEED_MPS, slow_at_end=True)
        alpha = pursuit.bearing(s.pos, s.yaw, (sx, sy))
        if abs(math.degrees(alpha)) > ROTATE_ENTER_DEG:
            _start_rotation(nav, s, s.yaw + math.degrees(alpha), "stage-final")
            return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
        thr, brk = _speed_control(s.vel, float(np.clip(0.6 * d_stage, SAMPLE_MIN_SPEED_MPS, 1.0)))
        return Command(thr, brk, float(np.clip(math.degrees(alpha), -STEER_LIMIT_DEG, STEER_LIMIT_DEG)))
    alpha = pursuit.bearing(s.pos, s.yaw, nav.rock_target)
    if abs(math.degrees(alpha)) > STAGE_FACE_DEG:
        if abs(s.vel) > TURN_IN_PLACE_SPEED_MPS:
            return Command(0.0, BRAKE_STOP, 0.0)
        _start_rotation(nav, s, s.yaw + math.degrees(alpha), "stage-face")
        return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
    nav.stage_done = True
    nav.path_goal = None
    return None


def mode_home(rover, nav, s):
    """Plan back to the start, follow the path, park within HOME_STOP_M."""
    home = nav.home
    dist = math.hypot(home[0] - s.pos[0], home[1] - s.pos[1])
    if dist <= HOME_STOP_M:
        nav.done = True
        log.info("home at t=%.1f (%.2f m from start)", s.t, dist)
        return Command(0.0, BRAKE_STOP, 0.0)
    goal = grid.world_to_cell(home)
    if nav.path_goal != ("home", goal) or paths.needs_replan(nav, s):
        paths.plan_to(rover, nav, s, "home", goal)
    if len(nav.path_xy) >= 2 and dist > PATH_END_SLOW_M:
        return _follow_path(nav, s, CRUISE_SPEED_MPS, slow_at_end=True)
    # last metres: drive straight at the start point
    alpha = pursuit.bearing(s.pos, s.yaw, home)
    if abs(math.degrees(alpha)) > ROTATE_ENTER_DEG:
        _start_rotation(nav, s, s.yaw + math.degrees(alpha), "home-final")
        return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
    speed = float(np.clip(0.6 * dist, SAMPLE_MIN_SPEED_MPS, 1.5))
    thr, brk = _speed_control(s.vel, speed)
    return Command(thr, brk, float(np.clip(math.degrees(alpha), -STEER_LIMIT_DEG, STEER_LIMIT_DEG)))


# ============================== driving helpers ========================================

def _speed_control(vel, target):
    """(throttle, brake) that move the speed toward `target` (m/s, >= 0)."""
    err = target - vel
    if target <= 0.01:
        return 0.0, (BRAKE_STOP if abs(vel) > 0.05 else 0.0)
    if err > 0:
        return float(min(MAX_THROTTLE, THROTTLE_GAIN * err)), 0.0
    if -err > BRAKE_DEADBAND_MPS:
        return 0.0, float(min(MAX_BRAKE, BRAKE_GAIN * (-err - BRAKE_DEADBAND_MPS) + 0.2))
    return 0.0, 0.0


def _start_rotation(nav, s, heading_deg, reason):
    nav.rotate_heading = float(heading_deg) % 360.0
    nav.rotate_since = s.t
    nav.rotate_dir = None
    nav.rotate_via = None
    nav.fixed_steer = False
    returning = _turn_back_after_glance(nav, s)  # always asked: it also ends the glance's claim on the next turn
    if not returning and reason in SWEEP_REASONS and search_plan.samples_missing(s) and nav.unsearched is not None:
        way = explore.sweep_direction(nav.unsearched, s.pos, s.yaw, nav.rotate_heading)
        if way * predict.wrap_deg(nav.rotate_heading - s.yaw) < 0:
            nav.rotate_dir = way
            log.info("turning the long way round (%+d) at (%.1f, %.1f) t=%.1f: unsearched wall feet on that side",
                     way, s.pos[0], s.pos[1], s.t)
        elif reason in GLANCE_REASONS:
            _glance_first(nav, s)
    log.debug("turn in place to %.0f deg (%s) at t=%.1f", nav.rotate_heading, reason, s.t)


def _turn_back_after_glance(nav, s):
    """The first turn after a glance that went against the planned turn's way goes back the planned way
    (through where the glance began), so it still sweeps what the planned turn would have; True when it
    set that way.

    Seed 0 at 10 fps: turning back 3.1 m north-west of the east nook (48 -> 291 deg, right, over the
    nook) the rover glanced left at 119 deg, at the lobe's north wall; the turn back then went the short
    way from there, left again, and the nook was never in view (its sample was never found)."""
    back, nav.glance_return = nav.glance_return, None
    if back is None:
        return False
    way, (x, y), until = back
    if s.pos is None or s.t > until or math.hypot(s.pos[0] - x, s.pos[1] - y) > GLANCE_DONE_M:
        return False
    err = predict.wrap_deg(nav.rotate_heading - s.yaw)
    if err * way >= 0 or 360.0 - abs(err) > GLANCE_RETURN_MAX_DEG:
        return False  # the short way is that way already, or the way back is too long
    nav.rotate_dir = way
    log.info("turning back through the glance's start (%+d) at (%.1f, %.1f) t=%.1f", way, s.pos[0], s.pos[1], s.t)
    return True


def _glance_first(nav, s):
    """Before a turn back (the short way) at a dead end (GLANCE_DEAD_END_REACH_M), turn first to face
    unsearched wall feet close by that the turn would not sweep (explore.glance_heading), once per
    place (GLANCE_DONE_M).

    A turn back is where a path doubles back: an arm's tip, a pocket's end, a nook beside a dead end.
    On seed 15 the rover turned back 3.4 m from the east-nook sample with the nook 65 deg to its left
    and turned right, away from it; the turn that would have swept it was 243 deg the long way."""
    cell = grid.world_to_cell(s.pos)
    if cell is None or nav.glanced[cell]:
        return
    corridor = reactive.width_limited(_frame_reach(s))
    if corridor.size and float(corridor.max()) >= GLANCE_DEAD_END_REACH_M:
        return  # a way on ahead: not a dead end (in the open hub a glance at every turn back cost 60-70 s)
    glance = explore.glance_heading(nav.unsearched, s.pos, s.yaw, nav.rotate_heading)
    if glance is None:
        return
    explore.ignore_disc(nav.glanced, cell, GLANCE_DONE_M)
    planned = 1 if predict.wrap_deg(nav.rotate_heading - s.yaw) >= 0 else -1
    if predict.wrap_deg(glance - s.yaw) * planned < 0:  # glancing the other way: come back through here
        nav.glance_return = (planned, (float(s.pos[0]), float(s.pos[1])), s.t + GLANCE_RETURN_S)
    nav.rotate_via, nav.rotate_heading = nav.rotate_heading, glance
    log.info("glancing at %.0f deg before turning back at (%.1f, %.1f) t=%.1f: unsearched wall feet there",
             glance, s.pos[0], s.pos[1], s.t)


def _drive_heading(nav, s, alpha, max_speed, planned=False):
    """Drive toward rover-frame bearing `alpha` (rad), avoiding what the camera sees as blocked.

    With `planned` (alpha comes from a path over the map) a view that looks
    blocked is not trusted blindly: in a narrow spur the walls fill the view
    although the way is open, so the rover creeps on along the path and lets
    the stuck detector judge.
    """
    if abs(math.degrees(alpha)) > ROTATE_ENTER_DEG:
        _start_rotation(nav, s, s.yaw + math.degrees(alpha), "path-behind")
        return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
    if nav.leaving_pickup:
        # a sample lies at a wall foot: arcing off at full lock from a standstill climbs the wall
        # (seeds 3 and 23 got stuck twice each leaving (70.3, 88.0)), so face the way on first
        if abs(math.degrees(alpha)) > LEAVE_PICKUP_ROTATE_DEG and abs(s.vel) < TURN_IN_PLACE_SPEED_MPS:
            _start_rotation(nav, s, s.yaw + math.degrees(alpha), "leave-pickup")
            return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
        nav.leaving_pickup = False
    reach = _frame_reach(s)
    heading, clear = reactive.choose_heading(reach, alpha)
    if clear < REACH_STOP_M and planned:
        steer = pursuit.steer_for_curvature(2.0 * math.sin(alpha) / pursuit.LOOKAHEAD_MIN_M, s.vel)
        thr, brk = _speed_control(s.vel, CREEP_SPEED_MPS)
        return Command(thr, brk, steer)
    if clear < REACH_STOP_M:
        # nothing drivable where we want to go: turn toward the open side (or the goal side)
        side = np.sign(alpha) if abs(alpha) > math.radians(15) else (
            np.sign(np.mean(s.nav_angles)) if s.nav_angles.size else 1.0)
        side = side if side != 0 else 1.0
        _start_rotation(nav, s, s.yaw + side * BLOCKED_TURN_DEG, "blocked")
        return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
    look = pursuit.lookahead_for_speed(s.vel)
    steer = pursuit.steer_for_curvature(2.0 * math.sin(heading) / look, s.vel)
    turn_frac = min(abs(math.degrees(heading)) / SLOW_TURN_DEG, 1.0)
    speed = max_speed - (max_speed - MIN_DRIVE_SPEED_MPS) * turn_frac
    speed = min(speed, max(MIN_DRIVE_SPEED_MPS, REACH_SPEED_GAIN * (clear - REACH_STOP_M) + MIN_DRIVE_SPEED_MPS))
    thr, brk = _speed_control(s.vel, speed)
    return Command(thr, brk, steer)


def _follow_path(nav, s, max_speed, slow_at_end):
    """Pure pursuit on nav.path_xy, with reactive correction and end-of-path slowdown.

    The pursuit point is chosen from the pose predicted one telemetry interval ahead, where the
    rover will be when this command acts.
    """
    x, y, yaw = predict.predict_pose(s.pos[0], s.pos[1], s.yaw, s.vel, nav.lead.yaw_rate_dps, nav.lead.lead_s)
    steer, alpha, pt, idx, remaining = pursuit.pursue(nav.path_xy, (x, y), yaw, s.vel, nav.path_idx)
    nav.path_idx = idx
    paths.track_goal_progress(nav, s, remaining)
    speed = max_speed
    if slow_at_end:
        speed = min(speed, max(MIN_DRIVE_SPEED_MPS, 0.8 * remaining))
    return _drive_heading(nav, s, alpha, speed, planned=True)


def _wall_follow(nav, s):
    """Fallback without a plan: steer to the left part of the navigable view."""
    if s.nav_angles.size < FALLBACK_MIN_NAV_PIXELS:
        _start_rotation(nav, s, s.yaw - BLOCKED_TURN_DEG, "fallback-empty")
        return mode_stop(nav, s) or Command(0.0, BRAKE_STOP, 0.0)
    wanted = float(np.mean(s.nav_angles) + WALL_BIAS_STD * np.std(s.nav_angles))
    wanted = float(np.clip(wanted, -math.radians(ROTATE_ENTER_DEG - 5), math.radians(ROTATE_ENTER_DEG - 5)))
    return _drive_heading(nav, s, wanted, CRUISE_SPEED_MPS)
