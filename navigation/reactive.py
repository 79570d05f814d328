"""Free-space profile of the current camera frame, for reactive obstacle avoidance.

The map can be wrong or stale; the current frame is not. Per angular bin we
estimate how far the ground stays navigable (nav pixels reach, cut short by
the nearest obstacle pixels) and pick the clear heading closest to the one
the planner wants.
"""
import math

import numpy as np
from numba import njit

BIN_DEG = 3.0  # angular bin width, degrees
FOV_HALF_DEG = 60.0  # profile covers +-this angle, degrees
MIN_PIXELS = 3  # a bin needs this many nav pixels to count as seen
MIN_OBS_PIXELS = 4  # obstacle pixels in a bin needed to cut its reach
NEAR_IGNORE_M = 0.5  # nav/obstacle pixels closer than this are ignored (projection noise), m
ROVER_HALF_WIDTH_BINS = 2  # bins either side that must also be clear (rover width), bins
CLEAR_REACH_M = 3.0  # reach at which a heading counts as fully clear, m
TURN_PENALTY_M_PER_RAD = 2.0  # reach given up per radian of deviation from the wanted heading, m/rad


_CENTRES = {}  # (FOV_HALF_DEG, BIN_DEG) -> read-only bin centres (asked for every driving frame)


def bin_centres():
    """Centres of the profile's bins, radians (read-only)."""
    key = (FOV_HALF_DEG, BIN_DEG)
    centres = _CENTRES.get(key)
    if centres is None:
        n = int(round(2 * FOV_HALF_DEG / BIN_DEG))
        centres = np.radians(-FOV_HALF_DEG + BIN_DEG * (np.arange(n) + 0.5))
        centres.flags.writeable = False
        _CENTRES[key] = centres
    return centres


def _bin_index(angles):
    n = int(round(2 * FOV_HALF_DEG / BIN_DEG))
    idx = np.floor((np.degrees(angles) + FOV_HALF_DEG) / BIN_DEG).astype(np.int64)
    ok = (idx >= 0) & (idx < n)
    return idx, ok, n


def _binned(angles, dists):
    """(bin index, distance) of the finite pixels beyond NEAR_IGNORE_M that fall inside the profile."""
    angles = np.asarray(angles, dtype=np.float64).ravel()
    dists = np.asarray(dists, dtype=np.float64).ravel()
    m = min(angles.size, dists.size)
    angles, dists = angles[:m], dists[:m]
    good = np.isfinite(angles) & np.isfinite(dists) & (dists > NEAR_IGNORE_M)
    idx, ok, n = _bin_index(angles[good])
    return idx[ok], dists[good][ok], n


def reach_profile(nav_angles, nav_dists, obs_angles=None, obs_dists=None):
    """Per-bin free distance (m) in the current frame; 0 where no ground is seen.

    The binning runs compiled (_bin_extremes, one pass per pixel list; this runs every driving
    frame over ~10,000 pixels); the same bins and values as _binned's NumPy version."""
    n = int(round(2 * FOV_HALF_DEG / BIN_DEG))
    counts, reach = _bin_extremes(_flat64(nav_angles), _flat64(nav_dists), n, FOV_HALF_DEG, BIN_DEG,
                                  NEAR_IGNORE_M, True)
    reach[counts < MIN_PIXELS] = 0.0
    if obs_angles is not None and obs_dists is not None:
        ocount, omin = _bin_extremes(_flat64(obs_angles), _flat64(obs_dists), n, FOV_HALF_DEG, BIN_DEG,
                                     NEAR_IGNORE_M, False)
        cut = ocount >= MIN_OBS_PIXELS
        reach[cut] = np.minimum(reach[cut], omin[cut])
    return reach


def _flat64(values):
    return np.ascontiguousarray(np.asarray(values, dtype=np.float64).ravel())


@njit(cache=True)
def _bin_extremes(angles, dists, n, fov_half_deg, bin_deg, near_m, largest):
    """Per angular bin: the count of finite pixels beyond near_m, and their largest (else smallest)
    distance (0 / inf for empty bins).  Bins as _bin_index: floor((degrees + fov) / bin_deg)."""
    count = np.zeros(n, np.int64)
    extreme = np.zeros(n) if largest else np.full(n, np.inf)
    for i in range(min(angles.size, dists.size)):
        a, d = angles[i], dists[i]
        if not (math.isfinite(a) and math.isfinite(d) and d > near_m):
            continue
        k = math.floor((a * (180.0 / math.pi) + fov_half_deg) / bin_deg)  # np.degrees is x * (180 / pi)
        if k < 0 or k >= n:
            continue
        count[k] += 1
        extreme[k] = max(extreme[k], d) if largest else min(extreme[k], d)
    return count, extreme


def width_limited(reach):
    """Reach of a rover-wide corridor per heading: min over neighbouring bins."""
    k = ROVER_HALF_WIDTH_BINS
    if reach.size == 0:
        return reach
    n = reach.size
    padded = np.concatenate([np.zeros(k), reach, np.zeros(k)])
    out = padded[:n].copy()
    for j in range(1, 2 * k + 1):  # the window minimum, shift by shift (40 bins: cheaper than a window view)
        np.minimum(out, padded[j:j + n], out=out)
    return out


def choose_heading(reach, wanted_rad):
    """Heading (rad) nearest `wanted_rad` with the most clear corridor, and that corridor's reach (m)."""
    centres = bin_centres()
    corridor = width_limited(np.asarray(reach, dtype=np.float64))
    if corridor.size == 0 or not np.isfinite(wanted_rad):
        return 0.0, 0.0
    score = np.minimum(corridor, CLEAR_REACH_M) - TURN_PENALTY_M_PER_RAD * np.abs(centres - wanted_rad)
    k = int(np.argmax(score))
    j = int(np.argmin(np.abs(centres - wanted_rad)))
    if corridor[j] >= CLEAR_REACH_M and abs(centres[j] - wanted_rad) <= np.radians(BIN_DEG):
        return float(wanted_rad), float(corridor[j])
    return float(centres[k]), float(corridor[k])


def reach_at(reach, angle_rad):
    """Corridor reach (m) straight along `angle_rad`."""
    centres = bin_centres()
    corridor = width_limited(np.asarray(reach, dtype=np.float64))
    if corridor.size == 0:
        return 0.0
    j = int(np.argmin(np.abs(centres - angle_rad)))
    return float(corridor[j])
