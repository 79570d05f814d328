"""The look of the real drives recorded without cast shadows (issue 28): what the twin's camera adds
when the world's cast_shadows is off (the simulator's quality levels without realtime shadows).

Measured on floor pixels (sand weight > 0.9) of the real frames against twin frames at the same
poses. Fitted on megalphian and dimaga, checked on royalejandro (held out); test_dataset was
recorded at a quality level with cast shadows and keeps the `--shadows on` look.

1. Far floor: the terrain's splat map seen through its mipmaps (`splat_pyramid`, `apply_splat_mip`).
   The terrain blends its sand layer and six dark rock layers by a 512 x 512 weight texture (0.39 m
   texels). The GPU samples that texture at the mip level of each pixel's footprint, and at grazing
   view a pixel's footprint along the ray grows with the square of the distance (4 m at 10 m), so far
   floor is drawn with a weight averaged over metres of floor: dark wherever a wall foot lies
   within that reach, bright only in the middle of wide floor. With no fitted parameter beyond the
   rock layers' colour and a mip cap, this predicts the far floor's brightness per distance band
   (5-6.5, 6.5-8, 8-10, 10-13, 13-18, 18-30 m: 0.98, 0.95, 0.90, 0.82, 0.67, 0.58 of the near floor;
   real on megalphian: 0.95, 0.93, 0.88, 0.77, 0.64, 0.56, the near floor itself being at 0.95) and,
   pixel by pixel, correlates 0.4-0.7 with the real frames' far-floor brightness within 18 m, which
   a distance curve cannot (it draws one value per distance).
   The far floor also turns redder because the rock layers are (green / red 0.68 against 0.91).
   An earlier distance curve (knee 5.2 m, e-folding 8.65 m) fitted the medians but drew all far
   floor alike, so the whole-view masks missed the bright far floor of open stretches.
2. Back-scatter: floor seen with the sun behind the camera is brighter, in a lobe of view azimuth
   (`apply_backscatter`). Real over twin floor brightness by the pixel's view azimuth minus the azimuth
   opposite the sun, 10-degree bins from -60 to +60: 0.97 0.98 1.00 1.03 1.08 1.17 1.20 1.14 1.06 1.00
   0.98 0.97 on megalphian, the same within 0.02 on royalejandro, dimaga and test_dataset (1.24 at
   the peak); flat by the rover's heading, so it belongs to the view ray, not to the drive. It shows as
   the bright streak the real frames have toward 115-120 degrees. The cause in the simulator's
   shader is not known; the lobe is applied at both quality levels.
3. The floor the walls hide from the sun is darker even without cast shadows, though far less than
   in cast shadow (`SHADOWLESS_SHADOW_FACTOR`). Within 5 m of the camera, on the floor the twin's
   shadow raster marks as shadowed, the real floor is 14 (megalphian), 12-30 (dimaga) and 34
   (royalejandro) grey levels darker than the twin without shadows, beyond the 5-14 of the sunlit
   floor. An isotropic sky-visibility (ambient-occlusion) term was tried first and rejected: it also
   darkens the floor at sunlit wall feet, which the real frames show bright (royalejandro facing
   the wall at (61, 104): IoU within 5 m fell 0.7 there, -0.018 over the drive).
4. Cast shadows (round 3, `cast_shadow_cover`): dimaga, royalejandro and test_dataset were all recorded at a
   quality level with cast shadows; only megalphian shows none. At the same 2 m floor cells (pure sand,
   within 5 m) megalphian reads 193-194 in the darkest channel where the shadow raster is above 0.02,
   the other three 164-168 (0.85 of their sunlit 194-197). The real shadow is one flat step, not a
   deep core with a 1.5 m penumbra, and it reaches the raster's blurred fringe (half the pure-sand
   pixels are dark where the raster is only 0.03-0.07). So with cast shadows the twin darkens by
   CAST_SHADOW_FACTOR over a ramp on the blurred raster, and draws the far floor with the same
   mipmaps and back-scatter as without (items 1 and 2); fitted on dimaga, checked on royalejandro
   and test_dataset.
5. Far falloff (round 4, `far_falloff`): on pure sunlit sand the real floor at 10-16 m is 8-16 % darker
   than the twin draws it with the mipmaps alone (real / twin darkest channel 0.92 / 0.86 megalphian,
   0.91 / 0.88 royalejandro, 0.94 / 0.84 dimaga at 10-12 / 12-16 m; 0.96-0.99 from 2 to 10 m), so
   everything beyond 8 m darkens by up to FAR_FALLOFF. Fitted on megalphian and dimaga, checked on
   royalejandro (held out). test_dataset's far floor is the other way round (real brighter, 1.03-1.23
   beyond 10 m): its quality level filters more sharply (round 3), and its whole view loses by this.
   Round 4 tried SHADOWLESS_SHADOW_FACTOR at megalphian's measured shadowed / sunlit ratio (0.97): +0.004
   IoU within 5 m there, but the twin then mapped 1.8 points more than the real frames (0.9: 1.4); 0.97 since
   round 6 (item 7).
6. Hue of the wall feet and of shaded floor (round 5, `floor_red_gain`): the real floor at sand weights 0.6-0.75 is
   redder than the colour table (green / red 0.006-0.013 and blue / red 0.007-0.014 lower on all four drives), and
   floor the terrain shades is redder still (about 0.7 % more red at full cast shadow: lit by the reddish sky alone).
   The twin raises red only, which is never sand's darkest channel, so the starter's 160 threshold and every IoU
   stay as they were; what changes is the client's shadowed-sand colour test (green / red >= 0.90, blue / red >=
   0.83), which the twin's shaded wall feet passed 1.7-2x as often as the real ones, so the twin mapped 2-3 points
   more. Fitted on megalphian, dimaga and test_dataset, royalejandro held out (docs/twin-realism.md round 5).
7. Wall feet without cast shadows (round 6, `shadowless_wall_foot_light`): at the same 2 m floor cells, sunlit, 1.5-6 m
   away, the shadowless drive (megalphian) reads 0.89-0.90 of royalejandro's and dimaga's brightness at sand weights
   0.70-0.77, 0.92-0.95 at 0.78-0.80 and 1.00 from 0.80 on (royalejandro / dimaga: flat, 1.05-1.06 at every weight),
   so the quality levels without cast shadows draw the sand-rock blend darker, the open floor not. The colour table
   was fitted at a quality level with cast shadows, so only the shadowless look darkens (10 % up to weight 0.775, none
   from 0.80). With it, SHADOWLESS_SHADOW_FACTOR is megalphian's measured shadowed / sunlit ratio (0.97, as
   `sim.realism --shadows auto` reports): round 4's 0.9 kept the map gap within 1.5 points, which the darker wall
   feet now do (docs/twin-realism.md round 6).
8. Hue spread of the wall feet (round 10, `wall_foot_red_grain`): at sand weights 0.65-0.75 the real floor's pixels
   scatter from texel to texel, much of it redder, where the colour table draws one colour just above the client's
   near-hue lines, so the twin's wall feet passed the near-hue and shadowed-sand tests far more often (near-hue
   0.64-0.78 of the band's pixels against 0.41-0.54 real) and its map at a real drive's poses read 1.3-2.3 points
   more floor at 0.9-1.4 points less fidelity. A fixed half-normal red grain per 0.1 m vertex closes that to within
   0.7 point on all three drives; fitted on megalphian and dimaga, royalejandro held out (docs/twin-realism.md
   round 10). Red only, so the starter's threshold is untouched (a brightness grain was tried and cost the 5 m IoU).
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit

SHADOWLESS_KNEE_M = 5.2  # the near floor's mild darkening stops growing here, m
SHADOWLESS_NEAR_SHARE = 0.5  # share of the other quality levels' near-floor darkening kept, 0..1
SHADOWLESS_SHADOW_FACTOR = 0.97  # brightness of the floor hidden from the sun without cast shadows (megalphian's shadowed / sunlit ratio), 0..1
FAR_FALLOFF = 0.08  # extra darkening of everything far away (real far floor 8-16 m darker than the mipmaps alone), fraction
FAR_FALLOFF_START_M = 8.0  # ... which starts at this viewing distance, m
FAR_FALLOFF_SCALE_M = 4.0  # ... and grows to its full size over this e-folding distance, m
ROCK_LAYER_RGB = (78.0, 53.0, 45.0)  # mean colour of the terrain's six rock layers on lit level ground, 0..255
SPLAT_LOD_MAX = 5.0  # coarsest mip level the far floor is drawn with (5: 12.5 m texels), levels
SPLAT_LOD_BIAS = 0.0  # added to each pixel's mip level (0: the footprint's long axis, isotropic filtering), levels
SPLAT_MIN_SIN = 0.005  # grazing-angle sine below which the footprint is taken as at this sine, 0..1
BACKSCATTER_GAIN = 0.25  # extra brightness of the floor seen straight away from the sun, fraction
BACKSCATTER_OFFSET_DEG = 3.0  # the bright lobe's centre, degrees counter-clockwise of the sun's opposite azimuth
BACKSCATTER_SIGMA_DEG = 13.6  # the lobe's width (Gaussian sigma) in view azimuth, degrees
MIN_FOOT_HEIGHT_M = 0.2  # pixels nearer than sqrt(texel x focal x this) skip the mip pass (level floor, camera 0.21 m up), m
ROCK_HIT_ABOVE_GROUND_M = 0.05  # a hit this far above the terrain is a rock mesh, drawn without the splat map, m
CAST_SHADOW_FACTOR = 0.82  # brightness of the terrain-shadowed floor at the quality levels with cast shadows, 0..1
CAST_SHADOW_COVER = (0.1, 0.3)  # blurred shadow raster values over which the cast shadow ramps from none to full, 0..1
WALL_FOOT_RED_GAIN = 0.012  # extra red of the sand-rock blend at the wall feet (item 6; red only: never the darkest channel), fraction
WALL_FOOT_RED_FULL_BELOW = 0.70  # ... in full at and below this sand weight, 0..1
WALL_FOOT_RED_NONE_FROM = 0.80  # ... fading to none at this sand weight (open floor keeps the colour table's hue), 0..1
SHADOW_RED_PER_DARKENING = 0.044  # extra red of floor the terrain shades, per unit of its darkening (full cast shadow 0.18: x1.008; item 6), fraction
SHADOWLESS_WALL_FOOT_DARKEN = 0.10  # darkening of the wall-foot floor at the quality levels without cast shadows (item 7), fraction
SHADOWLESS_WALL_FOOT_FULL_BELOW = 0.775  # ... in full at and below this sand weight, 0..1
SHADOWLESS_WALL_FOOT_NONE_FROM = 0.80  # ... fading to none at this sand weight (open floor as before), 0..1
WALL_FOOT_HUE_GRAIN = 0.045  # red spread of the wall-foot floor per 0.1 m vertex (sigma of a half-normal: only ever redder; item 8), fraction
WALL_FOOT_GRAIN_FULL_BELOW = 0.75  # ... in full at and below this sand weight, 0..1
WALL_FOOT_GRAIN_NONE_FROM = 0.85  # ... fading to none at this sand weight (open floor keeps the colour table's colour), 0..1
WALL_FOOT_GRAIN_SEED = 2718  # seed of the grain's fixed random field


def shadowless_darkening(dist_m) -> np.ndarray:
    """Brightness factor by viewing distance (both quality levels since round 3): a share of the first
    look's near-floor darkening (the colour table was fitted with that curve), held from the knee on,
    times the far falloff (item 5); the far floor's varying darkening comes from the splat mipmaps."""
    from sim.render import DIST_DARKEN, DIST_SCALE_M

    dist = np.asarray(dist_m, np.float64)
    near = 1.0 - SHADOWLESS_NEAR_SHARE * DIST_DARKEN * (1.0 - np.exp(-np.minimum(dist, SHADOWLESS_KNEE_M) / DIST_SCALE_M))
    return near * far_falloff(dist)


def far_falloff(dist_m) -> np.ndarray:
    """Brightness factor beyond FAR_FALLOFF_START_M (1 nearer): the real far floor is darker than the
    splat mipmaps alone draw it, on every drive except test_dataset's quality level (item 5)."""
    beyond = np.maximum(np.asarray(dist_m, np.float64) - FAR_FALLOFF_START_M, 0.0)
    return 1.0 - FAR_FALLOFF * (1.0 - np.exp(-beyond / FAR_FALLOFF_SCALE_M))


def cast_shadow_cover(shadow: np.ndarray) -> np.ndarray:
    """Share of the cast shadow (0..1) each cell gets at the quality levels with cast shadows: a ramp on the
    blurred shadow raster, so the shadow is one flat step reaching its fringe, as the real frames show."""
    lo, hi = CAST_SHADOW_COVER
    return np.clip((np.asarray(shadow, np.float32) - lo) / (hi - lo), 0.0, 1.0)


def wall_foot_ramp(sand: np.ndarray, full_below: float, none_from: float) -> np.ndarray:
    """float32 0..1: how much of a wall-foot term a terrain cell gets from its sand weight, 1 at and below
    full_below, fading to 0 at none_from (open floor), shared by items 6 and 7."""
    return np.clip((none_from - np.asarray(sand, np.float32)) / (none_from - full_below), 0.0, 1.0)


def floor_red_gain(sand: np.ndarray, darkening: np.ndarray) -> np.ndarray:
    """Factor on the red channel of the terrain colour (item 6): the real wall-foot floor is redder than the
    colour table draws it, and shaded floor redder still (lit by the reddish sky alone); only the client's
    shadowed-sand colour test sees either, the starter's threshold never (red is not sand's darkest channel).

    darkening: 1 - the shadow's brightness factor where the floor is shaded (0 in sun), 0..1."""
    ramp = wall_foot_ramp(sand, WALL_FOOT_RED_FULL_BELOW, WALL_FOOT_RED_NONE_FROM)
    return ((1.0 + WALL_FOOT_RED_GAIN * ramp) * (1.0 + SHADOW_RED_PER_DARKENING * np.asarray(darkening, np.float32))
            ).astype(np.float32)


def shadowless_wall_foot_light(sand: np.ndarray) -> np.ndarray:
    """Brightness factor of the terrain colour at the quality levels without cast shadows (item 7): at the same
    wall-foot floor cells the shadowless drive reads darker than the drives with cast shadows, whose look the
    colour table was fitted on, while open sand reads the same."""
    ramp = wall_foot_ramp(sand, SHADOWLESS_WALL_FOOT_FULL_BELOW, SHADOWLESS_WALL_FOOT_NONE_FROM)
    return (1.0 - SHADOWLESS_WALL_FOOT_DARKEN * ramp).astype(np.float32)


def wall_foot_red_grain(sand: np.ndarray, seed: int = WALL_FOOT_GRAIN_SEED) -> np.ndarray:
    """Factor on the red channel per terrain vertex (item 8): the real wall-foot floor blends sand with six rock
    layers that vary from texel to texel, so its pixels spread in hue around the colour table's one colour per
    sand weight, always toward the rock layers' red; a fixed half-normal grain per 0.1 m vertex, in full on the
    wall feet and none on open sand.  Red only: the starter's 160 threshold never sees it."""
    rng = np.random.default_rng(seed)  # fixed: the grain is part of the look, not random per run
    ramp = wall_foot_ramp(sand, WALL_FOOT_GRAIN_FULL_BELOW, WALL_FOOT_GRAIN_NONE_FROM)
    return (1.0 + WALL_FOOT_HUE_GRAIN * ramp * np.abs(rng.standard_normal(np.shape(sand), np.float32))).astype(np.float32)


def splat_pyramid(sand_weight: np.ndarray) -> np.ndarray:
    """float32 (levels, n, n): the sand weight texture and its 2x2-averaged mipmaps, level k in [:n >> k, :n >> k]."""
    level = np.ascontiguousarray(sand_weight, np.float32)
    n = level.shape[0]
    levels = int(math.ceil(SPLAT_LOD_MAX)) + 1
    out = np.zeros((levels + 1, n, n), np.float32)
    for k in range(levels + 1):
        out[k, : level.shape[0], : level.shape[1]] = level
        if level.shape[0] > 1:
            level = cv2.resize(level, (level.shape[1] // 2, level.shape[0] // 2), interpolation=cv2.INTER_AREA)
    return out


@njit(cache=True, nogil=True, inline="always")
def _clamped_cell(n, fx, fy):
    """(c, r, ax, ay): the cell of an n x n vertex grid that holds grid point (fx, fy), clamped into the grid,
    and the point's offsets inside it - the one clamp every bilinear lookup here shares."""
    fx = min(max(fx, 0.0), n - 1.0001)
    fy = min(max(fy, 0.0), n - 1.0001)
    c, r = int(fx), int(fy)
    return c, r, fx - c, fy - r


@njit(cache=True, nogil=True, inline="always")
def _blend(v00, v01, v10, v11, ax, ay):
    """Bilinear blend of a cell's four vertex values (row 0 then row 1) at offsets (ax, ay)."""
    return (v00 * (1.0 - ax) + v01 * ax) * (1.0 - ay) + (v10 * (1.0 - ax) + v11 * ax) * ay


@njit(cache=True, nogil=True, inline="always")
def _pyramid_cell_value(pyr, k, fx, fy):
    """Bilinear value of mip level k at its own grid coordinates (fx, fy), clamped."""
    c, r, ax, ay = _clamped_cell(pyr.shape[1] >> k, fx, fy)
    return _blend(pyr[k, r, c], pyr[k, r, c + 1], pyr[k, r + 1, c], pyr[k, r + 1, c + 1], ax, ay)


@njit(cache=True, nogil=True, inline="always")
def _texel_bilinear(pyr, k, texel_m, x, y):
    t = texel_m * (1 << k)
    return _pyramid_cell_value(pyr, k, x / t - 0.5, y / t - 0.5)


@njit(cache=True, nogil=True, inline="always")
def _terrain_bilinear(terrain, inv_cell, x, y):
    c, r, ax, ay = _clamped_cell(terrain.shape[0], x * inv_cell, y * inv_cell)
    return _blend(terrain[r, c], terrain[r, c + 1], terrain[r + 1, c], terrain[r + 1, c + 1], ax, ay)


@njit(cache=True, nogil=True, inline="always")
def _terrain_with_slope(terrain, inv_cell, x, y):
    """(height, dh/dx, dh/dy) of the bilinear terrain at (x, y), from one cell's four vertices."""
    c, r, ax, ay = _clamped_cell(terrain.shape[0], x * inv_cell, y * inv_cell)
    t00, t01, t10, t11 = terrain[r, c], terrain[r, c + 1], terrain[r + 1, c], terrain[r + 1, c + 1]
    h = _blend(t00, t01, t10, t11, ax, ay)
    gx = ((t01 - t00) * (1.0 - ay) + (t11 - t10) * ay) * inv_cell
    gy = ((t10 - t00) * (1.0 - ax) + (t11 - t01) * ax) * inv_cell
    return h, gx, gy


@njit(cache=True, nogil=True)
def apply_splat_mip(img, depth, origin, rot, ray_a, ray_b, pyr, texel_m, focal_px, terrain, inv_tcell,
                    sand_rgb, rock_rgb, lod_bias, lod_max, min_sin, rock_above_m):
    """Recolour each terrain pixel by the splat weight at its mip level over the weight at full resolution, in place.

    depth: the raymarch's depth along the forward axis (inf for sky); a pixel's footprint along the floor is
    its viewing distance / (focal length x sine of the grazing angle against the terrain's normal)."""
    h, w = depth.shape
    min_foot = texel_m  # footprints under one texel use the full-resolution texture: nothing to do
    for v in range(h):
        for u in range(w):
            d = depth[v, u]
            if not d < 1e30:
                continue
            dx = rot[0, 0] * ray_a[u] + rot[0, 1] * ray_b[v] + rot[0, 2]
            dy = rot[1, 0] * ray_a[u] + rot[1, 1] * ray_b[v] + rot[1, 2]
            dz = rot[2, 0] * ray_a[u] + rot[2, 1] * ray_b[v] + rot[2, 2]
            norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            dist = d * norm
            if dist * dist < min_foot * focal_px * MIN_FOOT_HEIGHT_M:  # nearer level floor shows full-resolution texels
                continue
            x, y, z = origin[0] + d * dx, origin[1] + d * dy, origin[2] + d * dz
            ground, gx, gy = _terrain_with_slope(terrain, inv_tcell, x, y)
            if z > ground + rock_above_m:
                continue
            sin_g = abs(-gx * dx - gy * dy + dz) / (norm * math.sqrt(gx * gx + gy * gy + 1.0))
            foot = dist / (focal_px * max(sin_g, min_sin))
            if foot <= min_foot:
                continue
            lod = min(math.log2(foot / texel_m) + lod_bias, lod_max)
            if lod <= 0.0:
                continue
            k = int(lod)
            f = lod - k
            blur = _texel_bilinear(pyr, k, texel_m, x, y)
            if f > 0.0:
                blur = blur * (1.0 - f) + _texel_bilinear(pyr, k + 1, texel_m, x, y) * f
            sharp = _texel_bilinear(pyr, 0, texel_m, x, y)
            for ch in range(3):
                s, r = sand_rgb[ch], rock_rgb[ch]
                factor = (blur * s + (1.0 - blur) * r) / (sharp * s + (1.0 - sharp) * r)
                img[v, u, ch] = np.uint8(min(img[v, u, ch] * factor + 0.5, 255.0))


def backscatter_columns(rot, ray_a, sun_azimuth_deg: float) -> np.ndarray:
    """Per image column, the back-scatter brightness factor (1 outside the lobe), from the column's view azimuth.

    The azimuth is taken at the image's middle row: the rover's pitch and roll move it by well under a
    degree across the rows that show the floor."""
    a = np.asarray(ray_a)
    az = np.degrees(np.arctan2(rot[1, 0] * a + rot[1, 2], rot[0, 0] * a + rot[0, 2]))
    rel = (az - (sun_azimuth_deg + 180.0 + BACKSCATTER_OFFSET_DEG) + 180.0) % 360.0 - 180.0
    return 1.0 + BACKSCATTER_GAIN * np.exp(-0.5 * (rel / BACKSCATTER_SIGMA_DEG) ** 2)


@njit(cache=True, nogil=True)
def apply_backscatter(img, depth, origin, rot, ray_a, ray_b, column_gain, terrain, inv_tcell, rock_above_m):
    """Brighten the terrain pixels of the columns inside the back-scatter lobe, in place (rock meshes and sky untouched)."""
    h, w = depth.shape
    for u in range(w):
        g = column_gain[u]
        if g < 1.002:
            continue
        for v in range(h):
            d = depth[v, u]
            if not d < 1e30:
                continue
            x = origin[0] + d * (rot[0, 0] * ray_a[u] + rot[0, 1] * ray_b[v] + rot[0, 2])
            y = origin[1] + d * (rot[1, 0] * ray_a[u] + rot[1, 1] * ray_b[v] + rot[1, 2])
            z = origin[2] + d * (rot[2, 0] * ray_a[u] + rot[2, 1] * ray_b[v] + rot[2, 2])
            if z > _terrain_bilinear(terrain, inv_tcell, x, y) + rock_above_m:
                continue
            for ch in range(3):
                img[v, u, ch] = np.uint8(min(img[v, u, ch] * g + 0.5, 255.0))


@njit(cache=True, nogil=True, inline="always")
def _texel_bilinear_scaled(pyr, k, qx, qy):
    """`_texel_bilinear` from the point in level-0 texels (qx, qy = x / texel_m, y / texel_m): the same value, as
    x / (texel_m * 2**k) == (x / texel_m) * 2**-k exactly (scaling by a power of two commutes with rounding)."""
    scale = 1.0 / (1 << k)
    return _pyramid_cell_value(pyr, k, qx * scale - 0.5, qy * scale - 0.5)


@njit(cache=True, nogil=True, error_model="numpy")
def apply_floor_look(img, depth, origin, rot, ray_a, ray_b, pyr, texel_m, focal_px, terrain, inv_tcell,
                     sand_rgb, rock_rgb, lod_bias, lod_max, min_sin, rock_above_m, column_gain, splat_mip, skip):
    """`apply_splat_mip` (when splat_mip) then `apply_backscatter` in one pass, in place: the same pixels and the
    same arithmetic on each, so the same bytes (tests/test_shading.py holds it to the two passes as the oracle).

    ~40 % less time than the two passes: each hit point and its terrain height are found once, not twice;
    the work goes row by row in stages (directions and hit points for the whole row; the pixels either term
    applies to; their terrain cells, vertices and slopes; footprints; mip levels; colours), so the compiler
    vectorises the branch-free ones and the divisions of independent pixels overlap; Python's zero-division
    checks are off (error_model="numpy": no divisor here is 0 for a pixel that is used).
    skip: (H, W) uint8, pixels left as they are (1; the renderer fills the ones its raymarch took from the two
    neighbouring columns from those columns afterwards), or all 0."""
    h, w = depth.shape
    min_foot = texel_m
    near2 = min_foot * focal_px * MIN_FOOT_HEIGHT_M
    buf = np.empty((4, w))  # stage 3's slopes (GX, GY, GR) and stage 4's footprint ratio, per pixel of the row
    CX, CY, AX, AY = np.empty(w), np.empty(w), np.empty(w), np.empty(w)
    T00, T01, T10, T11 = np.empty(w), np.empty(w), np.empty(w), np.empty(w)
    IDX = np.empty(w, np.int64)
    tn = terrain.shape[0]  # the clamp's bound, as in _terrain_with_slope
    stride = terrain.shape[1]
    tflat = terrain.reshape(-1)
    ax0 = np.empty(w, np.float32)
    ay0 = np.empty(w, np.float32)
    az0 = np.empty(w, np.float32)
    for u in range(w):
        ax0[u] = rot[0, 0] * ray_a[u]
        ay0[u] = rot[1, 0] * ray_a[u]
        az0[u] = rot[2, 0] * ray_a[u]
    buf32 = np.empty((8, w), np.float32)  # stage 1's per-pixel rows in float32 (round 12: twice the lanes)
    ox32, oy32, oz32 = np.float32(origin[0]), np.float32(origin[1]), np.float32(origin[2])
    r02_32, r12_32, r22_32 = np.float32(rot[0, 2]), np.float32(rot[1, 2]), np.float32(rot[2, 2])
    todo = np.empty(w, np.int64)  # the row's pixels in work: u (mip level, maybe lobe) or -1 - u (lobe only)
    for v in range(h):
        b0 = np.float32(rot[0, 1] * ray_b[v]) + r02_32
        b1 = np.float32(rot[1, 1] * ray_b[v]) + r12_32
        b2 = np.float32(rot[2, 1] * ray_b[v]) + r22_32
        X, Y, Z = buf32[0], buf32[1], buf32[2]
        DX, DY, DZ = buf32[3], buf32[4], buf32[5]
        NORM, DIST = buf32[6], buf32[7]
        drow = depth[v]
        srow = skip[v]
        # stage 1: ray directions, hit points, viewing distances (every pixel; sky gives inf/nan, never used)
        for u in range(w):
            d = drow[u]
            dx = ax0[u] + b0
            dy = ay0[u] + b1
            dz = az0[u] + b2
            DX[u] = dx
            DY[u] = dy
            DZ[u] = dz
            norm = np.sqrt(dx * dx + dy * dy + dz * dz)
            NORM[u] = norm
            DIST[u] = d * norm
            X[u] = ox32 + d * dx
            Y[u] = oy32 + d * dy
            Z[u] = oz32 + d * dz
        # stage 2: the pixels either term applies to
        m = 0
        for u in range(w):
            if not drow[u] < 1e30 or srow[u]:
                continue
            mip = splat_mip and not DIST[u] * DIST[u] < near2
            if mip or column_gain[u] >= 1.002:
                todo[m] = u if mip else -1 - u
                m += 1
        if m == 0:
            continue
        # stage 3: terrain height and slope under each; rock meshes drop out (neither term applies)
        GX, GY, GR = buf[0], buf[1], buf[2]
        for i in range(m):
            t = todo[i]
            u = t if t >= 0 else -1 - t
            CX[i] = X[u]
            CY[i] = Y[u]
        # _terrain_with_slope in three loops: cell and weights (vector), the four vertices (gather), the blend (vector)
        for i in range(m):
            fx = min(max(CX[i] * inv_tcell, 0.0), tn - 1.0001)
            fy = min(max(CY[i] * inv_tcell, 0.0), tn - 1.0001)
            c, r = int(fx), int(fy)
            AX[i] = fx - c
            AY[i] = fy - r
            IDX[i] = r * stride + c
        for i in range(m):
            j = IDX[i]
            T00[i] = tflat[j]
            T01[i] = tflat[j + 1]
            T10[i] = tflat[j + stride]
            T11[i] = tflat[j + stride + 1]
        for i in range(m):
            ax, ay = AX[i], AY[i]
            t00, t01, t10, t11 = T00[i], T01[i], T10[i], T11[i]
            GR[i] = (t00 * (1.0 - ax) + t01 * ax) * (1.0 - ay) + (t10 * (1.0 - ax) + t11 * ax) * ay
            GX[i] = ((t01 - t00) * (1.0 - ay) + (t11 - t10) * ay) * inv_tcell
            GY[i] = ((t10 - t00) * (1.0 - ax) + (t11 - t01) * ax) * inv_tcell
        n = 0
        for i in range(m):
            t = todo[i]
            u = t if t >= 0 else -1 - t
            todo[n] = t
            GX[n] = GX[i]
            GY[n] = GY[i]
            CX[n] = CX[i]
            CY[n] = CY[i]
            n += not Z[u] > GR[i] + rock_above_m  # branch-free: a rock mesh's pixel is overwritten by the next
        # stage 4: footprint in texels (independent pixels: divisions overlap), then its mip level
        RATIO = buf[3]
        for i in range(n):
            t = todo[i]
            u = t if t >= 0 else 0
            gx, gy = GX[i], GY[i]
            dx, dy, dz = DX[u], DY[u], DZ[u]
            sin_g = abs(-gx * dx - gy * dy + dz) / (NORM[u] * math.sqrt(gx * gx + gy * gy + 1.0))
            foot = DIST[u] / (focal_px * max(sin_g, min_sin))
            RATIO[i] = foot / texel_m if foot > min_foot else 0.0
        for i in range(n):
            t = todo[i]
            if t >= 0 and RATIO[i] > 0.0:
                RATIO[i] = min(math.log2(RATIO[i]) + lod_bias, lod_max)
            else:
                RATIO[i] = 0.0
        # stage 5: the splat weight at the pixel's mip level and at full resolution, then the colour terms
        for i in range(n):
            t = todo[i]
            u = t if t >= 0 else -1 - t
            lod = RATIO[i]
            if lod > 0.0:
                k = int(lod)
                f = lod - k
                qx, qy = CX[i] / texel_m, CY[i] / texel_m
                blur = _texel_bilinear_scaled(pyr, k, qx, qy)
                if f > 0.0:
                    blur = blur * (1.0 - f) + _texel_bilinear_scaled(pyr, k + 1, qx, qy) * f
                sharp = _texel_bilinear_scaled(pyr, 0, qx, qy)
                for ch in range(3):
                    s, r = sand_rgb[ch], rock_rgb[ch]
                    factor = (blur * s + (1.0 - blur) * r) / (sharp * s + (1.0 - sharp) * r)
                    img[v, u, ch] = np.uint8(min(img[v, u, ch] * factor + 0.5, 255.0))
            g = column_gain[u]
            if g >= 1.002:
                for ch in range(3):
                    img[v, u, ch] = np.uint8(min(img[v, u, ch] * g + 0.5, 255.0))
