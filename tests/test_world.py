"""World loading: the real export, the procedural canyon and map-PNG worlds."""
import cv2
import numpy as np
import pytest

from sim.world import World, default_world, load_world


@pytest.fixture(scope="module")
def real_world(world_dir):
    return load_world("real")


def _check_shapes(w: World):
    assert w.terrain_height.shape == (513, 513) and w.terrain_height.dtype == np.float32
    assert w.sand_weight.shape == (512, 512) and w.sand_weight.dtype == np.float32
    assert w.rock_top.shape == (2001, 2001) and w.rock_bottom.shape == (2001, 2001)
    assert w.nav_truth.shape == (200, 200) and w.nav_truth.dtype == np.uint8
    assert set(np.unique(w.nav_truth)) <= {0, 255}
    assert w.sample_spots.ndim == 2 and w.sample_spots.shape[1] == 2
    assert 0.0 <= w.sand_weight.min() and w.sand_weight.max() <= 1.0


def test_real_world_numbers(real_world):
    w = real_world
    _check_shapes(w)
    assert int(np.count_nonzero(w.nav_truth)) == 1993
    assert len(w.sample_spots) == 33
    assert w.start_xy == pytest.approx((99.67, 85.589), abs=1e-3)
    assert w.start_yaw_training == pytest.approx(56.83, abs=0.01)
    assert w.height_at(*w.start_xy) == pytest.approx(0.0, abs=1e-3)
    assert w.is_floor(*w.start_xy)
    assert w.nav_truth[int(w.start_xy[1]), int(w.start_xy[0])] == 255
    assert 38.0 < float(w.terrain_height.max()) < 39.5
    rows, cols = np.nonzero(w.nav_truth)
    heights = w.height_at(cols + 0.5, rows + 0.5)
    assert heights.max() < 0.05 and heights.mean() < 0.001


def test_real_world_overhang(real_world):
    """The rover drives under the rock at ~(106, 102): floor free, rock slab above."""
    w = real_world
    x, y = 107.5, 101.0
    bottom, top = w.rock_span_at(x, y)
    assert 2.0 < bottom < top
    assert w.height_at(x, y) < 0.05
    assert not w.is_solid(x, y, 0.5)
    assert w.is_solid(x, y, (bottom + top) / 2)
    assert w.is_solid(x, y, -0.1)  # below the floor


def test_height_at_vectorised_and_clamped(real_world):
    w = real_world
    xs = np.array([-50.0, 0.0, 99.67, 250.0])
    ys = np.array([-50.0, 0.0, 85.589, 250.0])
    h = w.height_at(xs, ys)
    assert h.shape == (4,)
    assert h[0] == pytest.approx(w.height_at(0.0, 0.0))
    assert h[3] == pytest.approx(w.height_at(200.0, 200.0))


def test_default_world_is_real_when_present(world_dir):
    assert default_world().name == "real"


def test_default_world_without_shared(monkeypatch, tmp_path):
    monkeypatch.setenv("ROVER_SHARED", str(tmp_path / "nowhere"))
    w = default_world()
    assert w.name == "procedural:0"


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_procedural_world_valid_and_connected(seed):
    w = load_world(f"procedural:{seed}")
    _check_shapes(w)
    n_nav = int(np.count_nonzero(w.nav_truth))
    assert 1000 < n_nav < 12000
    n, _ = cv2.connectedComponents((w.nav_truth > 0).astype(np.uint8), connectivity=4)
    assert n == 2  # background + one floor component
    assert w.is_floor(*w.start_xy)
    assert w.height_at(*w.start_xy) == 0.0
    assert 25 <= len(w.sample_spots) <= 35
    # sample spots on (or right next to) the floor
    for x, y in w.sample_spots:
        assert w.height_at(x, y) < 0.05
    # walls exist and there are a few obstacle rocks standing on the floor
    assert w.terrain_height.max() > 5.0
    assert 1 <= len(w.obstacles) <= 8
    for rock in w.obstacles:
        assert w.is_solid(rock["x"], rock["y"], 0.3)


def test_procedural_world_deterministic_per_seed():
    a, b, c = load_world("procedural:3"), load_world("procedural:3"), load_world("procedural:4")
    assert np.array_equal(a.terrain_height, b.terrain_height)
    assert np.array_equal(a.rock_top, b.rock_top)
    assert np.array_equal(a.sample_spots, b.sample_spots)
    assert a.start_xy == b.start_xy
    assert not np.array_equal(a.nav_truth, c.nav_truth)


def test_map_png_world(tmp_path):
    img = np.zeros((100, 100), np.uint8)  # resized to 200x200 on load
    img[30:70, 20:80] = 255
    img[45:55, 80:95] = 255
    path = tmp_path / "map.png"
    cv2.imwrite(str(path), img)
    w = load_world(str(path))
    _check_shapes(w)
    assert int(np.count_nonzero(w.nav_truth)) == 40 * 60 * 4 + 10 * 15 * 4
    assert w.is_floor(*w.start_xy)
    assert w.height_at(100.0, 100.0) == 0.0  # inside the navigable block
    assert w.height_at(10.0, 10.0) > 5.0  # far from it: wall
    assert w.sand_weight[256, 256] > 0.9 and w.sand_weight[20, 20] < 0.3
    for x, y in w.sample_spots:
        assert w.nav_truth[int(y), int(x)] == 255


def test_bad_specs(tmp_path):
    with pytest.raises(ValueError):
        load_world("procedural:abc")
    with pytest.raises(ValueError):
        load_world("no-such-kind")
    with pytest.raises(ValueError):
        load_world(str(tmp_path / "missing.png"))


def test_surface_and_floor_queries_vectorised():
    w = load_world("procedural:2")
    rock = w.obstacles[0]
    xs = np.array([w.start_xy[0], rock["x"]])
    ys = np.array([w.start_xy[1], rock["y"]])
    floor = w.is_floor(xs, ys)
    assert floor.tolist() == [True, False]
    surface = w.surface_at(xs, ys)
    assert surface[0] == pytest.approx(0.0) and surface[1] > 0.3
    assert w.is_solid(xs, ys, np.array([0.1, 0.1])).tolist() == [False, True]


def test_compiled_height_lookup_equals_the_numpy_one_bit_for_bit(real_world):
    """The physics' terrain lookups take a compiled path; it must give exactly the NumPy values
    (also outside the world, on grid nodes, at the edges, for NaN and infinities)."""
    rng = np.random.default_rng(0)
    nodes = np.arange(0.0, 200.01, real_world.terrain_cell_m)
    x = np.concatenate([rng.uniform(-5, 205, 20000), nodes, [np.nan, 0.0, 200.0, 1e9, -1e9, np.inf]])
    y = np.concatenate([rng.uniform(-5, 205, 20000), nodes[::-1], [1.0, np.nan, 200.0, 3.0, np.inf, -np.inf]])
    with np.errstate(invalid="ignore"):  # the NumPy path casts NaN to an index (then clips it)
        ref = real_world._height_at_numpy(x, y)
    new = real_world.height_at(x, y)
    assert new.dtype == ref.dtype and np.array_equal(new, ref, equal_nan=True)
    assert np.ptp(ref[np.isfinite(ref)]) > 1.0  # real relief, not a flat corner
    assert real_world.height_at(x[:4].reshape(2, 2), y[:4].reshape(2, 2)).shape == (2, 2)
    scalar = real_world.height_at(99.7, 85.6)
    assert isinstance(scalar, float) and scalar == real_world._height_at_numpy(99.7, 85.6)
