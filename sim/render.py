"""The rover camera of the twin: pose -> the 320x160 RGB frame the simulator would show.

How: everything static (terrain, rocks, sand texture, sun shading, baked shadows, unless the world
has cast_shadows off) is baked once into 0.1 m rasters (solid top, overhang gap, colour). A frame is a
column-wise heightfield raymarch (numba): each image column is walked from the
bottom row up, every ray resuming at the horizontal distance where the ray below
hit (exact for a level camera, a few-pixel approximation under pitch/roll), with
1 m max-height cells skipped in one jump. Every 16th column is marched first; the columns between
take the average of their two neighbours (8 apart, only where both hits are at least 16 m away; then 4, 2 and 1
apart at any distance) wherever both hit open terrain (or both rock) at nearly one depth and colour (column
coherence), and march the rest. Sample rocks are small shaded ellipsoids
drawn over it with a depth test.

Poses outside the world are clamped into it; a camera inside rock sees that rock
(no crash). Non-finite poses raise ValueError.
"""
from __future__ import annotations

import logging
import math

import cv2
import numpy as np
from llvmlite import ir as llvm_ir
from numba import njit
from numba import types as nb_types
from numba.extending import intrinsic

from sim.world import World

log = logging.getLogger(__name__)

# --- camera (../shared/udacity-rover/world/camera.json) ---
IMAGE_W, IMAGE_H = 320, 160  # frame size, px
FOCAL_PX = 114.251841  # pinhole focal length, px (vertical FOV 70 deg)
CX, CY = 160.0, 80.0  # principal point, px
CAMERA_MOUNT_UP_M = 0.2391  # camera above the rover root, m
CAMERA_MOUNT_FORWARD_M = 0.4287  # camera ahead of the rover root, m
ROOT_BELOW_GROUND_M = 0.0245  # rover root sits this far below the ground (suspension bottomed out), m
ROCK_NEAR_CELL_M = 0.5  # cell of the "any rock within a wheel's reach" raster that skips the wheel lookups, m
ROCK_LIFT_MAX_M = 0.5  # a rock top at most this far above the terrain under a wheel carries that wheel (the camera rises with it), m
JPEG_QUALITY = 75  # Texture2D.EncodeToJPG default quality

# --- raymarch ---
FAR_M = 120.0  # rays that hit nothing within this horizontal distance show the far colour, m
FINE_STEP_MIN_M = 0.04  # smallest march step near the camera, m
FINE_STEP_PER_M = 0.012  # march step growth with distance, m per m
REFINE_ITERS = 4  # bisection steps locating a rock surface between two march samples
COARSE_CELL_M = 1.0  # empty-space-skipping cell size, m
BLOCK_CELLS = 8  # coarse cells per side of the second skipping level (sky and far rays), count
COLUMN_SHARE_MAX_M = 120.0  # a column may average its neighbours' terrain hits nearer than this (0: never), m
COLUMN_SHARE_RATIO = 0.08  # ... when their depths differ by at most this fraction (0.06 before round 11)
COLUMN_SHARE_LEVELS = 12  # ... and their colours by at most this in every channel, grey levels
COLUMN_SHARE_TIERS = 3  # 1: odd columns may share; 2: so may columns 2 mod 4; 3: so may columns 4 mod 8 (every 8th is marched; 2 before round 11), count
COLUMN_SHARE_FAR_TIERS = 1  # tiers above those that share only hits at least COLUMN_SHARE_FAR_MIN_M away (1: every 16th column marched; 0 before round 12), count
COLUMN_SHARE_FAR_MIN_M = 16.0  # ... both neighbours' hits at least this far, m
COLUMN_SHARE_ROCK = True  # rock hits may be averaged too (both neighbours on rock, same colour test)
COLUMN_SHARE_ROCK_RATIO = 0.15  # ... when their depths differ by at most this fraction (dark walls: far below the navigable threshold)
UNDER_OVERHANG = 4  # flag added to a pixel's hit kind when its ray passed under rock (such hits are not shared)
DARK_LUT_STEP_M = 0.02  # distance resolution of the distance-darkening table, m
DARK_LUT_MAX_M = 200.0  # the table's reach (farther hits use its last entry), m
TEX_GROUND, TEX_COLOUR = 0, 1  # channels of the baked texel array (0.1 m height, 0xBBGGRR bits)
SLAB_LO, SLAB_HI = 0, 1  # channels of the baked slab array (rock bottom, rock top), m
COARSE_MAX, COARSE_GROUND, COARSE_BOTTOM, COARSE_FLAT = 0, 1, 2, 3  # channels of the baked coarse-cell array
WEIGHT_BITS = 13  # fixed-point bits of the colour blend weights (blend error < 0.1 grey level)
LANE_BITS = 21  # bits per channel lane of a packed colour: 255 x 2**13 x (1 + rounding) fits
GAP_MIN_M = 0.3  # rock bottom this far above the ground leaves a see-through gap, m
GAP_MAX_GROUND_M = 0.5  # gaps are kept only over floor this low (wall rocks are drawn solid), m
SHADOW_GRID_STRIDE = 2  # shadows are baked on every N-th vertex of the 0.1 m grid

# --- colours and lighting (fitted on the 283 test_dataset frames, see README section twin) ---
# median real colour of terrain pixels by sand weight (near the rover, sunlit), uint8 RGB
# (the 0.70/0.75 entries are nudged so blue crosses the 160 threshold at weight 0.735, where
# real near pixels are navigable half the time)
SAND_LUT_WEIGHT = (0.0, 0.3, 0.4, 0.55, 0.65, 0.70, 0.75, 0.85, 0.925, 0.97, 1.0)
SAND_LUT_RGB = ((38, 26, 22), (70, 55, 48), (113, 95, 86), (146, 128, 118), (167, 149, 137),
                (182, 163, 151), (196, 177, 164), (208, 189, 175), (232, 211, 197), (242, 221, 206),
                (244, 223, 208))
ROCK_RGB = (22, 16, 13)  # boulder (rock mesh) colour, uint8 RGB (real median 19-30)
SKY_RGB = (126, 117, 112)  # sky, uint8 RGB (real median)
FAR_RGB = (126, 117, 112)  # rays beyond FAR_M, uint8 RGB
SUN_AZIMUTH_DEG = 295.0  # direction the sunlight comes FROM, degrees CCW from +x (fitted)
SUN_ELEVATION_DEG = 60.0  # sun elevation above the horizon, degrees (fitted)
SHADOW_FACTOR = 0.6  # the first cast-shadow look's shadow brightness (now sim/shading.py CAST_SHADOW_FACTOR), 0..1
SHADOW_BLUR_M = 1.5  # soft shadow edge (Gaussian sigma; fitted, real edges are wide penumbrae), m
SLOPE_SHADE = 0.7  # how strongly faces turned from the sun darken (0 = flat look)
SHADOW_STEP_M = 0.2  # march step of the shadow rays baked at load, m
TEXTURE_AMPLITUDE = 0.45  # relative brightness noise on walls and rocks (not on sand), 0..1
TEXTURE_CELLS = (400, 1000)  # texture noise octaves: grid sides over the world, cells
UNDERSIDE_SHADE = 0.45  # darkening of the underside of overhanging rock, 0..1
UNDERSIDE_BAND_M = 0.3  # banded look (Renderer.smooth_underside False): that darkening within this of the bottom, m
UNDERSIDE_RAMP_M = 1.0  # smooth look: the darkening fades linearly over this height above the rock's bottom, m
UNDERSIDE_BLUR_M = 0.4  # smooth look: overhang colours averaged across neighbouring 0.1 m columns (Gaussian sigma), m
DIST_DARKEN = 0.17  # fraction of brightness lost far away (real sand 242 -> 202 at 30 m)
DIST_SCALE_M = 8.0  # e-folding distance of that darkening, m

# --- sample rocks ---
SAMPLE_RGB = (1.0, 0.82, 0.03)  # gold, 0..1 (Unity (1, 0.85, 0)); fitted to the cores of close real blobs through the JPEG (megalphian: blue median 4, G/R 0.825; royalejandro, held out: 3, 0.827)
SAMPLE_WIDTH_PER_SCALE_M = 0.37  # sample width at prefab scale 1, m
SAMPLE_HEIGHT_PER_SCALE_M = 0.32  # sample height at prefab scale 1, m
SAMPLE_SINK_M = 0.02  # samples are sunk this much into the floor, m
SAMPLE_MIN_SHADE = 0.62  # darkest shading of a sample, fraction of full colour
# --- tyre tracks (sim/tracks.py lays them; simulator-facts.md section 1) ---
TRACK_WHITE_RGB = (218.0, 194.0, 178.0)  # what a white surface on the lit floor looks like, 0..255 RGB
# (fitted on royalejandro frames 1522, 2240, 3758, 5926: core track pixels / the Tracks.mat tint)
TRACK_DRAW_MAX_M = 30.0  # quads farther than this (under half a pixel) are not drawn, m
TRACK_DEPTH_TOLERANCE_M = 0.03  # a quad shows where it is no farther than this behind the surface hit, m
TRACK_ANISO_MAX = 1.0  # tread mip level from the footprint's long axis over this (1: isotropic, as the real frames show; huge: short axis), ratio
SAMPLE_GROUND_CACHE = 256  # sample spots whose ground height a renderer remembers, count
SAMPLE_RGB_255 = np.array(SAMPLE_RGB) * 255.0  # the same gold in 0..255 (read by the numba drawer)


def _rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


# Unity (x right, y up, z forward) -> world (x east, y north, z up)
_UNITY_TO_WORLD = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])


def body_rotation(yaw_deg, pitch_deg, roll_deg) -> np.ndarray:
    """Rover body axes in world (x east, y north, z up): columns = right, up, forward.

    Unity: R = Ry(90 - yaw) . Rx(pitch) . Rz(roll); positive pitch nose down,
    positive roll right side up.
    """
    r_unity = _rot_y(math.radians(90.0 - yaw_deg)) @ _rot_x(math.radians(pitch_deg)) @ _rot_z(
        math.radians(roll_deg))
    return _UNITY_TO_WORLD @ r_unity


def validate_pose(pose):
    """(x, y, yaw, pitch, roll[, root_z]) as floats; ValueError on wrong length or non-finite."""
    try:
        values = [float(v) for v in pose]
    except (TypeError, ValueError):
        raise ValueError(f"pose must be numbers (x, y, yaw, pitch, roll), got {pose!r}") from None
    if len(values) not in (5, 6):
        raise ValueError(f"pose must be (x, y, yaw, pitch, roll[, root_z]), got {len(values)} values")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"pose has a non-finite value: {values}")
    return values


def encode_jpeg(rgb: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """JPEG bytes of an RGB uint8 image, like Texture2D.EncodeToJPG."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buf.tobytes()


# ---------------------------------------------------------------------- baking
def _bilinear_sample(grid: np.ndarray, cell_m: float, xs: np.ndarray, ys: np.ndarray):
    """Bilinear sample a vertex grid at world points (clamped)."""
    n = grid.shape[0] - 1
    fx = np.clip(xs / cell_m, 0, n - 1e-6)
    fy = np.clip(ys / cell_m, 0, n - 1e-6)
    return cv2.remap(grid.astype(np.float32), fx.astype(np.float32), fy.astype(np.float32),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


@njit(cache=True, nogil=True)
def _shadow_kernel(top, cell, sx, sy, tan_e, zmax, step, out):
    """1 where a vertex is hidden from the sun by higher terrain or rock."""
    n = top.shape[0]
    for r in range(n):
        for c in range(n):
            x0 = c * cell
            y0 = r * cell
            z0 = top[r, c] + 0.02
            s = step
            while True:
                z = z0 + s * tan_e
                if z > zmax:
                    break
                fx = (x0 + s * sx) / cell
                fy = (y0 + s * sy) / cell
                if fx < 0.0 or fy < 0.0 or fx > n - 1 or fy > n - 1:
                    break
                ci = int(fx + 0.5)
                ri = int(fy + 0.5)
                if top[ri, ci] > z:
                    out[r, c] = 1
                    break
                s += step


def bake_rasters(world: World):
    """Solid top, overhang gap and lit colour on a 0.1 m vertex grid, plus 1 m max cells."""
    n = world.rock_top.shape[0]
    cell = world.rock_cell_m
    coords = np.arange(n, dtype=np.float32) * np.float32(cell)
    xs, ys = np.meshgrid(coords, coords)
    ground = _bilinear_sample(world.terrain_height, world.terrain_cell_m, xs, ys)
    rock_top, rock_bottom = world.rock_top, world.rock_bottom
    has_rock = rock_top > ground + 0.01
    top = np.where(has_rock, rock_top, ground).astype(np.float32)
    has_gap = has_rock & (rock_bottom > ground + GAP_MIN_M) & (ground < GAP_MAX_GROUND_M)
    # rock slab [slab_lo, slab_hi] at the nearest cell; without a gap it reaches below the ground
    slab_lo = np.where(has_gap, rock_bottom, np.where(has_rock, -1e9, 1e9)).astype(np.float32)
    slab_hi = np.where(has_rock, rock_top, -1e9).astype(np.float32)
    # sand weight texels -> vertex grid
    sand_cell = world.sand_cell_m
    sand = cv2.remap(world.sand_weight.astype(np.float32), xs / sand_cell - 0.5, ys / sand_cell - 0.5,
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    az, el = math.radians(SUN_AZIMUTH_DEG), math.radians(SUN_ELEVATION_DEG)
    sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])

    def sun_shade(height):
        """Lambert shading of a height raster relative to level ground (1 on the floor)."""
        gy, gx = np.gradient(cv2.GaussianBlur(height, (3, 3), 0), cell)
        lam = np.clip((-gx * sun[0] - gy * sun[1] + sun[2]) / np.sqrt(gx * gx + gy * gy + 1.0), 0.0, 1.0)
        return (1.0 - SLOPE_SHADE) + SLOPE_SHADE * lam / math.sin(el)

    # both quality levels darken the floor the terrain hides from the sun, by different factors;
    # only the terrain casts shadows: the real frames show sunlit floor under and beside the rocks
    k = SHADOW_GRID_STRIDE
    coarse_ground = np.ascontiguousarray(ground[::k, ::k])
    shadow_c = np.zeros(coarse_ground.shape, np.uint8)
    _shadow_kernel(coarse_ground, cell * k, math.cos(az), math.sin(az), math.tan(el),
                   float(ground.max()), SHADOW_STEP_M, shadow_c)
    shadow = cv2.resize(shadow_c.astype(np.float32), (n, n), interpolation=cv2.INTER_LINEAR)
    shadow = cv2.GaussianBlur(shadow, (0, 0), SHADOW_BLUR_M / cell)
    shadow = np.where(has_gap, 0.0, shadow)  # the floor under the overhang looks sunlit in the real frames
    lut_rgb = np.array(SAND_LUT_RGB, np.float32)
    ground_rgb = np.stack([np.interp(sand, SAND_LUT_WEIGHT, lut_rgb[:, ch]) for ch in range(3)], -1)
    rng = np.random.default_rng(12345)  # fixed: the texture is part of the look, not random per run
    noise = sum(cv2.resize(rng.uniform(-1, 1, (cells, cells)).astype(np.float32), (n, n),
                           interpolation=cv2.INTER_CUBIC) for cells in TEXTURE_CELLS) / len(TEXTURE_CELLS)
    rough = 1.0 + TEXTURE_AMPLITUDE * noise * np.clip((0.7 - sand) / 0.4, 0.0, 1.0)
    # terrain colour everywhere (what a ray hitting the ground sees), bilinear in the kernel
    from sim.shading import cast_shadow_cover, floor_red_gain, shadowless_wall_foot_light, wall_foot_red_grain

    cover = cast_shadow_cover(shadow) if world.cast_shadows else shadow
    darkening = (1.0 - _shadow_factor(world)) * cover
    light = sun_shade(ground) * (1.0 - darkening)
    if not world.cast_shadows:  # the quality levels without cast shadows draw the wall feet darker (sim/shading.py item 7)
        light = light * shadowless_wall_foot_light(sand)
    ground_rgb[..., 0] *= floor_red_gain(sand, darkening)  # wall feet and shaded floor redder (sim/shading.py item 6)
    ground_rgb[..., 0] *= wall_foot_red_grain(sand)  # wall feet vary in hue from texel to texel (sim/shading.py item 8)
    colour_ground = np.clip(ground_rgb * (rough * light)[..., None], 0, 255).astype(np.uint8)
    # rock colour (what a ray hitting a rock slab sees), nearest cell in the kernel
    rock_rgb = np.array(ROCK_RGB, np.float32) * (1.0 + TEXTURE_AMPLITUDE * noise)[..., None]
    colour_rock = np.clip(rock_rgb * sun_shade(top)[..., None], 0, 255).astype(np.uint8)
    colour_rock = np.where(has_rock[..., None], colour_rock, colour_ground)
    rock64 = pack_rgb(colour_rock)
    # rock whose mesh bottom is off the ground overhangs (drawn with a gap over low floor, solid elsewhere)
    overhang = has_rock & (rock_bottom > ground + GAP_MIN_M)
    overhang_rc = np.nonzero(overhang)
    rock64_banded_overhang = rock64[overhang_rc].copy()  # the overhangs' per-column colours (the banded look's)
    rock64[overhang_rc] = pack_rgb(_smooth_over(colour_rock, overhang, UNDERSIDE_BLUR_M / cell)[overhang_rc])
    kc = int(round(COARSE_CELL_M / cell))
    # the kernel marches the terrain on its own grid: bound each coarse cell by that grid's vertices
    tmax, tmin = _terrain_cell_range(world.terrain_height, world.terrain_cell_m, COARSE_CELL_M,
                                     cmax_shape := (n - 1) // kc)
    cmax = np.maximum(_coarse_max(top, kc), tmax)
    # free band under overhangs per coarse cell: above every ground, below every rock bottom
    cground = np.maximum(_coarse_max(ground, kc), tmax)
    cbottom = -_coarse_max(-slab_lo, kc)  # lowest rock bottom (-1e9 solid rock, 1e9 open sky)
    rock = _coarse_max(slab_hi, kc) > -1e8
    # a level floor without rock: the kernel intersects such cells analytically
    cflat = np.where((tmax == tmin) & ~rock, tmax, np.nan).astype(np.float32)
    assert cflat.shape == (cmax_shape, cmax_shape)
    # the four per-cell figures the kernel reads on entering a coarse cell, side by side (one cache line)
    coarse = np.stack([cmax, cground, cbottom, cflat], axis=-1).astype(np.float32)
    return {"cflat": cflat, "coarse": coarse, "bmax": _block_max(cmax, BLOCK_CELLS),
            **_kernel_rasters(ground, slab_lo, slab_hi, colour_ground), "rock64": rock64,
            "overhang_rc": overhang_rc, "rock64_banded_overhang": rock64_banded_overhang,
            "top": top, "ground": ground.astype(np.float32), "slab_lo": slab_lo, "slab_hi": slab_hi,
            "has_gap": has_gap, "colour": colour_ground, "colour_rock": colour_rock, "cmax": cmax,
            "cground": cground, "cbottom": cbottom,
            "sand": sand.astype(np.float32), "shadow": shadow.astype(np.float32),
            "has_rock": has_rock, "light": light.astype(np.float32), "sun": sun}


def _rock_near_raster(world) -> np.ndarray:
    """bool raster, ROCK_NEAR_CELL_M cells: True where a rock cell lies within 1 m (beyond the wheels' 0.55 m from
    the root) of any point of the cell, so `Renderer._rock_lift` looks under the wheels only there."""
    k = max(1, int(round(ROCK_NEAR_CELL_M / float(world.rock_cell_m))))
    rock = world.rock_top > 0.0
    n = -(-rock.shape[0] // k)
    padded = np.zeros((n * k, n * k), bool)
    padded[: rock.shape[0], : rock.shape[1]] = rock
    coarse = padded.reshape(n, k, n, k).any(axis=(1, 3)).astype(np.uint8)
    reach = int(math.ceil(1.0 / ROCK_NEAR_CELL_M))
    return cv2.dilate(coarse, np.ones((2 * reach + 1, 2 * reach + 1), np.uint8)).astype(bool)


def _smooth_over(rgb: np.ndarray, mask: np.ndarray, sigma_px: float) -> np.ndarray:
    """uint8 colours Gaussian-averaged over the `mask` cells only (normalised convolution), so the
    overhang's 0.1 m columns, whose sides show one colour each from top to bottom, do not read as
    vertical bands; cells outside the mask keep their colour."""
    out = rgb.copy()
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return out
    pad = int(math.ceil(4 * sigma_px))  # only the overhangs' bounding box is filtered
    r0, r1 = max(rows.min() - pad, 0), min(rows.max() + pad + 1, mask.shape[0])
    c0, c1 = max(cols.min() - pad, 0), min(cols.max() + pad + 1, mask.shape[1])
    wb = mask[r0:r1, c0:c1].astype(np.float32)
    den = cv2.GaussianBlur(wb, (0, 0), sigma_px)
    for ch in range(3):
        num = cv2.GaussianBlur(rgb[r0:r1, c0:c1, ch].astype(np.float32) * wb, (0, 0), sigma_px)
        sm = np.clip(num / np.maximum(den, 1e-6) + 0.5, 0, 255).astype(np.uint8)
        out[r0:r1, c0:c1, ch] = np.where(wb > 0, sm, rgb[r0:r1, c0:c1, ch])
    return out


def _shadow_factor(world: World) -> float:
    """Brightness of the floor the terrain hides from the sun: cast shadows (test_dataset's quality
    level), or the weaker darkening the drives without cast shadows show (sim/shading.py)."""
    from sim.shading import CAST_SHADOW_FACTOR, SHADOWLESS_SHADOW_FACTOR

    return CAST_SHADOW_FACTOR if world.cast_shadows else SHADOWLESS_SHADOW_FACTOR


def _coarse_max(top: np.ndarray, k: int) -> np.ndarray:
    """Max of the vertex grid over each k-vertex block including its far edge (for skipping)."""
    n = (top.shape[0] - 1) // k
    pad = top[: n * k + 1, : n * k + 1]
    dil = cv2.dilate(pad, np.ones((3, 3), np.uint8))  # bilinear support reaches one vertex further
    blocks = dil[: n * k, : n * k].reshape(n, k, n, k).max(axis=(1, 3))
    edge_r = dil[k::k, : n * k].reshape(n, n, k).max(axis=2)  # row after each block
    edge_c = dil[: n * k, k::k].reshape(n, k, n).max(axis=1)
    return np.maximum(np.maximum(blocks, edge_r), edge_c).astype(np.float32)


def _terrain_cell_range(terrain: np.ndarray, tcell: float, coarse_m: float, cells: int):
    """Max and min of the terrain's bilinear surface over each coarse cell: the extremes of a bilinear
    patch are at its corners, so these are the extremes of the vertices of every patch the cell meets."""
    n = terrain.shape[0] - 1
    edges = np.arange(cells + 1) * coarse_m / tcell  # cell borders in terrain grid units
    lo = np.clip(np.floor(edges[:-1]).astype(int), 0, n)
    hi = np.clip(np.floor(edges[1:]).astype(int) + 1, 0, n)
    t = terrain.astype(np.float32)
    # along x, then along y
    xmax = np.stack([t[:, a:b + 1].max(axis=1) for a, b in zip(lo, hi)], axis=1)
    xmin = np.stack([t[:, a:b + 1].min(axis=1) for a, b in zip(lo, hi)], axis=1)
    tmax = np.stack([xmax[a:b + 1].max(axis=0) for a, b in zip(lo, hi)], axis=0)
    tmin = np.stack([xmin[a:b + 1].min(axis=0) for a, b in zip(lo, hi)], axis=0)
    return tmax, tmin


def _block_max(cmax: np.ndarray, cells: int) -> np.ndarray:
    """Max of the coarse max over blocks of `cells` x `cells` coarse cells (edge blocks padded)."""
    nb = -(-cmax.shape[0] // cells)
    pad = np.full((nb * cells, nb * cells), np.inf, np.float32)  # outside the world: never skipped
    pad[: cmax.shape[0], : cmax.shape[1]] = cmax
    return pad.reshape(nb, cells, nb, cells).max(axis=(1, 3))


def _darkening_lut(cast_shadows: bool = True) -> np.ndarray:
    """Brightness factor by viewing distance (one entry per DARK_LUT_STEP_M): the far floor darkens,
    more strongly at the simulator's quality levels without cast shadows (sim/shading.py)."""
    dist = np.arange(int(DARK_LUT_MAX_M / DARK_LUT_STEP_M) + 1) * DARK_LUT_STEP_M
    if not cast_shadows:
        from sim.shading import shadowless_darkening

        return shadowless_darkening(dist)
    return (1.0 - DIST_DARKEN * (1.0 - np.exp(-dist / DIST_SCALE_M))).astype(np.float64)


def _splat_mip(world: World):
    """(sand weight mipmaps, texel size m) for the shadowless far-floor look (sim/shading.py)."""
    from sim.shading import splat_pyramid

    return splat_pyramid(world.sand_weight), float(world.sand_cell_m)


# ---------------------------------------------------------------------- marching
@njit(cache=True, nogil=True, inline="always")
def _nearest(n, inv_cell, v):
    f = v * inv_cell + 0.5
    if f < 0.0:
        return 0
    i = int(f)
    return i if i < n else n - 1


@njit(cache=True, nogil=True, inline="always")
def _exit_dist(x, y, inv_hx, inv_hy, ci, ri, size):
    """Horizontal distance from (x, y) along a ray with reciprocal direction (inv_hx, inv_hy) until it
    leaves grid cell (ci, ri) of side `size` (a zero direction component has reciprocal 0: never)."""
    ex = 1e9
    if inv_hx > 0.0:
        ex = ((ci + 1) * size - x) * inv_hx
    elif inv_hx < 0.0:
        ex = (ci * size - x) * inv_hx
    ey = 1e9
    if inv_hy > 0.0:
        ey = ((ri + 1) * size - y) * inv_hy
    elif inv_hy < 0.0:
        ey = (ri * size - y) * inv_hy
    return min(ex, ey) + 1e-4


@njit(cache=True, nogil=True, fastmath=True)
def _ray_column(rot, a, ray_b, col):
    """Per row of one image column (x = a) the ray's horizontal unit direction, slope and reciprocals.

    col[c, v]: 0 hx, 1 hy, 2 k = dz / |d_h|, 3 1/|d_h|, 4 1/hx, 5 1/hy (0 for a zero component),
    6 |d| / |d_h| (distance per horizontal metre), 7 1/k (0 for a level ray). Branch-free, so it vectorises; one column at a
    time so the table stays in L1 next to the march. In float32 (round 12): eight lanes to a vector instead of four and
    far cheaper divisions and square roots, 0.19 -> 0.03 ms per frame; relative error ~1e-7 (1e-5 m at 120 m).
    """
    col_x = np.float32(rot[0, 0] * a + rot[0, 2])
    col_y = np.float32(rot[1, 0] * a + rot[1, 2])
    col_z = np.float32(rot[2, 0] * a + rot[2, 2])
    r01 = np.float32(rot[0, 1])
    r11 = np.float32(rot[1, 1])
    r21 = np.float32(rot[2, 1])
    one = np.float32(1.0)
    zero = np.float32(0.0)
    tiny = np.float32(1e-12)
    for v in range(ray_b.shape[0]):
        b = np.float32(ray_b[v])
        dx = col_x + r01 * b
        dy = col_y + r11 * b
        dz = col_z + r21 * b
        hlen = max(np.sqrt(dx * dx + dy * dy), np.float32(1e-9))
        inv_h = one / hlen
        hx = dx * inv_h
        hy = dy * inv_h
        k = dz * inv_h
        col[0, v] = hx
        col[1, v] = hy
        col[2, v] = k
        col[3, v] = inv_h
        col[4, v] = one / hx if abs(hx) > tiny else zero
        col[5, v] = one / hy if abs(hy) > tiny else zero
        col[6, v] = np.sqrt(one + k * k)
        col[7, v] = one / k if abs(k) > tiny else zero


@njit(cache=True, nogil=True, inline="always")
def _bilinear_terrain(terrain, fx, fy):
    """Bilinear terrain height at grid coordinates (fx, fy) known to lie inside the grid."""
    c = np.uint64(fx)
    r = np.uint64(fy)
    tx = fx - c
    ty = fy - r
    return ((terrain[r, c] * (1 - tx) + terrain[r, c + 1] * tx) * (1 - ty)
            + (terrain[r + 1, c] * (1 - tx) + terrain[r + 1, c + 1] * tx) * ty)


@njit(cache=True, nogil=True, inline="always")
def _ground_in(terrain, inv_tcell, x, y):
    """Bilinear terrain height at a point known to lie inside the world (no clamping).

    Read from the world's own terrain grid (513 x 513, 1 MB): it stays in the CPU's cache, where
    the 0.1 m resample (16 MB) did not; the surface is the same bilinear one."""
    return _bilinear_terrain(terrain, x * inv_tcell, y * inv_tcell)


@njit(cache=True, nogil=True, inline="always")
def _ground_at(terrain, inv_tcell, x, y):
    """Bilinear terrain height anywhere (clamped to the world)."""
    n = terrain.shape[0] - 1
    fx = min(max(x * inv_tcell, 0.0), n - 1e-6)
    fy = min(max(y * inv_tcell, 0.0), n - 1e-6)
    return _bilinear_terrain(terrain, fx, fy)


@njit(cache=True, nogil=True, inline="always")
def _ground01_at(tex, inv_cell, x, y):
    """Bilinear height of the 0.1 m ground resample (the surface the colours were baked on), clamped."""
    n = tex.shape[0] - 1
    fx = min(max(x * inv_cell, 0.0), n - 1e-4)
    fy = min(max(y * inv_cell, 0.0), n - 1e-4)
    c = np.uint64(fx)
    r = np.uint64(fy)
    tx = fx - c
    ty = fy - r
    return ((tex[r, c, TEX_GROUND] * (1 - tx) + tex[r, c + 1, TEX_GROUND] * tx) * (1 - ty)
            + (tex[r + 1, c, TEX_GROUND] * (1 - tx) + tex[r + 1, c + 1, TEX_GROUND] * tx) * ty)


@njit(cache=True, nogil=True)
def _solid_at(terrain, inv_tcell, slab, inv_cell, x, y, z):
    """0 free, 1 terrain, 3 rock slab, 2 free under an overhanging slab.

    Terrain is bilinear; rocks use the nearest 0.1 m cell (the world's own rule).
    """
    if z <= _ground_at(terrain, inv_tcell, x, y):
        return 1
    n = slab.shape[0]
    r = _nearest(n, inv_cell, y)
    c = _nearest(n, inv_cell, x)
    if z <= slab[r, c, SLAB_HI]:
        if z >= slab[r, c, SLAB_LO]:
            return 3
        return 2
    return 0


@njit(cache=True, nogil=True, inline="always")
def _colours_close(img, v, u0, u1, levels):
    """True when pixels (v, u0) and (v, u1) differ by at most `levels` in every channel."""
    for ch in range(3):
        if abs(np.int32(img[v, u0, ch]) - np.int32(img[v, u1, ch])) > levels:
            return False
    return True


@njit(cache=True, nogil=True, inline="always")
def _spread_shifts(c):
    """Packed 0xBBGGRR uint32 -> int64 with each channel in its own LANE_BITS-bit lane."""
    c = np.int64(c)
    return (c & 0xFF) | ((c & 0xFF00) << (LANE_BITS - 8)) | ((c & 0xFF0000) << (2 * LANE_BITS - 16))


@intrinsic
def _pdep64(typingctx, value, mask):
    """x86 BMI2 `pdep`: the low bits of `value` deposited, in order, at the set bits of `mask` (one instruction)."""
    sig = nb_types.int64(nb_types.int64, nb_types.int64)

    def codegen(context, builder, signature, args):
        i64 = llvm_ir.IntType(64)
        fn = builder.module.declare_intrinsic("llvm.x86.bmi.pdep.64", (), llvm_ir.FunctionType(i64, [i64, i64]))
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True, nogil=True, inline="always")
def _spread_pdep(c):
    """`_spread_shifts` in one instruction: the same bits (the three bytes land in the lanes' low bytes)."""
    return _pdep64(np.int64(c), SPREAD_MASK)


def _host_has_bmi2() -> bool:
    """pdep is used only when numba compiles for this very CPU and the CPU has a fast BMI2 pdep.

    Intel since 2013 and AMD since Zen 3 do it in one cycle; AMD Excavator, Zen 1 and Zen 2 run it
    as microcode (hundreds of cycles), where the shift version is far faster.
    """
    try:
        from llvmlite import binding
        from numba.core import config

        slow_pdep = binding.get_host_cpu_name().startswith(SLOW_PDEP_CPUS)
        return (config.CPU_NAME is None and not slow_pdep
                and bool(binding.get_host_cpu_features().get("bmi2", False)))
    except Exception:  # noqa: BLE001 - no feature query (another platform): the portable path
        return False


SLOW_PDEP_CPUS = ("bdver", "znver1", "znver2")  # LLVM host CPU names whose pdep is microcoded
SPREAD_MASK = 0xFF | (0xFF << LANE_BITS) | (0xFF << (2 * LANE_BITS))  # the lanes' low bytes, for pdep
_spread = _spread_pdep if _host_has_bmi2() else _spread_shifts  # (profiled: ~2 % of a frame's CPU)


@njit(cache=True, nogil=True, fastmath={"nsz", "arcp", "contract", "afn", "reassoc"})
def _render_kernel(img, depth, rot, ray_a, ray_b, terrain, inv_tcell, tex, tex_u, slab, rock64, coarse,
                   bmax, block_m, cell, coarse_m, origin,
                   far_m, step_min, step_k, refine_iters, zmax, sky_rgb, far_rgb,
                   underside_shade, underside_band_m, underside_ramp_m, world_size, dark_lut, dark_lut_step, share_depth_m, share_ratio,
                   share_levels, share_rock, col_order, col_offset, shared_px,
                   rock_ratio, col_min_m):
    """Column-wise raymarch into row-major (H, W, 3) image and (H, W) depth (module docstring).

    Free space is skipped per block_m block (above everything in it) and per coarse_m cell
    (above everything, or in the free band under an overhang); a coarse cell whose floor is one
    level plane without rock is hit analytically. Everything else is marched in fine steps; a
    coarse cell's summary is loaded once per visit, not once per fine step. Colours are packed
    three channels to an int64 (LANE_BITS each) so a bilinear blend is four integer multiplies.
    """
    h_img, w_img = depth.shape
    inv_cell = 1.0 / cell
    inv_coarse = 1.0 / coarse_m
    inv_block = 1.0 / block_m
    n = slab.shape[0]
    nc = coarse.shape[0]
    nb = bmax.shape[0]
    ox, oy, oz = origin[0], origin[1], origin[2]
    inv_lut_step = 1.0 / dark_lut_step
    n_lut = dark_lut.shape[0]
    lane_mask = (1 << 8) - 1
    half = 1 << (WEIGHT_BITS - 1)
    rounding = half | (half << LANE_BITS) | (half << (2 * LANE_BITS))
    wscale = float(1 << WEIGHT_BITS)
    table = np.empty((8, h_img), np.float32)  # the column's ray table (_ray_column)
    # per pixel: 1 terrain, 3 rock, 0 sky or far; + UNDER_OVERHANG when the ray passed under rock
    hit_kind = np.zeros((h_img, w_img), np.uint8)
    for i_col in range(w_img):
        # marched columns first, then the ones that may share their two neighbours' terrain hits
        u = col_order[i_col]
        off = col_offset[u]
        shared = off > 0 and share_depth_m > 0.0
        min_m = col_min_m[u]  # this column shares only hits at least this far (0 but in the far-only tiers)
        _ray_column(rot, ray_a[u], ray_b, table)
        prev_s = 0.0  # where the ray below ended (hit, sky or far), horizontal m
        sky_rest = False
        # overhang passage of the ray below: first/last distance under a slab, lowest slab bottom
        g_first = -1.0
        g_last = -1.0
        g_bottom = 1e9
        # summary of the last coarse cell looked up (reused while rays stay in it)
        ci_c = -1
        ri_c = -1
        cm = 0.0
        cg = 0.0
        cb = 0.0
        gz = 0.0
        rock_here = True
        for v in range(h_img - 1, -1, -1):
            if sky_rest:
                for ch in range(3):
                    img[v, u, ch] = sky_rgb[ch]
                depth[v, u] = np.inf
                continue
            kind_l = hit_kind[v, u - off] if shared else 0
            if (g_first < 0.0 and (kind_l == 1 or (kind_l == 3 and share_rock))
                    and hit_kind[v, u + off] == kind_l):
                # column coherence: both neighbours hit the open terrain (or both rock) at nearly one depth
                # and colour: this pixel is their average (measured: 99.8 % of pixels within 8 levels
                # of marching it, ~17 % less time per frame; rock hits too: a further ~3.5 %)
                d_l = depth[v, u - off]
                d_r = depth[v, u + off]
                ratio = share_ratio if kind_l == 1 else rock_ratio
                if (d_l < share_depth_m and d_r < share_depth_m and d_l >= min_m and d_r >= min_m
                        and abs(d_l - d_r) <= ratio * min(d_l, d_r)
                        and _colours_close(img, v, u - off, u + off, share_levels)):
                    for ch in range(3):
                        img[v, u, ch] = (np.uint16(img[v, u - off, ch]) + np.uint16(img[v, u + off, ch]) + 1) >> 1
                    d_mid = 0.5 * (d_l + d_r)
                    depth[v, u] = d_mid
                    hit_kind[v, u] = kind_l
                    shared_px[v, u] = 1
                    # the ray above restarts short of both neighbours' hits: the average may lie past a
                    # ridge this column's ray would have met first
                    prev_s = (1.0 - ratio) * min(d_l, d_r) / table[3, v]
                    continue
            hx = table[0, v]
            hy = table[1, v]
            k = table[2, v]
            inv_hx = table[4, v]
            inv_hy = table[5, v]
            # Coherence: this ray is above the one below, so it is free wherever that ray was free
            # in open air; only where that ray passed under an overhang may this one hit earlier
            # (the underside), and only if it can climb to the overhang's bottom.
            jump_from = -1.0
            jump_to = 0.0
            if g_first >= 0.0 and (k > 0.0 or oz >= g_bottom):
                s = g_first
                jump_from = g_last
                jump_to = prev_s
                s_reach = (g_bottom - oz) * table[7, v] if oz < g_bottom else 0.0
                if k > 0.0 and s_reach > s:
                    # below the passage's lowest rock bottom until it climbs to it: free until there
                    # (a camera under an overhang would otherwise march every upward ray from itself);
                    # the skipped stretch stays recorded as a passage for the ray above
                    s = min(s_reach, prev_s)
                    g_last = min(g_last, s)
                else:
                    g_first = -1.0
                    g_last = -1.0
                    g_bottom = 1e9
            else:
                s = prev_s
            s_free = s
            state = 0
            hit = 0  # 0 none, 1 surface, 2 sky, 3 far
            x = 0.0
            y = 0.0
            z = 0.0
            g = 0.0
            cell_end = -1.0  # the coarse cell being marched in fine steps ends here
            z_exit = 0.0
            inside = True
            while True:
                if jump_from >= 0.0 and s > jump_from:
                    if s < jump_to:
                        s = jump_to
                        s_free = s
                    jump_from = -1.0
                if s > far_m:
                    hit = 3
                    break
                x = ox + s * hx
                y = oy + s * hy
                z = oz + s * k
                if k >= 0.0 and z > zmax:
                    hit = 2
                    break
                inside = x >= 0.0 and y >= 0.0 and x < world_size and y < world_size
                if inside:
                    if s >= cell_end:  # entering a coarse cell
                        ci = min(int(x * inv_coarse), nc - 1)
                        ri = min(int(y * inv_coarse), nc - 1)
                        if ci != ci_c or ri != ri_c:
                            # whole block above everything in it: skip the block
                            bi = min(int(x * inv_block), nb - 1)
                            bj = min(int(y * inv_block), nb - 1)
                            bm = bmax[bj, bi]
                            if z > bm:
                                ds = _exit_dist(x, y, inv_hx, inv_hy, bi, bj, block_m)
                                if oz + (s + ds) * k > bm:
                                    s += ds
                                    s_free = s
                                    continue
                            ci_c = ci
                            ri_c = ri
                            cm = coarse[ri, ci, COARSE_MAX]
                            cg = coarse[ri, ci, COARSE_GROUND]
                            cb = coarse[ri, ci, COARSE_BOTTOM]
                            gz = coarse[ri, ci, COARSE_FLAT]
                            rock_here = cb < 1e8
                        cell_end = s + _exit_dist(x, y, inv_hx, inv_hy, ci, ri, coarse_m)
                        z_exit = oz + cell_end * k
                        if gz == gz:  # level floor without rock: the plane z = gz is the only surface
                            if z <= gz:
                                state = 1
                                hit = 1
                                break
                            if k < 0.0:
                                s_hit = (gz - oz) * table[7, v]
                                if s_hit < cell_end:
                                    s = max(s_hit, s)
                                    s_free = s
                                    x = ox + s * hx
                                    y = oy + s * hy
                                    z = oz + s * k
                                    state = 1
                                    hit = 1
                                    break
                            s = cell_end
                            s_free = s
                            continue
                    if z > cm:
                        if z_exit > cm:  # above everything to the cell's end
                            s = cell_end
                            s_free = s
                            continue
                    elif cg < z < cb and cg < z_exit < cb:  # in the free band under a rock
                        if cb < 1e8:  # passing under an overhang
                            if g_first < 0.0:
                                g_first = s
                            g_last = max(g_last, cell_end)
                            g_bottom = min(g_bottom, cb)
                        s = cell_end
                        s_free = s
                        continue
                    # fine step: terrain (bilinear) or the rock slab of the nearest 0.1 m cell
                    g = _ground_in(terrain, inv_tcell, x, y)
                    if z <= g:
                        state = 1
                        hit = 1
                        break
                    if rock_here:
                        rr = np.uint64(y * inv_cell + 0.5)
                        cc = np.uint64(x * inv_cell + 0.5)
                        if z <= slab[rr, cc, SLAB_HI]:
                            lo_r = slab[rr, cc, SLAB_LO]
                            if z >= lo_r:
                                state = 3
                                hit = 1
                                break
                            # free under an overhanging slab
                            if g_first < 0.0:
                                g_first = s
                            g_last = max(g_last, s)
                            g_bottom = min(g_bottom, lo_r)
                else:  # outside the world: its border continues (clamped lookups)
                    cell_end = -1.0
                    g = _ground_at(terrain, inv_tcell, x, y)
                    if z <= g:
                        state = 1
                        hit = 1
                        break
                    rr = _nearest(n, inv_cell, y)
                    cc = _nearest(n, inv_cell, x)
                    if z <= slab[rr, cc, SLAB_HI]:
                        lo_r = slab[rr, cc, SLAB_LO]
                        if z >= lo_r:
                            state = 3
                            hit = 1
                            break
                        if g_first < 0.0:
                            g_first = s
                        g_last = max(g_last, s)
                        g_bottom = min(g_bottom, lo_r)
                s_free = s
                s += step_min + step_k * s
            if hit == 1:
                lo = s_free
                hi = s
                if state == 1 and hi > lo:
                    # terrain: the march bracketed the crossing on the terrain grid's surface; place
                    # the hit on the 0.1 m surface the colours were baked on (one secant step; these
                    # are the cache lines the colour lookup reads next)
                    f_lo = (oz + lo * k) - _ground01_at(tex, inv_cell, ox + lo * hx, oy + lo * hy)
                    f_hi = z - _ground01_at(tex, inv_cell, x, y)
                    if f_lo <= 0.0:
                        hi = lo
                    elif f_hi <= 0.0 and f_lo - f_hi > 1e-9:
                        hi = lo + (hi - lo) * f_lo / (f_lo - f_hi)
                elif hi > lo:
                    # rock slab: bisection (nearest-cell slabs have vertical sides)
                    for _ in range(refine_iters):
                        mid = 0.5 * (lo + hi)
                        st = _solid_at(terrain, inv_tcell, slab, inv_cell, ox + mid * hx,
                                    oy + mid * hy, oz + mid * k)
                        if st == 1 or st == 3:
                            hi = mid
                        else:
                            lo = mid
                if hi != s:
                    s = hi
                    x = ox + s * hx
                    y = oy + s * hy
                    z = oz + s * k
                li = int(s * table[6, v] * inv_lut_step)
                shade = dark_lut[li] if li < n_lut else dark_lut[n_lut - 1]
                if state == 1:  # terrain: bilinear ground colour
                    fx = min(max(x * inv_cell, 0.0), n - 1 - 1e-4)
                    fy = min(max(y * inv_cell, 0.0), n - 1 - 1e-4)
                    c0 = np.uint64(fx)
                    r0 = np.uint64(fy)
                    tx = fx - c0
                    ty = fy - r0
                    ws = wscale * shade
                    acc = (_spread(tex_u[r0, c0, TEX_COLOUR]) * int((1.0 - tx) * (1.0 - ty) * ws + 0.5)
                           + _spread(tex_u[r0, c0 + 1, TEX_COLOUR]) * int(tx * (1.0 - ty) * ws + 0.5)
                           + _spread(tex_u[r0 + 1, c0, TEX_COLOUR]) * int((1.0 - tx) * ty * ws + 0.5)
                           + _spread(tex_u[r0 + 1, c0 + 1, TEX_COLOUR]) * int(tx * ty * ws + 0.5)
                           + rounding)
                else:  # rock slab: nearest cell, darker on the underside of an overhang
                    rr = _nearest(n, inv_cell, y)
                    cc = _nearest(n, inv_cell, x)
                    lo_r = slab[rr, cc, SLAB_LO]
                    if -1e8 < lo_r < 1e8:
                        if underside_ramp_m > 0.0:  # smooth: by the hit's height above the bottom
                            t = min(max((z - lo_r) / underside_ramp_m, 0.0), 1.0)
                            shade *= underside_shade + (1.0 - underside_shade) * t
                        elif z < lo_r + underside_band_m:
                            shade *= underside_shade
                    acc = rock64[rr, cc] * int(wscale * shade + 0.5) + rounding
                img[v, u, 0] = (acc >> WEIGHT_BITS) & lane_mask
                img[v, u, 1] = (acc >> (WEIGHT_BITS + LANE_BITS)) & lane_mask
                img[v, u, 2] = (acc >> (WEIGHT_BITS + 2 * LANE_BITS)) & lane_mask
                depth[v, u] = s * table[3, v]
                hit_kind[v, u] = state if g_first < 0.0 else state + UNDER_OVERHANG
                prev_s = s
            elif hit == 2:
                for ch in range(3):
                    img[v, u, ch] = sky_rgb[ch]
                depth[v, u] = np.inf
                sky_rest = g_first < 0.0
                prev_s = s
            else:
                for ch in range(3):
                    img[v, u, ch] = far_rgb[ch]
                depth[v, u] = np.inf
                prev_s = far_m


@njit(cache=True, nogil=True)
def _fill_shared_pixels(img, shared_px, col_order, col_offset):
    """Each pixel the raymarch averaged from its two neighbouring columns (shared_px 1) becomes the average of
    those neighbours again, after the floor look has been drawn on the marched pixels only: the look's
    factors change slowly from column to column, so this costs far less than computing them again.
    Columns go in the raymarch's order, so a column's neighbours are final before it is filled."""
    h_img = img.shape[0]
    for u in col_order:
        off = col_offset[u]
        if off == 0:
            continue
        for v in range(h_img):
            if shared_px[v, u]:
                for ch in range(3):
                    img[v, u, ch] = (np.uint16(img[v, u - off, ch]) + np.uint16(img[v, u + off, ch]) + 1) >> 1


def _kernel_rasters(ground, slab_lo, slab_hi, colour_ground) -> dict:
    """The baked rasters as the kernel reads them. "tex": float32 (n, n, 2) the 0.1 m ground resample and
    its colour (0xBBGGRR bits) side by side, so a hit's placement and its colour read the same cache
    lines ("tex_u" is the same memory seen as uint32); "slab": float32 (n, n, 2) rock bottom and top."""
    tex = np.empty(ground.shape + (2,), np.float32)
    tex[..., TEX_GROUND] = ground
    tex_u = tex.view(np.uint32)
    c = colour_ground.astype(np.uint32)
    tex_u[..., TEX_COLOUR] = c[..., 0] | (c[..., 1] << 8) | (c[..., 2] << 16)
    slab = np.stack([slab_lo, slab_hi], axis=-1).astype(np.float32)
    return {"tex": tex, "tex_u": tex_u, "slab": slab}


def column_plan(width: int, tiers: int):
    """Order in which the kernel draws the image columns, and per column the distance of the two
    neighbours it may average (0: marched). tiers 1: even columns marched, odd ones between them;
    tiers 2: every 4th column marched, then the ones two apart, then the odd ones; tiers 3: every 8th, then
    the ones four apart, and so on."""
    stride = 1 << tiers
    offset = np.zeros(width, np.int64)
    order = [u for u in range(0, width, stride)]
    for level in range(tiers - 1, -1, -1):
        off = 1 << level
        for u in range(off, width, 2 * off):
            if u + off < width:
                offset[u] = off
            order.append(u)
    assert sorted(order) == list(range(width))
    # a column without both neighbours is marched: move it ahead of every column that may read it
    marched = [u for u in order if offset[u] == 0]
    return np.array(marched + [u for u in order if offset[u] > 0], np.int64), offset


def far_tier_min_depth(offset: np.ndarray, tiers: int, min_m: float) -> np.ndarray:
    """Per column, the nearest hit it may average (0: any): columns whose neighbours are farther apart than
    the `tiers` ordinary tiers reach share only hits at least `min_m` away (where the time goes and a wider
    average moves the near navigable mask not at all)."""
    return np.where(offset >= (1 << tiers), float(min_m), 0.0)


def pack_rgb(rgb: np.ndarray) -> np.ndarray:
    """uint8 (..., 3) -> int64 with each channel in its own LANE_BITS-bit lane (for the kernel's blend)."""
    c = rgb.astype(np.int64)
    return c[..., 0] | (c[..., 1] << LANE_BITS) | (c[..., 2] << (2 * LANE_BITS))


_BAKE_CACHE = []  # [(weakref to World, baked rasters)], most recent last
BAKE_CACHE_SIZE = 2  # worlds whose baked rasters are kept (a mission batch reuses one world)


def _baked_for(world: World):
    """Bake once per World object (several renderers, e.g. one per mission, share it)."""
    import weakref

    for ref, baked in _BAKE_CACHE:
        if ref() is world:
            return baked
    baked = bake_rasters(world)
    _BAKE_CACHE[:] = [(r, b) for r, b in _BAKE_CACHE if r() is not None][-(BAKE_CACHE_SIZE - 1):]
    _BAKE_CACHE.append((weakref.ref(world), baked))
    return baked


_NO_PYRAMID = np.zeros((1, 1, 1), np.float32)  # stands in for the splat mipmaps of worlds drawn with cast shadows
_NO_GAIN = np.ones(IMAGE_W)  # the back-scatter gain per column when the lobe is off


class Renderer:
    """Bakes a World once; `.render(pose, samples)` draws camera frames."""

    def __init__(self, world: World):
        self.world = world
        baked = _baked_for(world)
        self._top = baked["top"]
        self._ground = baked["ground"]
        self._slab_lo = baked["slab_lo"]
        self._slab_hi = baked["slab_hi"]
        self.colour_map = baked["colour"]  # (2001, 2001, 3) uint8 lit albedo, [row=y, col=x]
        self._colour_rock = baked["colour_rock"]
        self._cmax = baked["cmax"]
        self._cground = baked["cground"]
        self._cbottom = baked["cbottom"]
        self.baked = baked
        self.zmax = float(self._top.max()) + 0.01
        self.ray_a = ((np.arange(IMAGE_W) + 0.5 - CX) / FOCAL_PX).astype(np.float64)
        self.ray_b = ((CY - (np.arange(IMAGE_H) + 0.5)) / FOCAL_PX).astype(np.float64)
        self.sky_rgb = np.array(SKY_RGB, np.uint8)
        self.far_rgb = np.array(FAR_RGB, np.uint8)
        # the far floor is drawn by the splat mipmaps at both quality levels (sim/shading.py items 1 and 4)
        self._dark_lut = _darkening_lut(False)
        self._splat_mip = _splat_mip(world)  # (weight mipmaps, texel m)
        self.backscatter = True  # the floor's bright lobe away from the sun (sim/shading.py); False: plain Lambert
        self.fused_floor_look = True  # False: far floor and lobe drawn by the two separate passes (the test oracle)
        self.smooth_underside = True  # False: overhangs as before issue 28 item 4 (one colour per 0.1 m column, a 0.3 m dark band)
        self._rock64_banded = None  # the packed rock colours of that look, built on first use
        from sim.shading import ROCK_LAYER_RGB

        self._sand_rgb_f64 = np.array(SAND_LUT_RGB[-1], np.float64)  # pure sand's colour, the splat map's bright end
        self._rock_layer_rgb_f64 = np.array(ROCK_LAYER_RGB, np.float64)
        self.column_share_m = COLUMN_SHARE_MAX_M  # 0: every column marched (the reference image)
        self.share_floor_look = True  # False: the floor look is computed on the shared pixels too (the older image)
        self.share_rock = COLUMN_SHARE_ROCK  # False: only terrain hits are averaged from neighbouring columns
        self.share_rock_ratio = COLUMN_SHARE_ROCK_RATIO  # depth test of averaged rock hits (fraction)
        self._col_order, self._col_offset = column_plan(IMAGE_W, COLUMN_SHARE_TIERS + COLUMN_SHARE_FAR_TIERS)
        self._col_min_m = far_tier_min_depth(self._col_offset, COLUMN_SHARE_TIERS, COLUMN_SHARE_FAR_MIN_M)
        self.last_depth = np.full((IMAGE_H, IMAGE_W), np.inf, np.float32)
        self.last_shared = np.zeros((IMAGE_H, IMAGE_W), np.uint8)
        self._last_camera = None
        self._terrain = np.ascontiguousarray(world.terrain_height, dtype=np.float32)
        self._rock_near = _rock_near_raster(world)  # any rock cell within a wheel's reach, per ROCK_NEAR_CELL_M cell
        self._tread = None  # tyre-track tread mask, loaded with the first tracks drawn
        self._track_rgb = None  # lit colour of a track texel on level floor, 0..255 RGB
        self._sample_ground = {}  # (x, y) of a sample spot -> terrain height there, m
        self._params_for = None  # the samples argument _params was built from (as a tuple of tuples)
        self._params = np.zeros((0, 8))  # their _sample_params rows
        az, el = math.radians(SUN_AZIMUTH_DEG), math.radians(SUN_ELEVATION_DEG)
        self._sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])

    def _rock64(self) -> np.ndarray:
        """Packed rock colours: overhang columns smoothed across neighbours, or per column (banded look)."""
        if self.smooth_underside:
            return self.baked["rock64"]
        if self._rock64_banded is None:
            self._rock64_banded = self.baked["rock64"].copy()
            self._rock64_banded[self.baked["overhang_rc"]] = self.baked["rock64_banded_overhang"]
        return self._rock64_banded

    def camera(self, pose):
        """(origin xyz in world, 3x3 rotation whose columns are right/up/forward) for a pose."""
        x, y, yaw, pitch, roll, *rest = validate_pose(pose)
        x, y = (float(v) for v in self.world.clamp_xy(x, y))
        rot = body_rotation(yaw, pitch, roll)
        if rest:
            root_z = rest[0]
        else:
            root_z = float(self.world.height_at(x, y)) - ROOT_BELOW_GROUND_M + self._rock_lift(x, y, yaw)
        mount = np.array([0.0, CAMERA_MOUNT_UP_M, CAMERA_MOUNT_FORWARD_M])
        origin = np.array([x, y, root_z]) + rot @ mount
        return origin, rot

    def _rock_lift(self, x: float, y: float, yaw_deg: float) -> float:
        """How far the rover root rises above its terrain height when wheels stand on a rock, m (0 off rocks).

        A pose without a height (a logged drive) used to put the camera at terrain height even with the rover
        on a boulder, inside the rock's columns; the real rover stands on its wheels. The wheels' support plane
        is taken as the physics does (sim.contact.wheel_plane): the rock top under a wheel where one is within
        ROCK_LIFT_MAX_M above the terrain, else the terrain; the lift is that plane's height at the root minus the
        terrain-only plane's."""
        from sim import contact as C

        near = self._rock_near
        if not near[min(max(int(y / ROCK_NEAR_CELL_M), 0), near.shape[0] - 1),
                    min(max(int(x / ROCK_NEAR_CELL_M), 0), near.shape[1] - 1)]:
            return 0.0  # no rock cell within a wheel's reach of the root: the common case, no lookups
        yaw = math.radians(yaw_deg)
        c, s = math.cos(yaw), math.sin(yaw)
        x, y = float(x), float(y)
        wheels = [(x + f * c - l * s, y + f * s + l * c) for f, l in zip(C.WHEEL_F_M, C.WHEEL_L_M)]
        spans = [self.world.rock_span_at(wx, wy) for wx, wy in wheels]
        terrain, support = [], []
        for (wx, wy), (bottom, top) in zip(wheels, spans):
            h = float(self.world.height_at(wx, wy))
            on_rock = h + 0.01 < top <= h + ROCK_LIFT_MAX_M and bottom <= h + 0.01
            terrain.append(h)
            support.append(top if on_rock else h)
        return max(0.0, C.wheel_plane(support)[0] - C.wheel_plane(terrain)[0])

    def render(self, pose, samples=(), tracks=None) -> np.ndarray:
        """uint8 RGB (160, 320, 3) for pose (x, y, yaw, pitch, roll) in degrees.

        samples: iterable of (x, y, scale, yaw_deg) gold sample rocks to draw.
        tracks: tyre tracks on the floor, a `sim.tracks.TyreTracks` or its (N, 4) `quads` array.
        """
        origin, rot = self.camera(pose)
        img = np.empty((IMAGE_H, IMAGE_W, 3), np.uint8)
        depth = np.empty((IMAGE_H, IMAGE_W), np.float32)
        shared_px = np.zeros((IMAGE_H, IMAGE_W), np.uint8)  # 1 where the kernel averaged the two neighbours
        b = self.baked
        terrain = self._terrain
        _render_kernel(img, depth, np.ascontiguousarray(rot), self.ray_a, self.ray_b, terrain, 1.0 / float(self.world.terrain_cell_m), b["tex"],
                       b["tex_u"],
                       b["slab"], self._rock64(), b["coarse"], b["bmax"],
                       BLOCK_CELLS * COARSE_CELL_M, float(self.world.rock_cell_m), COARSE_CELL_M,
                       origin, FAR_M, FINE_STEP_MIN_M, FINE_STEP_PER_M, REFINE_ITERS, self.zmax,
                       self.sky_rgb, self.far_rgb, UNDERSIDE_SHADE, UNDERSIDE_BAND_M,
                       UNDERSIDE_RAMP_M if self.smooth_underside else 0.0, float(self.world.size_m),
                       self._dark_lut, DARK_LUT_STEP_M, self.column_share_m, COLUMN_SHARE_RATIO,
                       COLUMN_SHARE_LEVELS, self.share_rock, self._col_order, self._col_offset, shared_px,
                       self.share_rock_ratio, self._col_min_m)
        if self._splat_mip is not None or self.backscatter:
            if self.share_floor_look and self.column_share_m > 0.0:
                self._draw_floor_look(img, depth, origin, np.ascontiguousarray(rot), shared_px)
                _fill_shared_pixels(img, shared_px, self._col_order, self._col_offset)
            else:
                self._draw_floor_look(img, depth, origin, np.ascontiguousarray(rot), np.zeros_like(shared_px))
        if tracks is not None:
            self.draw_tracks(img, depth, origin, rot, tracks)
        self.draw_samples(img, depth, origin, rot, samples)
        self.last_depth = depth  # distance along the ray / |forward|, inf for sky
        self.last_shared = shared_px  # 1 where the pixel is the average of its two neighbouring columns
        self._last_camera = (origin, rot)
        return img

    def _draw_floor_look(self, img, depth, origin, rot, skip):
        """The shadowless far floor (splat mipmaps) and the back-scatter lobe (sim/shading.py), in place."""
        from sim import shading

        terrain, inv_tcell = self._terrain, 1.0 / float(self.world.terrain_cell_m)
        sand, rock = self._sand_rgb_f64, self._rock_layer_rgb_f64
        gain = shading.backscatter_columns(rot, self.ray_a, SUN_AZIMUTH_DEG) if self.backscatter else None
        if not self.fused_floor_look:  # the two passes as first written: the oracle of the fused one
            if self._splat_mip is not None:
                shading.apply_splat_mip(img, depth, origin, rot, self.ray_a, self.ray_b, self._splat_mip[0],
                                        self._splat_mip[1], FOCAL_PX, terrain, inv_tcell, sand, rock,
                                        shading.SPLAT_LOD_BIAS, shading.SPLAT_LOD_MAX, shading.SPLAT_MIN_SIN,
                                        shading.ROCK_HIT_ABOVE_GROUND_M)
            if gain is not None:
                shading.apply_backscatter(img, depth, origin, rot, self.ray_a, self.ray_b, gain, terrain, inv_tcell,
                                          shading.ROCK_HIT_ABOVE_GROUND_M)
            return
        pyr, texel_m = self._splat_mip if self._splat_mip is not None else (_NO_PYRAMID, 1.0)
        shading.apply_floor_look(img, depth, origin, rot, self.ray_a, self.ray_b, pyr, texel_m, FOCAL_PX, terrain,
                                 inv_tcell, sand, rock, shading.SPLAT_LOD_BIAS, shading.SPLAT_LOD_MAX,
                                 shading.SPLAT_MIN_SIN, shading.ROCK_HIT_ABOVE_GROUND_M,
                                 gain if gain is not None else _NO_GAIN, self._splat_mip is not None, skip)

    @property
    def last_hit(self) -> np.ndarray:
        """World (x, y, z) of each pixel of the last frame (float32 (H, W, 3)), all nan for sky."""
        if self._last_camera is None:
            return np.full((IMAGE_H, IMAGE_W, 3), np.nan, np.float32)
        origin, rot = self._last_camera
        uu, vv = np.meshgrid(self.ray_a, self.ray_b)
        dirs = rot[:, 0] * uu[..., None] + rot[:, 1] * vv[..., None] + rot[:, 2]
        with np.errstate(invalid="ignore"):
            hit = origin + self.last_depth[..., None].astype(np.float64) * dirs
        hit[~np.isfinite(self.last_depth)] = np.nan
        return hit.astype(np.float32)

    def draw_tracks(self, img, depth, origin, rot, tracks):
        """Draw tyre-track quads (alpha cut-out tread, tinted, lit like the floor under them) in place."""
        quads = np.ascontiguousarray(getattr(tracks, "quads", tracks), dtype=np.float64).reshape(-1, 4)
        if not len(quads):
            return
        if self._tread is None:
            from sim import tracks as tyre

            self._tread = tyre.tread_mips(tyre.load_tread_alpha())
            self._track_rgb = np.array(tyre.TINT) * np.array(TRACK_WHITE_RGB)
        from sim.tracks import QUAD_HALF_M

        _draw_tracks_kernel(img, depth, np.ascontiguousarray(rot), origin, self.ray_a, self.ray_b, quads,
                            self._tread, QUAD_HALF_M, self._track_rgb, self.baked["light"],
                            float(self.world.rock_cell_m), self._dark_lut, DARK_LUT_STEP_M, TRACK_DRAW_MAX_M,
                            TRACK_DEPTH_TOLERANCE_M, FOCAL_PX, CX, CY, TRACK_ANISO_MAX)

    def draw_samples(self, img, depth, origin, rot, samples):
        """Draw gold sample rocks (shaded ellipsoids standing on the ground) into a frame in place,
        depth-tested against `depth` (which they update)."""
        params = self._sample_params(samples)
        if len(params):
            _draw_samples_kernel(img, depth, np.ascontiguousarray(rot), origin, self.ray_a, self.ray_b,
                                 params, self._sun, SAMPLE_MIN_SHADE, FAR_M, FOCAL_PX, CX, CY)

    def _sample_params(self, samples) -> np.ndarray:
        """(N, 8) float64 per finite sample: centre xyz, half width, half height, cos/sin yaw, scale.
        Samples rarely change between frames: the rows of the last call are reused when they have not."""
        key = tuple(tuple(sample) for sample in samples)
        if key != self._params_for:
            self._params = self._build_sample_params(key)
            self._params_for = key
        return self._params

    def _build_sample_params(self, samples) -> np.ndarray:
        rows = []
        for sample in samples:
            sx, sy, scale, syaw = (float(v) for v in sample)
            if not all(math.isfinite(v) for v in (sx, sy, scale, syaw)):
                continue
            key = (sx, sy)
            ground = self._sample_ground.get(key)
            if ground is None:  # samples never move: one terrain lookup per spot
                if len(self._sample_ground) > SAMPLE_GROUND_CACHE:
                    self._sample_ground.clear()
                ground = self._sample_ground[key] = float(self.world.height_at(sx, sy))
            half_w = 0.5 * SAMPLE_WIDTH_PER_SCALE_M * scale
            half_h = 0.5 * SAMPLE_HEIGHT_PER_SCALE_M * scale
            yaw = math.radians(syaw)
            rows.append((sx, sy, ground + half_h - SAMPLE_SINK_M, half_w, half_h, math.cos(yaw),
                         math.sin(yaw), scale))
        return np.array(rows, np.float64).reshape(-1, 8)


@njit(cache=True, nogil=True)
def _draw_samples_kernel(img, depth, rot, origin, ray_a, ray_b, params, sun, min_shade, far_m,
                         focal, cx, cy):
    """Ray-ellipsoid intersection per pixel of each sample's screen box, with a depth test."""
    h_img, w_img = depth.shape
    for i in range(params.shape[0]):
        px, py, pz, half_w, half_h, c, s = (params[i, 0], params[i, 1], params[i, 2], params[i, 3],
                                            params[i, 4], params[i, 5], params[i, 6])
        rx, ry, rz = px - origin[0], py - origin[1], pz - origin[2]
        cam_x = rot[0, 0] * rx + rot[1, 0] * ry + rot[2, 0] * rz  # right
        cam_y = rot[0, 1] * rx + rot[1, 1] * ry + rot[2, 1] * rz  # up
        cam_z = rot[0, 2] * rx + rot[1, 2] * ry + rot[2, 2] * rz  # forward
        radius = max(half_w, half_h) * 1.1
        if cam_z <= 0.05 or math.sqrt(rx * rx + ry * ry + rz * rz) > far_m:
            continue
        u_c = cx + focal * cam_x / cam_z
        v_c = cy - focal * cam_y / cam_z
        r_px = focal * radius / max(cam_z - radius, 0.05) + 2
        u0 = int(max(0.0, u_c - r_px))
        u1 = int(min(float(w_img), u_c + r_px + 1))
        v0 = int(max(0.0, v_c - r_px))
        v1 = int(min(float(h_img), v_c + r_px + 1))
        if u0 >= u1 or v0 >= v1:
            continue
        # ellipsoid frame: rotate by yaw, scale to the unit sphere (slightly oblong)
        ax, ay, az = half_w * 1.08, half_w * 0.92, half_h
        ex, ey, ez = origin[0] - px, origin[1] - py, origin[2] - pz
        ol_x = (c * ex + s * ey) / ax
        ol_y = (-s * ex + c * ey) / ay
        ol_z = ez / az
        qc = ol_x * ol_x + ol_y * ol_y + ol_z * ol_z - 1.0
        for v in range(v0, v1):
            bv = ray_b[v]
            for u in range(u0, u1):
                au = ray_a[u]
                # world ray direction (forward component 1)
                dx = rot[0, 0] * au + rot[0, 1] * bv + rot[0, 2]
                dy = rot[1, 0] * au + rot[1, 1] * bv + rot[1, 2]
                dz = rot[2, 0] * au + rot[2, 1] * bv + rot[2, 2]
                dl_x = (c * dx + s * dy) / ax
                dl_y = (-s * dx + c * dy) / ay
                dl_z = dz / az
                qa = dl_x * dl_x + dl_y * dl_y + dl_z * dl_z
                qb = 2.0 * (dl_x * ol_x + dl_y * ol_y + dl_z * ol_z)
                disc = qb * qb - 4.0 * qa * qc
                if disc <= 0.0:
                    continue
                t = (-qb - math.sqrt(disc)) / (2.0 * qa)
                if not (t > 0.0 and t < depth[v, u]):
                    continue
                # gradient of the ellipsoid at the hit, back in world axes
                pl_x = (ol_x + t * dl_x) / ax
                pl_y = (ol_y + t * dl_y) / ay
                pl_z = (ol_z + t * dl_z) / az
                nx = c * pl_x - s * pl_y
                ny = s * pl_x + c * pl_y
                nz = pl_z
                norm = math.sqrt(nx * nx + ny * ny + nz * nz) + 1e-12
                lam = (nx * sun[0] + ny * sun[1] + nz * sun[2]) / norm
                lam = min(max(lam, 0.0), 1.0)
                shade = min_shade + (1.0 - min_shade) * lam
                for ch in range(3):
                    img[v, u, ch] = np.uint8(min(max(SAMPLE_RGB_255[ch] * shade, 0.0), 255.0))
                depth[v, u] = t


@njit(cache=True, nogil=True)
def _draw_tracks_kernel(img, depth, rot, origin, ray_a, ray_b, quads, tread, half, rgb, light, cell,
                        dark_lut, dark_lut_step, max_dist, tolerance, focal, cx, cy, aniso):
    """Per quad: project its corners, and in that screen box intersect each pixel's ray with the quad's
    plane; an opaque tread texel in front of the surface the pixel shows (within `tolerance`) is drawn."""
    h_img, w_img = depth.shape
    ox, oy, oz = origin[0], origin[1], origin[2]
    n_levels = tread.shape[0]
    n_tex = tread.shape[1]
    n_light = light.shape[0]
    n_lut = dark_lut.shape[0]
    for i in range(quads.shape[0]):
        qx, qy, qz, yaw = quads[i, 0], quads[i, 1], quads[i, 2], quads[i, 3]
        fx, fy = math.cos(yaw), math.sin(yaw)  # along the track
        rx, ry = fy, -fx  # across it (the rover's right)
        if (qx - ox) ** 2 + (qy - oy) ** 2 > max_dist * max_dist:
            continue
        u_min, u_max, v_min, v_max = 1e9, -1e9, 1e9, -1e9
        behind = False
        for corner in range(4):
            sa = half if corner < 2 else -half
            sb = half if corner % 2 == 0 else -half
            px = qx + sa * fx + sb * rx - ox
            py = qy + sa * fy + sb * ry - oy
            pz = qz - oz
            cam_x = rot[0, 0] * px + rot[1, 0] * py + rot[2, 0] * pz
            cam_y = rot[0, 1] * px + rot[1, 1] * py + rot[2, 1] * pz
            cam_z = rot[0, 2] * px + rot[1, 2] * py + rot[2, 2] * pz
            if cam_z < 0.05:
                behind = True
                break
            u = cx + focal * cam_x / cam_z
            v = cy - focal * cam_y / cam_z
            u_min = min(u_min, u)
            u_max = max(u_max, u)
            v_min = min(v_min, v)
            v_max = max(v_max, v)
        if behind:  # at the camera's feet: the view's nearest floor is 0.31 m ahead, so not visible
            continue
        u0 = max(int(u_min), 0)
        u1 = min(int(u_max) + 1, w_img)
        v0 = max(int(v_min), 0)
        v1 = min(int(v_max) + 1, h_img)
        for v in range(v0, v1):
            b = ray_b[v]
            for u in range(u0, u1):
                a = ray_a[u]
                dz = rot[2, 0] * a + rot[2, 1] * b + rot[2, 2]
                if dz >= -1e-9:
                    continue
                t = (qz - oz) / dz
                if t <= 0.0 or t > depth[v, u] + tolerance:
                    continue
                dx = rot[0, 0] * a + rot[0, 1] * b + rot[0, 2]
                dy = rot[1, 0] * a + rot[1, 1] * b + rot[1, 2]
                ex = ox + t * dx - qx
                ey = oy + t * dy - qy
                along = ex * fx + ey * fy
                across = ex * rx + ey * ry
                if abs(along) >= half or abs(across) >= half:
                    continue
                norm = math.sqrt(dx * dx + dy * dy + dz * dz)
                dist = t * norm
                # mip level from the texels one pixel spans: across the view, or along the ray (the footprint's
                # long axis, 1 / sine of the grazing angle longer) over the anisotropy the texture is filtered with
                across_px = dist / focal
                texels = max(across_px, across_px * norm / (-dz) / aniso) * n_tex / (2.0 * half)
                level = 0
                while texels >= 2.0 and level < n_levels - 1:
                    texels *= 0.5
                    level += 1
                row = int((along / (2.0 * half) + 0.5) * n_tex)
                col = int((across / (2.0 * half) + 0.5) * n_tex)
                if not tread[level, min(row, n_tex - 1), min(col, n_tex - 1)]:
                    continue
                lr = min(max(int((oy + t * dy) / cell + 0.5), 0), n_light - 1)
                lc = min(max(int((ox + t * dx) / cell + 0.5), 0), n_light - 1)
                li = min(int(dist / dark_lut_step), n_lut - 1)
                shade = light[lr, lc] * dark_lut[li]
                for ch in range(3):
                    img[v, u, ch] = np.uint8(min(rgb[ch] * shade + 0.5, 255.0))
                depth[v, u] = t
