"""Pure-pursuit path following with the simulator's speed-dependent steering lock.

The rover's front-wheel angle is cmd/15 * lerp(5, 15, 1 - |v|/5) degrees, so
the same curvature needs a bigger command at speed; converting a pursuit
curvature through that law keeps the tracking gain the same at all speeds.
"""
import numpy as np

WHEELBASE_M = 0.722  # front-to-rear axle distance, m
STEER_LIMIT_DEG = 15.0  # command clamp, degrees (positive = left)
LOCK_AT_REST_DEG = 15.0  # front-wheel angle at full command when stopped, degrees
LOCK_AT_CAP_DEG = 5.0  # front-wheel angle at full command at the speed cap, degrees
SPEED_CAP_MPS = 5.0  # simulator forward speed clamp, m/s
LOOKAHEAD_MIN_M = 2.0  # shortest pursuit lookahead, m
LOOKAHEAD_MAX_M = 6.0  # longest pursuit lookahead, m
LOOKAHEAD_PER_MPS = 0.8  # extra lookahead per m/s of speed, s


def clamp(x, lo, hi):
    """float(np.clip(x, lo, hi)) for a scalar without NumPy's per-call overhead (several calls a frame): the
    same comparisons as NumPy's float clip, so NaN passes through and a -0.0 at a 0.0 bound stays -0.0."""
    x = float(x)
    if x != x:
        return x
    x = float(lo) if x < lo else x
    return float(hi) if x > hi else x


def wrap_angle(a):
    """Wrap radians to (-pi, pi]."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def wheel_lock_deg(speed):
    """Front-wheel angle reached at full steering command at this speed, degrees."""
    frac = 1.0 - min(abs(float(speed)) if np.isfinite(speed) else 0.0, SPEED_CAP_MPS) / SPEED_CAP_MPS
    return LOCK_AT_CAP_DEG + (LOCK_AT_REST_DEG - LOCK_AT_CAP_DEG) * frac


def steer_for_curvature(curvature, speed):
    """Steering command (degrees, clamped) that makes the bicycle model follow `curvature` (1/m, left +)."""
    if not np.isfinite(curvature):
        return 0.0
    wheel = np.degrees(np.arctan(WHEELBASE_M * curvature))
    cmd = STEER_LIMIT_DEG * wheel / wheel_lock_deg(speed)
    return clamp(cmd, -STEER_LIMIT_DEG, STEER_LIMIT_DEG)


def bearing(pos, yaw_deg, point):
    """Angle of `point` in the rover frame, radians, left positive."""
    dx, dy = point[0] - pos[0], point[1] - pos[1]
    return float(wrap_angle(np.arctan2(dy, dx) - np.radians(yaw_deg)))


def lookahead_for_speed(speed):
    """Pursuit lookahead distance for the current speed, m."""
    return clamp(LOOKAHEAD_MIN_M + LOOKAHEAD_PER_MPS * abs(speed), LOOKAHEAD_MIN_M, LOOKAHEAD_MAX_M)


def closest_index(path_xy, pos, start=0):
    """Index of the path point nearest to pos, searching from `start` onward."""
    seg = path_xy[start:]
    if len(seg) == 0:
        return max(len(path_xy) - 1, 0)
    d2 = (seg[:, 0] - pos[0]) ** 2 + (seg[:, 1] - pos[1]) ** 2
    return start + int(np.argmin(d2))


def lookahead_point(path_xy, pos, lookahead, start=0):
    """First path point at least `lookahead` metres (straight line) from pos after the nearest point.

    Returns (point, index_of_nearest, remaining_path_length_m).
    """
    i0 = closest_index(path_xy, pos, start)
    rest = path_xy[i0:]
    d = np.hypot(rest[:, 0] - pos[0], rest[:, 1] - pos[1])
    far = np.nonzero(d >= lookahead)[0]
    k = int(far[0]) if far.size else len(rest) - 1
    seg = np.diff(rest, axis=0)
    remaining = float(np.hypot(seg[:, 0], seg[:, 1]).sum()) + float(d[0]) if len(rest) > 1 else float(d[0])
    return rest[k], i0, remaining


def pursue(path_xy, pos, yaw_deg, speed, start=0):
    """Pure pursuit on a world path: (steer_cmd_deg, alpha_rad, lookahead_pt, nearest_index, remaining_m)."""
    path_xy = np.asarray(path_xy, dtype=np.float64)
    if path_xy.ndim != 2 or len(path_xy) == 0:
        return 0.0, 0.0, None, 0, 0.0
    lk = lookahead_for_speed(speed)
    pt, i0, remaining = lookahead_point(path_xy, pos, lk, start)
    alpha = bearing(pos, yaw_deg, pt)
    dist = max(float(np.hypot(pt[0] - pos[0], pt[1] - pos[1])), 0.5)
    curvature = 2.0 * np.sin(alpha) / dist
    return steer_for_curvature(curvature, speed), alpha, pt, i0, remaining
