"""Look terms for the real drives (sim/shading.py): splat mipmaps on the far floor, the back-scatter lobe."""
import numpy as np
import pytest

from sim import shading
from sim.render import SUN_AZIMUTH_DEG, Renderer, _darkening_lut
from sim.world import with_shadows
from test_render import _flat_world

FLOAT32_EDGE_PIXELS_MAX = 1e-4  # share of a frame's pixels the float32 floor look may put more than one level off (5 px)


def test_near_floor_darkening_stops_at_the_knee_and_the_far_falloff_starts_later():
    d = np.array([0.0, 2.0, shading.SHADOWLESS_KNEE_M, shading.FAR_FALLOFF_START_M, 10.0, 200.0])
    f = shading.shadowless_darkening(d)
    assert f[0] == 1.0 and np.all(np.diff(f) <= 0)
    assert f[2] > 0.93 and f[3] == f[2]  # the near floor loses a few per cent (measured 0.95), then holds
    assert f[4] < f[3] and f[5] == pytest.approx(f[2] * (1.0 - shading.FAR_FALLOFF))  # then the far falloff
    lut = _darkening_lut(False)
    assert lut[-1] == pytest.approx(f[-1]) and lut[-1] > _darkening_lut(True)[-1]  # the far darkening is the mipmaps'


def test_splat_pyramid_levels_are_two_by_two_means():
    rng = np.random.default_rng(0)
    w = rng.uniform(0, 1, (64, 64)).astype(np.float32)
    pyr = shading.splat_pyramid(w)
    assert pyr.shape[0] >= int(np.ceil(shading.SPLAT_LOD_MAX)) + 1
    assert np.array_equal(pyr[0], w)
    assert np.allclose(pyr[1, :32, :32], w.reshape(32, 2, 32, 2).mean(axis=(1, 3)), atol=1e-6)
    assert pyr[3, :8, :8].mean() == pytest.approx(w.mean(), abs=1e-5)


def _walled_world():
    """Level sand with a strip of rock-layer texture (weight 0, no relief) along x >= 120 m."""
    world = _flat_world()
    sand = world.sand_weight.copy()
    sand[:, int(120 / world.sand_cell_m):] = 0.0
    from dataclasses import replace

    return replace(world, sand_weight=sand)


def test_far_floor_beside_rock_texture_darkens_but_open_floor_far_away_does_not():
    """The mipmapped splat weight: floor 1 m from the dark strip is drawn darker seen from 12 m than from
    2 m, while open floor far from any strip keeps its colour at the same distance."""
    world = with_shadows(_walled_world(), False)
    r = Renderer(world)
    r.backscatter = False

    def farthest_floor_before(x_from, x_max):
        """(hit x, colour) of the centre column's pixel that hits the floor nearest short of x_max."""
        img = r.render((x_from, 100.0, 0.0, 0.0, 0.0))
        xs = r.last_hit[:, 160, 0]
        rows = np.flatnonzero(np.isfinite(xs) & (xs < x_max))
        v = rows[np.argmax(xs[rows])]
        return float(xs[v]), img[v, 160].astype(float)

    def seen_from_close(x):
        img = r.render((x - 2.0, 100.0, 0.0, 0.0, 0.0))
        xs = np.nan_to_num(r.last_hit[:, 160, 0], nan=-1e9)
        return img[np.argmin(np.abs(xs - x)), 160].astype(float)

    # a rover position from which a centre pixel sees floor 0.5-2 m short of the strip, at least 9 m ahead
    x, far = next(hit for hit in (farthest_floor_before(x0, 119.9) for x0 in np.arange(103.0, 109.0, 0.25))
                  if hit[0] > 118.0)
    assert x < 119.9
    near = seen_from_close(x)
    assert far.min() < near.min() - 30  # the far view averages the dark strip in
    assert far[1] / far[0] < near[1] / near[0]  # and turns redder, as the rock layers are
    x, open_far = farthest_floor_before(30.0, 43.0)  # open floor, the strip 77 m away
    # nothing dark within reach: only the few per cent of near-floor darkening held from the knee on
    assert np.all(open_far >= 0.93 * seen_from_close(x))


def test_backscatter_brightens_the_floor_seen_away_from_the_sun_only():
    world = with_shadows(_flat_world(), True)
    r = Renderer(world)
    away = SUN_AZIMUTH_DEG + 180.0 + shading.BACKSCATTER_OFFSET_DEG
    rows = slice(110, 160)  # floor within about 2 m

    def floor(yaw, on):
        r.backscatter = on
        return r.render((100.0, 100.0, yaw % 360.0, 0.0, 0.0))[rows, 155:165].astype(float)

    lit = floor(away, False)
    expected = np.minimum(lit * (1.0 + shading.BACKSCATTER_GAIN), 255.0)  # bright sand saturates
    assert np.abs(floor(away, True) - expected).max() <= 3.0
    assert np.abs(floor(away + 90.0, True) - floor(away + 90.0, False)).max() <= 1.0
    gains = shading.backscatter_columns(r.camera((100.0, 100.0, away, 0.0, 0.0))[1], r.ray_a, SUN_AZIMUTH_DEG)
    assert gains[155:165].min() > 1.0 + 0.95 * shading.BACKSCATTER_GAIN  # the middle columns look straight away
    assert gains[0] < 1.01 and gains[-1] < 1.01  # 54 deg to either side: outside the lobe


def _poses_on_floor(world, count, seed):
    rng = np.random.default_rng(seed)
    rows, cols = np.nonzero(world.nav_truth)
    pick = rng.integers(0, rows.size, count)
    return [(cols[i] + 0.5, rows[i] + 0.5, rng.uniform(0, 360), rng.normal(0, 3), rng.normal(0, 3)) for i in pick]


def _fused_and_two_pass_frames_agree(renderer, poses):
    for backscatter in (True, False):
        renderer.backscatter = backscatter
        for pose in poses:
            renderer.fused_floor_look = True
            fused = renderer.render(pose)
            renderer.fused_floor_look = False
            two_pass = renderer.render(pose)
            # the fused pass finds hit points and distances in float32 (round 12, docs/twin-render.md; ~0.03 ms a
            # frame); the two passes in float64: measured 1e-5 of pixels one level apart. A pixel whose ray
            # grazes an edge may land on the other side in float32: one pixel 6 levels apart under numpy 2.4
            diff = np.abs(fused.astype(int) - two_pass)
            assert (diff.max(axis=2) > 1).mean() <= FLOAT32_EDGE_PIXELS_MAX, (pose, backscatter, diff.max())
            assert (diff > 0).mean() <= 1e-3, (pose, backscatter, (diff > 0).mean())
    renderer.fused_floor_look = True


@pytest.mark.parametrize("name", ["procedural:0", "walled"])
def test_fused_floor_look_draws_the_two_passes_within_a_level(name):
    """apply_floor_look (one staged pass) against apply_splat_mip then apply_backscatter (the oracle): within one
    level on at most 0.1 % of pixels (byte for byte before round 12's float32 stage), without cast shadows (both terms, and the mipmaps alone) and with them (the lobe alone)."""
    from sim.world import load_world

    world = _walled_world() if name == "walled" else load_world(name)
    poses = _poses_on_floor(world, 4, 3)
    if name == "walled":
        poses += [(110.0, 100.0, 0.0, 0.0, 0.0), (112.0, 90.0, 20.0, 2.0, -1.0)]  # facing the dark strip
    for shadows in (False, True):
        _fused_and_two_pass_frames_agree(Renderer(with_shadows(world, shadows)), poses)


def test_fused_floor_look_draws_the_two_passes_within_a_level_on_the_real_world(world_dir):
    """The same on the real world at the logged test_dataset poses (the benchmark's), rough poses added."""
    from sim.realism import read_test_dataset
    from sim.world import load_world

    world = load_world("real")
    frames = read_test_dataset()
    poses = [frames[i].pose for i in range(0, len(frames), 40)] + _poses_on_floor(world, 4, 5)
    _fused_and_two_pass_frames_agree(Renderer(world), poses)


@pytest.mark.parametrize("shadows", [False, True])
def test_floor_look_on_marched_pixels_then_filled_keeps_marched_pixels_and_nearly_the_shared_ones(shadows):
    """Renderer.share_floor_look: the floor look is drawn on the marched pixels only and each pixel the raymarch
    took from its two neighbouring columns is their average again. The marched pixels keep their bytes, the
    shared ones stay within a few levels of the look computed on them (the look changes slowly across columns),
    and the navigable mask is all but the same."""
    from sim.world import load_world

    world = with_shadows(load_world("procedural:0"), shadows)
    shared, every = Renderer(world), Renderer(world)
    every.share_floor_look = False
    filled = 0
    for pose in _poses_on_floor(world, 6, 21):
        a, b = shared.render(pose), every.render(pose)
        mask = shared.last_shared.astype(bool)
        assert np.array_equal(mask, every.last_shared.astype(bool))  # the raymarch itself is the same
        assert np.array_equal(a[~mask], b[~mask]), pose
        diff = np.abs(a.astype(int) - b.astype(int)).max(axis=2)[mask]
        filled += mask.sum()
        # (the few large ones: a shared pixel on a ridge whose averaged hit lies above the ground, where the look
        # computed on it leaves it alone). Within 2 levels: 0.947-1.0 of the filled pixels per pose since the third
        # sharing tier averages columns 8 apart (0.967-1.0 with two tiers; docs/twin-render.md round 11)
        assert (diff <= 2).mean() >= 0.93 and (diff <= 16).mean() >= 0.995, (pose, np.percentile(diff, [50, 99, 100]))
        nav_a, nav_b = np.all(a > 160, axis=2), np.all(b > 160, axis=2)
        assert (nav_a == nav_b).mean() >= 0.999, pose
    assert filled > 6 * 10_000  # the fill is exercised: most of the floor is shared


def test_cast_shadow_is_one_flat_step_reaching_the_fringe():
    """The real cast shadow is a flat step (0.85 of sunlit on dimaga, royalejandro, test_dataset) that covers
    floor the blurred raster gives only 0.1-0.3: the cover is 0 outside, 1 from there in, monotone between."""
    from sim.shading import CAST_SHADOW_COVER, cast_shadow_cover

    raster = np.linspace(0.0, 1.0, 101)
    cover = cast_shadow_cover(raster)
    assert cover[raster <= CAST_SHADOW_COVER[0]].max() == 0.0
    assert cover[raster >= CAST_SHADOW_COVER[1]].min() == 1.0
    assert np.all(np.diff(cover) >= 0)
    assert cast_shadow_cover(np.array([0.5]))[0] == 1.0  # the raster's half-shadow is full shadow


def test_floor_red_gain_reddens_wall_feet_and_shaded_floor_only():
    """Item 6: red x(1 + WALL_FOOT_RED_GAIN) at and below weight 0.70, none from 0.80; shaded floor redder per unit
    of darkening; open sunlit floor keeps the colour table's hue."""
    sand = np.array([0.3, shading.WALL_FOOT_RED_FULL_BELOW, 0.75, shading.WALL_FOOT_RED_NONE_FROM, 1.0])
    sun = shading.floor_red_gain(sand, np.zeros_like(sand))
    assert sun[0] == sun[1] == pytest.approx(1.0 + shading.WALL_FOOT_RED_GAIN)
    assert sun[1] > sun[2] > sun[3] == sun[4] == 1.0
    shade = shading.floor_red_gain(sand, np.full_like(sand, 0.18))
    assert np.all(shade > sun)
    assert shade[4] == pytest.approx(1.0 + 0.18 * shading.SHADOW_RED_PER_DARKENING)


@pytest.mark.parametrize("shadows", [False, True])
def test_floor_red_gain_leaves_the_starter_threshold_alone(shadows, monkeypatch):
    """The gains (items 6 and 8) raise red only, never sand's darkest channel: frames with and without it differ in red alone, and
    the starter's navigable mask (every channel > 160) is the same pixel for pixel."""
    from dataclasses import replace

    from sim.world import load_world

    world = with_shadows(load_world("procedural:0"), shadows)
    poses = _poses_on_floor(world, 5, 7)

    def frames():
        renderer = Renderer(replace(world))  # a fresh World object: baked anew
        renderer.column_share_m = 0.0  # every column marched (which columns are shared depends on colour)
        return [renderer.render(p) for p in poses]

    shipped = frames()
    monkeypatch.setattr(shading, "WALL_FOOT_RED_GAIN", 0.0)
    monkeypatch.setattr(shading, "SHADOW_RED_PER_DARKENING", 0.0)
    monkeypatch.setattr(shading, "WALL_FOOT_HUE_GRAIN", 0.0)  # item 8's grain is red only too
    plain = frames()
    redder = 0
    for a, b in zip(shipped, plain):
        assert np.array_equal(a[..., 1:], b[..., 1:])
        assert np.all(a[..., 0] >= b[..., 0])
        redder += int(np.count_nonzero(a[..., 0] > b[..., 0]))
        assert np.array_equal(np.all(a > 160, axis=2), np.all(b > 160, axis=2))
    assert redder > 1000  # the gain is exercised


def test_wall_foot_red_grain_spreads_wall_feet_toward_red_and_leaves_open_sand_alone():
    """Item 8: a fixed half-normal red grain per vertex, in full at and below weight 0.75, none from 0.85."""
    sand = np.repeat([[0.3], [shading.WALL_FOOT_GRAIN_FULL_BELOW], [0.8], [shading.WALL_FOOT_GRAIN_NONE_FROM], [1.0]],
                     4000, axis=1)
    grain = shading.wall_foot_red_grain(sand)
    assert grain.dtype == np.float32 and np.all(grain >= 1.0)
    assert np.all(grain[3:] == 1.0)  # open sand keeps the colour table's colour
    spread = (grain - 1.0).mean(axis=1)
    half_normal_mean = shading.WALL_FOOT_HUE_GRAIN * np.sqrt(2 / np.pi)
    assert spread[0] == pytest.approx(half_normal_mean, rel=0.05) and spread[1] == pytest.approx(half_normal_mean, rel=0.05)
    assert 0.0 < spread[2] < spread[1]  # fading out between the two weights
    assert np.array_equal(grain, shading.wall_foot_red_grain(sand))  # fixed, not random per bake


def test_shadowless_wall_foot_light_darkens_the_wall_foot_band_only():
    """Item 7: x(1 - SHADOWLESS_WALL_FOOT_DARKEN) at and below weight 0.775, none from 0.80 (open floor unchanged)."""
    sand = np.array([0.3, shading.SHADOWLESS_WALL_FOOT_FULL_BELOW, 0.79, shading.SHADOWLESS_WALL_FOOT_NONE_FROM, 1.0])
    light = shading.shadowless_wall_foot_light(sand)
    assert light[0] == light[1] == pytest.approx(1.0 - shading.SHADOWLESS_WALL_FOOT_DARKEN)
    assert light[1] < light[2] < light[3] == light[4] == 1.0


@pytest.mark.parametrize("shadows", [False, True])
def test_wall_foot_darkening_is_in_the_shadowless_look_only(shadows, monkeypatch):
    """Without cast shadows the baked terrain colour darkens at the wall feet and keeps the open floor; with cast
    shadows (the quality level the colour table was fitted at) it is the same byte for byte."""
    from dataclasses import replace

    from sim.world import load_world

    world = with_shadows(load_world("procedural:0"), shadows)
    shipped = Renderer(replace(world)).baked
    monkeypatch.setattr(shading, "SHADOWLESS_WALL_FOOT_DARKEN", 0.0)
    plain = Renderer(replace(world)).baked
    a, b = shipped["colour"].astype(int), plain["colour"].astype(int)
    if shadows:
        assert np.array_equal(a, b)
        return
    sand = shipped["sand"]
    foot = sand <= shading.SHADOWLESS_WALL_FOOT_FULL_BELOW
    open_floor = sand >= shading.SHADOWLESS_WALL_FOOT_NONE_FROM
    assert foot.sum() > 1000 and open_floor.sum() > 1000
    assert np.array_equal(a[open_floor], b[open_floor])
    bright = foot & (b.min(axis=-1) >= 100)  # bright enough that rounding cannot hide the darkening
    assert bright.sum() > 100
    assert np.all(a[bright] < b[bright])
