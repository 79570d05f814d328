"""The rover camera of the twin: pose -> the 320x160 RGB frame the simulator would show.

How: everything static (terrain, rocks, sand texture, sun shading, baked shadows, unless the world
has cast_shadows off) is baked once into 0.1 m rasters (solid top, overhang gap, colour). A frame is a
column-wise heightfield raymarch (numba): each image column is walked from the
bottom row up, every ray resuming at the horizontal distance where the ray below
hit (exact for a level camera, a few-pixel approximation under pitch/roll), with
1 m max-height cells skipped in one jump. Sample rocks are small shaded ellipsoids
drawn over it with a depth test.

Poses outside the world are clamped into it; a camera inside rock sees that rock
(no crash). Non-finite poses raise ValueError.
"""
from __future__ import annotations

import logging
import math

import cv2
import numpy as np
from numba import njit

from sim.world import World

log = logging.getLogger(__name__)

# --- camera (../shared/udacity-rover/world/camera.json) ---
IMAGE_W, IMAGE_H = 320, 160  # frame size, px
FOCAL_PX = 114.251841  # pinhole focal length, px (vertical FOV 70 deg)
CX, CY = 160.0, 80.0  # principal point, px
CAMERA_MOUNT_UP_M = 0.2391  # camera above the rover root, m
CAMERA_MOUNT_FORWARD_M = 0.4287  # camera ahead of the rover root, m
ROOT_BELOW_GROUND_M = 0.0245  # rover root sits this far below the ground (suspension bottomed out), m
JPEG_QUALITY = 75  # Texture2D.EncodeToJPG default quality

# --- raymarch ---
FAR_M = 120.0  # rays that hit nothing within this horizontal distance show the far colour, m
FINE_STEP_MIN_M = 0.04  # smallest march step near the camera, m
FINE_STEP_PER_M = 0.012  # march step growth with distance, m per m
REFINE_ITERS = 4  # bisection steps locating a rock surface between two march samples
COARSE_CELL_M = 1.0  # empty-space-skipping cell size, m
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
SHADOW_FACTOR = 0.6  # brightness of cast shadow relative to sunlit, 0..1
SHADOW_BLUR_M = 1.5  # soft shadow edge (Gaussian sigma; fitted, real edges are wide penumbrae), m
SLOPE_SHADE = 0.7  # how strongly faces turned from the sun darken (0 = flat look)
SHADOW_STEP_M = 0.2  # march step of the shadow rays baked at load, m
TEXTURE_AMPLITUDE = 0.45  # relative brightness noise on walls and rocks (not on sand), 0..1
TEXTURE_CELLS = (400, 1000)  # texture noise octaves: grid sides over the world, cells
UNDERSIDE_SHADE = 0.45  # darkening of the underside of overhanging rock, 0..1
DIST_DARKEN = 0.17  # fraction of brightness lost far away (real sand 242 -> 202 at 30 m)
DIST_SCALE_M = 8.0  # e-folding distance of that darkening, m

# --- sample rocks ---
SAMPLE_RGB = (1.0, 217 / 255, 0.12)  # gold, 0..1 (Unity (1, 0.85, 0); real frames show blue ~34)
SAMPLE_WIDTH_PER_SCALE_M = 0.37  # sample width at prefab scale 1, m
SAMPLE_HEIGHT_PER_SCALE_M = 0.32  # sample height at prefab scale 1, m
SAMPLE_SINK_M = 0.02  # samples are sunk this much into the floor, m
SAMPLE_MIN_SHADE = 0.62  # darkest shading of a sample, fraction of full colour


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

    if world.cast_shadows:
        k = SHADOW_GRID_STRIDE
        # only the terrain casts shadows: the real frames show sunlit floor under and beside the rocks
        coarse_ground = np.ascontiguousarray(ground[::k, ::k])
        shadow_c = np.zeros(coarse_ground.shape, np.uint8)
        _shadow_kernel(coarse_ground, cell * k, math.cos(az), math.sin(az), math.tan(el),
                       float(ground.max()), SHADOW_STEP_M, shadow_c)
        shadow = cv2.resize(shadow_c.astype(np.float32), (n, n), interpolation=cv2.INTER_LINEAR)
        shadow = cv2.GaussianBlur(shadow, (0, 0), SHADOW_BLUR_M / cell)
        shadow = np.where(has_gap, 0.0, shadow)  # the floor under the overhang looks sunlit in the real frames
    else:  # the simulator's Fastest/Fast quality levels render no shadows
        shadow = np.zeros((n, n), np.float32)
    lut_rgb = np.array(SAND_LUT_RGB, np.float32)
    ground_rgb = np.stack([np.interp(sand, SAND_LUT_WEIGHT, lut_rgb[:, ch]) for ch in range(3)], -1)
    rng = np.random.default_rng(12345)  # fixed: the texture is part of the look, not random per run
    noise = sum(cv2.resize(rng.uniform(-1, 1, (cells, cells)).astype(np.float32), (n, n),
                           interpolation=cv2.INTER_CUBIC) for cells in TEXTURE_CELLS) / len(TEXTURE_CELLS)
    rough = 1.0 + TEXTURE_AMPLITUDE * noise * np.clip((0.7 - sand) / 0.4, 0.0, 1.0)
    # terrain colour everywhere (what a ray hitting the ground sees), bilinear in the kernel
    light = sun_shade(ground) * (1.0 - (1.0 - SHADOW_FACTOR) * shadow)
    colour_ground = np.clip(ground_rgb * (rough * light)[..., None], 0, 255).astype(np.uint8)
    # rock colour (what a ray hitting a rock slab sees), nearest cell in the kernel
    rock_rgb = np.array(ROCK_RGB, np.float32) * (1.0 + TEXTURE_AMPLITUDE * noise)[..., None]
    colour_rock = np.clip(rock_rgb * sun_shade(top)[..., None], 0, 255).astype(np.uint8)
    colour_rock = np.where(has_rock[..., None], colour_rock, colour_ground)
    kc = int(round(COARSE_CELL_M / cell))
    cmax = _coarse_max(top, kc)
    # free band under overhangs per coarse cell: above every ground, below every rock bottom
    cground = _coarse_max(ground, kc)
    cbottom = -_coarse_max(-slab_lo, kc)  # lowest rock bottom (-1e9 solid rock, 1e9 open sky)
    return {"top": top, "ground": ground.astype(np.float32), "slab_lo": slab_lo, "slab_hi": slab_hi,
            "has_gap": has_gap, "colour": colour_ground, "colour_rock": colour_rock, "cmax": cmax,
            "cground": cground, "cbottom": cbottom,
            "sand": sand.astype(np.float32), "shadow": shadow.astype(np.float32),
            "has_rock": has_rock, "light": light.astype(np.float32), "sun": sun}


def _coarse_max(top: np.ndarray, k: int) -> np.ndarray:
    """Max of the vertex grid over each k-vertex block including its far edge (for skipping)."""
    n = (top.shape[0] - 1) // k
    pad = top[: n * k + 1, : n * k + 1]
    dil = cv2.dilate(pad, np.ones((3, 3), np.uint8))  # bilinear support reaches one vertex further
    blocks = dil[: n * k, : n * k].reshape(n, k, n, k).max(axis=(1, 3))
    edge_r = dil[k::k, : n * k].reshape(n, n, k).max(axis=2)  # row after each block
    edge_c = dil[: n * k, k::k].reshape(n, k, n).max(axis=1)
    return np.maximum(np.maximum(blocks, edge_r), edge_c).astype(np.float32)


# ---------------------------------------------------------------------- marching
@njit(cache=True, nogil=True, inline="always")
def _top_at(top, inv_cell, x, y):
    n = top.shape[0] - 1
    fx = x * inv_cell
    fy = y * inv_cell
    if fx < 0.0:
        fx = 0.0
    elif fx > n - 1e-4:
        fx = n - 1e-4
    if fy < 0.0:
        fy = 0.0
    elif fy > n - 1e-4:
        fy = n - 1e-4
    c = int(fx)
    r = int(fy)
    tx = fx - c
    ty = fy - r
    return ((top[r, c] * (1 - tx) + top[r, c + 1] * tx) * (1 - ty)
            + (top[r + 1, c] * (1 - tx) + top[r + 1, c + 1] * tx) * ty)


@njit(cache=True, nogil=True, inline="always")
def _nearest(n, inv_cell, v):
    f = v * inv_cell + 0.5
    if f < 0.0:
        return 0
    i = int(f)
    return i if i < n else n - 1


@njit(cache=True, nogil=True)
def _solid(ground, slab_lo, slab_hi, inv_cell, x, y, z):
    """0 free, 1 terrain, 3 rock slab, 2 free under an overhanging slab.

    Terrain is bilinear; rocks use the nearest 0.1 m cell (the world's own rule).
    """
    if z <= _top_at(ground, inv_cell, x, y):
        return 1
    n = ground.shape[0]
    r = _nearest(n, inv_cell, y)
    c = _nearest(n, inv_cell, x)
    if z <= slab_hi[r, c]:
        if z >= slab_lo[r, c]:
            return 3
        return 2
    return 0


@njit(cache=True, nogil=True, fastmath={"nsz", "arcp", "contract", "afn", "reassoc"})
def _render_kernel(img_t, depth_t, hit_t, ground, slab_lo, slab_hi, colour, colour_rock, cmax,
                   cground, cbottom, cell, coarse_m, rot, origin,
                   ray_a, ray_b, far_m, step_min, step_k, refine_iters, zmax, sky_rgb, far_rgb,
                   underside_shade, world_size, dist_darken, dist_scale):
    w_img, h_img = img_t.shape[0], img_t.shape[1]
    inv_cell = 1.0 / cell
    n = ground.shape[0]
    nc = cmax.shape[0]
    ox, oy, oz = origin[0], origin[1], origin[2]
    for u in range(w_img):
        prev_s = 0.0  # where the ray below ended (hit, sky or far), horizontal m
        sky_rest = False
        # overhang passage of the ray below: first/last distance under a slab, lowest slab bottom
        g_first = -1.0
        g_last = -1.0
        g_bottom = 1e9
        for v in range(h_img - 1, -1, -1):
            if sky_rest:
                for ch in range(3):
                    img_t[u, v, ch] = sky_rgb[ch]
                depth_t[u, v] = np.inf
                hit_t[u, v, 0] = np.nan
                continue
            a = ray_a[u]
            b = ray_b[v]
            dx = rot[0, 0] * a + rot[0, 1] * b + rot[0, 2]
            dy = rot[1, 0] * a + rot[1, 1] * b + rot[1, 2]
            dz = rot[2, 0] * a + rot[2, 1] * b + rot[2, 2]
            hlen = math.sqrt(dx * dx + dy * dy)
            if hlen < 1e-9:
                hlen = 1e-9
            hx = dx / hlen
            hy = dy / hlen
            k = dz / hlen
            # Coherence: this ray is above the one below, so it is free wherever that ray was free
            # in open air; only where that ray passed under an overhang may this one hit earlier
            # (the underside), and only if it can climb to the overhang's bottom.
            jump_from = -1.0
            jump_to = 0.0
            if g_first >= 0.0 and (k > 0.0 or oz >= g_bottom):
                s = g_first
                jump_from = g_last
                jump_to = prev_s
                g_first = -1.0
                g_last = -1.0
                g_bottom = 1e9
            else:
                s = prev_s
            s_free = s
            state = 0
            hit = 0  # 0 none, 1 surface, 2 sky, 3 far
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
                    ci = int(x / coarse_m)
                    ri = int(y / coarse_m)
                    if ci >= nc:
                        ci = nc - 1
                    if ri >= nc:
                        ri = nc - 1
                    cm = cmax[ri, ci]
                    above = z > cm
                    under = (not above) and cground[ri, ci] < z < cbottom[ri, ci]
                    if above or under:
                        # distance to leave this coarse cell
                        if hx > 1e-12:
                            ex = ((ci + 1) * coarse_m - x) / hx
                        elif hx < -1e-12:
                            ex = (ci * coarse_m - x) / hx
                        else:
                            ex = 1e9
                        if hy > 1e-12:
                            ey = ((ri + 1) * coarse_m - y) / hy
                        elif hy < -1e-12:
                            ey = (ri * coarse_m - y) / hy
                        else:
                            ey = 1e9
                        ds = min(ex, ey) + 1e-4
                        z_exit = oz + (s + ds) * k
                        if (above and z_exit > cm) or (under and cground[ri, ci] < z_exit < cbottom[ri, ci]):
                            if under and cbottom[ri, ci] < 1e8:  # passing under an overhang
                                if g_first < 0.0:
                                    g_first = s
                                g_last = max(g_last, s + ds)
                                g_bottom = min(g_bottom, cbottom[ri, ci])
                            s_free = s + ds
                            s = s_free
                            continue
                state = _solid(ground, slab_lo, slab_hi, inv_cell, x, y, z)
                if state == 1 or state == 3:
                    hit = 1
                    break
                if state == 2:
                    if g_first < 0.0:
                        g_first = s
                    g_last = max(g_last, s)
                    g_bottom = min(g_bottom, slab_lo[_nearest(n, inv_cell, y), _nearest(n, inv_cell, x)])
                s_free = s
                step = step_min + step_k * s
                s += step
            if hit == 1:
                lo = s_free
                hi = s
                if state == 1 and hi > lo:
                    # terrain: one secant step on z - ground (smooth surface)
                    f_lo = (oz + lo * k) - _top_at(ground, inv_cell, ox + lo * hx, oy + lo * hy)
                    f_hi = z - _top_at(ground, inv_cell, x, y)
                    if f_lo > 0.0 and f_hi <= 0.0 and f_lo - f_hi > 1e-9:
                        hi = lo + (hi - lo) * f_lo / (f_lo - f_hi)
                elif hi > lo:
                    # rock slab: bisection (nearest-cell slabs have vertical sides)
                    for _ in range(refine_iters):
                        mid = 0.5 * (lo + hi)
                        st = _solid(ground, slab_lo, slab_hi, inv_cell, ox + mid * hx,
                                    oy + mid * hy, oz + mid * k)
                        if st == 1 or st == 3:
                            hi = mid
                        else:
                            lo = mid
                s = hi
                x = ox + s * hx
                y = oy + s * hy
                z = oz + s * k
                fx = min(max(x * inv_cell, 0.0), n - 1 - 1e-4)
                fy = min(max(y * inv_cell, 0.0), n - 1 - 1e-4)
                c0 = int(fx)
                r0 = int(fy)
                tx = fx - c0
                ty = fy - r0
                shade = 1.0
                dist = s * math.sqrt(1.0 + k * k)
                shade *= 1.0 - dist_darken * (1.0 - math.exp(-dist / dist_scale))
                if state == 1:  # terrain: bilinear ground colour
                    for ch in range(3):
                        val = ((colour[r0, c0, ch] * (1 - tx) + colour[r0, c0 + 1, ch] * tx) * (1 - ty)
                               + (colour[r0 + 1, c0, ch] * (1 - tx) + colour[r0 + 1, c0 + 1, ch] * tx) * ty)
                        img_t[u, v, ch] = np.uint8(min(255.0, val * shade + 0.5))
                else:  # rock slab: nearest cell, darker on the underside of an overhang
                    rr = _nearest(n, inv_cell, y)
                    cc = _nearest(n, inv_cell, x)
                    if -1e8 < slab_lo[rr, cc] < 1e8 and z < slab_lo[rr, cc] + 0.3:
                        shade *= underside_shade
                    for ch in range(3):
                        img_t[u, v, ch] = np.uint8(min(255.0, colour_rock[rr, cc, ch] * shade + 0.5))
                depth_t[u, v] = s / hlen
                hit_t[u, v, 0] = x
                hit_t[u, v, 1] = y
                hit_t[u, v, 2] = z
                prev_s = s
            elif hit == 2:
                for ch in range(3):
                    img_t[u, v, ch] = sky_rgb[ch]
                depth_t[u, v] = np.inf
                hit_t[u, v, 0] = np.nan
                sky_rest = g_first < 0.0
                prev_s = s
            else:
                for ch in range(3):
                    img_t[u, v, ch] = far_rgb[ch]
                depth_t[u, v] = np.inf
                hit_t[u, v, 0] = np.nan
                prev_s = far_m


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
        self._zmax = float(self._top.max()) + 0.01
        self._ray_a = ((np.arange(IMAGE_W) + 0.5 - CX) / FOCAL_PX).astype(np.float64)
        self._ray_b = ((CY - (np.arange(IMAGE_H) + 0.5)) / FOCAL_PX).astype(np.float64)
        self._sky = np.array(SKY_RGB, np.uint8)
        self._far = np.array(FAR_RGB, np.uint8)
        self.last_depth = np.full((IMAGE_H, IMAGE_W), np.inf, np.float32)

    def camera(self, pose):
        """(origin xyz in world, 3x3 rotation whose columns are right/up/forward) for a pose."""
        x, y, yaw, pitch, roll, *rest = validate_pose(pose)
        x, y = (float(v) for v in self.world.clamp_xy(x, y))
        rot = body_rotation(yaw, pitch, roll)
        if rest:
            root_z = rest[0]
        else:
            root_z = float(self.world.height_at(x, y)) - ROOT_BELOW_GROUND_M
        mount = np.array([0.0, CAMERA_MOUNT_UP_M, CAMERA_MOUNT_FORWARD_M])
        origin = np.array([x, y, root_z]) + rot @ mount
        return origin, rot

    def render(self, pose, samples=()) -> np.ndarray:
        """uint8 RGB (160, 320, 3) for pose (x, y, yaw, pitch, roll) in degrees.

        samples: iterable of (x, y, scale, yaw_deg) gold sample rocks to draw.
        """
        origin, rot = self.camera(pose)
        # column-major buffers: the kernel walks columns, so it writes contiguous memory
        img_t = np.empty((IMAGE_W, IMAGE_H, 3), np.uint8)
        depth_t = np.empty((IMAGE_W, IMAGE_H), np.float32)
        hit_t = np.full((IMAGE_W, IMAGE_H, 3), np.nan, np.float32)  # sky stays nan in all three (the kernel writes x only)
        _render_kernel(img_t, depth_t, hit_t, self._ground, self._slab_lo, self._slab_hi, self.colour_map,
                       self._colour_rock, self._cmax, self._cground, self._cbottom,
                       float(self.world.rock_cell_m), COARSE_CELL_M,
                       np.ascontiguousarray(rot), origin, self._ray_a, self._ray_b, FAR_M,
                       FINE_STEP_MIN_M, FINE_STEP_PER_M, REFINE_ITERS, self._zmax, self._sky,
                       self._far, UNDERSIDE_SHADE, float(self.world.size_m), DIST_DARKEN,
                       DIST_SCALE_M)
        img = np.ascontiguousarray(img_t.transpose(1, 0, 2))
        depth = np.ascontiguousarray(depth_t.T)
        hitpos = hit_t.transpose(1, 0, 2)
        for sample in samples:
            self._draw_sample(img, depth, origin, rot, sample)
        self.last_depth = depth  # distance along the ray / |forward|, inf for sky
        self.last_hit = hitpos  # world (x, y, z) of each pixel's surface, all nan for sky
        return img

    # ------------------------------------------------------------------ samples
    def _draw_sample(self, img, depth, origin, rot, sample):
        """Shaded gold ellipsoid standing on the ground, with a depth test."""
        sx, sy, scale, syaw = (float(v) for v in sample)
        if not all(math.isfinite(v) for v in (sx, sy, scale, syaw)):
            return
        half_w = 0.5 * SAMPLE_WIDTH_PER_SCALE_M * scale
        half_h = 0.5 * SAMPLE_HEIGHT_PER_SCALE_M * scale
        ground = float(self.world.height_at(sx, sy))
        centre = np.array([sx, sy, ground + half_h - SAMPLE_SINK_M])
        rel = centre - origin
        cam = rot.T @ rel  # right, up, forward
        radius = max(half_w, half_h) * 1.1
        if cam[2] <= 0.05 or np.linalg.norm(rel) > FAR_M:
            return
        u_c = CX + FOCAL_PX * cam[0] / cam[2]
        v_c = CY - FOCAL_PX * cam[1] / cam[2]
        r_px = FOCAL_PX * radius / max(cam[2] - radius, 0.05) + 2
        u0, u1 = int(max(0, u_c - r_px)), int(min(IMAGE_W, u_c + r_px + 1))
        v0, v1 = int(max(0, v_c - r_px)), int(min(IMAGE_H, v_c + r_px + 1))
        if u0 >= u1 or v0 >= v1:
            return
        uu, vv = np.meshgrid(self._ray_a[u0:u1], self._ray_b[v0:v1])
        dirs = (rot[:, 0][None, None] * uu[..., None] + rot[:, 1][None, None] * vv[..., None]
                + rot[:, 2][None, None])  # world ray directions (forward component 1)
        c, s = math.cos(math.radians(syaw)), math.sin(math.radians(syaw))
        # ellipsoid frame: rotate by yaw, scale to the unit sphere (slightly oblong)
        axes = np.array([half_w * 1.08, half_w * 0.92, half_h])
        basis = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        o_l = (basis @ (origin - centre)) / axes
        d_l = (dirs @ basis.T) / axes
        qa = np.einsum("ijk,ijk->ij", d_l, d_l)
        qb = 2.0 * (d_l @ o_l)
        qc = float(o_l @ o_l) - 1.0
        disc = qb * qb - 4 * qa * qc
        hit = disc > 0
        t = np.where(hit, (-qb - np.sqrt(np.maximum(disc, 0))) / (2 * qa), np.inf)
        hit &= (t > 0) & (t < depth[v0:v1, u0:u1])
        if not hit.any():
            return
        p_l = o_l[None] + t[hit][:, None] * d_l[hit]
        normal_w = (p_l / axes) @ basis  # gradient of the ellipsoid, back in world axes
        normal_w /= np.linalg.norm(normal_w, axis=-1, keepdims=True) + 1e-12
        az, el = math.radians(SUN_AZIMUTH_DEG), math.radians(SUN_ELEVATION_DEG)
        sun = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        lam = np.clip(normal_w @ sun, 0.0, 1.0)
        shade = SAMPLE_MIN_SHADE + (1.0 - SAMPLE_MIN_SHADE) * lam
        rgb = np.clip(np.array(SAMPLE_RGB)[None] * shade[:, None] * 255.0, 0, 255)
        patch = img[v0:v1, u0:u1]
        patch[hit] = rgb.astype(np.uint8)
        depth[v0:v1, u0:u1][hit] = t[hit]
