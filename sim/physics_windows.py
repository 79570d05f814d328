"""Does the twin's physics move like the real rover?  Open-loop 2 s windows of a real log.

From a logged state (pose and speed), the logged commands are re-applied for 2 s at the
0.02 s physics step; the twin's speed, yaw and position are then compared with the log
2 s later.  Windows start every `--every` rows.  Used by tests/test_physics.py and as a
CLI that prints the medians (the contact-model acceptance numbers are these medians on
megalphian and royalejandro, which the physics was not fitted on for contact):

    python -m sim.physics_windows [--log megalphian] [--every 50] [--out out/physics-windows]

NAME may be a folder under ../shared/real-logs, `test_dataset`, or a path to a log.
"""
from __future__ import annotations

import argparse
import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import shared_data
from sim import physics as P
from sim.logs import find_log

log = logging.getLogger(__name__)

WINDOW_S = 2.0  # s, length of one open-loop window
MAX_WINDOW_S = 2.3  # s, windows whose logged end lies later than this (recording gaps) are skipped
DEFAULT_EVERY = 50  # a window starts every N log rows
STAMP_RE = re.compile(r"(\d+)_(\d+)_(\d+)_(\d+)\.jpg$")  # robocam_..._HH_MM_SS_mmm.jpg


@dataclass
class WindowResult:
    t0: float  # s from the log start
    x0: float
    y0: float
    speed0: float  # m/s logged at the window start
    err_speed: float  # |twin - real| m/s at the end
    err_yaw: float  # deg
    err_pos: float  # m
    real_speed1: float  # m/s logged at the window end
    twin_speed1: float
    twin_collided: bool  # the twin touched something during the window
    twin_min_pitch: float  # deg, most nose-up twin pitch during the window
    real_min_pitch: float  # deg, most nose-up logged pitch during the window


def log_arrays(log_path) -> dict:
    """Time (s, from frame names) and telemetry columns of a log, in time order."""
    from replay.log_format import read_log

    data = read_log(log_path, require_images=False)
    rows = []
    for f in data.frames:
        m = STAMP_RE.search(f.image_path.name)
        if m is None:
            continue
        h, mi, s, ms = map(int, m.groups())
        rows.append((h * 3600 + mi * 60 + s + ms / 1000.0, f.steer, f.throttle, f.brake, f.speed,
                     f.x, f.y, f.yaw, f.pitch, f.roll))
    if len(rows) < 2:
        raise ValueError(f"{log_path}: fewer than two timestamped frames")
    a = np.array(rows, dtype=np.float64)
    a = a[np.argsort(a[:, 0], kind="stable")]
    keys = ("t", "steer", "throttle", "brake", "speed", "x", "y", "yaw", "pitch", "roll")
    out = {k: a[:, i] for i, k in enumerate(keys)}
    out["t"] = out["t"] - out["t"][0]
    out["pitch"] = (out["pitch"] + 180.0) % 360.0 - 180.0
    out["roll"] = (out["roll"] + 180.0) % 360.0 - 180.0
    return out


def replay_window(world, a: dict, i0: int, i1: int) -> WindowResult:
    """Run the twin from row i0's state with the logged commands until row i1's time."""
    t = a["t"]
    body = P.RoverPhysics(world, a["x"][i0], a["y"][i0], a["yaw"][i0])
    body.state.v = float(a["speed"][i0])
    sim_t = t[i0]
    collided, min_pitch = False, body.state.pitch
    for i in range(i0 + 1, i1 + 1):
        c = P.Controls(a["throttle"][i - 1], a["brake"][i - 1], a["steer"][i - 1])
        while sim_t < t[i] - 1e-9:
            body.step(c)
            sim_t += P.PHYSICS_DT
            collided |= body.state.collided
            min_pitch = min(min_pitch, body.state.pitch)
    s = body.state
    return WindowResult(
        t0=float(t[i0]), x0=float(a["x"][i0]), y0=float(a["y"][i0]), speed0=float(a["speed"][i0]),
        err_speed=float(abs(s.v - a["speed"][i1])),
        err_yaw=float(abs((s.yaw - a["yaw"][i1] + 180.0) % 360.0 - 180.0)),
        err_pos=float(np.hypot(s.x - a["x"][i1], s.y - a["y"][i1])),
        real_speed1=float(a["speed"][i1]), twin_speed1=float(s.v), twin_collided=bool(collided),
        twin_min_pitch=float(min_pitch), real_min_pitch=float(a["pitch"][i0:i1 + 1].min()))


def window_starts(a: dict, every: int = DEFAULT_EVERY):
    """(i0, i1) pairs: every `every`-th row, ending WINDOW_S later, skipping recording gaps."""
    t = a["t"]
    for i0 in range(0, len(t) - 1, max(1, int(every))):
        i1 = int(np.searchsorted(t, t[i0] + WINDOW_S))
        if i1 >= len(t) or t[i1] - t[i0] > MAX_WINDOW_S:
            continue
        yield i0, i1


def run_windows(world, log_path, every: int = DEFAULT_EVERY, progress: bool = False) -> list:
    a = log_arrays(log_path)
    pairs = list(window_starts(a, every))
    if progress:
        from tqdm import tqdm

        pairs = tqdm(pairs, desc="windows", unit="window")
    return [replay_window(world, a, i0, i1) for i0, i1 in pairs]


def summarise(results: list) -> dict:
    if not results:
        return {"windows": 0}
    ev = np.array([r.err_speed for r in results])
    ey = np.array([r.err_yaw for r in results])
    ep = np.array([r.err_pos for r in results])
    return {
        "windows": len(results),
        "speed_median": float(np.median(ev)), "speed_p90": float(np.percentile(ev, 90)),
        "yaw_median": float(np.median(ey)), "yaw_p90": float(np.percentile(ey, 90)),
        "pos_median": float(np.median(ep)), "pos_p90": float(np.percentile(ep, 90)),
        "pos_max": float(ep.max()),
    }


def main(argv=None) -> int:
    from sim.cli import parse_with_logging

    p = argparse.ArgumentParser(prog="python -m sim.physics_windows", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--log", action="append", help="log name or path (repeatable); default megalphian and royalejandro")
    p.add_argument("--every", type=int, default=DEFAULT_EVERY, help="a window starts every N rows")
    p.add_argument("--out", default="out/physics-windows", help="folder for metrics.json")
    a = parse_with_logging(p, argv)
    from sim.world import load_real_world, real_world_available

    if not real_world_available():
        log.error("the real world export is needed (set %s)", shared_data.SHARED_ENV_VAR)
        return 2
    world = load_real_world()
    names = a.log or ["megalphian", "royalejandro"]
    table = {}
    for name in names:
        try:
            path = find_log(name)
            table[name] = summarise(run_windows(world, path, a.every, progress=True))
        except (ValueError, FileNotFoundError) as exc:
            log.error("%s: %s", name, exc)
            return 2
    out = Path(a.out)
    from replay.outputs import write_json

    write_json(out / "metrics.json", {"every": a.every, "window_s": WINDOW_S, "logs": table})
    print(f"{'log':<14} {'windows':>7} {'speed m/s':>16} {'yaw deg':>14} {'position m':>14}")
    print(f"{'':<14} {'':>7} {'median   p90':>16} {'median  p90':>14} {'median  p90':>14}")
    for name, s in table.items():
        if not s.get("windows"):
            print(f"{name:<14} {0:>7}")
            continue
        print(f"{name:<14} {s['windows']:>7} {s['speed_median']:>8.3f} {s['speed_p90']:>6.2f} "
              f"{s['yaw_median']:>8.2f} {s['yaw_p90']:>5.1f} {s['pos_median']:>8.3f} {s['pos_p90']:>5.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
