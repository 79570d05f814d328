"""What the rover physically touches: its own colliders, its wheel rays and the rocks' collider shapes.

Read from the simulator's scene (../shared/docs/simulator-facts.md section 2 and
../shared/udacity-rover/world/rock_colliders.csv, rock_collider_meshes.json):

* the body collides only through two thin plates (Flatbed, Back) and two axle rods;
  everything else (arm, cameras, wheel meshes) passes through rock;
* four ray-cast wheels stand on an invisible floor plane 1 cm above the terrain, or on
  terrain, or on a rock top their ray finds (a surface at most WHEEL_REACH_M above
  the wheel's current contact: a ray starting inside a rock does not see it);
* rocks collide through spheres, a box and convex hulls (the hull of the mesh, as PhysX
  cooks a convex MeshCollider) or, for the three non-convex colliders, their triangles.

Rock shapes are rasterised once per world into small patches (PATCH_CELL_M) holding the
[bottom, top] slab of rock per column plus, for contact response, how far a body part
at body height is inside the rock (`depth`) and which way is out (`ex`, `ey`).  Patches
keep their spheres and hull facets for exact contact normals (RockField.contact_normals).
Worlds without collider data (procedural, map PNG, test worlds) collide with their
render envelopes (`rock_top`/`rock_bottom`) through the same patches.
"""
from __future__ import annotations

import csv
import json
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

log = logging.getLogger(__name__)

# --- the rover (Rover (Rigidbody) (Smaller).prefab; rover frame: f forward, l left, m) ---------------
FLOOR_PLANE_M = 0.01  # m, the invisible Grid_v2 collision plane above the terrain floor
ROOT_BELOW_CONTACT_M = 0.0245  # m, the rover root sits this far below the surface its wheels stand on
WHEEL_F_M = (0.386, 0.386, -0.336, -0.336)  # wheel centres, forward of the root: FL, FR, RL, RR
WHEEL_L_M = (0.395, -0.395, 0.395, -0.395)  # wheel centres, left of the root (track 0.79 m)
WHEELBASE_M = 0.722  # m, front to rear axle
TRACK_M = 0.79  # m, left to right wheel
WHEEL_REACH_M = 0.15  # m, a rock top this far above a wheel's contact is still found by its ray
FLATBED = (-0.330, 0.452, 0.268, 0.1815, 0.2145)  # f min, f max, half width, y bottom, y top above root
BACK_PLATE = (-0.373, -0.335, 0.268, 0.185, 0.389)
AXLE_F_M = (0.386, -0.336)  # front / rear axle rod positions
AXLE_HALF_LENGTH_M = 0.396  # m, capsules along the rover's width
AXLE_Y = (0.158, 0.191)  # y bottom, top above root (capsule radius 0.0165)
BODY_SAMPLE_M = 0.13  # m, spacing of the sample points along the plates
STEP_CLEAR_M = AXLE_Y[0] - ROOT_BELOW_CONTACT_M  # 0.134 m: rock below this passes under the body
BODY_TOP_M = BACK_PLATE[4] - ROOT_BELOW_CONTACT_M  # 0.365 m: rock above this passes over the body

# --- rock rasters ----------------------------------------------------------------------------------
PATCH_CELL_M = 0.05  # m, resolution of the rock collider patches
COARSE_PATCH_CELL_M = 0.1  # m, resolution of patches of big (wall) rocks
FINE_PATCH_MAX_AREA_M2 = 60.0  # m^2, rock footprints up to this size get the fine resolution
PATCH_MARGIN_M = 0.3  # m of free border around each rock patch
HULL_ROWS_PER_CHUNK = 40  # patch rows evaluated at once against all hull facets (memory bound)
ESCAPE_SMOOTH_CELLS = 2.0  # Gaussian sigma (cells) smoothing the depth field before its gradient
NO_ROCK_TOP = -1.0e9  # top value of a column without rock
NO_ROCK_BOTTOM = 1.0e9  # bottom value of a column without rock
ENVELOPE_MIN_CELLS = 1  # connected rock cells below this are ignored in envelope worlds
TOP_EDGE_BAND_M = 0.1  # m, rock columns this close to the rock's outline count as a vertical side, not a top
STEEP_SLOPE = 1.0e3  # slope (m/m) given to side columns: a horizontal contact normal


def body_points() -> np.ndarray:
    """(N, 4) sample points of the body colliders: f, l, bottom, top (m above the wheel contact plane)."""
    pts = []
    f0, f1, hw, yb, yt = FLATBED
    nf = max(2, int(math.ceil((f1 - f0) / BODY_SAMPLE_M)) + 1)
    nl = max(2, int(math.ceil(2 * hw / BODY_SAMPLE_M)) + 1)
    for f in np.linspace(f0, f1, nf):
        for lat in np.linspace(-hw, hw, nl):
            pts.append((f, lat, yb, yt))
    f0, f1, hw, yb, yt = BACK_PLATE
    for lat in np.linspace(-hw, hw, nl):
        pts.append((f0, lat, yb, yt))
    n_axle = max(2, int(math.ceil(2 * AXLE_HALF_LENGTH_M / BODY_SAMPLE_M)) + 1)
    for f in AXLE_F_M:
        for lat in np.linspace(-AXLE_HALF_LENGTH_M, AXLE_HALF_LENGTH_M, n_axle):
            pts.append((f, lat, AXLE_Y[0], AXLE_Y[1]))
    out = np.array(pts, dtype=np.float64)
    out[:, 2:] -= ROOT_BELOW_CONTACT_M
    return out


BODY_POINTS = body_points()
BODY_RADIUS_M = float(np.hypot(BODY_POINTS[:, 0], BODY_POINTS[:, 1]).max())  # bounding circle of the body


# ------------------------------------------------------------------ collider shapes
@dataclass
class Shape:
    """One collider primitive in world axes (x east, y north, z up), metres."""

    rock: str
    kind: str  # "sphere", "hull" or "mesh" (non-convex triangles)
    centre: tuple = (0.0, 0.0, 0.0)  # sphere centre
    radius: float = 0.0
    verts: np.ndarray | None = None  # (N, 3) hull points or mesh vertices
    tris: np.ndarray | None = None  # (M, 3) mesh triangles

    def bounds(self):
        """(xmin, ymin, xmax, ymax) of the footprint."""
        if self.kind == "sphere":
            x, y, _ = self.centre
            return x - self.radius, y - self.radius, x + self.radius, y + self.radius
        v = self.verts
        return float(v[:, 0].min()), float(v[:, 1].min()), float(v[:, 0].max()), float(v[:, 1].max())


def wheel_plane(wheel_h):
    """(height at the root, slope forward, slope left) of the plane four wheel contact heights (FL, FR, RL, RR)
    define: the physics stands the body on it, the renderer lifts a logged pose by it."""
    front, rear = 0.5 * (wheel_h[0] + wheel_h[1]), 0.5 * (wheel_h[2] + wheel_h[3])
    left, right = 0.5 * (wheel_h[0] + wheel_h[2]), 0.5 * (wheel_h[1] + wheel_h[3])
    a = (front - rear) / WHEELBASE_M
    b = (left - right) / TRACK_M
    f_mid = 0.5 * (WHEEL_F_M[0] + WHEEL_F_M[2])
    return 0.5 * (front + rear) - a * f_mid, a, b


def _unity_to_world(v) -> np.ndarray:
    """(Unity x, height, Unity z) -> (x, y, z) world axes."""
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    return v[:, [0, 2, 1]]


def _quat_matrix(qx, qy, qz, qw) -> np.ndarray:
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])


def _instance_transforms(world_dir: Path) -> dict:
    """name -> list of (position, rotation matrix, scale) in Unity axes, from obstacles.csv."""
    out = {}
    path = world_dir / "obstacles.csv"
    if not path.exists():
        return out
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            try:
                t = np.array([float(r[f"unity_pos_{a}"]) for a in "xyz"])
                q = [float(r[f"unity_rot_q{a}"]) for a in "xyzw"]
                s = np.array([float(r[f"unity_scale_{a}"]) for a in "xyz"])
            except (KeyError, ValueError):
                continue
            out.setdefault(r["name"], []).append((t, _quat_matrix(*q), s))
    return out


def _moved_instance(verts_u: np.ndarray, name: str, target_centre_u, transforms: dict):
    """The same prefab's collider at another instance: undo the stored instance's transform, apply the other's.

    rock_collider_meshes.json keys meshes by rock name, so of two instances with one name only one
    is stored; obstacles.csv has both instances' transforms.
    """
    cands = transforms.get(name, [])
    if len(cands) < 2:
        return None
    centre = verts_u.mean(axis=0)
    src = min(cands, key=lambda c: np.linalg.norm(c[0] - centre))
    dst = min((c for c in cands if c is not src), key=lambda c: np.linalg.norm(c[0] - target_centre_u))
    local = ((verts_u - src[0]) @ src[1]) / src[2]
    return (local * dst[2]) @ dst[1].T + dst[0]


def load_collider_shapes(world_dir) -> list:
    """Collider primitives of the real scene's rocks ([] when the export has no collider files)."""
    world_dir = Path(world_dir)
    csv_path, mesh_path = world_dir / "rock_colliders.csv", world_dir / "rock_collider_meshes.json"
    if not csv_path.exists():
        return []
    meshes = json.loads(mesh_path.read_text()) if mesh_path.exists() else {}
    transforms = _instance_transforms(world_dir)
    shapes = []
    with open(csv_path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        kind, name = r["type"], r["rock"]
        if kind == "sphere":
            c = _unity_to_world([float(r["cx"]), float(r["cy"]), float(r["cz"])])[0]
            shapes.append(Shape(name, "sphere", tuple(c), float(r["r"])))
        elif kind == "box":
            corners = json.loads(r["note"].split("world corners", 1)[1])
            shapes.append(Shape(name, "hull", verts=_unity_to_world(corners)))
        elif kind == "mesh":
            entry = meshes.get(name)
            if entry is None:
                log.warning("no collider mesh for %s; it will not collide", name)
                continue
            verts_u = np.asarray(entry["verts"], dtype=np.float64)
            centre_u = np.array([float(r["cx"]), float(r["cy"]), float(r["cz"])])
            if np.linalg.norm(verts_u.mean(axis=0)[[0, 2]] - centre_u[[0, 2]]) > 1.0:
                moved = _moved_instance(verts_u, name, centre_u, transforms)
                if moved is None:
                    log.warning("collider mesh of %s is stored for another instance; skipped", name)
                    continue
                verts_u = moved
            verts = _unity_to_world(verts_u)
            convex = str(r.get("convex", entry.get("convex", True))).strip().lower() == "true"
            if convex:
                shapes.append(Shape(name, "hull", verts=verts))
            else:
                shapes.append(Shape(name, "mesh", verts=verts, tris=np.asarray(entry["tris"], dtype=np.int64)))
    return shapes


# ------------------------------------------------------------------ rasterising shapes
def _sphere_slab(shape: Shape, xs, ys):
    cx, cy, cz = shape.centre
    d2 = (xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2
    h = np.sqrt(np.clip(shape.radius ** 2 - d2, 0.0, None))
    inside = d2 <= shape.radius ** 2
    return np.where(inside, cz - h, NO_ROCK_BOTTOM), np.where(inside, cz + h, NO_ROCK_TOP)


def _hull_slab(shape: Shape, xs, ys):
    """Column [bottom, top] of the convex hull of the points, from its facet half-spaces."""
    from scipy.spatial import ConvexHull

    eq = ConvexHull(shape.verts).equations  # a x + b y + c z + d <= 0 inside
    up, dn = eq[:, 2] > 1e-9, eq[:, 2] < -1e-9
    side = ~(up | dn)
    bottom = np.full((len(ys), len(xs)), NO_ROCK_BOTTOM)
    top = np.full((len(ys), len(xs)), NO_ROCK_TOP)
    for r0 in range(0, len(ys), HULL_ROWS_PER_CHUNK):
        yy = ys[r0:r0 + HULL_ROWS_PER_CHUNK]
        lin = xs[None, :, None] * eq[:, 0] + yy[:, None, None] * eq[:, 1] + eq[:, 3]
        t = np.min(-lin[..., up] / eq[up, 2], axis=-1)
        b = np.max(-lin[..., dn] / eq[dn, 2], axis=-1)
        ok = b <= t
        if side.any():
            ok &= np.all(lin[..., side] <= 1e-9, axis=-1)
        top[r0:r0 + len(yy)] = np.where(ok, t, NO_ROCK_TOP)
        bottom[r0:r0 + len(yy)] = np.where(ok, b, NO_ROCK_BOTTOM)
    return bottom, top


def _mesh_slab(shape: Shape, x0, y0, nx, ny, cell):
    """Column [lowest, highest] surface of a closed non-convex mesh, by sampling its triangles."""
    bottom = np.full(ny * nx, NO_ROCK_BOTTOM)
    top = np.full(ny * nx, NO_ROCK_TOP)
    v = shape.verts
    step = cell / 2.0
    for a, b, c in shape.tris:
        pa, pb, pc = v[a], v[b], v[c]
        n = int(math.ceil(max(np.linalg.norm(pb - pa), np.linalg.norm(pc - pa), np.linalg.norm(pc - pb)) / step)) + 1
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
        keep = (i + j) <= n
        u, w = i[keep] / n, j[keep] / n
        p = pa + np.outer(u, pb - pa) + np.outer(w, pc - pa)
        ci = np.rint((p[:, 0] - x0) / cell).astype(np.int64)
        ri = np.rint((p[:, 1] - y0) / cell).astype(np.int64)
        ok = (ci >= 0) & (ci < nx) & (ri >= 0) & (ri < ny)
        idx = ri[ok] * nx + ci[ok]
        np.minimum.at(bottom, idx, p[ok, 2])
        np.maximum.at(top, idx, p[ok, 2])
    return bottom.reshape(ny, nx), top.reshape(ny, nx)


@dataclass
class Patch:
    """Rock slabs of one rock (or one envelope component) on a PATCH_CELL_M grid; [row = y, col = x]."""

    name: str
    x0: float  # world x of column 0, m
    y0: float  # world y of row 0, m
    cell: float
    bottom: np.ndarray  # m, NO_ROCK_BOTTOM where none
    top: np.ndarray  # m, NO_ROCK_TOP where none
    depth: np.ndarray  # m, signed horizontal distance into body-height rock (negative outside), bilinear
    ex: np.ndarray  # unit escape direction x (from inside towards free space)
    ey: np.ndarray
    sx: np.ndarray | None = None  # slope of the rock top along x (m/m; STEEP_SLOPE on the sides): the contact
    sy: np.ndarray | None = None  # normals of rocks without collider shapes (meshes, render envelopes)
    spheres: np.ndarray | None = None  # (K, 4) cx, cy, cz, r of the rock's collider spheres (exact normals)
    hulls: list | None = None  # (F, 4) facet equations (a x + b y + c z + d <= 0 inside) of its convex hulls

    @property
    def bounds(self):
        h, w = self.top.shape
        return self.x0, self.y0, self.x0 + (w - 1) * self.cell, self.y0 + (h - 1) * self.cell


def _finish_patch(name, x0, y0, cell, bottom, top, ground) -> Patch:
    """Add the body-height depth field and escape directions to a patch's slabs."""
    import cv2

    body = (top > ground + STEP_CLEAR_M) & (bottom < ground + BODY_TOP_M)
    inside = cv2.distanceTransform(body.astype(np.uint8), cv2.DIST_L2, 5)
    outside = cv2.distanceTransform((~body).astype(np.uint8), cv2.DIST_L2, 5)
    # the face lies half a cell outside the last rock cell centre: a signed distance that is 0 there
    depth = (np.where(body, inside - 0.5, 0.5 - outside) * cell).astype(np.float32)
    smooth = cv2.GaussianBlur(depth, (0, 0), ESCAPE_SMOOTH_CELLS)
    gy, gx = np.gradient(smooth)
    norm = np.hypot(gx, gy)
    norm[norm < 1e-9] = 1.0
    ex, ey = (-gx / norm).astype(np.float32), (-gy / norm).astype(np.float32)
    sx, sy = top_slopes(top, cell)
    return Patch(name, float(x0), float(y0), float(cell), bottom.astype(np.float32), top.astype(np.float32),
                 depth, ex, ey, sx, sy)


def top_slopes(top: np.ndarray, cell: float):
    """(d top / dx, d top / dy) of a patch's rock top: for rocks without collider shapes (non-convex meshes,
    render envelopes) the contact normal of a body part resting on it is (-sx, -sy, 1) normalised.

    Columns within TOP_EDGE_BAND_M of the rock's outline get STEEP_SLOPE: there a body part meets the
    rock's side (a box edge, a slab's face, a sphere's flank), whose normal is horizontal.
    """
    import cv2

    rock = top > 0.5 * NO_ROCK_TOP
    band = max(1, int(math.ceil(TOP_EDGE_BAND_M / cell - 1e-9)))
    kernel = np.ones((2 * band + 1, 2 * band + 1), np.uint8)
    inner = cv2.erode(rock.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    t = np.where(rock, top, 0.0)
    sx, sy = np.full(top.shape, STEEP_SLOPE), np.full(top.shape, STEEP_SLOPE)
    gx = np.zeros(top.shape)
    gy = np.zeros(top.shape)
    gx[:, 1:-1] = (t[:, 2:] - t[:, :-2]) / (2 * cell)
    gy[1:-1, :] = (t[2:, :] - t[:-2, :]) / (2 * cell)
    sx[inner], sy[inner] = gx[inner], gy[inner]
    return sx.astype(np.float32), sy.astype(np.float32)


def _ground_grid(height_at, xs, ys) -> np.ndarray:
    gx, gy = np.meshgrid(xs, ys)
    return np.maximum(np.asarray(height_at(gx, gy), dtype=np.float64), FLOOR_PLANE_M)


def patches_from_shapes(shapes: list, height_at, fine_cell: float = PATCH_CELL_M,
                        coarse_cell: float = COARSE_PATCH_CELL_M) -> list:
    """One patch per rock: the union (per column) of its collider shapes' slabs."""
    by_rock = {}
    for i, s in enumerate(shapes):  # a sphere cluster is one rock; each mesh or box is its own
        by_rock.setdefault((s.rock, -1 if s.kind == "sphere" else i), []).append(s)
    patches = []
    for (name, _), group in by_rock.items():
        b = np.array([s.bounds() for s in group])
        area = (b[:, 2].max() - b[:, 0].min()) * (b[:, 3].max() - b[:, 1].min())
        cell = fine_cell if area <= FINE_PATCH_MAX_AREA_M2 else coarse_cell
        x0 = math.floor((b[:, 0].min() - PATCH_MARGIN_M) / cell) * cell
        y0 = math.floor((b[:, 1].min() - PATCH_MARGIN_M) / cell) * cell
        nx = int(math.ceil((b[:, 2].max() + PATCH_MARGIN_M - x0) / cell)) + 1
        ny = int(math.ceil((b[:, 3].max() + PATCH_MARGIN_M - y0) / cell)) + 1
        xs, ys = x0 + np.arange(nx) * cell, y0 + np.arange(ny) * cell
        bottom = np.full((ny, nx), NO_ROCK_BOTTOM)
        top = np.full((ny, nx), NO_ROCK_TOP)
        for s in group:
            if s.kind == "sphere":
                sb, st = _sphere_slab(s, xs, ys)
            elif s.kind == "hull":
                sb, st = _hull_slab(s, xs, ys)
            else:
                sb, st = _mesh_slab(s, x0, y0, nx, ny, cell)
            bottom, top = np.minimum(bottom, sb), np.maximum(top, st)
        patch = _finish_patch(name, x0, y0, cell, bottom, top, _ground_grid(height_at, xs, ys))
        if all(s.kind != "mesh" for s in group):
            sph = [(*s.centre, s.radius) for s in group if s.kind == "sphere"]
            patch.spheres = np.array(sph, dtype=np.float64).reshape(-1, 4)
            patch.hulls = [_hull_equations(s.verts) for s in group if s.kind == "hull"]
        patches.append(patch)
    return patches


def _hull_equations(verts) -> np.ndarray:
    from scipy.spatial import ConvexHull

    return np.asarray(ConvexHull(verts).equations, dtype=np.float64)


def patches_from_envelopes(world) -> list:
    """Patches from a world's render envelopes (rock_top/rock_bottom rasters), one per connected rock."""
    import cv2

    top_r = np.asarray(world.rock_top, np.float32)
    present = (top_r > 0).astype(np.uint8)
    if not present.any():
        return []
    n, labels, stats, _ = cv2.connectedComponentsWithStats(present, connectivity=8)
    cell = float(world.rock_cell_m)
    margin = int(math.ceil(PATCH_MARGIN_M / cell))
    patches = []
    for k in range(1, n):
        c0, r0, w, h, area = stats[k]
        if area < ENVELOPE_MIN_CELLS:
            continue
        r0m, c0m = max(0, r0 - margin), max(0, c0 - margin)
        r1m, c1m = min(top_r.shape[0], r0 + h + margin), min(top_r.shape[1], c0 + w + margin)
        mine = labels[r0m:r1m, c0m:c1m] == k
        top = np.where(mine, top_r[r0m:r1m, c0m:c1m], NO_ROCK_TOP).astype(np.float64)
        bottom = np.where(mine, np.asarray(world.rock_bottom, np.float32)[r0m:r1m, c0m:c1m],
                          NO_ROCK_BOTTOM).astype(np.float64)
        xs, ys = c0m * cell + np.arange(c1m - c0m) * cell, r0m * cell + np.arange(r1m - r0m) * cell
        patches.append(_finish_patch(f"envelope {k}", xs[0], ys[0], cell, bottom, top,
                                     _ground_grid(world.height_at, xs, ys)))
    return patches


class RockField:
    """All rock patches of a world, queried at a handful of points per physics step."""

    def __init__(self, patches: list):
        self.patches = patches
        self._bounds = np.array([p.bounds for p in patches], dtype=np.float64).reshape(-1, 4)
        self._last_near = (None, None)  # ((x, y, radius), patches) of the last near() call

    def near(self, x: float, y: float, radius: float) -> list:
        """Patches whose extent comes within `radius` of (x, y) (a new list; the physics asks twice per step
        at the same point, so the last answer is kept)."""
        key, found = self._last_near
        if key == (x, y, radius):
            return list(found)
        b = self._bounds
        hit = (b[:, 0] - radius <= x) & (x <= b[:, 2] + radius) & (b[:, 1] - radius <= y) & (y <= b[:, 3] + radius)
        found = [self.patches[i] for i in np.nonzero(hit)[0]]
        self._last_near = ((x, y, radius), found)
        return list(found)

    @staticmethod
    def no_rock(shape):
        """(bottom, top, depth, ex, ey) of points no patch covers: what query starts from before the patches."""
        return (np.full(shape, NO_ROCK_BOTTOM), np.full(shape, NO_ROCK_TOP), np.full(shape, -1.0),
                np.zeros(shape), np.zeros(shape))

    @staticmethod
    def query(patches: list, px: np.ndarray, py: np.ndarray):
        """(bottom, top, depth, ex, ey) at the points from the given patches.

        No rock: huge bottom, tiny top, depth <= 0.  Slabs come from the nearest cell, the signed
        depth is interpolated bilinearly so that a push-out moves the body just clear of the face.
        float64 points of the same shape take a compiled path (the physics asks several times per step;
        NumPy's per-call overhead was most of the time), bit-identical to query_numpy.
        """
        if not (isinstance(px, np.ndarray) and isinstance(py, np.ndarray) and px.dtype == np.float64
                and py.dtype == np.float64 and px.shape == py.shape):
            return RockField.query_numpy(patches, px, py)
        xs, ys = np.ascontiguousarray(px).reshape(-1), np.ascontiguousarray(py).reshape(-1)
        bottom, top, depth, ex, ey = RockField.no_rock(xs.size)
        for p in patches:
            _query_patch(xs, ys, p.x0, p.y0, p.cell, p.bottom, p.top, p.depth, p.ex, p.ey, bottom, top, depth, ex, ey)
        shape = px.shape
        return bottom.reshape(shape), top.reshape(shape), depth.reshape(shape), ex.reshape(shape), ey.reshape(shape)

    @staticmethod
    def contact_normals(patches: list, px: np.ndarray, py: np.ndarray, pz: np.ndarray, top: np.ndarray):
        """Unit outward contact normals (nx, ny, nz) of the rock at body points (px, py, pz) inside it.

        PhysX resolves a contact along the shapes' own normal: a sphere's centre -> point direction, a convex
        hull's facet of least penetration.  Rocks without shapes (non-convex meshes, render envelopes) use the
        rock-top slope there, horizontal on a rock's sides.  Of several rocks, the most deeply penetrated
        one's normal is kept.  NumPy: asked only at the few points touching a rock.
        """
        n = px.shape[0]
        nx, ny, nz = np.zeros(n), np.zeros(n), np.zeros(n)
        best = np.full(n, -np.inf)
        for p in patches:
            x0, y0, x1, y1 = p.bounds
            ok = (px >= x0) & (px <= x1) & (py >= y0) & (py <= y1)
            if not ok.any():
                continue
            i = np.nonzero(ok)[0]
            pts = np.stack([px[i], py[i], pz[i]], axis=1)
            cand = []  # (penetration, normal) per shape
            if p.spheres is not None:
                for cx, cy, cz, r in p.spheres:
                    v = pts - (cx, cy, cz)
                    dist = np.sqrt(np.sum(v * v, axis=1))
                    cand.append((r - dist, v / np.maximum(dist, 1e-9)[:, None]))
                for eq in p.hulls or []:
                    pen = -(pts @ eq[:, :3].T + eq[:, 3])  # >= 0 inside each facet's half-space
                    k = np.argmin(pen, axis=1)
                    cand.append((pen[np.arange(len(i)), k], eq[k, :3]))
            elif p.sx is not None:
                h, w = p.top.shape
                c = np.clip(np.rint((px[i] - p.x0) / p.cell).astype(np.int64), 0, w - 1)
                r = np.clip(np.rint((py[i] - p.y0) / p.cell).astype(np.int64), 0, h - 1)
                sx, sy = np.float64(p.sx[r, c]), np.float64(p.sy[r, c])
                norm = np.sqrt(1.0 + sx * sx + sy * sy)
                pen = np.where(np.float64(p.top[r, c]) == top[i], (top[i] - pz[i]) / norm, -np.inf)
                cand.append((pen, np.stack([-sx / norm, -sy / norm, 1.0 / norm], axis=1)))
            for pen, nrm in cand:
                deeper = pen > best[i]
                j = i[deeper]
                best[j] = pen[deeper]
                nx[j], ny[j], nz[j] = nrm[deeper, 0], nrm[deeper, 1], nrm[deeper, 2]
        return nx, ny, nz

    @staticmethod
    def query_numpy(patches: list, px: np.ndarray, py: np.ndarray):
        """query in NumPy (any broadcastable inputs; the reference the compiled path is tested against)."""
        bottom, top, depth, ex, ey = RockField.no_rock(px.shape)
        for p in patches:
            h, w = p.top.shape
            fx, fy = (px - p.x0) / p.cell, (py - p.y0) / p.cell
            c, r = np.rint(fx).astype(np.int64), np.rint(fy).astype(np.int64)
            ok = (c >= 0) & (c < w) & (r >= 0) & (r < h)
            if not ok.any():
                continue
            rr, cc = r[ok], c[ok]
            bottom[ok] = np.minimum(bottom[ok], p.bottom[rr, cc])
            top[ok] = np.maximum(top[ok], p.top[rr, cc])
            c0 = np.clip(np.floor(fx[ok]).astype(np.int64), 0, w - 2)
            r0 = np.clip(np.floor(fy[ok]).astype(np.int64), 0, h - 2)
            tx, ty = np.clip(fx[ok] - c0, 0, 1), np.clip(fy[ok] - r0, 0, 1)
            g = p.depth
            d = ((g[r0, c0] * (1 - tx) + g[r0, c0 + 1] * tx) * (1 - ty)
                 + (g[r0 + 1, c0] * (1 - tx) + g[r0 + 1, c0 + 1] * tx) * ty)
            deeper = d > depth[ok]
            idx = np.nonzero(ok)[0][deeper]
            depth[idx] = d[deeper]
            ex[idx] = p.ex[rr, cc][deeper]
            ey[idx] = p.ey[rr, cc][deeper]
        return bottom, top, depth, ex, ey


@njit(cache=True, nogil=True)
def _query_patch(xs, ys, x0, y0, cell, p_bottom, p_top, p_depth, p_ex, p_ey, bottom, top, depth, ex, ey):
    """One patch's part of RockField.query, in place, point by point: the same rint / floor / clip and
    bilinear blend in the same order as query_numpy, float32 slabs widened to float64 as NumPy does, and
    NumPy's minimum / maximum comparisons (so bit-identical)."""
    h, w = p_top.shape
    for i in range(xs.size):
        fx = (xs[i] - x0) / cell
        fy = (ys[i] - y0) / cell
        cf, rf = np.rint(fx), np.rint(fy)
        if not (cf >= 0 and cf < w and rf >= 0 and rf < h):  # NaN and far points fail here too
            continue
        c, r = int(cf), int(rf)
        v = np.float64(p_bottom[r, c])
        a = bottom[i]
        bottom[i] = a if (a <= v or a != a) else v
        v = np.float64(p_top[r, c])
        a = top[i]
        top[i] = a if (a >= v or a != a) else v
        c0 = min(max(int(math.floor(fx)), 0), w - 2)
        r0 = min(max(int(math.floor(fy)), 0), h - 2)
        tx = fx - c0
        tx = 0.0 if tx < 0.0 else tx
        tx = 1.0 if tx > 1.0 else tx
        ty = fy - r0
        ty = 0.0 if ty < 0.0 else ty
        ty = 1.0 if ty > 1.0 else ty
        d = ((np.float64(p_depth[r0, c0]) * (1 - tx) + np.float64(p_depth[r0, c0 + 1]) * tx) * (1 - ty)
             + (np.float64(p_depth[r0 + 1, c0]) * (1 - tx) + np.float64(p_depth[r0 + 1, c0 + 1]) * tx) * ty)
        if d > depth[i]:
            depth[i] = d
            ex[i] = np.float64(p_ex[r, c])
            ey[i] = np.float64(p_ey[r, c])


def rock_field_for(world) -> RockField:
    """The world's rock field, built once per World object and cached on it.

    Collider shapes when the world carries them (the real scene), else its render envelopes.
    """
    cached = getattr(world, "_twin_rock_field", None)
    if cached is None:
        shapes = getattr(world, "rock_colliders", None)
        if shapes:
            cached = RockField(patches_from_shapes(shapes, world.height_at))
        else:
            cached = RockField(patches_from_envelopes(world))
        try:
            setattr(world, "_twin_rock_field", cached)
        except AttributeError:  # a frozen/slotted world: just do not cache
            pass
    return cached
