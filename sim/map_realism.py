"""Does a map built from twin frames score like one built from the real frames?

A real recorded drive is replayed twice through the client's perception: once with
its own camera frames, once with twin frames rendered at the same logged poses.
The two worldmaps are scored against map_bw.png. Per-frame IoU (sim.realism) only
covers the start area; this covers the whole canyon, where the edge cells decide
the mapped figure, and it is how the missing shadows of some recordings showed up.

    python -m sim.map_realism [--log megalphian] [--stride 2] [--shadows on|off] [--out out/map-realism]
"""
from __future__ import annotations

import argparse
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import perception
import shared_data
from evaluation.metrics import load_ground_truth, score_map
from replay.log_format import LogFormatError, read_log, resolve_log_path
from replay.runner import FALLBACK_FRAME_PERIOD_S, apply_frame, decode_frame, signed_angle
from rover_state import RoverState
from sim.cli import add_shadows_option, parse_with_logging
from sim.render import Renderer
from sim.realism import jpeg_roundtrip

log = logging.getLogger(__name__)

DEFAULT_LOG = "megalphian"  # folder under ../shared/real-logs (or a path to a log folder)
DEFAULT_STRIDE = 2  # every N-th frame is used (both replays see the same frames)


@dataclass
class MapRealism:
    frames: int
    real_mapped_pct: float
    real_fidelity_pct: float
    twin_mapped_pct: float
    twin_fidelity_pct: float
    shadows: str

    @property
    def mapped_gap(self) -> float:
        """Twin minus real mapped %, points (negative: the twin is harder than the recording)."""
        return self.twin_mapped_pct - self.real_mapped_pct


def find_log(name_or_path) -> Path:
    """The robot_log.csv of a real-logs folder name, a log folder or a csv path (read_log's rule)."""
    p = Path(name_or_path)
    if not p.exists():
        p = shared_data.real_logs_dir() / str(name_or_path)
    try:
        return resolve_log_path(p)
    except LogFormatError as exc:
        raise FileNotFoundError(f"{exc} (real logs are looked up in {shared_data.real_logs_dir()})") from None


def compare(log_path, world, stride: int = DEFAULT_STRIDE, progress: bool = False, truth=None):
    """Replay real and twin frames of one log; returns (MapRealism, real worldmap, twin worldmap).

    truth: map_bw as load_ground_truth gives it (read from ../shared when None).
    """
    data = read_log(log_path)
    if truth is None:
        truth = load_ground_truth(shared_data.ground_truth_map_path())
    renderer = Renderer(world)
    real_rover, twin_rover = RoverState(), RoverState()
    frames = data.frames[:: max(1, int(stride))]
    it = frames
    if progress:
        from tqdm import tqdm

        it = tqdm(frames, desc="map realism", unit="frame")
    used = 0
    for i, frame in enumerate(it):
        real = decode_frame(frame.image_path)
        if real is None:
            continue
        pose = (frame.x, frame.y, frame.yaw, signed_angle(frame.pitch), signed_angle(frame.roll))
        twin = jpeg_roundtrip(renderer.render(pose))
        now = i * FALLBACK_FRAME_PERIOD_S
        for rover, rgb in ((real_rover, real), (twin_rover, twin)):
            apply_frame(rover, frame, rgb, now)
            perception.perception_step(rover)
        used += 1
    if used == 0:
        raise ValueError(f"no readable frames in {log_path}")
    real_score = score_map(real_rover.worldmap, truth)
    twin_score = score_map(twin_rover.worldmap, truth)
    result = MapRealism(used, real_score.mapped_pct, real_score.fidelity_pct, twin_score.mapped_pct,
                        twin_score.fidelity_pct, "on" if world.cast_shadows else "off")
    return result, real_rover.worldmap, twin_rover.worldmap


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--log", default=DEFAULT_LOG, help="real-logs folder name, a log folder or a robot_log.csv")
    p.add_argument("--stride", type=int, default=DEFAULT_STRIDE, help="use every N-th frame")
    p.add_argument("--out", default="out/map-realism", help="folder for metrics.json and the two scored map images")
    add_shadows_option(p)
    a = parse_with_logging(p, argv)
    if a.stride < 1:
        p.error("--stride must be at least 1")
    from sim.world import load_real_world, real_world_available, with_shadows

    if not real_world_available() or not shared_data.ground_truth_map_path().exists():
        log.error("the real world and map_bw.png are needed (set %s)", shared_data.SHARED_ENV_VAR)
        return 2
    try:
        log_path = find_log(a.log)
        world = with_shadows(load_real_world(), a.shadows == "on")
        truth = load_ground_truth(shared_data.ground_truth_map_path())
        result, real_map, twin_map = compare(log_path, world, a.stride, progress=True, truth=truth)
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    out = Path(a.out)
    from replay.outputs import map_image, write_json, write_png

    write_json(out / "metrics.json", {**asdict(result), "log": str(log_path), "stride": a.stride})
    for name, worldmap, mapped, fidelity in (("real", real_map, result.real_mapped_pct, result.real_fidelity_pct),
                                             ("twin", twin_map, result.twin_mapped_pct, result.twin_fidelity_pct)):
        title = [f"{name} frames, shadows {result.shadows}", f"{mapped:.1f}% mapped {fidelity:.1f}% fidelity"]
        write_png(out / f"{name}_map.png", map_image(worldmap, truth, title_lines=title))
    log.info("%s, %d frames, shadows %s", log_path, result.frames, result.shadows)
    log.info("  real frames: %.1f %% mapped, %.1f %% fidelity", result.real_mapped_pct, result.real_fidelity_pct)
    log.info("  twin frames: %.1f %% mapped, %.1f %% fidelity (mapped gap %+.1f points)",
             result.twin_mapped_pct, result.twin_fidelity_pct, result.mapped_gap)
    log.info("  metrics.json and worldmaps in %s", out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
