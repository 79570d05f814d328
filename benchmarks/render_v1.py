"""The twin's renderer as it was before the speed work (commit c22f41d), kept only for the benchmark.

`python -m benchmarks.render` renders the same poses with this kernel and with sim.render's,
and prints both speeds, their ratio and how far the images agree. Not used by the twin.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from sim.render import (CAMERA_MOUNT_FORWARD_M, CAMERA_MOUNT_UP_M, CX, CY, FOCAL_PX, IMAGE_H, IMAGE_W,
                        ROOT_BELOW_GROUND_M, SAMPLE_HEIGHT_PER_SCALE_M, SAMPLE_MIN_SHADE, SAMPLE_RGB,
                        SAMPLE_SINK_M, SAMPLE_WIDTH_PER_SCALE_M, SKY_RGB, FAR_RGB, SUN_AZIMUTH_DEG,
                        SUN_ELEVATION_DEG, _baked_for, body_rotation, validate_pose)

# the raymarch constants as they were (frozen here so later tuning of sim.render does not move the baseline)
FAR_M = 120.0
FINE_STEP_MIN_M = 0.04
FINE_STEP_PER_M = 0.012
REFINE_ITERS = 4
COARSE_CELL_M = 1.0
UNDERSIDE_SHADE = 0.45
DIST_DARKEN = 0.17
DIST_SCALE_M = 8.0


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
def _render_kernel_v1(img_t, depth_t, hit_t, ground, slab_lo, slab_hi, colour, colour_rock, cmax,
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


class RendererV1:
    """The old Renderer, verbatim apart from the kernel's name."""

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
        _render_kernel_v1(img_t, depth_t, hit_t, self._ground, self._slab_lo, self._slab_hi, self.colour_map,
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
