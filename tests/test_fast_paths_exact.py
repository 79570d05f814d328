"""The compiled and rewritten hot paths of the client (perception, navigation) give bit-identical results
to the plain NumPy versions they replaced (kept here as references): speed work must not change a vote."""
import math

import cv2
import numpy as np

import perception as P
from rover_state import RoverState


def _reference_vote(mem, grid, x, y, yaw, occluded=None):
    """The NumPy vote as it was before the compiled kernel (the reference for bit-exactness), with hidden
    ground's votes weighed down as the kernel now does."""
    labels = grid.ravel()[P._MAP_CELLS]
    known = labels != P._LABEL_UNKNOWN
    xw, yw = P.rover_to_world(P._MAP_X[known], P._MAP_Y[known], x, y, yaw)
    ix = np.floor(xw).astype(np.int64)
    iy = np.floor(yw).astype(np.int64)
    inside = (ix >= 0) & (ix < P.WORLD_SIZE) & (iy >= 0) & (iy < P.WORLD_SIZE)
    ix, iy = ix[inside], iy[inside]
    known_idx = np.flatnonzero(known)[inside]
    if ix.size == 0:
        return None
    x0, x1, y0, y1 = int(ix.min()), int(ix.max()) + 1, int(iy.min()), int(iy.max()) + 1
    w_cols = x1 - x0
    local = (iy - y0) * w_cols + (ix - x0)
    w = P._MAP_WEIGHT[known_idx]
    if occluded is not None:
        w = np.where(occluded.ravel()[P._MAP_CELLS][known_idx] != 0, w * P.OCCLUDED_VOTE_WEIGHT, w)
    kind = labels[known_idx]
    is_nav = kind == P._LABEL_NAV
    size = (y1 - y0) * w_cols
    for label, votes in ((P._LABEL_SHADE, mem.shade_votes), (P._LABEL_DIM_SHADE, mem.dim_shade_votes),
                         (P._LABEL_NEAR_SAND, mem.near_sand_votes)):
        is_shade = kind == label
        if is_shade.any():
            votes[y0:y1, x0:x1] += np.bincount(local[is_shade], w[is_shade] * P.OBS_VOTE_WEIGHT,
                                               size).reshape(y1 - y0, w_cols)
    mem.nav_votes[y0:y1, x0:x1] += np.bincount(local[is_nav], w[is_nav] * P.NAV_VOTE_WEIGHT,
                                               size).reshape(y1 - y0, w_cols)
    mem.obs_votes[y0:y1, x0:x1] += np.bincount(local[~is_nav], w[~is_nav] * P.OBS_VOTE_WEIGHT,
                                               size).reshape(y1 - y0, w_cols)
    band = P._MAP_BAND[known_idx]
    for b in range(P.SCORED_BANDS):
        mine = band == b
        mem.band_nav_votes[b, y0:y1, x0:x1] += np.bincount(local[mine & is_nav], w[mine & is_nav] * P.NAV_VOTE_WEIGHT,
                                                           size).reshape(y1 - y0, w_cols)
        all_w = w * np.where(is_nav, P.NAV_VOTE_WEIGHT, P.OBS_VOTE_WEIGHT)
        mem.band_votes[b, y0:y1, x0:x1] += np.bincount(local[mine], all_w[mine], size).reshape(y1 - y0, w_cols)
    near = P._MAP_LOOK[known_idx]
    np.minimum.at(mem.look_range, (iy[near], ix[near]), P._MAP_DIST[known_idx[near]])
    return y0, y1, x0, x1


def _label_grid(img, pitch, roll):
    """The label grid perception_step warps from a camera frame (light sand, shadowed and dim sand, near-hue sand)
    and its hidden-ground grid."""
    r = RoverState()
    r.img, r.pos, r.yaw, r.pitch, r.roll = img, (100.0, 100.0), 0.0, pitch, roll
    P.perception_step(r)
    return P.get_memory(r).last_grid, P._occluded_grid(P._pixel_labels(img)[0], P._frame_homography(pitch, roll))


def _maps(mem):
    return [mem.nav_votes, mem.obs_votes, mem.shade_votes, mem.dim_shade_votes, mem.near_sand_votes, mem.look_range,
            mem.band_nav_votes, mem.band_votes]


def test_compiled_vote_equals_the_numpy_reference_bit_for_bit(test_dataset_dir):
    from replay.log_format import read_log

    frames = read_log(test_dataset_dir).frames[::9]
    rng = np.random.default_rng(3)
    new, ref = P.PerceptionMemory(), P.PerceptionMemory()
    poses = hidden = 0
    for f in frames:
        img = cv2.cvtColor(cv2.imread(str(f.image_path)), cv2.COLOR_BGR2RGB)
        grid, occluded = _label_grid(img, rng.normal(0, 1.5), rng.normal(0, 1.5))
        assert (grid == P._LABEL_NAV).any() and (grid == P._LABEL_OBSTACLE).any()
        hidden += int(occluded[grid != P._LABEL_UNKNOWN].any())
        # the logged pose, a random one, and one hanging over the map's edge (cells fall off it)
        for x, y, yaw in ((f.x, f.y, f.yaw), (rng.uniform(20, 180), rng.uniform(20, 180), rng.uniform(0, 360)),
                          (rng.uniform(-3, 3), rng.uniform(190, 203), rng.uniform(0, 360))):
            assert P._vote(new, grid, x, y, yaw, occluded) == _reference_vote(ref, grid, x, y, yaw, occluded)
            poses += 1
    assert poses > 60 and np.isfinite(ref.look_range).sum() > 500 and hidden > 5
    for a, b in zip(_maps(new), _maps(ref)):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert P._vote(new, grid, -50.0, -50.0, 0.0) is None  # nothing on the map


def test_compiled_vote_differs_when_a_vote_does():
    """The comparison above can fail: one extra navigable cell changes the maps."""
    grid = np.zeros((P._GRID_ROWS, P._GRID_COLS), np.uint8)
    grid[30:40, 100:140] = P._LABEL_NAV
    a, b = P.PerceptionMemory(), P.PerceptionMemory()
    P._vote(a, grid, 100.0, 100.0, 30.0)
    grid[35, 120] = P._LABEL_OBSTACLE
    _reference_vote(b, grid, 100.0, 100.0, 30.0)
    assert not np.array_equal(a.nav_votes, b.nav_votes)
    assert math.isclose(float(a.nav_votes.sum() + a.obs_votes.sum()), float(b.nav_votes.sum() + b.obs_votes.sum()),
                        rel_tol=1e-6)


def _colour_sweep_images():
    """Images holding every (red, green) and every (red, blue) pair, with smooth and rough rows: every
    colour threshold and the texture test's boundary get crossed."""
    r, other = np.meshgrid(np.arange(256, dtype=np.uint8), np.arange(256, dtype=np.uint8), indexing="ij")
    images = []
    for fixed in (0, 120, 200, 255):
        for green_varies in (True, False):
            big = np.full((256, 256, 3), fixed, np.uint8)
            big[:, :, 0] = r
            big[:, :, 1 if green_varies else 2] = other
            for top in range(0, 256, 160):  # 160x320 frames: two 256-wide blocks side by side
                img = np.zeros((160, 320, 3), np.uint8)
                part = big[top:top + 160]
                img[:part.shape[0], :256] = part
                img[:part.shape[0], 256:] = part[:, :64]
                images.append(img)
    return images


def test_compiled_pixel_labels_equal_the_opencv_chain_bit_for_bit(test_dataset_dir):
    from replay.log_format import read_log

    rng = np.random.default_rng(5)
    frames = [cv2.cvtColor(cv2.imread(str(f.image_path)), cv2.COLOR_BGR2RGB)
              for f in read_log(test_dataset_dir).frames[::4]]
    # narrow-range noise puts many windows right at the texture test's variance limit
    noisy = [np.clip(rng.normal(rng.uniform(100, 200), rng.uniform(2, 14), (160, 320, 3)), 0, 255).astype(np.uint8)
             for _ in range(20)]
    shade_pixels = near_pixels = 0
    for img in frames + noisy + _colour_sweep_images():
        new, ref = P._pixel_labels(img), P._pixel_labels_opencv(img)
        for a, b in zip(new, ref):
            assert a.dtype == np.uint8 and np.array_equal(a, b)
        shade_pixels += int((ref[3] > 0).sum())
        near_pixels += int((ref[0] == P._NEAR_SAND_VALUE).sum())
    assert shade_pixels > 10000 and near_pixels > 1000


def test_pixel_labels_follow_changed_thresholds(monkeypatch):
    """Constants are read at call time (a sweep sets them), not frozen into the compiled kernel."""
    img = np.full((160, 320, 3), 150, np.uint8)
    assert not P._pixel_labels(img)[1].any()
    monkeypatch.setattr(P, "NAV_RGB_MIN", (140, 140, 140))
    assert P._pixel_labels(img)[1].all()


def test_vision_image_is_drawn_on_first_read_and_equals_the_overlay():
    img = np.full((160, 320, 3), 40, np.uint8)
    img[90:] = (210, 190, 175)
    img[120:126, 150:156] = (220, 190, 10)
    r = RoverState()
    r.img, r.pos, r.yaw = img, (100.0, 100.0), 0.0
    P.perception_step(r)
    assert r._vision_draw is not None  # nothing drawn yet
    _labels, nav8, rock8, shade8 = P._pixel_labels(img)
    assert np.array_equal(r.vision_image, P._overlay_u8(img, nav8, rock8, shade8))
    P.perception_step(r)
    r.vision_image = np.zeros((160, 320, 3), np.uint8)  # an explicit image replaces the pending drawing
    assert not r.vision_image.any()


def _reference_reach_profile(nav_angles, nav_dists, obs_angles, obs_dists):
    """navigation.reactive.reach_profile as it was in NumPy (the reference for the compiled binning)."""
    from navigation import reactive as R

    idx, d, n = R._binned(nav_angles, nav_dists)
    counts = np.bincount(idx, minlength=n)
    reach = np.zeros(n)
    np.maximum.at(reach, idx, d)
    reach[counts < R.MIN_PIXELS] = 0.0
    oidx, od, _ = R._binned(obs_angles, obs_dists)
    ocount = np.bincount(oidx, minlength=n)
    omin = np.full(n, np.inf)
    np.minimum.at(omin, oidx, od)
    cut = ocount >= R.MIN_OBS_PIXELS
    reach[cut] = np.minimum(reach[cut], omin[cut])
    return reach


def test_compiled_reach_profile_equals_the_numpy_reference(test_dataset_dir):
    from navigation import reactive
    from replay.log_format import read_log

    rng = np.random.default_rng(7)
    for f in read_log(test_dataset_dir).frames[::15]:
        r = RoverState()
        r.img, r.pos, r.yaw = cv2.cvtColor(cv2.imread(str(f.image_path)), cv2.COLOR_BGR2RGB), (f.x, f.y), f.yaw
        P.perception_step(r)
        args = [np.asarray(v, np.float64) for v in (r.nav_angles, r.nav_dists, r.obs_angles, r.obs_dists)]
        # bin edges exactly, NaN, inf and pixels under NEAR_IGNORE_M too
        edges = np.radians(np.arange(-60.0, 61.0, reactive.BIN_DEG))
        args[0] = np.concatenate([args[0], edges, [np.nan, 0.1, 0.2]])
        args[1] = np.concatenate([args[1], rng.uniform(0.3, 9, edges.size), [2.0, np.inf, 0.4]])
        new, ref = reactive.reach_profile(*args), _reference_reach_profile(*args)
        assert np.array_equal(new, ref) and (ref > 0).sum() >= 5


def test_width_limited_equals_the_sliding_window_minimum():
    from navigation import reactive

    k = reactive.ROVER_HALF_WIDTH_BINS
    rng = np.random.default_rng(11)
    for i in range(300):
        reach = rng.uniform(0, 10, 40) * (rng.random(40) < 0.8)
        if i % 10 == 0:
            reach[rng.integers(40)] = np.nan
        ref = np.lib.stride_tricks.sliding_window_view(np.pad(reach, k), 2 * k + 1).min(axis=1)
        assert np.array_equal(reactive.width_limited(reach), ref, equal_nan=True)


def test_polar_outputs_equal_the_masked_tables():
    rng = np.random.default_rng(2)
    for _ in range(20):
        grid = rng.integers(0, 5, (P._GRID_ROWS, P._GRID_COLS)).astype(np.uint8)
        grid[rng.random(grid.shape) < 0.5] = P._LABEL_UNKNOWN
        nav = grid == P._LABEL_NAV
        obs = (grid != P._LABEL_UNKNOWN) & ~nav
        ref = (P._GRID_ANGLE[nav], P._GRID_DIST[nav], P._GRID_ANGLE[obs], P._GRID_DIST[obs])
        for a, b in zip(P._polar_outputs(grid), ref):
            assert a.dtype == b.dtype and np.array_equal(a, b)


def test_scalar_clamp_equals_numpy_clip_bit_for_bit():
    """navigation.pursuit.clamp (decision's command clamps, steering and lookahead) gives float(np.clip)'s very
    value, signed zeros at a 0 bound and NaN included, and a plain float."""
    from navigation.pursuit import clamp

    values = [-0.0, 0.0, 1.0, -1.0, 15.0, -15.0, 15.000001, math.inf, -math.inf, math.nan, 5e-324, -5e-324,
              np.float32(-2.5), np.float64(3.25)] + list(np.random.default_rng(0).normal(0.0, 10.0, 500))
    for lo, hi in ((-1.0, 1.0), (0.0, 1.0), (-15.0, 15.0), (2.0, 6.0), (-0.0, 0.0)):
        for v in values:
            want, got = float(np.clip(v, lo, hi)), clamp(v, lo, hi)
            assert type(got) is float
            assert (math.isnan(want) and math.isnan(got)) or (want == got and math.copysign(1, want) == math.copysign(1, got))


def _tie_votes(rng, shape):
    """float32 votes from a few exact levels, so shares land exactly on and next to the rules' thresholds."""
    levels = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 0.75, 0.1, 0.35, 0.25], np.float32)
    v = levels[rng.integers(0, levels.size, shape)] * np.float32(rng.choice([1.0, 2.0, 7.0]))
    jitter = rng.random(shape) < 0.2  # some cells a float32 step off the level
    return np.where(jitter, np.nextafter(v, np.float32(10.0)), v).astype(np.float32)


def test_worldmap_kernel_equals_the_numpy_rules():
    """render_worldmap's compiled window rebuild writes exactly the bytes of the NumPy rules (scored map with its
    band rule and neighbour fill, and the drive map), on windows inside the map, on its edges and the whole map."""
    rng = np.random.default_rng(7)
    differing = 0
    for trial in range(60):
        mem = P.PerceptionMemory()
        for votes in (mem.nav_votes, mem.obs_votes, mem.shade_votes, mem.dim_shade_votes, mem.near_sand_votes):
            votes[...] = _tie_votes(rng, votes.shape)
        mem.band_votes[...] = _tie_votes(rng, mem.band_votes.shape)
        mem.band_nav_votes[...] = np.minimum(_tie_votes(rng, mem.band_votes.shape), mem.band_votes)
        if trial % 3 == 0:  # shares exactly at the thresholds
            mem.nav_votes[...] = np.float32(P.SCORED_NAV_MAJORITY) * (mem.nav_votes + mem.obs_votes)
        y0, x0 = (int(a) for a in rng.integers(0, P.WORLD_SIZE - 1, 2))
        window = [(y0, min(y0 + int(rng.integers(1, 40)), P.WORLD_SIZE), x0, min(x0 + int(rng.integers(1, 40)),
                                                                                  P.WORLD_SIZE)),
                  (0, 12, 190, 200), (195, 200, 0, 7), (0, 0, 0, 0), None][trial % 5]
        for drive in (False, True):
            if window == (0, 0, 0, 0) and drive:
                continue
            start = rng.integers(0, 256, (P.WORLD_SIZE, P.WORLD_SIZE, 3), dtype=np.uint8)
            fast, ref = start.copy(), start.copy()
            try:
                P.FAST_WORLDMAP = False
                P.render_worldmap(mem, ref, window, drive=drive)
            finally:
                P.FAST_WORLDMAP = True
            P.render_worldmap(mem, fast, window, drive=drive)
            assert np.array_equal(fast, ref), (trial, window, drive)
            differing += int((fast != start).any())
    assert differing > 30  # the windows were really rewritten
