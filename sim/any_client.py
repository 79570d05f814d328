"""A mission for any starter-style client: its own process, the real wire protocol, real time.

`run_client_mission(world, seed, "PATH/drive_rover.py")` starts the client,
unchanged, through `sim/client_hook.py` (numpy/matplotlib shims, its server
moved to a free port, its `RoverState.worldmap` snapshotted to a file), and
drives it from `sim.wire.WireSimulator` in real-time mode: the twin's clock
runs with the wall clock whatever the client does, as Unity's does, because
such clients time themselves with `time.time()`.  Truth metrics (collected,
home, time, stuck, distance) always come from the twin; mapped / fidelity /
located are scored when a worldmap snapshot could be read.
"""
from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

HOOK_PATH = Path(__file__).resolve().parent / "client_hook.py"  # the bootstrap run in the client's process
CLIENT_START_TIMEOUT_S = 60.0  # wall s for the client to start listening
SNAPSHOT_EVERY_S = 1.0  # wall s between the client's worldmap snapshots
LOG_TAIL_BYTES = 64_000  # the last this-many bytes of the client's output kept as client.log
HOME_STILL_S = 2.0  # s stopped at home with every sample = done (as sim.wire's wire missions)
STALL_TIMEOUT_S = 30.0  # wall s without a command from the client before the mission gives up


def _client_env(port, map_path, truth_png):
    env = dict(os.environ, PYTHONUNBUFFERED="1", MPLBACKEND="Agg")
    env.update({"ROVER_HOOK_PORT": str(port), "ROVER_HOOK_MAP": map_path,
                "ROVER_HOOK_GROUND_TRUTH": truth_png, "ROVER_HOOK_SNAPSHOT_S": str(SNAPSHOT_EVERY_S)})
    env.pop("PYTHONPATH", None)  # the client's own folder, not the project's, decides what it imports
    return env


def launch(client_path, port, workdir, nav_truth):
    """Start `client_path` under the hook; returns (Popen, worldmap snapshot path, log path)."""
    import cv2

    client_path = Path(client_path).resolve()
    if not client_path.is_file():
        raise FileNotFoundError(f"client not found: {client_path}")
    truth_png = os.path.join(workdir, "map_bw.png")
    cv2.imwrite(truth_png, np.where(np.asarray(nav_truth) > 0, 255, 0).astype(np.uint8))
    map_path = os.path.join(workdir, "worldmap.npy")
    log_path = os.path.join(workdir, "client.log")
    with open(log_path, "ab") as out:
        proc = subprocess.Popen([sys.executable, str(HOOK_PATH), str(client_path)], cwd=str(client_path.parent),
                                stdout=out, stderr=subprocess.STDOUT, env=_client_env(port, map_path, truth_png))
    return proc, map_path, log_path


def read_worldmap(path):
    """The client's snapshot as the scorer's uint8 (200, 200, 3) map: any positive value counts (starter rule)."""
    try:
        m = np.load(path)
    except (OSError, ValueError, EOFError):
        return None
    if m.ndim != 3 or m.shape[:2] != (200, 200) or m.shape[2] < 3:
        log.warning("client worldmap has shape %s, not (200, 200, 3); not scored", m.shape)
        return None
    m = np.nan_to_num(np.asarray(m[:, :, :3], np.float64), nan=0.0)
    return np.where(m > 0, 255, 0).astype(np.uint8)


def _log_tail(path) -> bytes:
    try:
        with open(path, "rb") as fh:
            fh.seek(max(0, os.path.getsize(path) - LOG_TAIL_BYTES))
            return fh.read()
    except OSError:
        return b""


def run_client_summary(world, seed, client_path, time_limit=900.0, progress=True, fps=None):
    """Run the mission; returns the summary dict sim.mission.finish_mission scores (+ "client_log" bytes)."""
    from sim.timing import Timing
    from sim.twin import RoverTwin
    from sim.wire import DEFAULT_FPS, WireMissionWatch, WireSimulator, free_port, stop_process, wait_for_port

    twin = RoverTwin(world, seed=seed)  # no sim_time: such clients time themselves
    port = free_port()
    workdir = tempfile.mkdtemp(prefix="twin-any-client-")
    watch = WireMissionWatch(twin, time_limit, progress, f"seed {seed} ({Path(client_path).name})",
                             home_still_s=HOME_STILL_S, stall_timeout_s=STALL_TIMEOUT_S)
    track, bar = watch.track, watch.bar
    proc = None
    wire = WireSimulator(twin, port=port, mode="realtime", fps=fps or DEFAULT_FPS, on_frame=watch.on_frame,
                        should_stop=watch.should_stop)
    watch.wire = wire
    t0 = time.perf_counter()
    try:
        proc, map_path, log_path = launch(client_path, port, workdir, world.nav_truth)
        watch.proc = proc
        if not wait_for_port(port, proc, timeout=CLIENT_START_TIMEOUT_S):
            tail = _log_tail(log_path).decode("utf-8", "replace")[-2000:]
            raise RuntimeError(f"{client_path} did not listen on port {port} (exit {proc.poll()}):\n{tail}")
        wire.last_command_wall = time.monotonic()
        wire.run()
    finally:
        bar.close()
        stop_process(proc)  # SIGTERM: the hook writes a last worldmap snapshot first
        worldmap = read_worldmap(os.path.join(workdir, "worldmap.npy"))
        client_log = _log_tail(os.path.join(workdir, "client.log"))
        shutil.rmtree(workdir, ignore_errors=True)  # our own temp folder
    if worldmap is None:
        log.info("no readable worldmap from %s: mapped/fidelity not scored", client_path)
    return dict(twin=twin, stuck=track.stuck, traj=track.traj, distance=track.distance,
                wall=time.perf_counter() - t0, end_reason=watch.end, completed=watch.completed,
                worldmap=worldmap, rejected=wire.rejected, client_log=client_log, commands=wire.commands,
                timing=Timing(fps=fps or DEFAULT_FPS))


def run_client_mission(world, seed, client_path, time_limit=900.0, out=None, progress=True, write_files=True,
                       fps=None) -> dict:
    """Run, score and (optionally) write mission.json/.png/worldmap.npy + client.log; returns the result dict."""
    from sim.mission import finish_mission

    summary = run_client_summary(world, seed, client_path, time_limit=time_limit, progress=progress, fps=fps)
    result = finish_mission(world, seed, "client", summary, time_limit, out=out, write_files=write_files)
    result["client"] = str(Path(client_path).resolve())
    result["client_commands"] = summary["commands"]
    if write_files and out:
        from sim.mission import write_json_atomic

        path = Path(out) / "client.log"
        tmp = path.with_name(".client.log.tmp")
        tmp.write_bytes(summary["client_log"])
        os.replace(tmp, path)
        result["files"]["client_log"] = str(path)
        write_json_atomic(Path(out) / "mission.json", result)
    return result
