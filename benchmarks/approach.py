"""Sample approach from any side: the client dropped near a hard sample spot, collected or not.

    python -m benchmarks.approach [--spot east-nook|sw-pocket|north-tip|X,Y,B,R] [--radii 4,6,8]
                                  [--step-deg 15] [--shadows off,on] [--time-limit 150] [--jobs 2]
                                  [--out DIR]

Whole missions reach a hard spot (the east nook between two rocks, the hub's south-west pocket,
the north arm's tip) in one or two ways per seed, so twenty seeds try its approach a handful of
times. Here a fresh client (empty map) is first shown the sample for a second from a stand where the
camera sees it, as a mission's rover has seen a sample it goes for. The body is then moved to a start
on true floor at each radius and bearing around the spot, facing the spot and facing away, in the real
world with that one sample, under Unity timing at 30 fps (no sim_time). A start counts as collected when the twin's arm picks
up that sample within --time-limit simulated seconds. Printed: collected / starts per shadow
setting and radius, median and worst time to collect, stuck time, and the starts that failed.
The figure to compare is the collected share; a change to the approach is measured by running
this before and after it (the spots are the issue's named places; no seed of the evaluation is
involved). Written: approach.json and approach.png (start points coloured by outcome) in --out.
"""
import argparse
import logging
import math
import statistics
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

log = logging.getLogger("benchmarks.approach")

SPOTS = {  # named hard sample spots of the real world (world/ sample spots), x, y m
    "east-nook": (148.8, 109.6),  # between two rocks, open to the north-west only
    "sw-pocket": (76.2, 71.4),  # the hub's south-west pocket, seen from 60-75 deg only
    "north-tip": (103.8, 192.7),  # the north arm's end
}
DEFAULT_RADII_M = (4.0, 6.0, 8.0)  # start distances from the spot, m
START_MIN_FLOOR_CELLS = 7  # a start's 3x3 cells must hold this many true floor cells (room for the body), cells
DEFAULT_STEP_DEG = 15.0  # bearing spacing of the starts around the spot, degrees
DEFAULT_TIME_LIMIT_S = 150.0  # simulated seconds a start gets to collect the sample, s
VIEWS = {  # where each spot's sample shows in the camera: (bearing from the spot deg, range m)
    "east-nook": (165.0, 3.0),
    "sw-pocket": (60.0, 3.0),
    "north-tip": (270.0, 3.0),
}
VIEW_S = 1.0  # simulated seconds the client is shown the sample before the start, s
MOVE_GAP_S = 4.0  # simulated seconds without telemetry while the body moves to its start (the client's teleport check allows 5 m/s), s
BRAKE_COMMAND = {"throttle": "0", "brake": "1", "steering_angle": "0"}  # what the twin is told during that gap
SPOT_MATCH_M = 1.0  # a world sample spot this close to the asked spot is the one used, m
PICKED_MATCH_M = 0.5  # a collected sample this close to the spot is the spot's, m


def _starts(world, spot, radii, step_deg):
    """(x, y, yaw) starts on true floor around the spot: facing it and facing away."""
    sx, sy = spot
    truth = world.nav_truth > 0
    out = []
    for r in radii:
        for b in np.arange(0.0, 360.0, step_deg):
            x, y = sx + r * math.cos(math.radians(b)), sy + r * math.sin(math.radians(b))
            col, row = int(math.floor(x)), int(math.floor(y))
            if not (0 <= row < truth.shape[0] and 0 <= col < truth.shape[1]) or not truth[row, col]:
                continue
            if truth[max(row - 1, 0):row + 2, max(col - 1, 0):col + 2].sum() < START_MIN_FLOOR_CELLS:
                continue  # not on a wall foot: the rover's body must fit
            toward = math.degrees(math.atan2(sy - y, sx - x)) % 360.0
            out.extend([(r, float(b), x, y, toward, "toward"), (r, float(b), x, y, (toward + 180.0) % 360.0, "away")])
    return out


def _place_sample(twin, spot):
    """Keep one sample, the one at the spot (the world's own sample spot nearest to it)."""
    from sim.samples import spawn_samples

    spots = np.asarray(twin.world.sample_spots, float)
    k = int(np.argmin(np.hypot(spots[:, 0] - spot[0], spots[:, 1] - spot[1])))
    if math.hypot(spots[k, 0] - spot[0], spots[k, 1] - spot[1]) > SPOT_MATCH_M:
        raise ValueError(f"no sample spot of the world within {SPOT_MATCH_M} m of {spot}")
    placed = spawn_samples(spots[k:k + 1], np.random.default_rng(0), count=1)
    twin.samples = list(placed)
    twin.initial_samples = list(placed)
    return float(spots[k, 0]), float(spots[k, 1])


def run_start(args):
    """One start -> dict(outcome); runs in a worker process."""
    start, spot, view, shadows, time_limit = args
    from autonomy import AutonomyClient
    from sim.mission_parts import StuckMeter
    from sim.physics import RoverPhysics
    from sim.timing import Timing, TwinLoop
    from sim.twin import RoverTwin

    r, bearing, x, y, yaw, facing = start
    world = _real_world(shadows)
    twin = RoverTwin(world, seed=0)
    loop = TwinLoop(twin, Timing())
    loop.reset(0)
    spot_xy = _place_sample(twin, spot)
    client = AutonomyClient(ground_truth=world.nav_truth, insets=False, clock=loop.clock)
    _show_sample(client, loop, world, spot_xy, view)
    gap_end = twin.sim_time + MOVE_GAP_S  # the client hears nothing while the body is moved to the start
    while twin.sim_time < gap_end:
        twin.physics = RoverPhysics(world, x, y, yaw)
        tel, _dt = loop.step("data", BRAKE_COMMAND)
    twin.physics = RoverPhysics(world, x, y, yaw)
    tel = twin.telemetry()
    time_limit += twin.sim_time
    t_start = twin.sim_time
    meter, collected_at = StuckMeter(), None
    while twin.sim_time < time_limit:
        event, payload = client.handle_telemetry(tel)
        tel, dt = loop.step(event, payload)
        st = twin.physics.state
        meter.update(twin.sim_time, dt, st.x, st.y, st.v, twin.controls.throttle, twin.arm.active)
        if any(math.hypot(c[0] - spot_xy[0], c[1] - spot_xy[1]) < PICKED_MATCH_M for c in _collected_xy(twin)):
            collected_at = twin.sim_time - t_start
            break
    st = twin.physics.state
    return dict(radius_m=r, bearing_deg=bearing, x=round(x, 2), y=round(y, 2), yaw=round(yaw, 1), facing=facing,
                shadows=shadows, collected=collected_at is not None,
                time_s=None if collected_at is None else round(collected_at, 1), stuck_s=round(meter.total_s, 1),
                end=(round(float(st.x), 1), round(float(st.y), 1)))


def _real_world(shadows):
    """The real world with shadows "on" or "off", loaded once per worker process (sim.backend's cache)."""
    from sim.backend import cached_world

    return cached_world("real", shadows == "on")


def _show_sample(client, loop, world, spot_xy, view):
    """Let the client see the sample first, as a mission's rover has when it turns to fetch it: the rover is
    held still at the view stand (view = (bearing deg, range m) from the spot), facing the spot, for
    VIEW_S; its replies are answered but the body is put back each frame."""
    from sim.physics import RoverPhysics

    bearing, rng = view
    vx = spot_xy[0] + rng * math.cos(math.radians(bearing))
    vy = spot_xy[1] + rng * math.sin(math.radians(bearing))
    yaw = (bearing + 180.0) % 360.0
    twin = loop.twin
    start = twin.sim_time
    while twin.sim_time - start < VIEW_S:
        twin.physics = RoverPhysics(world, vx, vy, yaw)
        event, payload = client.handle_telemetry(twin.telemetry())
        loop.step(event, payload)


def _collected_xy(twin):
    return [(float(c.x), float(c.y)) for c in twin.arm.collected]


def _parse_spot(text):
    """A named spot -> ((x, y), view), or X,Y,VIEW_BEARING,VIEW_RANGE."""
    if text in SPOTS:
        return SPOTS[text], VIEWS[text]
    try:
        x, y, b, r = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"spot must be one of {sorted(SPOTS)} or X,Y,VIEW_BEARING,VIEW_RANGE, "
                                         f"not {text!r}") from None
    return (x, y), (b, r)


def _parse_floats(text):
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, not {text!r}") from None


def summarise(rows):
    """Lines of the printed table: per shadow setting and radius."""
    lines = []
    for shadows in sorted({r["shadows"] for r in rows}):
        for radius in sorted({r["radius_m"] for r in rows}):
            sel = [r for r in rows if r["shadows"] == shadows and r["radius_m"] == radius]
            if not sel:
                continue
            times = [r["time_s"] for r in sel if r["collected"]]
            lines.append(f"shadows {shadows:3s} r={radius:4.1f} m: collected {len(times)}/{len(sel)}"
                         + (f", time median {statistics.median(times):.1f} s, worst {max(times):.1f} s" if times else "")
                         + f", stuck median {statistics.median(r['stuck_s'] for r in sel):.1f} s")
    failed = [r for r in rows if not r["collected"]]
    for r in failed:
        lines.append(f"  not collected: shadows {r['shadows']} r={r['radius_m']} bearing {r['bearing_deg']:.0f} "
                     f"facing {r['facing']} (start {r['x']}, {r['y']}; ended at {r['end']})")
    total = sum(r["collected"] for r in rows)
    lines.append(f"collected {total}/{len(rows)} starts")
    return lines


def draw(rows, spot, path, world):
    """Start points around the spot over the true floor (grey) and the rocks (brown): green when every run from
    there collected, orange when some did, red when none; the spot is the yellow ring."""
    import cv2

    scale, half, legend_px = 32, 9.0, 28
    n = int(2 * half * scale)
    x0, y1 = spot[0] - half, spot[1] + half
    xs = (np.arange(n) + 0.5) / scale + x0
    ys = y1 - (np.arange(n) + 0.5) / scale
    truth = world.nav_truth[np.clip(ys.astype(int), 0, 199)[:, None], np.clip(xs.astype(int), 0, 199)[None, :]] > 0
    rock_rows = np.clip((ys / world.rock_cell_m).astype(int), 0, world.rock_top.shape[0] - 1)
    rock_cols = np.clip((xs / world.rock_cell_m).astype(int), 0, world.rock_top.shape[1] - 1)
    rock = world.rock_top[rock_rows[:, None], rock_cols[None, :]] > 0
    img = np.full((n + legend_px, n, 3), 25, np.uint8)
    img[:n][truth] = (95, 95, 95)
    img[:n][rock] = (40, 70, 120)

    def px(x, y):
        return int(round((x - x0) * scale)), int(round((y1 - y) * scale))

    cv2.circle(img, px(*spot), 7, (0, 215, 255), 2)
    by_start = {}
    for r in rows:
        by_start.setdefault((r["x"], r["y"]), []).append(r["collected"])
    for (x, y), outcomes in by_start.items():
        share = sum(outcomes) / len(outcomes)
        colour = (60, 200, 60) if share == 1 else ((0, 140, 255) if share > 0 else (50, 50, 230))
        cv2.circle(img, px(x, y), 5, colour, -1)
    cv2.putText(img, "start: green all collected, orange some, red none; ring = sample; brown = rock",
                (6, n + 19), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (230, 230, 230), 1, cv2.LINE_AA)
    cv2.imwrite(str(path), img)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spot", type=_parse_spot, default="east-nook",
                    help="named spot or X,Y,VIEW_BEARING,VIEW_RANGE: the sample and where it shows from (default east-nook)")
    ap.add_argument("--radii", type=_parse_floats, default=DEFAULT_RADII_M, help="start distances, m (default 4,6,8)")
    ap.add_argument("--step-deg", type=float, default=DEFAULT_STEP_DEG, help="bearing spacing, degrees (default 15)")
    ap.add_argument("--shadows", default="off,on", help="off, on or off,on (default)")
    ap.add_argument("--time-limit", type=float, default=DEFAULT_TIME_LIMIT_S, help="simulated s per start (default 150)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--out", type=Path, default=None, help="folder for approach.json and approach.png")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    log.setLevel(logging.INFO)
    from sim.world import load_world

    world = load_world("real")
    shadows = [s for s in args.shadows.split(",") if s in ("on", "off")]
    if not shadows or args.jobs < 1 or args.time_limit <= 0:
        ap.error("--shadows needs on and/or off; --jobs >= 1; --time-limit > 0")
    spot, view = args.spot
    starts = _starts(world, spot, args.radii, args.step_deg)
    if not starts:
        ap.error(f"no start on true floor around {spot}")
    tasks = [(s, spot, view, sh, args.time_limit) for sh in shadows for s in starts]
    log.info("%d starts around (%.1f, %.1f), %d worker(s)", len(tasks), *spot, args.jobs)
    from sim.mission_parts import progress_bar

    bar = progress_bar(len(tasks), True, "starts")
    rows = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for row in pool.map(run_start, tasks):
            rows.append(row)
            bar.update(1)
    bar.close()
    for line in summarise(rows):
        print(line)
    if args.out is not None:
        from sim.mission_parts import write_json_atomic

        args.out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.out / "approach.json", dict(spot=list(spot), view=list(view), rows=rows))
        draw(rows, spot, args.out / "approach.png", world)
        log.info("wrote %s", args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
