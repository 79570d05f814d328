"""How close the twin's camera is to the real simulator: navigable-mask IoU on test_dataset.

For every logged frame of ../shared/udacity-rover/test_dataset the renderer draws the
view at the logged pose; both images go through the starter's pipeline (RGB > 160 on
every channel = navigable, standard top-down warp) and the masks are compared inside
the camera's field of view: within 5 m of the rover and over the whole warped view.

    python -m sim.realism [--stride 1] [--out out/realism] [--examples 6]
"""
from __future__ import annotations

import argparse
import csv
import json
import logging
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

import shared_data
from sim.render import IMAGE_H, IMAGE_W, Renderer, encode_jpeg

log = logging.getLogger(__name__)

NAV_THRESHOLD = 160  # starter rule: navigable where every channel is above this
NEAR_RADIUS_PX = 50  # "within 5 m": 10 px per metre in the standard warp
ROVER_PX = (160.0, 160.0)  # rover origin in the standard warped image (x, y), px
# floors the tests hold (the acceptance numbers)
FLOOR_NEAR_MEAN = 0.93  # mean IoU within 5 m
FLOOR_NEAR_P10 = 0.85  # 10th percentile IoU within 5 m
FLOOR_WHOLE_MEAN = 0.82  # mean IoU over the whole warped view
DEFAULT_EXAMPLES = 6  # side-by-side images written
# standard calibration (camera.json standard_perspective_calibration), used when ../shared is absent
STANDARD_SOURCE_PX = [[14, 140], [301, 140], [200, 96], [118, 96]]
STANDARD_DESTINATION_PX = [[155, 154], [165, 154], [165, 144], [155, 144]]


@dataclass
class LoggedFrame:
    image_path: Path
    pose: tuple  # (x, y, yaw, pitch, roll), degrees, pitch/roll signed


def _signed(angle_deg: float) -> float:
    return (angle_deg + 180.0) % 360.0 - 180.0


def read_test_dataset(folder: Path | None = None) -> list:
    """Logged frames of the test_dataset (robot_log.csv with ';' separators)."""
    folder = Path(folder) if folder is not None else shared_data.test_dataset_dir()
    frames = []
    with open(folder / "robot_log.csv", newline="") as fh:
        for row in csv.DictReader(fh, delimiter=";"):
            name = Path(row["Path"].replace("\\", "/")).name
            pose = (float(row["X_Position"]), float(row["Y_Position"]), float(row["Yaw"]),
                    _signed(float(row["Pitch"])), _signed(float(row["Roll"])))
            frames.append(LoggedFrame(folder / "IMG" / name, pose))
    return frames


def standard_warp():
    """(perspective matrix, FOV mask, 5 m mask) of the starter's top-down warp."""
    src, dst = STANDARD_SOURCE_PX, STANDARD_DESTINATION_PX
    cam_path = shared_data.world_dir() / "camera.json"
    if cam_path.exists():
        calib = json.loads(cam_path.read_text())["standard_perspective_calibration"]
        src, dst = calib["source_px"], calib["destination_px"]
    m = cv2.getPerspectiveTransform(np.float32(src), np.float32(dst))
    fov = cv2.warpPerspective(np.ones((IMAGE_H, IMAGE_W), np.uint8), m, (IMAGE_W, IMAGE_H)) > 0
    yy, xx = np.mgrid[0:IMAGE_H, 0:IMAGE_W]
    near = fov & ((xx - ROVER_PX[0]) ** 2 + (yy - ROVER_PX[1]) ** 2 <= NEAR_RADIUS_PX ** 2)
    return m, fov, near


def navigable(rgb: np.ndarray) -> np.ndarray:
    return np.all(rgb > NAV_THRESHOLD, axis=2)


def warped_navigable(rgb: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Starter pipeline: warp the colour image, then threshold."""
    return navigable(cv2.warpPerspective(rgb, m, (IMAGE_W, IMAGE_H)))


def iou(a: np.ndarray, b: np.ndarray, region: np.ndarray) -> float:
    a, b = a & region, b & region
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


def jpeg_roundtrip(rgb: np.ndarray) -> np.ndarray:
    """What the client receives: the frame after the simulator's JPEG encoding."""
    buf = np.frombuffer(encode_jpeg(rgb), np.uint8)
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def read_rgb(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ValueError(f"cannot read frame {path}")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def evaluate(renderer: Renderer, frames: list, progress: bool = False, keep=()):
    """Per-frame IoUs (near, whole) and the images of the frames listed in `keep`."""
    m, fov, near = standard_warp()
    near_iou, whole_iou, kept = [], [], {}
    it = frames
    if progress:
        from tqdm import tqdm

        it = tqdm(frames, desc="realism", unit="frame")
    for i, frame in enumerate(it):
        real = read_rgb(frame.image_path)
        sim = jpeg_roundtrip(renderer.render(frame.pose))
        real_nav = warped_navigable(real, m)
        sim_nav = warped_navigable(sim, m)
        near_iou.append(iou(real_nav, sim_nav, near))
        whole_iou.append(iou(real_nav, sim_nav, fov))
        if i in keep:
            kept[i] = (real, sim, real_nav & fov, sim_nav & fov)
    return np.array(near_iou), np.array(whole_iou), kept


def summarise(near_iou: np.ndarray, whole_iou: np.ndarray) -> dict:
    return {
        "frames": int(near_iou.size),
        "near_5m_mean": float(near_iou.mean()),
        "near_5m_p10": float(np.percentile(near_iou, 10)),
        "near_5m_min": float(near_iou.min()),
        "whole_view_mean": float(whole_iou.mean()),
        "whole_view_p10": float(np.percentile(whole_iou, 10)),
    }


def side_by_side(real, sim, real_mask, sim_mask) -> np.ndarray:
    """real | rendered | masks (white both, red real only, cyan rendered only), RGB."""
    masks = np.zeros_like(real)
    masks[real_mask & sim_mask] = (255, 255, 255)
    masks[real_mask & ~sim_mask] = (255, 0, 0)
    masks[~real_mask & sim_mask] = (0, 255, 255)
    return np.hstack([real, sim, masks])


def _write_png(path: Path, rgb: np.ndarray):
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".png", dir=path.parent)
    os.close(fd)
    cv2.imwrite(tmp, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    os.replace(tmp, path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stride", type=int, default=1, help="use every N-th frame")
    parser.add_argument("--out", default="out/realism", help="folder for side-by-side images and metrics")
    parser.add_argument("--examples", type=int, default=DEFAULT_EXAMPLES, help="side-by-side images to write")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    folder = shared_data.test_dataset_dir()
    if not folder.exists():
        log.error("test_dataset not found at %s (set %s)", folder, shared_data.SHARED_ENV_VAR)
        return 2
    from sim.world import load_world

    frames = read_test_dataset(folder)[:: max(1, args.stride)]
    renderer = Renderer(load_world("real"))
    keep = set(np.linspace(0, len(frames) - 1, max(args.examples, 0)).astype(int).tolist()) if args.examples else set()
    near_iou, whole_iou, kept = evaluate(renderer, frames, progress=True, keep=keep)
    summary = summarise(near_iou, whole_iou)
    out = Path(args.out)
    worst = np.argsort(near_iou)[:3]
    for i, (real, sim, rm, sm) in kept.items():
        _write_png(out / f"frame_{i:04d}.png", side_by_side(real, sim, rm, sm))
    out.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".json", dir=out)
    with os.fdopen(fd, "w") as fh:
        json.dump({**summary, "worst_frames": [int(i) for i in worst]}, fh, indent=1)
    os.replace(tmp, out / "metrics.json")
    log.info("realism over %d frames (navigable IoU, real vs twin, standard warp):", summary["frames"])
    log.info("  within 5 m : mean %.3f  p10 %.3f  min %.3f  (floors %.2f / %.2f)", summary["near_5m_mean"],
             summary["near_5m_p10"], summary["near_5m_min"], FLOOR_NEAR_MEAN, FLOOR_NEAR_P10)
    log.info("  whole view : mean %.3f  p10 %.3f  (floor %.2f)", summary["whole_view_mean"],
             summary["whole_view_p10"], FLOOR_WHOLE_MEAN)
    log.info("  images and metrics.json in %s", out)
    ok = (summary["near_5m_mean"] >= FLOOR_NEAR_MEAN and summary["near_5m_p10"] >= FLOOR_NEAR_P10
          and summary["whole_view_mean"] >= FLOOR_WHOLE_MEAN)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
