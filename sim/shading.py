"""The look of the real drives recorded without cast shadows (issue 28): what the twin's camera adds
when the world's cast_shadows is off (the simulator's quality levels without realtime shadows).

Measured on floor pixels (sand weight > 0.9) of the real frames against twin frames at the same
poses. Fitted on megalphian alone, checked on royalejandro and dimaga (held out); test_dataset was
recorded at a quality level with cast shadows and keeps the `--shadows on` look.

1. Far-floor darkening (`shadowless_darkening`, `apply_far_tint`). The floor keeps its brightness out
   to about 5 m and then darkens quickly with viewing distance: at 10 m it is at 0.75 of the near
   floor's brightness, at 25 m at 0.55, and turns a little redder (green/red falls from 0.91 to
   0.86, so the client no longer takes it for shadowed sand). test_dataset darkens much less (0.80 at
   10 m), which the old exponential curve in sim/render.py fits. The raymarch applies the green
   curve as its scalar distance table; `apply_far_tint` then scales red and blue by their curve over
   green.
2. The floor the walls hide from the sun is darker even without cast shadows, though far less than
   in cast shadow (`SHADOWLESS_SHADOW_FACTOR`). Within 5 m of the camera, on the floor the twin's
   shadow raster marks as shadowed, the real floor is 14 (megalphian), 12-30 (dimaga) and 34
   (royalejandro) grey levels darker than the twin without shadows, beyond the 5-14 of the sunlit
   floor. An isotropic sky-visibility (ambient-occlusion) term was tried first and rejected: it also
   darkens the floor at sunlit wall feet, which the real frames show bright (royalejandro facing
   the wall at (61, 104): IoU within 5 m fell 0.7 there, -0.018 over the drive).
"""
from __future__ import annotations

import numpy as np
from numba import njit

SHADOWLESS_KNEE_M = 5.2  # beyond this viewing distance the floor darkens, m
SHADOWLESS_SCALE_M = 8.65  # e-folding distance of the darkening beyond the knee, m
SHADOWLESS_FAR_RGB = (0.506, 0.474, 0.467)  # brightness the far floor tends to per channel (a little redder), 0..1
SHADOWLESS_SCALAR_CHANNEL = 1  # the distance table the raymarch applies is this channel's curve (green)
SHADOWLESS_NEAR_SHARE = 0.5  # share of the other quality levels' near-floor darkening kept within the knee, 0..1
SHADOWLESS_SHADOW_FACTOR = 0.9  # brightness of the floor hidden from the sun without cast shadows, 0..1
DARK_TINT_STEP_M = 0.05  # distance resolution of the far tint table, m
DARK_TINT_MAX_M = 200.0  # the table's reach (farther hits use its last entry), m


def shadowless_darkening(dist_m, channel: int = SHADOWLESS_SCALAR_CHANNEL) -> np.ndarray:
    """Brightness factor of one colour channel by viewing distance at the simulator's shadowless quality levels:
    the near floor as at the other quality levels (the colour table was fitted with that curve), then the
    knee's darkening on top."""
    from sim.render import DIST_DARKEN, DIST_SCALE_M

    dist = np.asarray(dist_m, np.float64)
    near = 1.0 - SHADOWLESS_NEAR_SHARE * DIST_DARKEN * (1.0 - np.exp(-np.minimum(dist, SHADOWLESS_KNEE_M) / DIST_SCALE_M))
    beyond = np.maximum(dist - SHADOWLESS_KNEE_M, 0.0)
    far = SHADOWLESS_FAR_RGB[channel]
    return near * (far + (1.0 - far) * np.exp(-beyond / SHADOWLESS_SCALE_M))


def far_tint_lut() -> np.ndarray:
    """float32 (n, 3): per channel, its darkening over the scalar channel's, one row per DARK_TINT_STEP_M."""
    dist = np.arange(int(DARK_TINT_MAX_M / DARK_TINT_STEP_M) + 1) * DARK_TINT_STEP_M
    scalar = shadowless_darkening(dist)
    return np.stack([shadowless_darkening(dist, ch) / scalar for ch in range(3)], -1).astype(np.float32)


@njit(cache=True, nogil=True)
def apply_far_tint(img, depth, ray_norm, lut, step):
    """Scale each channel of the pixels beyond the knee by the tint table, in place.

    depth: the raymarch's depth along the forward axis (inf for sky); ray_norm: |ray| per pixel for a
    unit forward component, so depth * ray_norm is the viewing distance the table is indexed by."""
    h, w = depth.shape
    n = lut.shape[0]
    first = int(SHADOWLESS_KNEE_M / step)
    for v in range(h):
        for u in range(w):
            d = depth[v, u]
            if not d < 1e30:
                continue
            i = int(d * ray_norm[v, u] / step)
            if i <= first:
                continue
            if i >= n:
                i = n - 1
            for ch in range(3):
                if ch != SHADOWLESS_SCALAR_CHANNEL:
                    img[v, u, ch] = np.uint8(min(img[v, u, ch] * lut[i, ch] + 0.5, 255.0))
