"""Tyre tracks as the real simulator lays them (`TireTracks.cs`, simulator-facts.md section 1).

Each rear wheel, while grounded, lays a 0.12 m x 0.12 m quad aligned with the rover 0.01 m above
the surface under it, in the first rendered frame after the wheel has moved more than 0.05 m from
where it laid the last one. Only the last 200 quads per wheel are kept, trimmed 50 at a time.
The quad shows a tread texture, alpha cut-out at 0.5, tinted (0.659, 0.616, 0.562): darker than
sunlit sand, so tracks fail the client's brightness threshold where the rover drives back over
its own path.

The state belongs to the twin: `tyre_tracks(twin)` returns the twin's `TyreTracks`, updated from
its current pose (call it once per rendered frame); the renderer draws `TyreTracks.quads`.
The texture is read at run time from ../shared (`world/tyre_track_texture.png`); without it a
procedural tread of the project's own is used (`procedural_tread`).
"""
from __future__ import annotations

import logging
import math

import numpy as np

log = logging.getLogger(__name__)

# --- TireTracks.cs and the Rover prefab (simulator-facts.md sections 1 and 2) ---
QUAD_HALF_M = 0.06  # half side of a track quad (serialized width 0.06 m either side), m
MIN_MOVE_M = 0.05  # a wheel lays its next quad once it is this far from its last one, m
MAX_QUADS_PER_WHEEL = 200  # quads kept per wheel, count
TRIM_BATCH = 50  # oldest quads dropped at once when a wheel exceeds the maximum, count
LIFT_M = 0.01  # quads float this far above the surface, m
REAR_AXLE_M = -0.336  # rear axle along the rover's forward axis from its origin, m
HALF_TRACK_M = 0.395  # rear wheel centre either side of the rover's centre line (track 0.79 m), m
WHEEL_RADIUS_M = 0.1485  # rear wheel radius: a rock whose bottom is below this is under the wheel, m
WHEEL_CLIMB_M = 0.5  # a rock top higher than this above the terrain is not stood on (an overhang), m
TINT = (0.659, 0.616, 0.562)  # Tracks.mat colour, 0..1 RGB
ALPHA_CUTOFF = 0.5  # alpha below this is cut out (not drawn), 0..1
TEXTURE_NAME = "tyre_track_texture.png"  # file under shared world/
# --- laying tracks along a logged drive (sim.realism, sim.map_realism) ---
REPLAY_RENDER_FPS = 30.0  # the simulator's render rate at the qualities the logs used (tracks are laid per frame), Hz
REPLAY_MAX_GAP_S = 1.0  # rows further apart than this (a pause or a cut) are not interpolated between, s

# --- the procedural stand-in tread (only when the shared texture is absent) ---
TREAD_SIZE = 128  # texels per side, like the real texture
TREAD_PERIOD = 64  # texels per repeat of the chevron pattern along the track
TREAD_BAR = 0.42  # fraction of each repeat that is rubber (opaque): ~40 % opaque like the real one


def procedural_tread(size: int = TREAD_SIZE) -> np.ndarray:
    """A bool (size, size) chevron tread of the project's own (rows run along the track).

    Used only when the simulator's texture is not available; it has the real texture's size and
    about its opaque fraction, so tracks look and threshold about the same.
    """
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float64)
    across = np.abs(cols / (size - 1) - 0.5) * 2.0  # 0 at the centre line, 1 at the edges
    phase = ((rows + 0.35 * across * TREAD_PERIOD) % TREAD_PERIOD) / TREAD_PERIOD
    bars = phase < TREAD_BAR
    shoulders = across > 0.8  # a solid rim along both edges
    return bars | (shoulders & (phase < 0.75))


def load_tread_alpha(path=None) -> np.ndarray:
    """The tread's alpha, float32 0..1 (rows along the track, columns across it)."""
    import cv2

    if path is None:
        try:
            import shared_data

            path = shared_data.world_dir() / TEXTURE_NAME
        except ImportError:
            path = None
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) if path is not None else None
    if image is None or image.ndim != 3 or image.shape[2] != 4 or image.shape[0] != image.shape[1]:
        log.info("tyre track texture not found or not square RGBA (%s): using the procedural tread", path)
        return procedural_tread().astype(np.float32)
    return image[..., 3].astype(np.float32) / 255.0


def tread_mips(alpha: np.ndarray) -> np.ndarray:
    """uint8 (levels, n, n): the alpha cut-out at each mip level (box-averaged alpha >= ALPHA_CUTOFF),
    every level stretched back to n x n so one index serves all. Far away a pixel spans many texels;
    the averaged alpha of a 40 %-opaque tread falls under the cut-off and the track fades out, as
    the simulator's mipmapped texture does."""
    n = alpha.shape[0]
    levels = []
    level = alpha.astype(np.float32)
    while True:
        reps = n // level.shape[0]
        levels.append(np.kron(level >= ALPHA_CUTOFF, np.ones((reps, reps), bool)))
        if level.shape[0] == 1 or level.shape[0] % 2:
            break
        level = level.reshape(level.shape[0] // 2, 2, level.shape[1] // 2, 2).mean(axis=(1, 3))
    return np.ascontiguousarray(np.stack(levels), dtype=np.uint8)


class TyreTracks:
    """The quads both rear wheels have laid, oldest first per wheel."""

    def __init__(self, world=None):
        self.world = world  # for the surface height under a wheel (None: flat ground at 0 m)
        self.clear()

    def clear(self) -> None:
        # per rear wheel (left, right): rows (x, y, z, yaw_rad) oldest first in a fixed buffer, and how many are
        # kept (appending a row costs no rebuild of a list of tuples as an array every frame a quad is laid)
        self._wheels = [np.empty((MAX_QUADS_PER_WHEEL + 1, 4)), np.empty((MAX_QUADS_PER_WHEEL + 1, 4))]
        self._counts = [0, 0]
        self._last = [None, None]  # where each wheel laid its last quad, (x, y)
        self._quads = None  # cached (N, 4) array, None when stale
        self.laid = 0  # quads laid since the last clear (trimmed ones included): changes whenever the tracks do

    @staticmethod
    def wheel_positions(x, y, yaw_deg):
        """World (x, y) of the left and right rear wheel for a rover pose."""
        yaw = math.radians(yaw_deg)
        fx, fy = math.cos(yaw), math.sin(yaw)
        bx, by = x + REAR_AXLE_M * fx, y + REAR_AXLE_M * fy
        # left of the heading is (-fy, fx)
        return (bx - HALF_TRACK_M * fy, by + HALF_TRACK_M * fx), (bx + HALF_TRACK_M * fy, by - HALF_TRACK_M * fx)

    def update(self, x, y, yaw_deg, grounded=(True, True)) -> "TyreTracks":
        """One rendered frame at this pose: each grounded wheel that moved > MIN_MOVE_M lays a quad."""
        if not all(math.isfinite(float(v)) for v in (x, y, yaw_deg)):
            return self
        yaw = math.radians(yaw_deg)
        for i, (wx, wy) in enumerate(self.wheel_positions(float(x), float(y), float(yaw_deg))):
            last = self._last[i]
            if last is not None and math.hypot(wx - last[0], wy - last[1]) <= MIN_MOVE_M:
                continue
            if not grounded[i]:
                continue
            buf, n = self._wheels[i], self._counts[i]
            buf[n] = (wx, wy, self._surface(wx, wy) + LIFT_M, yaw)
            n += 1
            if n > MAX_QUADS_PER_WHEEL:
                buf[:n - TRIM_BATCH] = buf[TRIM_BATCH:n].copy()
                n -= TRIM_BATCH
            self._counts[i] = n
            self._last[i] = (wx, wy)
            self._quads = None
            self.laid += 1
        return self

    def _surface(self, x, y) -> float:
        """Height the wheel stands on: the terrain, or a low rock top under the wheel (tracks land on
        rocks too), never the top of an overhang above it."""
        if self.world is None:
            return 0.0
        ground = float(self.world.height_at(x, y))
        bottom, top = self.world.rock_span_at(x, y)
        if top > ground and bottom <= ground + WHEEL_RADIUS_M and top - ground <= WHEEL_CLIMB_M:
            return float(top)
        return ground

    def counts(self):
        """Quads kept per wheel (left, right)."""
        return tuple(self._counts)

    @property
    def quads(self) -> np.ndarray:
        """float64 (N, 4): centre x, y, z (surface + LIFT_M) and yaw (rad) of every kept quad."""
        if self._quads is None:
            (left, right), (n_left, n_right) = self._wheels, self._counts
            self._quads = np.concatenate((left[:n_left], right[:n_right]))
        return self._quads


def tyre_tracks(twin) -> TyreTracks:
    """The twin's tyre tracks, updated for this rendered frame (a new scene starts with none).

    A reset gives the twin a new physics object; that is how a new scene is recognised, so the
    twin needs no track code of its own beyond this call.
    """
    tracks = getattr(twin, "_tyre_tracks", None)
    if tracks is None or tracks.world is not twin.world:
        tracks = TyreTracks(twin.world)
        twin._tyre_tracks = tracks
    if getattr(tracks, "_physics", None) is not twin.physics:
        tracks.clear()
        tracks._physics = twin.physics
    s = twin.physics.state
    return tracks.update(s.x, s.y, s.yaw)


def replay_quads(poses, times=None, world=None, keep=None):
    """Tyre tracks along a logged drive: yields (row index, quads array) for every row in `keep`
    (all rows when None), with the tracks the real simulator would show in that row's frame.

    poses: (x, y, yaw_deg) per logged row, in order. times: seconds per row (None, or None for any
    row: unknown, so no row is interpolated — a log's times are used for all rows or for none).
    A log is written at 15-21 Hz while the simulator lays tracks in each rendered frame (~30 Hz),
    so poses are interpolated between rows at REPLAY_RENDER_FPS when the rows' times are known;
    without times, one update per row. All wheels are taken as grounded.
    """
    tracks = TyreTracks(world)
    keep = None if keep is None else set(keep)
    if times is not None and any(t is None for t in times):
        times = None
    prev = prev_t = None
    for i, (x, y, yaw) in enumerate(poses):
        t = None if times is None else times[i]
        if prev is not None and t is not None and prev_t is not None and 0.0 < t - prev_t <= REPLAY_MAX_GAP_S:
            steps = int(math.ceil((t - prev_t) * REPLAY_RENDER_FPS - 1e-6))
            dyaw = (yaw - prev[2] + 180.0) % 360.0 - 180.0
            for k in range(1, steps):
                f = k / steps
                tracks.update(prev[0] + f * (x - prev[0]), prev[1] + f * (y - prev[1]), prev[2] + f * dyaw)
        tracks.update(x, y, yaw)
        prev, prev_t = (x, y, yaw), t
        if keep is None or i in keep:
            yield i, tracks.quads

