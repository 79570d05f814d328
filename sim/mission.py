"""Run one full mission of the autonomy client on the twin and score it.

    python -m sim.mission --seed N [--world real|procedural:K|PNG] [--time-limit S]
                          [--timing unity|lockstep] [--fps 30] [--latency-ms MS] [--compute-ms MS]
                          [--video out.mp4] [--out DIR] [--record DIR] [--wire]

Default: `AutonomyClient` in-process against `RoverTwin` under the real simulator's
loop (`--timing unity`, sim/timing.py): physics free-runs, each command acts at the
first render frame after it arrives, no clock is sent and the client reads a
virtual clock as its wall clock, so a mission is deterministic and much faster
than real time.  `--timing lockstep` is the old, EASIER loop (one frame per
command, the twin's `sim_time` clock).  `--wire`: `drive_rover.py` runs as a
subprocess on a free port and the twin talks to it over the real Socket.IO wire
protocol like the Unity program (real time under unity timing).

Writes `<out>/mission.json`, `<out>/worldmap.npy` (all atomic) and `<out>/mission.png` (worldmap vs truth,
trajectory, samples, start).  Mapped/fidelity/located use
`evaluation.metrics.score_map` on the client's worldmap; collected, returned
home, time and stuck figures come from the twin's ground truth.
"""
from __future__ import annotations

import logging
import math
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from dashboard import add_dashboard_options
from drive_rover import add_home_by_option
from interrupts import caused_by_interrupt
from sim.cli import (INTERRUPTED_EXIT, add_shadows_option, check_paths, parse_with_logging, positive_number,
                     seed_number, tool_parser)
from sim.mission_parts import (HOME_RADIUS_M, StuckMeter, TruthTrack, nan_to_none, open_recorder,  # noqa: F401
                               progress_bar, write_json_atomic, write_npy_atomic, write_png_atomic)
from sim.timing import Timing, TwinLoop, add_timing_options, frame_after, frame_time, timing_from_args

log = logging.getLogger(__name__)

TIME_LIMIT_S = 900.0  # simulated seconds before a mission is stopped
MAP_PNG_SCALE = 4  # px per metre in the mission PNG
MAP_TRAIL_POINTS = 4000  # trail points drawn in the mission PNG at most (thinned evenly), count
DEFAULT_OUT_ROOT = "out"  # default output folder root
INTERRUPTED = "interrupted"  # end_reason of a mission stopped by Ctrl-C (its files hold the partial run)


@dataclass
class MissionResult:
    seed: int
    world: str
    mode: str  # inprocess | wire
    mapped_pct: float | None
    fidelity_pct: float | None
    located: int | None
    collected: int
    samples: int
    returned_home: bool
    completed: bool  # the client reported mission_complete (in-process) / truth says done (wire)
    end_reason: str
    time_s: float  # simulated seconds
    stuck_time_s: float
    longest_stuck_s: float
    frames: int
    distance_m: float
    final_distance_to_start_m: float
    wall_s: float
    frames_per_s: float
    rejected_commands: int
    stuck_stretches: list = field(default_factory=list)  # [t, x, y, duration_s] >= STUCK_REPORT_MIN_S
    files: dict = field(default_factory=dict)
    shadows: bool = False  # the twin rendered terrain cast shadows (--shadows on)
    home_by_s: float | None = None  # the client's return deadline when set (--home-by), s
    timing: str = "unity"  # the loop: unity (the real simulator's) or lockstep (easier)
    fps: float | None = None  # render frames/s (unity timing)
    latency_ms: float | None = None  # transport round trip modelled in-process / asked for on the wire, ms
    compute_ms: float | None = None  # client compute time modelled in-process, ms
    telemetry_hz: float | None = None  # telemetry messages per simulated second
    reply_delay_ms: float | None = None  # median capture -> command applied, ms of simulated time
    round_trip_ms: float | None = None  # wire, unity timing: median capture -> command received, wall ms
    time_limit_s: float | None = None  # the mission's time limit (--time-limit), simulated s
    code_version: str | None = None  # git commit of the code that ran (+ "-dirty" with local changes)
    render_fps: float | None = None  # wire, unity timing: render frames the twin managed per second (falls under load)
    fixed_turns: int | None = None  # in-process: fixed_turn commands the client sent
    fixed_turn_deg: float | None = None  # ...and their degrees in all
    fixed_turns_refused: int | None = None  # ...of which the client saw the simulator refuse (and steered instead)
    reused_frames: int | None = None  # in-process: frames that reused the last image, the rover still (sim/twin.py)

    def as_dict(self):
        return {k: nan_to_none(v) for k, v in asdict(self).items()}


# ----------------------------------------------------------------------------- the PNG
def mission_image(world, worldmap, trajectory, initial_samples, collected_xy, start_xy, stuck_xy=(), result=None):
    """BGR picture of a mission, north up, in the replay map's colours (dashboard.mapview): the
    client's map scored against the truth, trail, samples (collected or not), stuck places, start;
    with ``result`` (a MissionResult) a title, the figures and a legend."""
    from dashboard import mapview

    collected = {(round(x, 3), round(y, 3)) for x, y in collected_xy}
    left = [s[:2] for s in initial_samples if (round(s[0], 3), round(s[1], 3)) not in collected]
    traj = np.asarray(trajectory, float).reshape(-1, 2)
    trail = traj[:: max(1, len(traj) // MAP_TRAIL_POINTS)]
    if len(traj):
        trail = np.vstack([trail, traj[-1:]])
    wm = worldmap if worldmap is not None else np.zeros(world.nav_truth.shape + (3,), np.uint8)
    pose = None
    if len(traj) > 1:
        d = traj[-1] - traj[max(0, len(traj) - 10)]
        pose = (traj[-1][0], traj[-1][1], math.degrees(math.atan2(d[1], d[0])))
    img = mapview.scene(wm, world.nav_truth, scale=MAP_PNG_SCALE, trail=trail, samples=left,
                        collected=list(collected_xy), stuck=stuck_xy, start=start_xy, pose=pose)
    if result is None:
        return img
    return mapview.titled(img, *mission_caption(result.as_dict()))


MODE_NAMES = {"inprocess": "in-process", "wire": "over the wire"}  # mission modes as mission.png names them


def mission_caption(r: dict):
    """(title, figure lines) for mission.png."""
    def pct(v):
        return "n/a" if v is None else f"{v:.1f} %"

    title = f"Seed {r['seed']} on {r['world']}: {r['end_reason']} at {r['time_s']:.0f} s"
    lines = [f"mapped {pct(r['mapped_pct'])}   fidelity {pct(r['fidelity_pct'])}   located "
             f"{'n/a' if r['located'] is None else r['located']}/{r['samples']}   collected "
             f"{r['collected']}/{r['samples']}   home {'yes' if r['returned_home'] else 'no'}",
             f"stuck {r['stuck_time_s']:.0f} s (longest {r['longest_stuck_s']:.0f} s)   driven "
             f"{r['distance_m']:.0f} m   {MODE_NAMES.get(r['mode'], r['mode'])}, {timing_label(r)}, shadows "
             f"{'on' if r.get('shadows') else 'off'}"
             + (f", home by {r['home_by_s']:.0f} s" if r.get("home_by_s") else "")]
    return title, lines


# ----------------------------------------------------------------------------- in-process
def _video_writer(path, fps):
    import cv2

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (480, 160))
    if not writer.isOpened():
        raise ValueError(f"cannot open video writer for {path}")
    return writer


def _video_frame(rgb, worldmap):
    import cv2

    cam = np.zeros((160, 320, 3), np.uint8) if rgb is None else rgb[:, :, ::-1]
    mp = np.zeros((200, 200, 3), np.uint8) if worldmap is None else worldmap[::-1, :, ::-1]
    mp = cv2.resize(np.ascontiguousarray(mp), (160, 160), interpolation=cv2.INTER_NEAREST)
    return np.ascontiguousarray(np.hstack([cam, mp]))


class FixedTurnCount:
    """The fixed_turn commands a client sent: how many, and their degrees in all."""

    def __init__(self):
        self.count, self.degrees = 0, 0.0

    def add(self, event, payload) -> None:
        if event != "fixed_turn":
            return
        self.count += 1
        try:
            self.degrees += abs(float(payload["angle"]))
        except (TypeError, ValueError, KeyError):
            pass


def telemetry_period_s(timing: Timing) -> float:
    """Simulated seconds between telemetries with a client that answers each in reply_delay_s."""
    if not timing.unity:
        from sim.timing import LOCKSTEP_FRAME_S

        return LOCKSTEP_FRAME_S
    return frame_time(frame_after(timing.reply_delay_s, timing.fps), timing.fps)


def run_inprocess(world, seed, time_limit=TIME_LIMIT_S, video=None, record=None, progress=True,
                  render=True, client_factory=None, home_by=None, watchers=(), timing: Timing | None = None):
    """Drive `AutonomyClient` against `RoverTwin` in this process; returns the summary dict.

    timing: the loop (default Timing(): the real simulator's, on a virtual clock).
    client_factory(clock) builds the client; `clock` is what it must read as its wall clock.
    watchers: objects with ``observe(client, event, force=False)`` called after every reply
    (the dashboard and the viewer's timeline), and once more with force=True at the end.
    """
    from sim.twin import CommandError, RoverTwin

    timing = timing or Timing()
    if client_factory is None:
        from autonomy import AutonomyClient

        def client_factory(clock):
            return AutonomyClient(ground_truth=world.nav_truth, insets=False, home_by_s=home_by, clock=clock)
    twin = RoverTwin(world, seed=seed, render=render)
    loop = TwinLoop(twin, timing)
    client = client_factory(loop.clock)
    tel = loop.reset(seed)
    recorder = open_recorder(record)
    writer = _video_writer(video, 1.0 / telemetry_period_s(timing)) if video else None
    track = TruthTrack(twin)
    end_reason, completed = "time limit", False
    bar = progress_bar(time_limit, progress, f"seed {seed}")
    turns = FixedTurnCount()
    t_wall = time.perf_counter()
    try:
        while twin.sim_time < time_limit:
            if recorder is not None:
                recorder.write_twin(twin)
            event, payload = client.handle_telemetry(tel)
            turns.add(event, payload)
            for watcher in watchers:
                watcher.observe(client, event)
            try:
                tel, dt = loop.step(event, payload)
            except CommandError as exc:  # the real simulator would stall here
                end_reason = f"stalled: {exc}"
                log.warning("client sent a command the simulator cannot parse: %s", exc)
                break
            track.update(twin, dt)
            if writer is not None:
                writer.write(_video_frame(twin.last_rgb, client.rover.worldmap))
            bar.update(dt)
            if getattr(client.rover, "mission_complete", False):
                end_reason, completed = "mission complete", True
                break
    except BaseException as exc:  # Ctrl-C (also wrapped by a numba kernel): stop here, the caller writes what we have
        if not caused_by_interrupt(exc):
            raise
        end_reason = INTERRUPTED
        log.warning("Ctrl-C at %.0f s simulated: writing the partial mission", twin.sim_time)
    finally:
        for watcher in watchers:
            watcher.observe(client, None, force=True)
        bar.close()
        if writer is not None:
            writer.release()
        if recorder is not None:
            recorder.close()
    wall = time.perf_counter() - t_wall
    return dict(twin=twin, stuck=track.stuck, traj=track.traj, distance=track.distance, wall=wall,
                end_reason=end_reason, completed=completed,
                worldmap=np.array(client.rover.worldmap, copy=True),
                rejected=twin.rejected_commands, timing=timing,
                fixed_turns=turns.count, fixed_turn_deg=round(turns.degrees, 1),
                fixed_turns_refused=getattr(getattr(client.rover, "nav", None), "fixed_refused", None),
                reused_frames=twin.reused_frames,
                reply_delay_ms=round(1e3 * statistics.median(loop.delays), 1) if loop.delays else None)


# ----------------------------------------------------------------------------- scoring
def score(world, seed, mode, summary, time_limit) -> MissionResult:
    from evaluation.metrics import score_map

    twin = summary["twin"]
    tr = twin.truth
    samples_xy = [(s.x, s.y) for s in tr.initial_samples]
    worldmap = summary.get("worldmap")
    if worldmap is not None:
        ms = score_map(worldmap, world.nav_truth, samples_xy)
        mapped, fidelity, located = ms.mapped_pct, ms.fidelity_pct, ms.located
    else:
        mapped = fidelity = located = None
    home = math.hypot(tr.x - tr.start_xy[0], tr.y - tr.start_xy[1])
    all_collected = len(tr.collected) == len(tr.initial_samples) and len(tr.initial_samples) > 0
    wall = summary["wall"]
    timing = summary.get("timing") or Timing()
    period = tr.sim_time / tr.frame if tr.frame else None
    return MissionResult(
        seed=seed, world=world.name, mode=mode, mapped_pct=mapped, fidelity_pct=fidelity,
        located=located, collected=len(tr.collected), samples=len(tr.initial_samples),
        returned_home=bool(all_collected and home <= HOME_RADIUS_M), completed=summary["completed"],
        end_reason=summary["end_reason"], time_s=round(tr.sim_time, 3),
        stuck_time_s=round(summary["stuck"].total_s, 2), longest_stuck_s=round(summary["stuck"].longest_s, 2),
        frames=tr.frame, distance_m=round(summary["distance"], 2),
        final_distance_to_start_m=round(home, 2), wall_s=round(wall, 2),
        frames_per_s=round(tr.frame / wall, 1) if wall > 0 else float("nan"),
        rejected_commands=summary["rejected"], stuck_stretches=list(summary["stuck"].stretches),
        shadows=bool(world.cast_shadows), **timing.describe(),
        telemetry_hz=round(1.0 / period, 2) if period else None,
        reply_delay_ms=summary.get("reply_delay_ms"), round_trip_ms=summary.get("round_trip_ms"),
        fixed_turns=summary.get("fixed_turns"), fixed_turn_deg=summary.get("fixed_turn_deg"),
        fixed_turns_refused=summary.get("fixed_turns_refused"), reused_frames=summary.get("reused_frames"),
        render_fps=round(summary["render_frames"] / tr.sim_time, 1) if summary.get("render_frames") and tr.sim_time
        else None)


def run_mission(seed=0, world="default", time_limit=TIME_LIMIT_S, out=None, video=None, record=None,
                wire=False, progress=True, render=True, write_files=True, home_by=None, dashboard=None,
                dashboard_port=None, timing: Timing | None = None, watchers=()) -> dict:
    """Run, score and (optionally) write mission.json + mission.png; returns the result dict.

    home_by: the client's return deadline, s (None: its default, decision.HOME_BY_S).
    dashboard: a live dashboard (in-process missions) fed every frame; dashboard_port: with
    ``wire``, drive_rover.py serves the dashboard itself on this port.
    timing: the simulator loop (default Timing(): the real simulator's at 30 fps).
    watchers: more per-frame observers for in-process missions (e.g. sim.evaluate's progress meter).
    """
    timing = timing or Timing()
    from sim.world import World, load_world

    world_obj = world if isinstance(world, World) else load_world(world)
    if wire:
        from sim.wire import run_wire_mission

        client_args = ["--dashboard", "--dashboard-port", str(dashboard_port)] if dashboard_port else []
        summary = run_wire_mission(world_obj, seed, time_limit=time_limit, record=record,
                                   progress=progress, render=render, home_by=home_by, client_args=client_args,
                                   timing=timing)
        mode = "wire"
    else:
        from dashboard.timeline import Timeline

        timeline = Timeline() if write_files else None
        watchers = [w for w in (timeline, dashboard, *watchers) if w is not None]
        summary = run_inprocess(world_obj, seed, time_limit=time_limit, video=video, record=record,
                                progress=progress, render=render, home_by=home_by, watchers=watchers,
                                timing=timing)
        summary["timeline"] = timeline
        mode = "inprocess"
    return finish_mission(world_obj, seed, mode, summary, time_limit, out=out, write_files=write_files,
                          home_by=home_by, video=video, record=record)


def finish_mission(world_obj, seed, mode, summary, time_limit, out=None, write_files=True, home_by=None,
                   video=None, record=None) -> dict:
    """Score a finished run's summary and (optionally) write mission.json/.png and worldmap.npy.

    Shared by every way of running a mission (in-process, wire, a third-party client).
    """
    summary["stuck"].close_run()
    result = score(world_obj, seed, mode, summary, time_limit)
    result.home_by_s = home_by
    result.time_limit_s = time_limit
    result.code_version = code_version()
    if write_files:
        out = Path(out) if out else Path(DEFAULT_OUT_ROOT) / f"mission-seed{seed}"
        tr = summary["twin"].truth
        img = mission_image(world_obj, summary.get("worldmap"), summary["traj"],
                            [(s.x, s.y) for s in tr.initial_samples],
                            [(s.x, s.y) for s in tr.collected], tr.start_xy,
                            [(st[1], st[2]) for st in result.stuck_stretches], result)
        write_png_atomic(out / "mission.png", img)
        result.files = {"json": str(out / "mission.json"), "png": str(out / "mission.png")}
        if summary.get("worldmap") is not None:
            write_npy_atomic(out / "worldmap.npy", summary["worldmap"])
            result.files["worldmap"] = str(out / "worldmap.npy")
        if summary.get("timeline") is not None:  # the finished-mission viewer's story (python -m dashboard)
            result.files["timeline"] = str(summary["timeline"].save(out / "timeline.npz"))
        if video:
            result.files["video"] = str(video)
        if record:
            result.files["record"] = str(record)
        write_json_atomic(out / "mission.json", result.as_dict())
    return result.as_dict()


def code_version() -> str:
    """``git describe --always --dirty`` of this checkout, or the source hash outside git."""
    import subprocess

    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=Path(__file__).resolve().parent,
                             capture_output=True, text=True, timeout=10)
        if out.returncode == 0 and out.stdout.strip():
            return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    from sim.backend import code_fingerprint

    return "source " + code_fingerprint()


def format_result(r: dict) -> str:
    def f(v, fmt="{:.1f}%"):
        return "n/a" if v is None else fmt.format(v)

    shadows = ", shadows on" if r.get("shadows", False) else ""
    return (f"seed {r['seed']} [{r['world']}, {r['mode']}{shadows}, {timing_label(r)}]: mapped {f(r['mapped_pct'])}, "
            f"fidelity {f(r['fidelity_pct'])}, located {f(r['located'], '{}')}/{r['samples']}, "
            f"collected {r['collected']}/{r['samples']}, home {'yes' if r['returned_home'] else 'no'}, "
            f"time {r['time_s']:.0f} s ({r['end_reason']}), stuck {r['stuck_time_s']:.0f} s "
            f"(longest {r['longest_stuck_s']:.0f} s), {r['frames']} telemetry frames "
            f"({f(r.get('telemetry_hz'), '{:.1f}')} per sim s, {f(r['frames_per_s'], '{:.1f}')} per wall s)")


def timing_label(r: dict) -> str:
    """'unity 30 fps, 4 ms latency' or 'lockstep (easier)' from a result or evaluation meta dict."""
    if r.get("timing", "unity") == "lockstep":
        return "lockstep (easier than the real simulator)"
    default = Timing()  # a result that names no parameters ran the defaults
    fps = r.get("fps") if r.get("fps") is not None else default.fps
    latency = r.get("latency_ms") if r.get("latency_ms") is not None else default.latency_ms
    return f"unity {fps:g} fps, {latency:g} ms latency"


def main(argv=None) -> int:
    p = tool_parser("python -m sim.mission", "Run one autonomous mission on the digital twin and score it "
                    "(mission.json, mission.png, worldmap.npy, timeline.npz in --out).")
    p.add_argument("--seed", type=seed_number, default=0, help="scene seed >= 0: start yaw and samples (default 0)")
    p.add_argument("--world", default="default", help="real | procedural:K | PATH.png (default: real if present)")
    p.add_argument("--time-limit", type=positive_number, default=TIME_LIMIT_S, metavar="SECONDS",
                   help="simulated seconds before the mission is stopped (default %(default).0f)")
    p.add_argument("--out", default=None, help="output folder (default out/mission-seedN)")
    p.add_argument("--video", default=None, help="write camera + map video (mp4)")
    p.add_argument("--record", default=None, help="record a simulator-format log (robot_log.csv + IMG)")
    p.add_argument("--wire", action="store_true", help="run drive_rover.py and talk the real wire protocol")
    add_home_by_option(p)
    add_shadows_option(p)
    add_dashboard_options(p)
    add_timing_options(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    a = parse_with_logging(p, argv)
    a.out = a.out or str(Path(DEFAULT_OUT_ROOT) / f"mission-seed{a.seed}")
    check_paths(p, a, folders=("--out", "--record"), files=("--video",))
    try:
        timing = timing_from_args(a)
    except ValueError as exc:
        p.error(str(exc))
    try:
        from sim.world import load_world, with_shadows

        world = with_shadows(load_world(a.world), a.shadows == "on")
    except (ValueError, FileNotFoundError) as exc:
        p.error(f"--world: {exc}")
    log.info("timing: %s", timing.label())
    dash = None
    if a.dashboard and not a.wire:
        from dashboard import LiveDashboard

        try:
            dash = LiveDashboard(a.dashboard_port, title=f"seed {a.seed} on the twin").start()
        except OSError as exc:
            p.error(f"--dashboard-port: {exc}")
    elif a.dashboard:  # drive_rover.py serves it; check the port here so the error comes first
        from dashboard.server import port_problem
        from sim.wire import free_port

        a.dashboard_port = a.dashboard_port or free_port()
        problem = port_problem("127.0.0.1", a.dashboard_port)
        if problem:
            p.error(f"--dashboard-port: {problem}")
        log.info("dashboard (served by drive_rover.py): open http://127.0.0.1:%d/ in a browser", a.dashboard_port)
    from tqdm.contrib.logging import logging_redirect_tqdm

    try:
        with logging_redirect_tqdm():  # log lines print above the progress bar instead of through it
            r = run_mission(a.seed, world, a.time_limit, a.out, a.video, a.record, a.wire,
                            progress=not a.no_progress, home_by=a.home_by, dashboard=dash, timing=timing,
                            dashboard_port=a.dashboard_port if a.dashboard and a.wire else None)
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 1
    except KeyboardInterrupt:  # before the mission loop started or while writing: nothing (more) to save
        log.warning("interrupted before the mission could be written")
        return INTERRUPTED_EXIT
    log.info("%s", format_result(r))
    log.info("wrote %s", ", ".join(r["files"].values()))
    if r["end_reason"] == INTERRUPTED:
        log.warning("interrupted: the files above hold the mission up to %.0f s", r["time_s"])
        return INTERRUPTED_EXIT
    if dash is not None:
        _keep_showing(dash, r)
    return 0


def _keep_showing(dash, result):
    """After a --dashboard mission the page turns into the finished-mission viewer until Ctrl-C."""
    from dashboard.viewer import MissionSource

    folder = Path(result["files"]["json"]).parent
    try:
        dash.server.show(MissionSource(folder, result["files"].get("record")))
        log.info("mission over: %s now scrubs through it; Ctrl-C to quit", dash.url)
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        dash.close()


if __name__ == "__main__":
    raise SystemExit(main())
