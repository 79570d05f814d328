"""Renderer: shape and layout of frames, sample rocks visible to the client, bad poses."""
import importlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from sim.render import IMAGE_H, IMAGE_W, Renderer, body_rotation, encode_jpeg
from sim.world import World, load_world


def _flat_world(size=200.0):
    """A level sand floor, no walls or rocks: the simplest scene to reason about."""
    return World(
        terrain_height=np.zeros((513, 513), np.float32),
        sand_weight=np.ones((512, 512), np.float32),
        rock_top=np.zeros((2001, 2001), np.float32),
        rock_bottom=np.zeros((2001, 2001), np.float32),
        nav_truth=np.full((200, 200), 255, np.uint8),
        sample_spots=np.zeros((0, 2)),
        start_xy=(100.0, 100.0), start_yaw_training=0.0, name="flat")


@pytest.fixture(scope="module")
def flat_renderer():
    return Renderer(_flat_world())


@pytest.fixture(scope="module")
def canyon_renderer():
    return Renderer(load_world("procedural:0"))


def _navigable(rgb):
    return np.all(rgb > 160, axis=2)


def test_frame_shape_dtype(flat_renderer):
    img = flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0))
    assert img.shape == (IMAGE_H, IMAGE_W, 3) and img.dtype == np.uint8


def test_sky_on_top_floor_below_on_flat_ground(flat_renderer):
    img = flat_renderer.render((100.0, 100.0, 30.0, 0.0, 0.0))
    nav = _navigable(img)
    assert nav[100:].mean() > 0.99  # floor below the horizon (row 80) is light sand
    assert nav[:78].mean() == 0.0  # sky above it is not
    assert np.isinf(flat_renderer.last_depth[:78]).all()
    # floor distance follows the camera geometry: bottom row ~0.31 m ahead of the camera
    assert 0.25 < flat_renderer.last_depth[-1, 160] < 0.4


def test_pitch_moves_horizon(flat_renderer):
    """Positive pitch is nose down, so the horizon moves up in the image."""
    def horizon_row(img):
        col = _navigable(img)[:, 160]
        return int(np.argmax(col))

    level = horizon_row(flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0)))
    nose_down = horizon_row(flat_renderer.render((100.0, 100.0, 0.0, 5.0, 0.0)))
    assert nose_down < level - 5


def test_roll_tilts_horizon(flat_renderer):
    """Positive roll lifts the right side: the horizon drops on the right of the image."""
    img = flat_renderer.render((100.0, 100.0, 0.0, 0.0, 5.0))
    nav = _navigable(img)
    left, right = int(np.argmax(nav[:, 20])), int(np.argmax(nav[:, 300]))
    assert right > left + 5


def test_body_rotation_axes():
    rot = body_rotation(90.0, 0.0, 0.0)  # facing north
    np.testing.assert_allclose(rot[:, 2], [0, 1, 0], atol=1e-12)  # forward
    np.testing.assert_allclose(rot[:, 0], [1, 0, 0], atol=1e-12)  # right = east
    rot = body_rotation(0.0, 10.0, 0.0)  # facing east, nose down
    assert rot[2, 2] < 0


def test_canyon_has_floor_and_walls(canyon_renderer):
    w = canyon_renderer.world
    img = canyon_renderer.render((*w.start_xy, w.start_yaw_training, 0.0, 0.0))
    nav = _navigable(img)
    assert nav[140:].mean() > 0.5  # standing on floor
    assert not nav.all()


@pytest.mark.parametrize("distance", [1.0, 2.0, 3.0, 4.0, 5.0])
def test_sample_rock_visible_to_client_threshold(flat_renderer, distance):
    perception = pytest.importorskip("perception", reason="perception.py (client) not present yet")
    x0, y0 = 100.0, 100.0
    cam_ahead = 0.4287
    pose = (x0, y0, 0.0, 0.0, 0.0)  # facing east
    sample = (x0 + cam_ahead + distance, y0 + 0.2, 0.36, 30.0)  # smallest spawn scale
    img = flat_renderer.render(pose, samples=[sample])
    assert perception.rock_mask(img).sum() >= 4
    if distance > 3.0:
        return  # farther, the smallest rock is ~3 px wide: JPEG chroma subsampling may wash it out
    # and still after the simulator's JPEG encoding
    decoded = cv2.cvtColor(cv2.imdecode(np.frombuffer(encode_jpeg(img), np.uint8), cv2.IMREAD_COLOR),
                           cv2.COLOR_BGR2RGB)
    assert perception.rock_mask(decoded).sum() >= 1
    plain = flat_renderer.render(pose)
    assert perception.rock_mask(plain).sum() == 0


def test_sample_rock_size_and_colour(flat_renderer):
    img = flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0), samples=[(101.43, 100.0, 0.5, 0.0)])
    gold = (img[..., 0] > 150) & (img[..., 1] > 120) & (img[..., 2] < 60)
    ys, xs = np.nonzero(gold)
    assert xs.size > 0
    width_px = xs.max() - xs.min() + 1  # at 1 m from the camera: ~0.19 m * 114 px/m
    assert 14 <= width_px <= 28
    assert abs(xs.mean() - 160) < 4


def _gold_core(perception, rgb):
    """Pixels of the client's gold blobs with their one-pixel edge (where the JPEG mixes in the sand) eroded away."""
    blob = perception.rock_mask(rgb).astype(np.uint8)
    return rgb[cv2.erode(blob, np.ones((3, 3), np.uint8)) > 0].astype(float)


def test_sample_gold_matches_the_cores_of_close_real_blobs(flat_renderer):
    """sim.render.SAMPLE_RGB: eroded cores of close real blobs (megalphian, through the simulator's JPEG)
    have blue median 4 and green / red 0.825; the old gold (blue 0.12) drew blue 18-28 before any JPEG."""
    perception = pytest.importorskip("perception", reason="perception.py (client) not present yet")
    img = flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0), samples=[(102.4, 100.0, 0.45, 20.0)])
    px = _gold_core(perception, img)
    assert len(px) >= 20
    assert np.median(px[:, 2]) <= 10
    assert 0.80 <= np.median(px[:, 1] / px[:, 0]) <= 0.84


def test_sample_hidden_behind_wall(canyon_renderer):
    """Depth test: a sample far behind the viewer's wall does not show."""
    w = canyon_renderer.world
    pose = (*w.start_xy, 0.0, 0.0, 0.0)
    base = canyon_renderer.render(pose)
    far_sample = (min(w.start_xy[0] + 60.0, 199.0), w.start_xy[1], 0.5, 0.0)
    img = canyon_renderer.render(pose, samples=[far_sample])
    depth_along = canyon_renderer.last_depth[80:, 150:170]
    if np.isfinite(depth_along).all() and depth_along.max() < 50:
        assert np.array_equal(base, img)


def test_out_of_world_and_inside_rock_poses_render(canyon_renderer):
    w = canyon_renderer.world
    for pose in [(-50.0, -50.0, 0.0, 0.0, 0.0), (500.0, 100.0, 180.0, 0.0, 0.0),
                 (100.0, 100.0, 0.0, 359.0, 1.0), (100.0, 100.0, 720.0, -30.0, 60.0)]:
        img = canyon_renderer.render(pose)
        assert img.shape == (160, 320, 3)
    # out-of-world poses are clamped to the border
    np.testing.assert_array_equal(canyon_renderer.render((-5.0, 50.0, 0.0, 0.0, 0.0)),
                                  canyon_renderer.render((0.0, 50.0, 0.0, 0.0, 0.0)))
    if w.obstacles:
        rock = w.obstacles[0]
        img = canyon_renderer.render((rock["x"], rock["y"], 0.0, 0.0, 0.0))
        assert img.shape == (160, 320, 3)


@pytest.mark.parametrize("pose", [(float("nan"), 1.0, 0.0, 0.0, 0.0), (1.0, 1.0, float("inf"), 0.0, 0.0),
                                  (1.0, 2.0, 3.0), ("a", 1, 1, 1, 1)])
def test_bad_pose_raises_value_error(flat_renderer, pose):
    with pytest.raises(ValueError):
        flat_renderer.render(pose)


def test_encode_jpeg_roundtrip(flat_renderer):
    img = flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0))
    data = encode_jpeg(img)
    assert data[:2] == b"\xff\xd8"
    decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (160, 320, 3)
    assert np.abs(decoded[..., ::-1].astype(int) - img.astype(int)).mean() < 6


def test_real_world_start_view(world_dir):
    w = load_world("real")
    r = Renderer(w)
    img = r.render((*w.start_xy, w.start_yaw_training, 0.0, 0.0))
    nav = _navigable(img)
    assert nav[120:].mean() > 0.9  # the start looks down a sandy valley
    assert nav[:60].mean() < 0.05  # walls and sky above
    assert importlib.import_module("sim.render").IMAGE_W == 320


def test_explicit_root_height_raises_camera(flat_renderer):
    """A 6th pose value is the rover root height: a higher camera sees the floor ahead farther away."""
    flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0))
    low = flat_renderer.last_depth[-1, 160]
    flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0, 0.5))
    high = flat_renderer.last_depth[-1, 160]
    assert high > 2 * low


def _world_with_rock_under_front_wheels(height_m):
    """The flat world with a low block of rock under the front axle of a rover at (100, 100) heading +x."""
    world = _flat_world()
    top = world.rock_top.copy()
    top[990:1011, 1035:1045] = height_m  # y 99-101 m, x 103.5-104.5 m (front wheels 0.386 m ahead of the root)
    world.rock_top = top
    return world


def test_logged_pose_on_a_rock_raises_the_camera_by_the_wheels_support():
    """A pose without a root height stands on its wheels: front wheels on a 0.2 m rock lift the root by the
    support plane (front axle up 0.2 m: about 0.1 m at the root) and the camera sees the floor ahead farther off;
    off the rock (and on a rock too tall for a wheel to stand on) nothing changes."""
    flat = Renderer(_flat_world())
    on_rock = Renderer(_world_with_rock_under_front_wheels(0.2))
    too_tall = Renderer(_world_with_rock_under_front_wheels(2.0))
    pose = (103.7, 100.0, 0.0, 0.0, 0.0)  # front wheels at x 104.09, on the block
    lift = on_rock._rock_lift(*pose[:3])
    assert 0.08 < lift < 0.12
    assert too_tall._rock_lift(*pose[:3]) == 0.0
    assert on_rock._rock_lift(90.0, 100.0, 0.0) == 0.0  # far from the rock
    origin_flat, _ = flat.camera(pose)
    origin_rock, _ = on_rock.camera(pose)
    assert origin_rock[2] - origin_flat[2] == pytest.approx(lift)
    # an explicit root height (the twin's physics) is used as given
    assert on_rock.camera(pose + (0.3,))[0][2] == pytest.approx(flat.camera(pose + (0.3,))[0][2])


def test_shipped_calibration_images_show_floor_and_todays_gold():
    """calibration_images/ (the project's own, for users without ../shared): floor in front, no gold in the grid
    view, and in the rock view a blob the client finds, in the twin's current gold (blue median under 10 in the
    blob's core; the images rendered with the old gold had 17)."""
    perception = pytest.importorskip("perception", reason="perception.py (client) not present yet")
    folder = Path(__file__).resolve().parent.parent / "calibration_images"
    grid, rock = (cv2.cvtColor(cv2.imread(str(folder / name)), cv2.COLOR_BGR2RGB) for name in ("grid1.jpg", "rock1.jpg"))
    assert grid.shape == rock.shape == (IMAGE_H, IMAGE_W, 3)
    assert perception.navigable_mask(grid)[140:].mean() > 0.8
    assert perception.rock_mask(grid).sum() < perception.ROCK_MIN_PIXELS
    assert perception.rock_mask(rock).sum() > 50
    assert np.median(_gold_core(perception, rock)[:, 2]) < 10


def test_calibration_grid_matches_standard_points(flat_renderer):
    from sim import calibration

    corners = calibration.grid_square_corners_px()
    np.testing.assert_allclose(corners, calibration.STANDARD_SOURCE_PX, atol=6)  # standard fit has 0.76 deg pitch
    pose = (100.0, 100.0, 0.0, 0.0, 0.0)
    base = flat_renderer.render(pose)
    grid = calibration.draw_floor_grid(base, flat_renderer.last_hit, pose)
    dark = np.all(grid < 60, axis=2) & ~np.all(base < 60, axis=2)
    assert dark[100:].sum() > 300  # grid lines drawn on the floor
    assert not dark[:78].any()  # none in the sky


def test_shadows_off_lights_the_shadowed_floor():
    """--shadows off (Fastest/Fast quality) brightens exactly the floor the terrain shadows, to the weak
    darkening the shadowless real drives show there (sim/shading.py); open floor (sand weight from
    SHADOWLESS_WALL_FOOT_NONE_FROM on: the wall feet are darker without shadows, item 7) is compared."""
    from sim.render import _baked_for
    from sim.shading import CAST_SHADOW_FACTOR, SHADOWLESS_SHADOW_FACTOR, SHADOWLESS_WALL_FOOT_NONE_FROM
    from sim.world import with_shadows

    on = with_shadows(load_world("procedural:0"), True)
    off = with_shadows(on, False)
    assert off is not on and not off.cast_shadows and on.cast_shadows
    assert with_shadows(on, True) is on  # no copy when nothing changes
    assert not load_world("procedural:0").cast_shadows  # off unless asked for
    lit_on, lit_off = _baked_for(on)["light"], _baked_for(off)["light"]
    shadow_on = _baked_for(on)["shadow"]
    open_floor = _baked_for(on)["sand"] >= SHADOWLESS_WALL_FOOT_NONE_FROM
    shadowed = (shadow_on > 0.9) & open_floor
    assert shadowed.any(), "the procedural canyon walls should shadow some floor"
    assert np.array_equal(_baked_for(off)["shadow"], shadow_on)  # the same floor is hidden from the sun
    ratio = lit_on[shadowed] / lit_off[shadowed]
    assert np.median(ratio) == pytest.approx(CAST_SHADOW_FACTOR / SHADOWLESS_SHADOW_FACTOR, abs=0.05)
    sunlit = ~(shadow_on > 0) & open_floor
    assert np.array_equal(lit_on[sunlit], lit_off[sunlit])


def test_last_hit_is_nan_in_every_coordinate_for_sky(flat_renderer):
    """Sky pixels must not leak uninitialised memory into y and z (it made grid drawing warn)."""
    for _ in range(3):
        flat_renderer.render((100.0, 100.0, 0.0, 0.0, 0.0))
        hit = flat_renderer.last_hit
        sky = np.isnan(hit[..., 0])
        assert sky[:70].all() and not sky[100:].any()
        assert np.isnan(hit[sky]).all()
        assert np.isfinite(hit[~sky]).all()


def test_fast_kernel_draws_the_same_frames_as_the_reference_kernel(canyon_renderer):
    """The sped-up raymarch (analytic level floor, block skipping, terrain marched on its own grid,
    packed colours, numba samples) must draw what the frozen pre-speed-up renderer draws, pitched and
    rolled poses included. The one intended difference: the terrain is now the bilinear surface of its
    own 0.39 m grid, not of a 0.1 m resample of it, so wall feet seen from close by shift a pixel or two."""
    from benchmarks.render_v1 import RendererV1
    from sim.render import _darkening_lut

    w = canyon_renderer.world
    old = RendererV1(w)
    canyon_renderer = Renderer(w)  # shares the baked rasters
    canyon_renderer._dark_lut = _darkening_lut(True)  # the reference has only the cast-shadow distance darkening
    canyon_renderer._splat_mip = None  # ... and none of the look terms drawn after the march (sim/shading.py)
    canyon_renderer.backscatter = False
    rng = np.random.default_rng(7)
    rows, cols = np.nonzero(w.nav_truth)
    spots = w.sample_spots[:6]
    samples = [(x, y, 0.43, 25.0) for x, y in spots]
    close_fractions = []
    for i in rng.integers(0, rows.size, 12):
        pose = (cols[i] + 0.5, rows[i] + 0.5, rng.uniform(0, 360), rng.normal(0, 3), rng.normal(0, 3))
        new_img = canyon_renderer.render(pose, samples)
        old_img = old.render(pose, samples)
        close_fractions.append((np.abs(new_img.astype(int) - old_img.astype(int)).max(axis=2) <= 8).mean())
        assert (_navigable(new_img) == _navigable(old_img)).mean() >= 0.99, pose
        same_sky = np.isfinite(old.last_depth) == np.isfinite(canyon_renderer.last_depth)
        assert same_sky.mean() >= 0.998, pose
        gold_old = (old_img[..., 0] > 150) & (old_img[..., 2] < 60)
        gold_new = (new_img[..., 0] > 150) & (new_img[..., 2] < 60)
        assert abs(int(gold_old.sum()) - int(gold_new.sum())) <= max(2, gold_old.sum() // 20), pose
    assert np.mean(close_fractions) >= 0.97, close_fractions


def test_odd_columns_sharing_their_neighbours_hits_draw_nearly_the_marched_frame(canyon_renderer):
    """Column coherence (an odd column averages its two neighbours' terrain hits where they agree) must
    draw what marching every column draws: same navigable mask, same sky, colours within a few levels."""
    w = canyon_renderer.world
    marched = Renderer(w)
    marched.column_share_m = 0.0
    rng = np.random.default_rng(11)
    rows, cols = np.nonzero(w.nav_truth)
    for i in rng.integers(0, rows.size, 8):
        pose = (cols[i] + 0.5, rows[i] + 0.5, rng.uniform(0, 360), rng.normal(0, 2), rng.normal(0, 2))
        shared_img = canyon_renderer.render(pose)
        marched_img = marched.render(pose)
        diff = np.abs(shared_img.astype(int) - marched_img.astype(int)).max(axis=2)
        # 0.977-0.989 of pixels within 8 levels with the third sharing tier (0.988-0.996 with two; docs/twin-render.md
        # round 11): the shadowless look no longer darkens far walls by distance (sim/shading.py), so their texture
        # contrast, which sharing averages, is up to 1.8 times larger
        assert (diff <= 8).mean() >= 0.97, pose
        assert (_navigable(shared_img) == _navigable(marched_img)).mean() >= 0.998, pose
        same_sky = np.isfinite(canyon_renderer.last_depth) == np.isfinite(marched.last_depth)
        assert same_sky.mean() >= 0.999, pose


def test_rock_hits_are_shared_between_columns_only_where_both_neighbours_are_rock(canyon_renderer):
    """COLUMN_SHARE_ROCK: a column also averages its neighbours' rock hits (dark wall pixels); the pixels this adds
    are all rock-dark, the navigable mask and the sky stay as with terrain-only sharing."""
    w = canyon_renderer.world
    terrain_only = Renderer(w)
    terrain_only.share_rock = False
    rng = np.random.default_rng(12)
    rows, cols = np.nonzero(w.nav_truth)
    added = 0
    for i in rng.integers(0, rows.size, 6):
        pose = (cols[i] + 0.5, rows[i] + 0.5, rng.uniform(0, 360), rng.normal(0, 2), rng.normal(0, 2))
        img = canyon_renderer.render(pose)
        ref = terrain_only.render(pose)
        extra = canyon_renderer.last_shared.astype(bool) & ~terrain_only.last_shared.astype(bool)
        added += extra.sum()
        assert img[extra].max(initial=0) < 100, pose  # rock-dark (the floor is far brighter)
        assert (_navigable(img) == _navigable(ref)).mean() >= 0.999, pose
        assert (np.isfinite(canyon_renderer.last_depth) == np.isfinite(terrain_only.last_depth)).mean() >= 0.999
    assert added > 1000  # it does share rock (~1,300 pixels per real-world frame)


@pytest.mark.parametrize("tiers", [1, 2, 3, 4])
def test_column_plan_draws_every_column_once_after_the_neighbours_it_averages(tiers):
    from sim.render import column_plan

    order, offset = column_plan(IMAGE_W, tiers)
    assert sorted(order.tolist()) == list(range(IMAGE_W))
    done = set()
    for u in order.tolist():
        if offset[u]:
            assert {u - offset[u], u + offset[u]} <= done, u
        done.add(u)
    assert (offset == 0).sum() <= IMAGE_W // 2 ** tiers + tiers  # only the last column of each tier lacks a right neighbour


def test_far_tier_columns_share_only_far_hits(canyon_renderer):
    """Round 12's fourth tier (every 16th column marched): the columns between take their neighbours' average only
    where both hit at least COLUMN_SHARE_FAR_MIN_M away, so nothing near the rover (the 5 m mask) is averaged
    across 16 columns; the ordinary tiers still share near hits."""
    from sim.render import COLUMN_SHARE_FAR_MIN_M, COLUMN_SHARE_TIERS

    r = canyon_renderer
    far_cols = r._col_offset >= (1 << COLUMN_SHARE_TIERS)
    assert far_cols.sum() == IMAGE_W // 16 - 1  # columns 8 mod 16 (the last has no right neighbour)
    rng = np.random.default_rng(21)
    rows, cols = np.nonzero(r.world.nav_truth)
    far_shared = near_shared = 0
    for i in rng.integers(0, rows.size, 6):
        r.render((cols[i] + 0.5, rows[i] + 0.5, rng.uniform(0, 360), rng.normal(0, 2), rng.normal(0, 2)))
        shared = r.last_shared.astype(bool)
        assert (r.last_depth[:, far_cols][shared[:, far_cols]] >= COLUMN_SHARE_FAR_MIN_M).all()
        far_shared += shared[:, far_cols].sum()
        near_shared += (shared[:, ~far_cols] & (r.last_depth[:, ~far_cols] < 5.0)).sum()
    assert far_shared > 0 and near_shared > 0


def test_ray_table_in_float32_matches_float64():
    """The kernel's per-column ray table is computed in float32 (round 12): within ~1e-6 of the float64 values,
    with the same zero convention for level rays and axis-parallel directions."""
    from sim.render import CX, CY, FOCAL_PX, _ray_column

    rng = np.random.default_rng(3)
    ray_a = (np.arange(IMAGE_W) + 0.5 - CX) / FOCAL_PX
    ray_b = (CY - (np.arange(IMAGE_H) + 0.5)) / FOCAL_PX
    for yaw, pitch, roll in [(0.0, 0.0, 0.0), (90.0, 0.0, 0.0)] + [tuple(rng.uniform(-5, 5, 3) + (rng.uniform(0, 360), 0, 0))
                                                                  for _ in range(4)]:
        rot = body_rotation(yaw, pitch, roll)
        for u in (0, 77, 160, 319):
            table = np.empty((8, IMAGE_H), np.float32)
            _ray_column(rot, ray_a[u], ray_b, table)
            d = rot @ np.stack([np.full(IMAGE_H, ray_a[u]), ray_b, np.ones(IMAGE_H)])
            h = np.hypot(d[0], d[1])
            hx, hy, k = d[0] / h, d[1] / h, d[2] / h
            want = {0: hx, 1: hy, 2: k, 3: 1 / h, 6: np.sqrt(1 + k * k)}
            for c in (0, 1, 2, 3, 6):  # components near zero (k at the horizon) to within ~1e-7 absolute
                assert np.allclose(table[c], want[c], rtol=2e-6, atol=2e-7), (yaw, pitch, roll, u, c)
            for c, of in ((4, 0), (5, 1), (7, 2)):  # reciprocals of the float32 components, 0 for a zero one
                x = table[of].astype(np.float64)
                ok = np.abs(x) > 1e-12
                assert np.allclose(table[c][ok] * x[ok], 1.0, rtol=2e-6), (yaw, pitch, roll, u, c)
                assert (table[c][~ok] == 0).all()


# poses of the logged test_dataset frames 135, 143 and 151, looking at the overhang at (106-110, 100)
OVERHANG_VIEWS = [(103.8, 95.3, 73.0, 1.2, -0.4), (104.4, 96.6, 59.0, 0.0, -1.3), (105.4, 97.8, 44.0, 0.0, -1.2)]


def _overhang_hits(renderer):
    """Pixels of the last frame whose hit is a rock column with its mesh bottom off the ground."""
    b = renderer.baked
    overhang = np.zeros(b["has_rock"].shape, bool)
    overhang[b["overhang_rc"]] = True
    hit = renderer.last_hit
    ok = np.isfinite(hit[..., 0])
    idx = np.zeros(hit.shape[:2] + (2,), int)
    cell = float(renderer.world.rock_cell_m)
    idx[ok] = np.clip(np.rint(hit[ok][:, :2] / cell).astype(int), 0, overhang.shape[0] - 1)
    return ok & overhang[idx[..., 1], idx[..., 0]]


def test_overhang_underside_is_smooth_and_nothing_else_changes(world_dir):
    """Issue 28 item 4: the overhang's 0.1 m rock columns no longer show one colour each from top to
    bottom (vertical bands): the colour step between neighbouring pixels on it (sum of channels) falls
    by a third or more. Only pixels that hit rock whose mesh bottom is off the ground change (every such
    rock, not only this one), and no navigable mask."""
    r = Renderer(load_world("real"))
    start = (*r.world.start_xy, r.world.start_yaw_training, 0.0, 0.0)
    elsewhere = [start, (78.9, 75.6, 227.0, -0.3, 0.1)]  # wall rocks whose bottoms are off the slope are seen too
    r.share_rock = False  # sharing rock hits between columns tests their colours: that would couple other pixels in
    for pose in OVERHANG_VIEWS + elsewhere:
        r.smooth_underside = True
        smooth = r.render(pose)
        r.smooth_underside = False
        banded = r.render(pose)
        rock = _overhang_hits(r)
        changed = np.any(smooth != banded, axis=2)
        assert not (changed & ~rock).any(), pose
        assert np.array_equal(_navigable(smooth), _navigable(banded)), pose
        if pose in elsewhere:
            continue
        both = rock[:, 1:] & rock[:, :-1]  # horizontally adjacent pixels both on overhanging rock
        assert both.sum() > 500, pose

        def streak(img):
            return np.abs(np.diff(img.astype(int).sum(axis=2), axis=1))[both].mean()

        # measured 3.2 / 5.3, 2.0 / 3.1, 2.2 / 3.2 (what is left are the overhang's silhouette and depth edges)
        assert streak(smooth) < 0.75 * streak(banded), (pose, streak(smooth), streak(banded))


def test_colour_lane_spread_of_the_kernel_equals_the_shift_version():
    """The kernel spreads packed 0xBBGGRR colours into their blend lanes with BMI2 pdep where the CPU has it:
    every byte pattern must land exactly where the portable shifts put it (the frames are byte-identical)."""
    from numba import njit

    from sim import render as R

    @njit
    def both(values, out):
        for i in range(values.shape[0]):
            out[i, 0] = R._spread(values[i])
            out[i, 1] = R._spread_shifts(values[i])

    rng = np.random.default_rng(5)
    values = np.concatenate([rng.integers(0, 1 << 24, 20000), [0, 0xFF, 0xFF00, 0xFF0000, 0xFFFFFF]]).astype(np.uint32)
    out = np.zeros((values.size, 2), np.int64)
    both(values, out)
    assert np.array_equal(out[:, 0], out[:, 1])
    lanes = (out[:, 1] >> np.array([[0], [R.LANE_BITS], [2 * R.LANE_BITS]])) & 0xFF
    assert np.array_equal(lanes, [(values >> 0) & 0xFF, (values >> 8) & 0xFF, (values >> 16) & 0xFF])
