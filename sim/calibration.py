"""The project's own calibration images, rendered by the twin (no simulator frames copied).

    python -m sim.calibration [--world procedural:0] [--out calibration_images]

Writes `grid1.jpg` (1 m grid of dark lines on the floor in front of the rover, the
grid the simulator shows with G) and `rock1.jpg` (a gold sample rock in view), both
JPEG q75 like the simulator. It also logs where the corners of the grid square
0.82-1.82 m ahead of the rover land in the image, next to the starter's standard
source points, as a check of the camera model.
"""
from __future__ import annotations

import argparse
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from sim.render import CAMERA_MOUNT_FORWARD_M, CX, CY, FOCAL_PX, Renderer, encode_jpeg
from sim.world import load_world

log = logging.getLogger(__name__)

GRID_FIRST_LINE_M = 0.82  # first grid line ahead of the rover origin (standard calibration square), m
GRID_SPACING_M = 1.0  # grid line spacing, m
GRID_HALF_OFFSET_M = 0.5  # lateral lines at +-0.5 m, +-1.5 m, ... from the rover centre line, m
GRID_LINE_RGB = (25, 25, 25)  # grid line colour, uint8 RGB
GRID_MAX_RANGE_M = 10.0  # grid drawn up to this distance (farther lines alias), m
ROCK_AHEAD_M = 2.0  # sample rock distance ahead of the rover origin in rock1.jpg, m
ROCK_LEFT_M = -0.25  # and to the left (negative = right), m
ROCK_SCALE = 0.45  # prefab scale of the rock in rock1.jpg
CAMERA_HEIGHT_M = 0.2146  # camera above flat floor, m (camera.json)
STANDARD_SOURCE_PX = [[14, 140], [301, 140], [200, 96], [118, 96]]  # starter's calibration points


def _open_floor_pose(world):
    """A pose on the floor with open floor ahead (start pose, or the most open floor cell)."""
    import cv2

    nav = (world.nav_truth > 0).astype(np.uint8)
    dist = cv2.distanceTransform(nav, cv2.DIST_L2, 5)
    sx, sy = world.start_xy
    if dist[int(sy), int(sx)] >= 4:
        best_yaw, best_len = world.start_yaw_training, -1.0
        for yaw in np.arange(0.0, 360.0, 15.0):
            free = 0.0
            for d in np.arange(0.5, 15.0, 0.5):
                x = sx + d * np.cos(np.radians(yaw))
                y = sy + d * np.sin(np.radians(yaw))
                if not world.is_floor(x, y):
                    break
                free = d
            if free > best_len:
                best_yaw, best_len = float(yaw), free
        return (sx, sy, best_yaw, 0.0, 0.0)
    r, c = np.unravel_index(int(np.argmax(dist)), dist.shape)
    return (c + 0.5, r + 0.5, 0.0, 0.0, 0.0)


def draw_floor_grid(img, hit_xyz, pose):
    """Dark 1-px lines where the floor crosses the rover-aligned 1 m grid."""
    x0, y0, yaw = pose[0], pose[1], np.radians(pose[2])
    dx, dy = hit_xyz[..., 0] - x0, hit_xyz[..., 1] - y0
    fwd = dx * np.cos(yaw) + dy * np.sin(yaw)
    left = -dx * np.sin(yaw) + dy * np.cos(yaw)
    valid = np.isfinite(fwd) & (np.abs(hit_xyz[..., 2]) < 0.05) & (fwd > 0) & (fwd < GRID_MAX_RANGE_M)
    fwd_cell = np.floor((np.where(valid, fwd, 0) - GRID_FIRST_LINE_M) / GRID_SPACING_M)
    left_cell = np.floor((np.where(valid, left, 0) - GRID_HALF_OFFSET_M) / GRID_SPACING_M)
    line = np.zeros(valid.shape, bool)
    for cell in (fwd_cell, left_cell):
        line[1:, :] |= cell[1:, :] != cell[:-1, :]
        line[:, 1:] |= cell[:, 1:] != cell[:, :-1]
    line &= valid
    line[1:, :] &= valid[:-1, :]
    line[:, 1:] &= valid[:, :-1]
    out = img.copy()
    out[line] = GRID_LINE_RGB
    return out


def grid_square_corners_px():
    """Image position of the grid square 0.82-1.82 m ahead, +-0.5 m, on flat floor, level camera."""
    pts = []
    for fwd, left in [(GRID_FIRST_LINE_M, GRID_HALF_OFFSET_M), (GRID_FIRST_LINE_M, -GRID_HALF_OFFSET_M),
                      (GRID_FIRST_LINE_M + 1, -GRID_HALF_OFFSET_M), (GRID_FIRST_LINE_M + 1, GRID_HALF_OFFSET_M)]:
        z_cam = fwd - CAMERA_MOUNT_FORWARD_M
        pts.append([CX + FOCAL_PX * (-left) / z_cam, CY + FOCAL_PX * CAMERA_HEIGHT_M / z_cam])
    return np.array(pts)


def _write_bytes(path: Path, data: bytes):
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=path.suffix, dir=path.parent)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
    os.replace(tmp, path)


def render_calibration_images(world_spec="procedural:0"):
    """(grid rgb, rock rgb, pose) rendered on the given world."""
    world = load_world(world_spec)
    renderer = Renderer(world)
    pose = _open_floor_pose(world)
    base = renderer.render(pose)
    grid = draw_floor_grid(base, renderer.last_hit, pose)
    yaw = np.radians(pose[2])
    rx = pose[0] + ROCK_AHEAD_M * np.cos(yaw) - ROCK_LEFT_M * np.sin(yaw)
    ry = pose[1] + ROCK_AHEAD_M * np.sin(yaw) + ROCK_LEFT_M * np.cos(yaw)
    rock = renderer.render(pose, samples=[(rx, ry, ROCK_SCALE, 20.0)])
    return grid, rock, pose


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m sim.calibration", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--world", default="procedural:0", help="world spec (default: the project's own canyon)")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "calibration_images"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    grid, rock, pose = render_calibration_images(args.world)
    out = Path(args.out)
    _write_bytes(out / "grid1.jpg", encode_jpeg(grid))
    _write_bytes(out / "rock1.jpg", encode_jpeg(rock))
    corners = grid_square_corners_px()
    log.info("wrote %s and %s (world %s, pose %s)", out / "grid1.jpg", out / "rock1.jpg", args.world,
             tuple(round(float(v), 2) for v in pose))
    log.info("grid square 0.82-1.82 m ahead lands at %s px; starter standard source points %s",
             corners.round(1).tolist(), STANDARD_SOURCE_PX)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
