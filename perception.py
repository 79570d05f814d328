"""Vision and mapping: camera frame -> rover-frame terrain -> world confidence map.

Why it is built this way:
- The perspective transform comes from the simulator's real camera geometry
  (pinhole f = 114.25 px, cx = 160, cy = 80, 0.2146 m above the floor, 0.4287 m
  ahead of the rover origin) instead of hand-picked calibration points, and it is
  recomputed for the body's pitch and roll, so small tilts do not smear the map.
- The map is a pair of per-cell vote accumulators (navigable, obstacle) fed only by
  nearby ground (range limit) while the body is level enough (tilt gate); the
  displayed ``rover.worldmap`` is rebuilt from the votes every frame, so early
  wrong marks are overturned by later, better views.  The scored map's light-sand share is the
  mean over range bands, so the many blurred far views of a wall foot do not outvote the near ones.
- Sand in a cast shadow is too dark for the classic threshold; a colour-and-texture
  rule finds it.  It is mapped as floor (the map is scored against the canyon's
  floor), but the planner drives on the bright-sand map only (:func:`drive_map`):
  a shadowed pocket is often a wall foot where the rover wedges.  The sample search's
  peeks into pockets read :func:`pocket_floor`, which keeps a stricter red floor.
- Speed: everything per frame is a few OpenCV calls on a fixed-size top-down grid
  plus ``np.bincount`` on precomputed cell indices (well under 1 ms).

Frames (see docs/ARCHITECTURE.md): world x east / y north, 1 map px = 1 m,
maps indexed ``[y, x]``; rover frame x forward, y left, angles radians, left +.
Unity axes inside the camera model: x right, y up, z forward; body rotation
``R = Ry(90 - yaw) . Rx(pitch) . Rz(roll)``, positive pitch = nose down.

Private memory lives in ``rover.perception_memory`` (a :class:`PerceptionMemory`).
Planning code should read it through :func:`occupancy_grids`.
"""
from __future__ import annotations

import json
import logging
import math
from dataclasses import dataclass, field
from typing import List, NamedTuple, Optional, Tuple

import cv2
import numpy as np
from numba import njit

log = logging.getLogger(__name__)

# --- camera (simulator geometry; overridden by ../shared/.../camera.json if present) ---
IMAGE_W = 320  # camera frame width, px
IMAGE_H = 160  # camera frame height, px
FOCAL_PX = 114.251841  # pinhole focal length, px (80 / tan 35 deg)
CX = 160.0  # principal point column, px (pixel u has its centre at u + 0.5)
CY = 80.0  # principal point row, px (the horizon of a level camera)
CAMERA_FORWARD_M = 0.4287  # camera ahead of the rover origin, m
CAMERA_MOUNT_UP_M = 0.2391  # camera above the rover root, m
ROOT_HEIGHT_M = -0.0245  # rover root relative to the floor (suspension bottomed out), m
CAMERA_HEIGHT_M = CAMERA_MOUNT_UP_M + ROOT_HEIGHT_M  # camera above a flat floor, m (0.2146)

# --- colour thresholds (RGB, inclusive) ---
NAV_RGB_MIN = (161, 161, 161)  # light floor sand: every channel above 160
# sand in a cast shadow: darker than NAV_RGB_MIN but still sand-coloured (grey-beige) and smooth
SHADE_SAND_MIN_R = 110  # red at least this (sand light enough to map keeps R >= ~110 in a 0.6 shadow; shadowed walls are darker), 0..255
POCKET_SAND_MIN_R = 130  # shadowed sand at least this red also counts for the sample search's pocket peeks (darker sand is mapped, not peeked into), 0..255
SHADE_SAND_MIN_G_PER_R = 0.90  # green / red at least this (slope feet and rock faces are redder)
SHADE_SAND_MIN_B_PER_R = 0.83  # blue / red at least this (gold samples and brown rock have little blue)
# sand just outside that hue: cast-shadowed sand sits on the 0.90 / 0.83 lines (test_dataset: medians 0.904 / 0.830),
# so the rule takes about half of it; the looser band takes more wall than sand on the real drives, so it gets its
# own vote, weighed by the scored cell model (perception.md, ninth round)
NEAR_SAND_MIN_G_PER_R = 0.88  # green / red at least this for near-hue sand (smooth, R >= SHADE_SAND_MIN_R, not shadowed)
NEAR_SAND_MIN_B_PER_R = 0.80  # blue / red at least this for near-hue sand
SHADE_SAND_MAX_SD = 10.0  # red standard deviation in the window at most this (rough rock is textured), 0..255
SHADE_SAND_WINDOW_W_PX = 7  # width of the window for that texture test, px
SHADE_SAND_WINDOW_H_PX = 1  # its height, px: one row, so it never straddles the floor/wall edge, which runs across
SHADE_SAND_FIRST_ROW = 60  # rows above this are never floor within map range, px
ROCK_RGB_MIN = (110, 90, 0)  # sample rocks are gold (1, 0.85, 0): bright R and G ...
ROCK_RGB_MAX = (255, 255, 60)  # ... and little blue
ROCK_MIN_PIXELS = 4  # smaller gold blobs are ignored as noise, px
ROCK_EDGE_PX = 1  # a blob this close to the image's left or right edge is cut off: steered toward, never remembered, px
ROCK_MAX_WIDTH_M = 0.25  # no sample looks wider than this (largest 0.19 m; real blobs 90 % <= 0.3 m incl. slopes), m

# --- top-down grid (rover frame) used for both decision outputs and map votes ---
GRID_RES_M = 0.1  # top-down cell edge, m (the starter's 10 px per metre)
GRID_FORWARD_M = 12.0  # grid reaches this far ahead of the rover origin, m
GRID_HALF_WIDTH_M = 12.0  # grid spans +- this much to each side, m
GRID_MIN_FORWARD_M = 0.6  # cells nearer than this are hidden under the camera, m
DECISION_RANGE_M = 12.0  # nav/obstacle pixels handed to decision reach this far, m

# --- mapping ---
WORLD_SIZE = 200  # world map edge, cells (1 cell = 1 m)
MAP_RANGE_M = 9.0  # only ground within this distance votes, m
MAP_RANGE_FALLOFF = 0.5  # vote weight at MAP_RANGE_M relative to 1 at the rover (linear), 0..1
NAV_VOTE_WEIGHT = 1.0  # weight of one navigable top-down cell vote
OBS_VOTE_WEIGHT = 1.0  # weight of one obstacle top-down cell vote
NAV_MAJORITY = 0.2  # the drive map and pocket floor take a cell as navigable when the light-sand share of votes exceeds this, 0..1 (edge cells are mixed)
SCORED_NAV_MAJORITY = 0.25  # the scored vote-share rule (the cell model's neighbour term) asks this light-sand share of a cell no range band has spoken for yet, 0..1
# The scored light share gives each range band an equal say (issue 27, round 5): a wall-foot cell gets thousands of
# votes from 6-9 m, where it blurs into the wall, and a few hundred from 1.5-4.5 m, where it is plainly floor
# or plainly not; summed, the far votes decide.  Averaged per band, each distance counts once.
SCORED_BAND_EDGES_M = (1.5, 3.0, 4.5, 6.0)  # inner edges of the range bands, m (the last band runs to MAP_RANGE_M)
SCORED_BAND_MIN_SHARE = 0.01  # a band's light share counts once it holds this share of the cell's votes (and MIN_CELL_VOTES), 0..1
SCORED_BAND_SHARE = 0.35  # ...and takes a cell as light sand when the mean of its bands' light shares exceeds this, 0..1
SHADE_MAJORITY = 0.5  # ...or when light plus shadowed sand make up more than this share (the weaker evidence), 0..1
MIN_CELL_VOTES = 3.0  # weighted votes a cell needs before it is shown at all
# The scored map itself (issue 27, round 8) weighs a cell's shares and its neighbours in one logistic model of
# map_bw: a rim cell is part sand and part wall, and whether its centre is floor shows in its shares and in how
# much floor surrounds it together, not in either alone.  Fitted by `python -m evaluation.fit_scored_cells` on
# megalphian, test_dataset and twin missions (seeds 0-3 shadows off, 0-2 on); checked on the other drives (round 10:
# the floor-side term; the canyon is lit from one side, so which side of a rim cell the floor lies on matters;
# round 14: refitted on votes that weigh hidden ground down, OCCLUDED_VOTE_WEIGHT).
SCORED_CELL_W_LIGHT = 4.563  # logit per unit of light-sand share (band mean, or the plain share where no band speaks)
SCORED_CELL_W_SAND = 4.692  # logit per unit of light plus shadowed sand share
SCORED_CELL_W_SHADE = 4.372  # logit per unit of shadowed sand share (both shades)
SCORED_CELL_W_NEAR = 4.812  # logit per unit of near-hue sand share (NEAR_SAND_MIN_*)
SCORED_CELL_W_NEIGHBOUR = 0.381  # logit per neighbour (of 8) the vote-share rules call navigable
SCORED_CELL_W_FLOOR_NE = 0.086  # logit per unit of floor toward the north-east (neighbours' east + north offsets, -6..6)
SCORED_CELL_BIAS = -6.227  # logit of a cell with no sand and no floor around it
SCORED_CELL_MIN_P = 0.400  # a seen cell is navigable on the scored map when the model's probability exceeds this, 0..1
TILT_GATE_DEG = 3.0  # skip map votes when |pitch| or |roll| exceeds this, deg
NO_VOTE_MODES = ("stuck",)  # decision modes (rover.mode, from the last frame) whose frames do not vote: a rover wedged against a rock sees its face, which the flat-floor projection paints as wall over the floor behind it
OCCLUDED_VOTE_WEIGHT = 0.3  # weight of a vote from ground behind the first rock or wall face a pixel column meets (the flat-floor projection paints that face over it), 0..1
VIEW_FOOT_RUN_PX = 3  # a column's view of the floor ends at its lowest run of this many non-sand pixels (that face's foot), px
VIEW_FOOT_MARGIN_M = 1.0  # ground up to this far beyond the foot still counts as seen (the foot's own cell, a wall's rim), m
LOOK_RANGE_MAX_M = 4.0  # the closest-look map (how near the camera has seen each cell) records looks up to this, m
LOOK_HALF_ANGLE_DEG = 40.0  # ...and only this far off the rover's heading, deg (a sample at the image's side edge is cut off or a few px; seed 0 passed the east-nook rock 50-80 deg off-axis and called it searched)

# --- rocks ---
ROCK_MAX_RANGE_M = 9.0  # rock detections farther than this are not remembered, m
ROCK_TILT_GATE_DEG = 5.0  # rock positions are not remembered above this tilt, deg (the pose's pitch places them; a hard stop pitches ~4.3 deg while a nook's sample shows: 3.0 lost seed 15's at 15 fps)
ROCK_MERGE_RADIUS_M = 2.0  # detections closer than this to a known rock refine it, m
ROCK_MIN_HITS = 3  # detections needed before a rock is reported in rocks_world
ROCK_SUPPRESS_RADIUS_M = 5.0  # a weak cluster this close to a much stronger one is an echo of it, m
ROCK_SUPPRESS_RATIO = 5.0  # "much stronger": this many times the weight
FAST_WORLDMAP = True  # render_worldmap through the compiled kernel (False: the NumPy rules, its reference)
ROCK_MARK_HALF_PX = 1  # rocks are drawn as (2*half+1)^2 green squares on the worldmap

# --- display ---
VISION_BLEND = 0.45  # weight of the camera image under the colour-coded masks, 0..1


def _load_camera_json():
    """Use the simulator's camera.json when ../shared is present (never required)."""
    global FOCAL_PX, CX, CY, CAMERA_FORWARD_M, CAMERA_MOUNT_UP_M, ROOT_HEIGHT_M, CAMERA_HEIGHT_M
    try:
        import shared_data

        path = shared_data.world_dir() / "camera.json"
        if not path.is_file():
            return
        cam = json.loads(path.read_text())
        intr, mount = cam["intrinsics_px"], cam["mount_in_rover_frame_m"]
        values = (float(intr["fx"]), float(intr["cx"]), float(intr["cy"]), float(mount["z_forward"]),
                  float(mount["y_up"]), float(cam["rover_root_height_on_flat_floor_m"]))
        if not all(math.isfinite(v) for v in values) or values[0] <= 0:
            raise ValueError("non-finite or non-positive camera numbers")
        FOCAL_PX, CX, CY, CAMERA_FORWARD_M, CAMERA_MOUNT_UP_M, ROOT_HEIGHT_M = values
        CAMERA_HEIGHT_M = CAMERA_MOUNT_UP_M + ROOT_HEIGHT_M
    except Exception as exc:  # a broken reference file must not break the client
        log.warning("ignoring camera.json (%s); using built-in camera constants", exc)


_load_camera_json()


# =============================================================================== masks
def navigable_mask(rgb: np.ndarray) -> np.ndarray:
    """Light floor sand: bool (160, 320), True where every channel > 160."""
    return cv2.inRange(rgb, NAV_RGB_MIN, (255, 255, 255)) > 0


def shadowed_sand_mask(rgb: np.ndarray) -> np.ndarray:
    """Sand in a cast shadow (not already light sand): bool (160, 320)."""
    return cv2.bitwise_and(shadowed_sand_u8(rgb), cv2.bitwise_not(cv2.inRange(rgb, NAV_RGB_MIN, (255, 255, 255)))) > 0


def shadowed_sand_u8(rgb: np.ndarray) -> np.ndarray:
    """uint8 0/255 (160, 320): sand-coloured, smooth pixels at or below SHADE_SAND_FIRST_ROW.

    Shadow dims every channel alike, so sand keeps its grey-beige ratios; brown
    slope feet, gold samples and dark rock do not.  Rough rock can share the
    colour but not the smoothness, hence the local spread of red.
    """
    return _smooth_sand_u8(rgb)[0]


def _smooth_sand_u8(rgb: np.ndarray):
    """(shadowed-sand hue, near-hue band) uint8 0/255 masks of smooth pixels at or below SHADE_SAND_FIRST_ROW:
    the first passes SHADE_SAND_MIN_*, the second the looser NEAR_SAND_MIN_* (a superset); the texture test
    is computed once for both."""
    sub = rgb[SHADE_SAND_FIRST_ROW:]
    red = sub[:, :, 0].astype(np.float32)
    k = (SHADE_SAND_WINDOW_W_PX, SHADE_SAND_WINDOW_H_PX)
    mean = cv2.boxFilter(red, -1, k, borderType=cv2.BORDER_REFLECT)
    mean_sq = cv2.boxFilter(red * red, -1, k, borderType=cv2.BORDER_REFLECT)
    smooth = ((mean_sq - mean * mean) <= SHADE_SAND_MAX_SD ** 2) & (red >= SHADE_SAND_MIN_R)
    masks = []
    for g_per_r, b_per_r in ((SHADE_SAND_MIN_G_PER_R, SHADE_SAND_MIN_B_PER_R),
                             (NEAR_SAND_MIN_G_PER_R, NEAR_SAND_MIN_B_PER_R)):
        out = np.zeros(rgb.shape[:2], np.uint8)
        hue = (sub[:, :, 1] >= g_per_r * red) & (sub[:, :, 2] >= b_per_r * red)
        out[SHADE_SAND_FIRST_ROW:] = (smooth & hue).view(np.uint8) * np.uint8(255)
        masks.append(out)
    return tuple(masks)


def rock_mask(rgb: np.ndarray) -> np.ndarray:
    """Gold sample-rock pixels: bool (160, 320)."""
    return cv2.inRange(rgb, ROCK_RGB_MIN, ROCK_RGB_MAX) > 0


def obstacle_mask(rgb: np.ndarray) -> np.ndarray:
    """Below-horizon pixels that are neither sand nor sample rock (walls, boulders): bool (160, 320)."""
    nav = cv2.inRange(rgb, NAV_RGB_MIN, (255, 255, 255))
    rock = cv2.inRange(rgb, ROCK_RGB_MIN, ROCK_RGB_MAX)
    obs = cv2.bitwise_not(cv2.bitwise_or(nav, rock))
    obs[:_HORIZON_ROW] = 0
    return obs > 0


# =============================================================================== camera model
def _rot_x(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def body_rotation(yaw_deg=90.0, pitch_deg=0.0, roll_deg=0.0) -> np.ndarray:
    """Unity-axes body rotation R = Ry(90 - yaw) Rx(pitch) Rz(roll); yaw 90 = level frame."""
    return _rot_y(90.0 - yaw_deg) @ _rot_x(pitch_deg) @ _rot_z(roll_deg)


def camera_position(pitch_deg=0.0, roll_deg=0.0) -> np.ndarray:
    """Camera centre in the level frame (Unity axes, origin on the floor under the root), m."""
    tilt = body_rotation(90.0, pitch_deg, roll_deg)
    return np.array([0.0, ROOT_HEIGHT_M, 0.0]) + tilt @ np.array([0.0, CAMERA_MOUNT_UP_M, CAMERA_FORWARD_M])


def pixel_rays(u, v) -> np.ndarray:
    """Camera-frame ray directions (N, 3) for pixel indices (camera.json convention)."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    return np.stack([(u + 0.5 - CX) / FOCAL_PX, (CY - (v + 0.5)) / FOCAL_PX, np.ones_like(u)], axis=-1)


def pixel_to_rover(u, v, pitch_deg=0.0, roll_deg=0.0, _tilt=None, _cam=None):
    """Floor point seen at pixel (u, v): rover-frame (x fwd, y left) in m, and a validity mask.

    Rays that do not hit the floor ahead (above the horizon) are invalid (x, y = nan).
    """
    tilt = body_rotation(90.0, pitch_deg, roll_deg) if _tilt is None else _tilt
    c = camera_position(pitch_deg, roll_deg) if _cam is None else _cam
    d = pixel_rays(u, v) @ tilt.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -c[1] / d[..., 1]
    valid = (d[..., 1] < -1e-9) & np.isfinite(t)
    t = np.where(valid, t, np.nan)
    px = c[0] + t * d[..., 0]
    pz = c[2] + t * d[..., 2]
    return pz, -px, valid


def rover_to_pixel(x, y, pitch_deg=0.0, roll_deg=0.0):
    """Pixel coordinates (continuous, pixel u spans [u, u+1)) of floor point(s) in the rover frame."""
    tilt = body_rotation(90.0, pitch_deg, roll_deg)
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    p = np.stack([-y, np.zeros_like(x), x], axis=-1)  # level frame, Unity axes
    q = (p - camera_position(pitch_deg, roll_deg)) @ tilt  # = tilt.T @ (p - c)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = CX + FOCAL_PX * q[..., 0] / q[..., 2]
        v = CY - FOCAL_PX * q[..., 1] / q[..., 2]
    return u, v, q[..., 2] > 0


def ground_homography(pitch_deg=0.0, roll_deg=0.0) -> np.ndarray:
    """3x3 map from top-down grid (col j, row i, 1) to OpenCV pixel coords (u - 0.5, v - 0.5, 1).

    Grid cell (i, j) centre: x = (i + 0.5) * GRID_RES_M ahead, y = (j + 0.5) * GRID_RES_M - half width.
    Used with cv2.WARP_INVERSE_MAP, so the floor plane is exact for any pitch/roll.
    """
    res, half = GRID_RES_M, GRID_HALF_WIDTH_M
    c = camera_position(pitch_deg, roll_deg)
    # level-frame floor point minus camera: Unity x = -y_left, y = 0, z = x_fwd
    b = np.array([[-res, 0.0, half - 0.5 * res - c[0]],
                  [0.0, 0.0, -c[1]],
                  [0.0, res, 0.5 * res - c[2]]])
    tilt = body_rotation(90.0, pitch_deg, roll_deg)
    k = np.array([[FOCAL_PX, 0.0, CX - 0.5], [0.0, -FOCAL_PX, CY - 0.5], [0.0, 0.0, 1.0]])
    return k @ tilt.T @ b


# =============================================================================== transforms
def rover_coords(mask: np.ndarray, pitch_deg=0.0, roll_deg=0.0):
    """Rover-frame floor coordinates (x fwd, y left; m) of a camera-image mask's True pixels."""
    v, u = np.nonzero(mask)
    x, y, valid = pixel_to_rover(u, v, pitch_deg, roll_deg)
    return x[valid], y[valid]


def to_polar_coords(x, y):
    """Rover-frame (x, y) -> (distance m, angle rad, left +)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    return np.hypot(x, y), np.arctan2(y, x)


def from_polar_coords(dist, angle):
    """Inverse of to_polar_coords."""
    return dist * np.cos(angle), dist * np.sin(angle)


def rover_to_world(x, y, xpos, ypos, yaw_deg, scale=1.0):
    """Rover-frame metres -> world metres (float; floor() gives the map cell)."""
    a = math.radians(yaw_deg)
    c, s = math.cos(a), math.sin(a)
    x = np.asarray(x, dtype=np.float64) / scale
    y = np.asarray(y, dtype=np.float64) / scale
    return xpos + x * c - y * s, ypos + x * s + y * c


def world_to_rover(xw, yw, xpos, ypos, yaw_deg, scale=1.0):
    """World metres -> rover-frame metres (inverse of rover_to_world)."""
    a = math.radians(yaw_deg)
    c, s = math.cos(a), math.sin(a)
    dx = np.asarray(xw, dtype=np.float64) - xpos
    dy = np.asarray(yw, dtype=np.float64) - ypos
    return (dx * c + dy * s) * scale, (-dx * s + dy * c) * scale


# =============================================================================== precomputed tables
def _build_tables():
    """Precompute the top-down grid geometry (call again after changing grid/map constants)."""
    global _GRID_ROWS, _GRID_COLS, _GRID_X, _GRID_Y, _GRID_DIST, _GRID_ANGLE, _GRID_USABLE
    global _GRID_USABLE_U8, _MAP_CELLS, _MAP_X, _MAP_Y, _MAP_WEIGHT, _MAP_DIST, _MAP_LOOK, _HORIZON_ROW, _LEVEL_H
    global _MAP_BAND
    _GRID_ROWS = int(round(GRID_FORWARD_M / GRID_RES_M))
    _GRID_COLS = int(round(2 * GRID_HALF_WIDTH_M / GRID_RES_M))
    _GRID_X = (np.arange(_GRID_ROWS)[:, None] + 0.5) * GRID_RES_M + np.zeros((1, _GRID_COLS))  # fwd, m
    _GRID_Y = (np.arange(_GRID_COLS)[None, :] + 0.5) * GRID_RES_M - GRID_HALF_WIDTH_M + np.zeros((_GRID_ROWS, 1))
    dist, angle = to_polar_coords(_GRID_X, _GRID_Y)
    _GRID_DIST = dist.astype(np.float32)
    _GRID_ANGLE = angle.astype(np.float32)
    _GRID_USABLE = (_GRID_X >= GRID_MIN_FORWARD_M) & (dist <= DECISION_RANGE_M)
    _GRID_USABLE_U8 = _GRID_USABLE.astype(np.uint8) * np.uint8(255)
    _MAP_CELLS = np.flatnonzero(_GRID_USABLE & (dist <= MAP_RANGE_M))  # flat grid indices that vote
    _MAP_X = _GRID_X.ravel()[_MAP_CELLS]
    _MAP_Y = _GRID_Y.ravel()[_MAP_CELLS]
    map_dist = dist.ravel()[_MAP_CELLS]
    _MAP_WEIGHT = 1.0 - (1.0 - MAP_RANGE_FALLOFF) * map_dist / MAP_RANGE_M
    _MAP_DIST = map_dist.astype(np.float32)
    _MAP_BAND = np.digitize(_MAP_DIST, SCORED_BAND_EDGES_M).astype(np.int64)  # range band of each voting cell
    map_angle = angle.ravel()[_MAP_CELLS]
    # voting cells that also update the closest-look map: near, and in the middle of the view
    _MAP_LOOK = (_MAP_DIST <= LOOK_RANGE_MAX_M) & (np.abs(map_angle) <= math.radians(LOOK_HALF_ANGLE_DEG))
    _HORIZON_ROW = int(math.floor(CY))  # rows above this never see the floor of a level camera
    _LEVEL_H = ground_homography(0.0, 0.0)


_LABEL_UNKNOWN, _LABEL_OBSTACLE, _LABEL_NAV, _LABEL_SHADE, _LABEL_DIM_SHADE, _LABEL_NEAR_SAND = 0, 1, 2, 3, 4, 5
SCORED_BANDS = len(SCORED_BAND_EDGES_M) + 1  # number of range bands
_build_tables()


def ground_fov_mask(max_range_m=MAP_RANGE_M) -> np.ndarray:
    """Camera pixels (bool 160x320) whose ray meets a flat floor within max_range_m of the rover."""
    v, u = np.mgrid[0:IMAGE_H, 0:IMAGE_W]
    x, y, valid = pixel_to_rover(u, v)
    with np.errstate(invalid="ignore"):
        return valid & (np.hypot(x, y) <= max_range_m)


def topdown_fov_mask() -> np.ndarray:
    """Top-down grid cells (bool) a level camera sees, within DECISION_RANGE_M."""
    u, v, ahead = rover_to_pixel(_GRID_X, _GRID_Y)
    inside = ahead & (u >= 0) & (u < IMAGE_W) & (v >= 0) & (v < IMAGE_H)
    return inside & _GRID_USABLE


# =============================================================================== memory
@dataclass
class PerceptionMemory:
    """Perception's private state on ``rover.perception_memory``.

    nav_votes, obs_votes: float32 (200, 200) [y, x]; distance-weighted counts of
        0.1 m top-down cells that looked navigable / obstacle in a cell. Votes only
        come from level frames (TILT_GATE_DEG) taken outside NO_VOTE_MODES, and ground within MAP_RANGE_M;
        a vote from ground the camera could not see (behind a face's foot, :func:`_occluded_grid`) counts
        OCCLUDED_VOTE_WEIGHT of one.
    rock_clusters: list of [sum_w*x, sum_w*y, sum_w, hits] per remembered sample rock.
    frames_seen, frames_mapped: counters (mapped = passed the tilt gate, outside NO_VOTE_MODES).
    shade_votes: float32 (200, 200); the part of obs_votes that was sand in shadow at least
        POCKET_SAND_MIN_R red.  The scored ``rover.worldmap`` counts it as navigable, the
        drive map as obstacle; :func:`pocket_floor` counts it too.
    dim_shade_votes: float32 (200, 200); the part of obs_votes that was darker sand in shadow
        (SHADE_SAND_MIN_R up to POCKET_SAND_MIN_R): navigable on the scored map only.
    near_sand_votes: float32 (200, 200); the part of obs_votes that was near-hue sand (NEAR_SAND_MIN_*):
        an obstacle everywhere but an input of the scored cell model.
    band_nav_votes, band_votes: float32 (SCORED_BANDS, 200, 200); nav_votes and all votes split by the
        range band (SCORED_BAND_EDGES_M) of the ground that cast them: the scored map's light share.
    look_range: float32 (200, 200); the closest range (m) from which the camera has seen
        each cell within LOOK_HALF_ANGLE_DEG of the heading (inf: never within LOOK_RANGE_MAX_M).  Small samples only show from close
        by, so the sample search reads it through :func:`looked_at_within`.
    last_grid: uint8 top-down label grid of the last frame (0 unknown, 1 obstacle, 2 navigable,
        3 sand in shadow, 4 darker sand in shadow, 5 near-hue sand),
        rows = forward distance (row i at (i + 0.5) * GRID_RES_M), cols = lateral (left at high j).
    last_occluded: uint8 grid of the same shape, 1 where the last frame's ground was hidden (:func:`_occluded_grid`).
    """
    nav_votes: np.ndarray = field(default_factory=lambda: np.zeros((WORLD_SIZE, WORLD_SIZE), np.float32))
    obs_votes: np.ndarray = field(default_factory=lambda: np.zeros((WORLD_SIZE, WORLD_SIZE), np.float32))
    shade_votes: np.ndarray = field(default_factory=lambda: np.zeros((WORLD_SIZE, WORLD_SIZE), np.float32))
    dim_shade_votes: np.ndarray = field(default_factory=lambda: np.zeros((WORLD_SIZE, WORLD_SIZE), np.float32))
    near_sand_votes: np.ndarray = field(default_factory=lambda: np.zeros((WORLD_SIZE, WORLD_SIZE), np.float32))
    look_range: np.ndarray = field(default_factory=lambda: np.full((WORLD_SIZE, WORLD_SIZE), np.inf, np.float32))
    band_nav_votes: np.ndarray = field(
        default_factory=lambda: np.zeros((SCORED_BANDS, WORLD_SIZE, WORLD_SIZE), np.float32))
    band_votes: np.ndarray = field(default_factory=lambda: np.zeros((SCORED_BANDS, WORLD_SIZE, WORLD_SIZE), np.float32))
    rock_clusters: List[list] = field(default_factory=list)
    frames_seen: int = 0
    frames_mapped: int = 0
    last_grid: Optional[np.ndarray] = None
    last_occluded: Optional[np.ndarray] = None
    worldmap: Optional[np.ndarray] = None  # the array last handed out as rover.worldmap
    drive_worldmap: Optional[np.ndarray] = None  # same layout, shadowed sand as obstacle (see drive_map)
    drawn_rocks: List[Tuple[float, float]] = field(default_factory=list)


def get_memory(rover) -> PerceptionMemory:
    mem = getattr(rover, "perception_memory", None)
    if mem is None:
        mem = PerceptionMemory()
        rover.perception_memory = mem
    return mem


def occupancy_grids(rover) -> Tuple[np.ndarray, np.ndarray]:
    """(navigable_confidence, obstacle_confidence): float32 (200, 200) [y, x] in 0..1.

    Each is that class's share of the cell's votes times a certainty that grows with
    the number of votes (0 for never-seen cells), so ``nav > obs`` means "probably
    free" and both near 0 means "unknown" (a frontier).
    """
    mem = get_memory(rover)
    total = mem.nav_votes + mem.obs_votes
    certainty = total / (total + MIN_CELL_VOTES)
    with np.errstate(invalid="ignore", divide="ignore"):
        nav = np.where(total > 0, mem.nav_votes / total, 0.0) * certainty
        obs = np.where(total > 0, mem.obs_votes / total, 0.0) * certainty
    return nav.astype(np.float32), obs.astype(np.float32)


def looked_at_within(rover, range_m: float) -> np.ndarray:
    """bool (200, 200) [y, x]: cells the camera has seen from no farther than range_m (<= LOOK_RANGE_MAX_M)."""
    return get_memory(rover).look_range <= range_m


def sand_share(rover) -> np.ndarray:
    """float32 (200, 200) [y, x]: light plus shadowed sand (dark shadowed sand included) as a share of each
    cell's votes, 0 for never-seen cells.

    Sand in a deep cast shadow loses the vote to the wall around it, but a slot's floor still keeps
    a tenth to a third of its votes as sand, where a wall two cells from the floor keeps almost none:
    the sample search uses that faint evidence to look into pockets mapped as wall (seed 14, shadows on).
    """
    mem = get_memory(rover)
    total = mem.nav_votes + mem.obs_votes
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total > 0, _sand_votes(mem, 0, WORLD_SIZE, 0, WORLD_SIZE) / total, 0.0)
    return share.astype(np.float32)


def drive_map(rover) -> np.ndarray:
    """The map to plan on: like ``rover.worldmap`` but sand in shadow counts as obstacle, no rocks.

    Shadowed floor pockets are mostly wall feet and overhang gaps; driving into them
    wedged the rover (twin seeds 0-19: 5 missions of 20 incomplete), so planning
    keeps to floor the classic threshold sees.  Falls back to ``rover.worldmap``.
    """
    mem = getattr(rover, "perception_memory", None)
    if mem is not None and mem.drive_worldmap is not None:
        return mem.drive_worldmap
    return getattr(rover, "worldmap", None)


def pocket_floor(rover) -> np.ndarray:
    """bool (200, 200) [y, x]: floor the sample search may peek into for hidden samples.

    The vote-share rules without the darker shadowed sand and without the cell model: the
    peeks were tuned on this stricter floor, and every extra pocket costs a detour
    (procedural:2 ran out of time at 5 of 6 samples when the peeks read the scored map).
    """
    return _majority_navigable(get_memory(rover), 0, WORLD_SIZE, 0, WORLD_SIZE, dim_shade=False)[1]


def render_worldmap(mem: PerceptionMemory, out: Optional[np.ndarray] = None, window=None,
                    drive=False) -> np.ndarray:
    """Rebuild the displayed worldmap from the votes (R obstacle, G rock, B navigable).

    ``window`` = (y0, y1, x0, x1) limits the R/B rebuild to the cells whose votes changed
    (and, on the scored map, their neighbours, whose cell model counts them).
    ``drive`` renders the drive map: shadowed sand stays obstacle, no cell model, no rocks.
    """
    if out is None:
        out = np.zeros((WORLD_SIZE, WORLD_SIZE, 3), np.uint8)
    y0, y1, x0, x1 = (0, WORLD_SIZE, 0, WORLD_SIZE) if window is None else window
    if FAST_WORLDMAP:
        _worldmap_fast(mem, out, y0, y1, x0, x1, drive)
    else:
        _worldmap_numpy(mem, out, y0, y1, x0, x1, drive)
    if drive:
        return out
    rocks = rocks_from_memory(mem)
    if window is None or rocks != mem.drawn_rocks:
        out[:, :, 1] = 0
        for cx, cy in rocks:
            ix, iy = int(cx), int(cy)
            h = ROCK_MARK_HALF_PX
            out[max(iy - h, 0):iy + h + 1, max(ix - h, 0):ix + h + 1, 1] = 255
        mem.drawn_rocks = rocks
    return out


def _worldmap_numpy(mem: PerceptionMemory, out: np.ndarray, y0, y1, x0, x1, drive: bool):
    """render_worldmap's R/B rebuild of the window by the NumPy rules (the reference of `_worldmap_fast`)."""
    if drive:
        seen, is_nav = _majority_navigable(mem, y0, y1, x0, x1, drive=True)
    elif y1 > y0 and x1 > x0:
        y0, y1, x0, x1 = _grown(y0, y1, x0, x1)
        seen, is_nav = _scored_navigable(mem, y0, y1, x0, x1)
    else:
        seen = is_nav = np.zeros((0, 0), bool)
    out[y0:y1, x0:x1, 2] = is_nav.view(np.uint8) * np.uint8(255)
    out[y0:y1, x0:x1, 0] = (seen & ~is_nav).view(np.uint8) * np.uint8(255)


def _worldmap_fast(mem: PerceptionMemory, out: np.ndarray, y0, y1, x0, x1, drive: bool):
    """render_worldmap's R/B rebuild of the window in one compiled pass (`_worldmap_kernel`): the same bytes
    as the NumPy rules below (`_majority_navigable`, `band_light_share`, `_scored_navigable`; the reference,
    tests/test_fast_paths_exact.py), at a fraction of their ~40 small-array calls per frame."""
    if drive:
        gy0, gy1, gx0, gx1 = y0, y1, x0, x1
        py0, py1, px0, px1 = y0, y1, x0, x1
    elif y1 > y0 and x1 > x0:
        gy0, gy1, gx0, gx1 = _grown(y0, y1, x0, x1)
        py0, py1, px0, px1 = _grown(gy0, gy1, gx0, gx1)
    else:
        return
    if gy1 <= gy0 or gx1 <= gx0:
        return
    f32 = np.float32  # NumPy compares and scales a float32 array by a Python float in float32 (NEP 50)
    model = np.array([*scored_cell_weights(), scored_logit_min()], np.float32)
    _worldmap_kernel(mem.nav_votes, mem.obs_votes, mem.shade_votes, mem.dim_shade_votes, mem.near_sand_votes,
                     mem.band_nav_votes, mem.band_votes, py0, py1, px0, px1, gy0, gy1, gx0, gx1, drive,
                     f32(MIN_CELL_VOTES), f32(NAV_MAJORITY), f32(SCORED_NAV_MAJORITY), f32(SCORED_BAND_MIN_SHARE),
                     f32(SCORED_BAND_SHARE), f32(SHADE_MAJORITY), model, out)


@njit(cache=True)
def _worldmap_kernel(nav_v, obs_v, shade_v, dim_v, near_v, band_nav, band_all, py0, py1, px0, px1, gy0, gy1, gx0,
                     gx1, drive, min_votes, nav_major, scored_major, band_min_share, band_share, shade_major, model,
                     out):
    """Cells of (py0:py1, px0:px1) classified by the vote-share rules (drive: light sand only; else the scored
    band rule plus shadowed sand), then on (gy0:gy1, gx0:gx1) either those rules (drive) or the scored cell
    model (``model`` = light, sand, shade, near-hue, neighbour and floor-north-east weights, bias, log-odds
    threshold) on the shares and the rules' navigable neighbours, written to out's R (seen, not navigable) and B
    (navigable) channels as 0/255.

    Bit-exactness with the NumPy rules: every sum, product, quotient and comparison in float32 as NumPy does
    them on float32 arrays with Python-float constants (the constants arrive as float32); the band sums in band
    order, as ``sum(axis=0)`` adds them; the mean share as float64 sum / count rounded to float32, as NumPy's
    float32 / int64 division and ``astype(float32)`` give it; the model's terms in `scored_cell_logit`'s order.
    No fastmath (no reassociation, no fused multiply-add)."""
    ph, pw = py1 - py0, px1 - px0
    bands = band_nav.shape[0]
    seen = np.zeros((ph, pw), np.uint8)
    is_nav = np.zeros((ph, pw), np.uint8)
    light_share = np.zeros((ph, pw), np.float32)
    for i in range(ph):
        yy = py0 + i
        for j in range(pw):
            xx = px0 + j
            nav = nav_v[yy, xx]
            total = nav + obs_v[yy, xx]
            if not total >= min_votes:
                continue
            seen[i, j] = 1
            if drive:
                is_nav[i, j] = nav > nav_major * total
                continue
            band_sum = band_all[0, yy, xx]
            for b in range(1, bands):
                band_sum = band_sum + band_all[b, yy, xx]
            need = band_min_share * band_sum
            share_sum = np.float32(0.0)
            count = 0
            for b in range(bands):
                bt = band_all[b, yy, xx]
                if bt >= min_votes and bt >= need:
                    share_sum = share_sum + band_nav[b, yy, xx] / bt
                    count += 1
                else:
                    share_sum = share_sum + np.float32(0.0)
            if count > 0:
                mean = np.float32(np.float64(share_sum) / np.float64(count))
                light_share[i, j] = mean
                light = mean > band_share
            else:
                light_share[i, j] = nav / total
                light = nav > scored_major * total
            sand = (nav + shade_v[yy, xx]) + dim_v[yy, xx]
            is_nav[i, j] = light or sand > shade_major * total
    for yy in range(gy0, gy1):
        i = yy - py0
        for xx in range(gx0, gx1):
            j = xx - px0
            nav_here = is_nav[i, j]
            if not drive and seen[i, j]:
                neighbours = 0
                floor_ne = 0
                for di in range(-1, 2):
                    for dj in range(-1, 2):
                        ii, jj = i + di, j + dj
                        if (di != 0 or dj != 0) and 0 <= ii < ph and 0 <= jj < pw:
                            neighbours += is_nav[ii, jj]
                            floor_ne += (di + dj) * is_nav[ii, jj]
                total = nav_v[yy, xx] + obs_v[yy, xx]
                sand = ((nav_v[yy, xx] + shade_v[yy, xx]) + dim_v[yy, xx]) / total
                shade = (shade_v[yy, xx] + dim_v[yy, xx]) / total
                near = near_v[yy, xx] / total
                logit = (((((model[0] * light_share[i, j] + model[1] * sand) + model[2] * shade) + model[3] * near)
                          + model[4] * np.float32(neighbours)) + model[5] * np.float32(floor_ne)) + model[6]
                nav_here = logit > model[7]
            out[yy, xx, 2] = 255 if nav_here else 0
            out[yy, xx, 0] = 255 if (seen[i, j] and not nav_here) else 0


def _majority_navigable(mem: PerceptionMemory, y0, y1, x0, x1, drive=False, dim_shade=True, scored=False):
    """(seen, navigable) bool arrays for the window by the vote-share rules alone.

    ``drive`` ignores shadowed sand; ``dim_shade=False`` ignores only its darker part;
    ``scored`` asks the light-sand share of the scored map (SCORED_NAV_MAJORITY).
    """
    nav = mem.nav_votes[y0:y1, x0:x1]
    total = nav + mem.obs_votes[y0:y1, x0:x1]
    seen = total >= MIN_CELL_VOTES
    if scored:
        share, spoken = band_light_share(mem, y0, y1, x0, x1)
        is_nav = seen & np.where(spoken, share > SCORED_BAND_SHARE, nav > SCORED_NAV_MAJORITY * total)
    else:
        is_nav = seen & (nav > NAV_MAJORITY * total)
    if not drive:
        is_nav |= seen & (_sand_votes(mem, y0, y1, x0, x1, dim_shade) > SHADE_MAJORITY * total)
    return seen, is_nav


def band_light_share(mem: PerceptionMemory, y0=0, y1=WORLD_SIZE, x0=0, x1=WORLD_SIZE):
    """(share, spoken) float32 / bool arrays for the window: the mean light-sand share of the range bands
    that hold at least SCORED_BAND_MIN_SHARE of the cell's votes and MIN_CELL_VOTES, and whether any band
    does (else share is 0).  A share of the cell's votes, not a count, so the rule does not change with
    the frame rate."""
    nav = mem.band_nav_votes[:, y0:y1, x0:x1]
    total = mem.band_votes[:, y0:y1, x0:x1]
    ok = (total >= MIN_CELL_VOTES) & (total >= SCORED_BAND_MIN_SHARE * total.sum(axis=0))
    with np.errstate(invalid="ignore", divide="ignore"):
        shares = np.where(ok, nav / total, 0.0)
    count = ok.sum(axis=0)
    return (shares.sum(axis=0) / np.maximum(count, 1)).astype(np.float32), count > 0


def _sand_votes(mem: PerceptionMemory, y0, y1, x0, x1, dim_shade=True) -> np.ndarray:
    """Light plus shadowed sand votes in the window (``dim_shade=False``: without the darker part)."""
    sand = mem.nav_votes[y0:y1, x0:x1] + mem.shade_votes[y0:y1, x0:x1]
    return sand + mem.dim_shade_votes[y0:y1, x0:x1] if dim_shade else sand


class CellFeatures(NamedTuple):
    """The scored cell model's inputs for a window, float32 arrays (0 where the cell is not seen)."""
    seen: np.ndarray  # bool: the cell has MIN_CELL_VOTES
    light: np.ndarray  # the band-mean light-sand share (the plain share where no band speaks)
    sand: np.ndarray  # light plus shadowed sand, a share of the votes
    shade: np.ndarray  # shadowed sand alone
    near: np.ndarray  # near-hue sand alone
    neighbours: np.ndarray  # how many of the 8 neighbours the vote-share rules (scored) call navigable
    floor_ne: np.ndarray  # those neighbours' offsets east plus north, summed (-6..6: floor lies north-east if > 0)


def scored_cell_features(mem: PerceptionMemory, y0, y1, x0, x1) -> CellFeatures:
    """The scored cell model's inputs for the window (`CellFeatures`).

    The floor side matters because the canyon is lit from one side: on real and twin frames alike, rims with the
    floor to their south-west (the floor's north-east edges) read too much like floor, the others too little
    (tenth round).
    """
    py0, py1, px0, px1 = _grown(y0, y1, x0, x1)
    _, rule_nav = _majority_navigable(mem, py0, py1, px0, px1, scored=True)

    def around(kernel):
        counts = cv2.filter2D(rule_nav.view(np.uint8), cv2.CV_16S, kernel, borderType=cv2.BORDER_CONSTANT)
        return counts[y0 - py0:y0 - py0 + (y1 - y0), x0 - px0:x0 - px0 + (x1 - x0)].astype(np.float32)

    nav = mem.nav_votes[y0:y1, x0:x1]
    total = nav + mem.obs_votes[y0:y1, x0:x1]
    seen = total >= MIN_CELL_VOTES
    safe = np.where(seen, total, np.float32(1.0))
    share, spoken = band_light_share(mem, y0, y1, x0, x1)
    light = np.where(spoken, share, nav / safe)
    sand = _sand_votes(mem, y0, y1, x0, x1) / safe
    shade = (mem.shade_votes[y0:y1, x0:x1] + mem.dim_shade_votes[y0:y1, x0:x1]) / safe
    near = mem.near_sand_votes[y0:y1, x0:x1] / safe
    zero = np.float32(0.0)
    figures = (light, sand, shade, near, around(_EIGHT_NEIGHBOURS), around(_FLOOR_NORTH_EAST))
    return CellFeatures(seen, *(np.where(seen, f, zero) for f in figures))


def scored_cell_logit(light, sand, shade, near, neighbours, floor_ne):
    """The scored cell model's log-odds that a cell is map_bw floor (float32, summed in a fixed order so the
    compiled kernel gives the same bits)."""
    return (((((SCORED_CELL_W_LIGHT * light + SCORED_CELL_W_SAND * sand) + SCORED_CELL_W_SHADE * shade)
              + SCORED_CELL_W_NEAR * near) + SCORED_CELL_W_NEIGHBOUR * neighbours)
            + SCORED_CELL_W_FLOOR_NE * floor_ne) + SCORED_CELL_BIAS


def scored_cell_weights() -> Tuple[float, ...]:
    """The cell model's weights in `scored_cell_logit`'s order (light, sand, shade, near-hue, per neighbour,
    floor toward the north-east), then its bias."""
    return (SCORED_CELL_W_LIGHT, SCORED_CELL_W_SAND, SCORED_CELL_W_SHADE, SCORED_CELL_W_NEAR,
            SCORED_CELL_W_NEIGHBOUR, SCORED_CELL_W_FLOOR_NE, SCORED_CELL_BIAS)


def scored_logit_min(min_p: Optional[float] = None) -> float:
    """A probability threshold (default SCORED_CELL_MIN_P) as the log-odds the cell model's logit must exceed."""
    p = SCORED_CELL_MIN_P if min_p is None else min_p
    return math.log(p / (1.0 - p))


def _scored_navigable(mem: PerceptionMemory, y0, y1, x0, x1):
    """(seen, navigable) for the scored map: the cell model on the window's shares and neighbours."""
    seen, *figures = scored_cell_features(mem, y0, y1, x0, x1)
    return seen, seen & (scored_cell_logit(*figures) > scored_logit_min())


def _grown(y0, y1, x0, x1):
    """The window (y0, y1, x0, x1) one cell larger on every side, within the map."""
    return max(y0 - 1, 0), min(y1 + 1, WORLD_SIZE), max(x0 - 1, 0), min(x1 + 1, WORLD_SIZE)


_EIGHT_NEIGHBOURS = np.array([[1, 1, 1], [1, 0, 1], [1, 1, 1]], np.float32)  # kernel counting a cell's neighbours
_FLOOR_NORTH_EAST = np.array([[-2, -1, 0], [-1, 0, 1], [0, 1, 2]], np.float32)  # ...their east + north offsets


def rocks_from_memory(mem: PerceptionMemory) -> List[Tuple[float, float]]:
    """Weighted mean positions of clusters seen often enough and not echoes of a stronger one."""
    clusters = [(c[0] / c[2], c[1] / c[2], c[2]) for c in mem.rock_clusters if c[3] >= ROCK_MIN_HITS]
    rocks = []
    for x, y, w in clusters:
        echo = any(w2 >= ROCK_SUPPRESS_RATIO * w and math.hypot(x2 - x, y2 - y) < ROCK_SUPPRESS_RADIUS_M
                   for x2, y2, w2 in clusters)
        if not echo:
            rocks.append((x, y))
    return rocks


def _remember_rock(mem: PerceptionMemory, xw: float, yw: float, weight: float):
    best, best_d = None, ROCK_MERGE_RADIUS_M
    for c in mem.rock_clusters:
        d = math.hypot(c[0] / c[2] - xw, c[1] / c[2] - yw)
        if d < best_d:
            best, best_d = c, d
    if best is None:
        mem.rock_clusters.append([xw * weight, yw * weight, weight, 1])
    else:
        best[0] += xw * weight
        best[1] += yw * weight
        best[2] += weight
        best[3] += 1


# =============================================================================== per frame
def _to_u8(mask: np.ndarray) -> np.ndarray:
    """A mask as uint8 0/255 (bool or any nonzero-is-true array accepted)."""
    if mask.dtype == np.uint8:
        return mask if mask.max(initial=0) in (0, 255) else np.where(mask > 0, np.uint8(255), np.uint8(0))
    return np.where(mask, np.uint8(255), np.uint8(0))


_GRID_LUT = np.zeros(256, np.uint8)  # warped nav8 value -> label
_GRID_LUT[0], _GRID_LUT[255], _GRID_LUT[128] = 1, 2, 0  # obstacle, navigable, outside the image
_SHADE_VALUE = 192  # camera-mask value of sand in shadow (neither 0, 255 nor the border)
_GRID_LUT[_SHADE_VALUE] = _LABEL_SHADE
_DIM_SHADE_VALUE = _SHADE_VALUE - 128  # camera-mask value of shadowed sand darker than POCKET_SAND_MIN_R
_GRID_LUT[_DIM_SHADE_VALUE] = _LABEL_DIM_SHADE
_NEAR_SAND_VALUE = 160  # camera-mask value of near-hue sand (none of the values above)
_GRID_LUT[_NEAR_SAND_VALUE] = _LABEL_NEAR_SAND
_WARP_BORDER = 128  # value the warp gives grid cells outside the camera image


def label_grid(nav: np.ndarray, pitch_deg=0.0, roll_deg=0.0) -> np.ndarray:
    """Warp a camera navigable mask (bool, or uint8 nonzero = navigable) onto the top-down grid.

    Returns uint8 (rows, cols): 0 unknown (outside view / too near), 1 obstacle, 2 navigable.
    """
    return _warp_labels(_to_u8(nav), _frame_homography(pitch_deg, roll_deg))


def _frame_homography(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """ground_homography for a frame's tilt (the precomputed level one when level); a frame's warps share it."""
    return _LEVEL_H if (pitch_deg == 0.0 and roll_deg == 0.0) else ground_homography(pitch_deg, roll_deg)


def _warp_labels(nav8: np.ndarray, h: np.ndarray) -> np.ndarray:
    """label_grid for a uint8 0/255 mask (the hot path: no conversion) through the frame's homography ``h``."""
    warped = cv2.warpPerspective(nav8, h, (_GRID_COLS, _GRID_ROWS),
                                 flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=_WARP_BORDER)
    return cv2.bitwise_and(cv2.LUT(warped, _GRID_LUT), _GRID_USABLE_U8)


def _column_feet(labels8: np.ndarray):
    """Per image column: (has a foot, the level camera's range to it in m).

    The foot is the bottom pixel of the column's lowest run of VIEW_FOOT_RUN_PX non-sand pixels
    (labels8 == 0): where the first rock or wall face the column meets stands on the floor."""
    blocked = (labels8 == 0).view(np.uint8)
    run = cv2.erode(blocked, np.ones((VIEW_FOOT_RUN_PX, 1), np.uint8), anchor=(0, 0),
                    borderType=cv2.BORDER_CONSTANT, borderValue=0)  # 1 where this and the next rows down are blocked
    has_run = run.any(axis=0)
    foot = IMAGE_H - 1 - np.argmax(run[::-1], axis=0) + VIEW_FOOT_RUN_PX - 1
    below = foot + 0.5 - CY  # rows below the horizon
    has_foot = has_run & (below > 0)
    return has_foot, FOCAL_PX * CAMERA_HEIGHT_M / np.where(has_foot, below, 1.0)


def _occluded_grid(labels8: np.ndarray, h: np.ndarray) -> np.ndarray:
    """uint8 top-down grid, 1 where this frame's ground was hidden from the camera.

    The camera is 0.21 m above the floor, so the flat-floor projection paints any rock or wall face
    taller than that over all the ground behind it, out to the map range: a rock in the hub cast
    a wedge of wall votes over true floor from every side it was seen from (seed 12, shadows on).
    Ground more than VIEW_FOOT_MARGIN_M beyond a column's foot is hidden; its votes, floor and wall
    alike, count OCCLUDED_VOTE_WEIGHT of one, so the views that did see it decide.  Rows are cut
    at the level camera's range (like _column_feet); the warp (the frame's homography ``h``) applies its tilt."""
    has_foot, foot_m = _column_feet(labels8)
    fh = FOCAL_PX * CAMERA_HEIGHT_M
    cut = np.where(has_foot, CY - 0.5 + fh / (foot_m + VIEW_FOOT_MARGIN_M), -np.inf)  # first row still seen
    hidden = (np.arange(IMAGE_H, dtype=np.float64)[:, None] < cut[None, :]).view(np.uint8)
    warped = cv2.warpPerspective(hidden, h, (_GRID_COLS, _GRID_ROWS),
                                 flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return cv2.bitwise_and(warped, _GRID_USABLE_U8)  # ground behind the camera projects upside down: not in view


def _rock_detections(rock8: np.ndarray, pitch_deg, roll_deg):
    """Per gold blob: rover-frame floor point under its nearest (bottom) pixel, plus per-pixel polar.

    The blob's bottom row touches the floor, so projecting it is exact; its centroid
    would project too far because the rock stands above the floor.  A rock resting on
    a wall slope stands above the floor too, and the camera is so low (0.21 m) that
    its base then projects several times too far; the blob's width caps the distance
    (no sample looks wider than ROCK_MAX_WIDTH_M).  Returns (points [(x, y)], angles,
    dists) where every blob pixel column is placed on the floor at the blob's base row.

    A blob touching the image's left or right edge (ROCK_EDGE_PX) is a sample cut off by the
    frame: its lowest visible pixel need not be its base, nor its width the sample's, so it gives
    angles and dists but no point (a sample 0.6 m off the camera, 60 deg aside, showed as a sliver
    at the edge that placed it 4 m away, and the rover chased that place for 460 s: seed 137).
    """
    rock8 = _to_u8(rock8)
    bx, by, bw, bh = cv2.boundingRect(rock8)
    crop = rock8[by:by + bh, bx:bx + bw]
    n, labels, stats, _ = cv2.connectedComponentsWithStats(crop, connectivity=8)
    us_all, vs_all, blob_u, blob_v, blob_w, blob_of, cut = [], [], [], [], [], [], []
    for k in range(1, n):
        if stats[k, cv2.CC_STAT_AREA] < ROCK_MIN_PIXELS:
            continue
        x0, y0 = stats[k, cv2.CC_STAT_LEFT], stats[k, cv2.CC_STAT_TOP]
        w, h = stats[k, cv2.CC_STAT_WIDTH], stats[k, cv2.CC_STAT_HEIGHT]
        vs, us = np.nonzero(labels[y0:y0 + h, x0:x0 + w] == k)
        bottom = vs.max()
        cut.append(x0 + bx < ROCK_EDGE_PX or x0 + bx + w > rock8.shape[1] - ROCK_EDGE_PX)
        blob_of.append(np.full(us.shape, len(blob_u)))
        blob_u.append(us[vs == bottom].mean() + x0 + bx)
        blob_v.append(bottom + y0 + by)
        blob_w.append(w)
        us_all.append(us + x0 + bx)
        vs_all.append(np.full(us.shape, bottom + y0 + by))
    if not blob_u:
        return [], np.zeros(0), np.zeros(0)
    tilt = body_rotation(90.0, pitch_deg, roll_deg)
    cam = camera_position(pitch_deg, roll_deg)
    xr, yr, ok = pixel_to_rover(np.array(blob_u), np.array(blob_v), _tilt=tilt, _cam=cam)
    shrink = _width_shrink(xr, yr, np.array(blob_w, np.float64))
    xr, yr = _shrink_toward_camera(xr, yr, shrink)
    points = [(float(a), float(b)) for a, b, good, edge in zip(xr, yr, ok, cut) if good and not edge]
    px, py, pv = pixel_to_rover(np.concatenate(us_all), np.concatenate(vs_all), _tilt=tilt, _cam=cam)
    px, py = _shrink_toward_camera(px, py, shrink[np.concatenate(blob_of)])
    dists, angles = to_polar_coords(px[pv], py[pv])
    return points, angles, dists


def _width_shrink(xr, yr, width_px):
    """Per blob, factor (<= 1) that brings its floor distance from the camera within the width cap."""
    with np.errstate(invalid="ignore", divide="ignore"):
        from_cam = np.hypot(xr - CAMERA_FORWARD_M, yr)
        cap = FOCAL_PX * ROCK_MAX_WIDTH_M / np.maximum(width_px, 1.0)
        return np.where(from_cam > cap, cap / from_cam, 1.0)


def _shrink_toward_camera(xr, yr, factor):
    return CAMERA_FORWARD_M + (xr - CAMERA_FORWARD_M) * factor, yr * factor


def _finite(v) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def _signed(deg) -> float:
    d = float(deg) % 360.0
    return d - 360.0 if d > 180.0 else d


def vision_overlay(rgb: np.ndarray, nav: np.ndarray, rock: np.ndarray) -> np.ndarray:
    """Camera view with thresholds colour-coded: blue navigable, red obstacle (below horizon), yellow rock."""
    return _overlay_u8(rgb, _to_u8(nav), _to_u8(rock))


def _overlay_u8(rgb: np.ndarray, nav8: np.ndarray, rock8: np.ndarray, shade8: Optional[np.ndarray] = None
                ) -> np.ndarray:
    """shade8 (sand in shadow, 0/255, disjoint from nav8) is drawn half blue."""
    known = cv2.bitwise_or(nav8, rock8)
    blue = nav8
    if shade8 is not None:
        known = cv2.bitwise_or(known, shade8)
        blue = cv2.bitwise_or(nav8, np.bitwise_and(shade8, np.uint8(128)))
    obs8 = cv2.bitwise_not(known)
    obs8[:_HORIZON_ROW] = 0
    overlay = cv2.merge([cv2.bitwise_or(obs8, rock8), rock8, blue])
    return cv2.addWeighted(rgb, VISION_BLEND, overlay, 1.0 - VISION_BLEND, 0.0)


def _vote(mem: PerceptionMemory, grid: np.ndarray, x: float, y: float, yaw: float, occluded=None):
    """Add this frame's distance-weighted votes; returns the changed map window (y0, y1, x0, x1).
    ``occluded`` (uint8 grid like ``grid``, 1 = hidden ground, :func:`_occluded_grid`; None: none hidden)
    scales those cells' votes by OCCLUDED_VOTE_WEIGHT.

    One compiled pass (:func:`_vote_kernel`) instead of a dozen NumPy passes over the ~7000 seen
    cells: the same arithmetic in the same order, so the maps are bit for bit what the NumPy
    version (kept in tests/test_fast_paths_exact.py as the reference) gives.
    """
    a = math.radians(yaw)
    window = np.zeros(4, np.int64)
    if occluded is None:
        occluded = np.zeros(grid.shape, np.uint8)
    found = _vote_kernel(grid.ravel(), occluded.ravel(), float(OCCLUDED_VOTE_WEIGHT), _MAP_CELLS, _MAP_X, _MAP_Y,
                         _MAP_WEIGHT, _MAP_LOOK, _MAP_DIST, _MAP_BAND, float(x), float(y), math.cos(a), math.sin(a),
                         float(NAV_VOTE_WEIGHT), float(OBS_VOTE_WEIGHT), mem.nav_votes, mem.obs_votes, mem.shade_votes,
                         mem.dim_shade_votes, mem.near_sand_votes, mem.look_range, mem.band_nav_votes, mem.band_votes,
                         window)
    return (int(window[0]), int(window[1]), int(window[2]), int(window[3])) if found else None


@njit(cache=True)
def _vote_kernel(labels, occluded, occluded_weight, cells, map_x, map_y, map_weight, map_look, map_dist, map_band,
                 xpos, ypos, c, s, nav_weight, obs_weight, nav_votes, obs_votes, shade_votes, dim_votes, near_votes,
                 look_range, band_nav, band_all, window):
    """The votes of the grid cells ``cells`` (flat indices into ``labels``) at pose (xpos, ypos, yaw
    with cos c, sin s), those where ``occluded`` is set weighted by ``occluded_weight``; writes (y0, y1, x0, x1)
    into ``window`` and returns False when no seen cell falls on the map.

    Module constants are passed in, never read as globals (numba would freeze them at compile
    time and a sweep that sets them would change nothing).  Bit-exactness with the NumPy version: world coordinates are ``xpos + x c - y s`` and
    ``ypos + x s + y c`` evaluated left to right in float64 (no fast-math, so no fused
    multiply-add); each map cell's votes are summed in float64 in cell order, as ``np.bincount``
    sums them, and added once to the float32 map through float64, as ``float32 += float64`` does.
    """
    size_y, size_x = nav_votes.shape
    n = cells.size
    ix = np.empty(n, np.int64)
    iy = np.empty(n, np.int64)
    keep = np.empty(n, np.int64)
    m = 0
    x0, y0 = size_x, size_y
    x1 = y1 = -1
    for k in range(n):
        if labels[cells[k]] == _LABEL_UNKNOWN:
            continue
        xw = xpos + map_x[k] * c - map_y[k] * s
        yw = ypos + map_x[k] * s + map_y[k] * c
        cx = int(math.floor(xw))
        cy = int(math.floor(yw))
        if cx < 0 or cx >= size_x or cy < 0 or cy >= size_y:
            continue
        ix[m], iy[m], keep[m] = cx, cy, k
        m += 1
        x0, x1 = min(x0, cx), max(x1, cx)
        y0, y1 = min(y0, cy), max(y1, cy)
    if m == 0:
        return False
    x1 += 1
    y1 += 1
    cols = x1 - x0
    size = (y1 - y0) * cols
    nav_sum = np.zeros(size)
    obs_sum = np.zeros(size)
    shade_sum = np.zeros(size)
    dim_sum = np.zeros(size)
    near_sum = np.zeros(size)
    bands = band_nav.shape[0]
    band_nav_sum = np.zeros(bands * size)
    band_all_sum = np.zeros(bands * size)
    for j in range(m):
        k = keep[j]
        label = labels[cells[k]]
        w = map_weight[k]
        if occluded[cells[k]]:
            w = w * occluded_weight
        cell = (iy[j] - y0) * cols + (ix[j] - x0)
        bcell = map_band[k] * size + cell
        if label == _LABEL_NAV:
            nav_sum[cell] += w * nav_weight
            band_nav_sum[bcell] += w * nav_weight
            band_all_sum[bcell] += w * nav_weight
        else:
            obs_sum[cell] += w * obs_weight
            band_all_sum[bcell] += w * obs_weight
            if label == _LABEL_SHADE:
                shade_sum[cell] += w * obs_weight
            elif label == _LABEL_DIM_SHADE:
                dim_sum[cell] += w * obs_weight
            elif label == _LABEL_NEAR_SAND:
                near_sum[cell] += w * obs_weight
        if map_look[k] and map_dist[k] < look_range[iy[j], ix[j]]:
            look_range[iy[j], ix[j]] = map_dist[k]
    for r in range(y1 - y0):
        for q in range(cols):
            cell = r * cols + q
            yy, xx = y0 + r, x0 + q
            nav_votes[yy, xx] = np.float32(np.float64(nav_votes[yy, xx]) + nav_sum[cell])
            obs_votes[yy, xx] = np.float32(np.float64(obs_votes[yy, xx]) + obs_sum[cell])
            shade_votes[yy, xx] = np.float32(np.float64(shade_votes[yy, xx]) + shade_sum[cell])
            dim_votes[yy, xx] = np.float32(np.float64(dim_votes[yy, xx]) + dim_sum[cell])
            near_votes[yy, xx] = np.float32(np.float64(near_votes[yy, xx]) + near_sum[cell])
            for b in range(bands):
                band_nav[b, yy, xx] = np.float32(np.float64(band_nav[b, yy, xx]) + band_nav_sum[b * size + cell])
                band_all[b, yy, xx] = np.float32(np.float64(band_all[b, yy, xx]) + band_all_sum[b * size + cell])
    window[0], window[1], window[2], window[3] = y0, y1, x0, x1
    return True


def _pixel_labels(img: np.ndarray):
    """(labels8, nav8, rock8, shade8) of a camera frame in one compiled pass.

    labels8: 255 light sand, _SHADE_VALUE sand in shadow, _DIM_SHADE_VALUE darker sand in shadow,
    _NEAR_SAND_VALUE near-hue sand, 0 anything else (what label_grid warps); the others uint8 0/255 masks as
    navigable_mask, rock_mask and shadowed_sand_mask give them.  Bit for bit what the OpenCV/NumPy chain of
    those functions gives (tests/test_fast_paths_exact.py), at a fraction of its dozen passes.
    """
    if SHADE_SAND_WINDOW_H_PX != 1:  # the kernel slides a one-row window only
        return _pixel_labels_opencv(img)
    h, w = img.shape[:2]
    labels8, nav8, rock8, shade8 = (np.empty((h, w), np.uint8) for _ in range(4))
    _pixel_labels_kernel(img, np.array(NAV_RGB_MIN, np.int64), np.array(ROCK_RGB_MIN, np.int64),
                         np.array(ROCK_RGB_MAX, np.int64), int(SHADE_SAND_MIN_R), int(POCKET_SAND_MIN_R),
                         float(SHADE_SAND_MIN_G_PER_R), float(SHADE_SAND_MIN_B_PER_R),
                         float(NEAR_SAND_MIN_G_PER_R), float(NEAR_SAND_MIN_B_PER_R),
                         float(SHADE_SAND_MAX_SD) ** 2, int(SHADE_SAND_WINDOW_W_PX), int(SHADE_SAND_FIRST_ROW),
                         _SHADE_VALUE, _DIM_SHADE_VALUE, _NEAR_SAND_VALUE, labels8, nav8, rock8, shade8)
    return labels8, nav8, rock8, shade8


def _pixel_labels_opencv(img: np.ndarray):
    """_pixel_labels as a chain of OpenCV/NumPy calls (the reference the kernel is tested against)."""
    nav8 = cv2.inRange(img, NAV_RGB_MIN, (255, 255, 255))
    rock8 = cv2.inRange(img, ROCK_RGB_MIN, ROCK_RGB_MAX)
    sand_hue8, near_hue8 = _smooth_sand_u8(img)
    shade8 = cv2.bitwise_and(sand_hue8, cv2.bitwise_not(nav8))
    dim8 = cv2.bitwise_and(shade8, cv2.inRange(img, (0, 0, 0), (POCKET_SAND_MIN_R - 1, 255, 255)))
    labels8 = cv2.bitwise_or(nav8, np.bitwise_and(shade8, np.uint8(_SHADE_VALUE)))
    labels8 = cv2.subtract(labels8, np.bitwise_and(dim8, np.uint8(_SHADE_VALUE - _DIM_SHADE_VALUE)))
    near8 = cv2.bitwise_and(near_hue8, cv2.bitwise_not(cv2.bitwise_or(nav8, shade8)))
    labels8 = cv2.bitwise_or(labels8, np.bitwise_and(near8, np.uint8(_NEAR_SAND_VALUE)))
    return labels8, nav8, rock8, shade8


@njit(cache=True)
def _pixel_labels_kernel(img, nav_min, rock_min, rock_max, shade_min_r, pocket_min_r, g_per_r, b_per_r, near_g_per_r,
                         near_b_per_r, max_var, win_w, first_row, shade_value, dim_value, near_value, labels8, nav8,
                         rock8, shade8):
    """See _pixel_labels.  The texture test is _smooth_sand_u8's: the red mean and mean square over a
    win_w x 1 window (reflected at the image edge) as OpenCV's boxFilter computes them for float32
    (exact integer sums, times 1/win_w in float64, rounded to float32), then their float32 variance."""
    h, w = img.shape[0], img.shape[1]
    g_ratio, b_ratio = np.float32(g_per_r), np.float32(b_per_r)
    near_g, near_b = np.float32(near_g_per_r), np.float32(near_b_per_r)
    inv = 1.0 / win_w
    half = win_w // 2
    for v in range(h):
        for u in range(w):
            r, g, b = img[v, u, 0], img[v, u, 1], img[v, u, 2]
            nav = r >= nav_min[0] and g >= nav_min[1] and b >= nav_min[2]
            rock = (rock_min[0] <= r <= rock_max[0] and rock_min[1] <= g <= rock_max[1]
                    and rock_min[2] <= b <= rock_max[2])
            shade = False
            near = False
            if v >= first_row and not nav and r >= shade_min_r:
                red = np.float32(r)
                hue = g >= g_ratio * red and b >= b_ratio * red
                if hue or (g >= near_g * red and b >= near_b * red):
                    s1 = 0
                    s2 = 0
                    for k in range(u - half, u - half + win_w):
                        kk = -k - 1 if k < 0 else (2 * w - k - 1 if k >= w else k)
                        x = np.int64(img[v, kk, 0])
                        s1 += x
                        s2 += x * x
                    mean = np.float32(s1 * inv)
                    mean_sq = np.float32(s2 * inv)
                    smooth = mean_sq - mean * mean <= max_var
                    shade = smooth and hue
                    near = smooth and not hue
            nav8[v, u] = 255 if nav else 0
            rock8[v, u] = 255 if rock else 0
            shade8[v, u] = 255 if shade else 0
            labels8[v, u] = 255 if nav else ((dim_value if r < pocket_min_r else shade_value) if shade
                                             else (near_value if near else 0))


def _polar_outputs(grid: np.ndarray):
    """(nav_angles, nav_dists, obs_angles, obs_dists) of a label grid, in grid (C) order: the cells
    labelled navigable, and the seen ones that are not, as ``_GRID_ANGLE[mask]`` would list them."""
    n_nav, n_obs = _count_labels(grid.ravel(), _LABEL_NAV, _LABEL_UNKNOWN)
    out = (np.empty(n_nav, np.float32), np.empty(n_nav, np.float32), np.empty(n_obs, np.float32),
           np.empty(n_obs, np.float32))
    _gather_polar(grid.ravel(), _GRID_ANGLE.ravel(), _GRID_DIST.ravel(), _LABEL_NAV, _LABEL_UNKNOWN, *out)
    return out


@njit(cache=True)
def _count_labels(labels, nav_label, unknown_label):
    n_nav = n_obs = 0
    for lab in labels:
        if lab == nav_label:
            n_nav += 1
        elif lab != unknown_label:
            n_obs += 1
    return n_nav, n_obs


@njit(cache=True)
def _gather_polar(labels, angle, dist, nav_label, unknown_label, nav_a, nav_d, obs_a, obs_d):
    i = j = 0
    for k in range(labels.size):
        lab = labels[k]
        if lab == nav_label:
            nav_a[i], nav_d[i] = angle[k], dist[k]
            i += 1
        elif lab != unknown_label:
            obs_a[j], obs_d[j] = angle[k], dist[k]
            j += 1


def perception_step(rover):
    """Fill the perception block of RoverState from rover.img and the pose; returns rover."""
    mem = get_memory(rover)
    rover.map_updated = False
    img = getattr(rover, "img", None)
    if img is None or getattr(img, "shape", None) != (IMAGE_H, IMAGE_W, 3):
        return rover  # no frame: keep the previous perception
    if img.dtype != np.uint8 or not img.flags.c_contiguous:
        img = np.ascontiguousarray(img, dtype=np.uint8)
    mem.frames_seen += 1
    pitch = _signed(rover.pitch) if _finite(rover.pitch) else 0.0
    roll = _signed(rover.roll) if _finite(rover.roll) else 0.0

    labels8, nav8, rock8, shade8 = _pixel_labels(img)
    homography = _frame_homography(pitch, roll)
    grid = _warp_labels(labels8, homography)
    mem.last_grid = grid

    # decision outputs (always, even when tilted: the warp already accounts for tilt);
    # the rover drives on bright sand only, so shadowed sand is an obstacle here
    rover.nav_angles, rover.nav_dists, rover.obs_angles, rover.obs_dists = _polar_outputs(grid)

    pos = getattr(rover, "pos", (np.nan, np.nan))
    pose_ok = pos is not None and len(pos) == 2 and _finite(pos[0]) and _finite(pos[1]) and _finite(rover.yaw)
    level = abs(pitch) <= TILT_GATE_DEG and abs(roll) <= TILT_GATE_DEG
    votes = level and getattr(rover, "mode", None) not in NO_VOTE_MODES

    window = None
    if pose_ok and votes:
        mem.last_occluded = _occluded_grid(labels8, homography)
        window = _vote(mem, grid, float(pos[0]), float(pos[1]), float(rover.yaw), mem.last_occluded)
        mem.frames_mapped += 1
        rover.map_updated = True

    # rocks: cheap presence test first, blob analysis only when gold is in view
    if cv2.countNonZero(rock8) >= ROCK_MIN_PIXELS:
        points, rock_angles, rock_dists = _rock_detections(rock8, pitch, roll)
        rover.rock_angles, rover.rock_dists = rock_angles, rock_dists
        if pose_ok and abs(pitch) <= ROCK_TILT_GATE_DEG and abs(roll) <= ROCK_TILT_GATE_DEG:
            for xr, yr in points:
                d = math.hypot(xr, yr)
                if d <= ROCK_MAX_RANGE_M:
                    xw, yw = rover_to_world(xr, yr, float(pos[0]), float(pos[1]), float(rover.yaw))
                    _remember_rock(mem, float(xw), float(yw), 1.0 / max(d, 0.5))
    else:
        rover.rock_angles, rover.rock_dists = np.zeros(0), np.zeros(0)

    rover.rocks_world = rocks_from_memory(mem)
    if getattr(rover, "worldmap", None) is not mem.worldmap or mem.worldmap is None:
        mem.worldmap = render_worldmap(mem)  # first frame, or someone replaced the array: full rebuild
        mem.drive_worldmap = render_worldmap(mem, drive=True)
    elif window is not None or rover.rocks_world != mem.drawn_rocks:
        render_worldmap(mem, mem.worldmap, window if window is not None else (0, 0, 0, 0))
        if window is not None:
            render_worldmap(mem, mem.drive_worldmap, window, drive=True)
    rover.worldmap = mem.worldmap
    if hasattr(rover, "defer_vision_image"):  # RoverState: drawn only if someone looks (insets, dashboard)
        rover.defer_vision_image(lambda: _overlay_u8(img, nav8, rock8, shade8))
    else:
        rover.vision_image = _overlay_u8(img, nav8, rock8, shade8)
    return rover
