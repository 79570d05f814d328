"""Coordinate transforms and the camera model (simulator geometry, tilt-aware)."""
import math

import numpy as np
import pytest

import perception as P


def test_rover_world_round_trip():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-10, 10, 50), rng.uniform(-10, 10, 50)
    for yaw in (0.0, 37.5, 90.0, 271.0):
        xw, yw = P.rover_to_world(x, y, 100.0, 80.0, yaw)
        xr, yr = P.world_to_rover(xw, yw, 100.0, 80.0, yaw)
        np.testing.assert_allclose(xr, x, atol=1e-9)
        np.testing.assert_allclose(yr, y, atol=1e-9)


def test_rover_to_world_directions():
    # yaw 90 = facing north: 1 m ahead is +y, 1 m to the left is -x
    xw, yw = P.rover_to_world(np.array([1.0, 0.0]), np.array([0.0, 1.0]), 50.0, 60.0, 90.0)
    np.testing.assert_allclose(xw, [50.0, 49.0], atol=1e-12)
    np.testing.assert_allclose(yw, [61.0, 60.0], atol=1e-12)


def test_polar_round_trip_and_sign():
    d, a = P.to_polar_coords(np.array([1.0, 0.0, 0.0]), np.array([0.0, 2.0, -3.0]))
    np.testing.assert_allclose(d, [1, 2, 3])
    np.testing.assert_allclose(a, [0, math.pi / 2, -math.pi / 2])  # left is positive
    x, y = P.from_polar_coords(d, a)
    np.testing.assert_allclose(x, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(y, [0, 2, -3], atol=1e-12)


def test_camera_constants_match_simulator():
    assert P.FOCAL_PX == pytest.approx(114.25, abs=0.01)
    assert (P.CX, P.CY) == (160.0, 80.0)
    assert P.CAMERA_HEIGHT_M == pytest.approx(0.2146, abs=1e-4)
    assert P.CAMERA_FORWARD_M == pytest.approx(0.4287, abs=1e-4)


def test_known_floor_point_projects_to_expected_pixel():
    # 2 m ahead of the rover origin = 1.5713 m ahead of the camera, 0.2146 m below it
    u, v, ahead = P.rover_to_pixel(2.0, 0.0)
    assert ahead
    assert u == pytest.approx(160.0, abs=1e-6)
    assert v == pytest.approx(80.0 + 114.2518 * 0.2146 / (2.0 - 0.4287), abs=0.01)
    # and back (pixel indices are continuous coordinates minus the 0.5 centre offset)
    x, y, ok = P.pixel_to_rover(np.array([u - 0.5]), np.array([v - 0.5]))
    assert ok[0] and x[0] == pytest.approx(2.0, abs=1e-9) and y[0] == pytest.approx(0.0, abs=1e-9)


def test_standard_calibration_grid_lands_where_the_fact_sheet_says():
    # the starter's 1 m grid square corners: 0.82-1.82 m ahead of the rover origin, +-0.5 m wide
    x, y, ok = P.pixel_to_rover(np.array([14, 301, 200, 118]), np.array([140, 140, 96, 96]))
    assert ok.all()
    np.testing.assert_allclose(x, [0.82, 0.82, 1.82, 1.82], atol=0.12)
    np.testing.assert_allclose(np.abs(y), 0.5, atol=0.05)
    assert y[0] > 0 > y[1]  # left of the image is left of the rover


@pytest.mark.parametrize("pitch,roll", [(0.0, 0.0), (2.0, 0.0), (-3.0, 1.5), (1.0, -4.0)])
def test_tilted_projection_round_trip_and_homography_agree(pitch, roll):
    rng = np.random.default_rng(1)
    u = rng.uniform(0, 319, 200)
    v = rng.uniform(100, 159, 200)
    x, y, ok = P.pixel_to_rover(u, v, pitch, roll)
    assert ok.all()
    u2, v2, ahead = P.rover_to_pixel(x, y, pitch, roll)
    assert ahead.all()
    np.testing.assert_allclose(u2 - 0.5, u, atol=1e-6)
    np.testing.assert_allclose(v2 - 0.5, v, atol=1e-6)
    # the warp homography maps grid cell (row i, col j) to the same pixel
    h = P.ground_homography(pitch, roll)
    i, j = 50, 130
    xc, yc = (i + 0.5) * P.GRID_RES_M, (j + 0.5) * P.GRID_RES_M - P.GRID_HALF_WIDTH_M
    p = h @ np.array([j, i, 1.0])
    uc, vc, _ = P.rover_to_pixel(xc, yc, pitch, roll)
    assert p[0] / p[2] == pytest.approx(uc - 0.5, abs=1e-6)
    assert p[1] / p[2] == pytest.approx(vc - 0.5, abs=1e-6)


def test_tilt_signs_follow_unity_convention():
    _, v0, _ = P.rover_to_pixel(3.0, 0.0)
    _, v_down, _ = P.rover_to_pixel(3.0, 0.0, pitch_deg=2.0)  # nose down: the floor rises in the image
    assert v_down < v0
    _, v_right0, _ = P.rover_to_pixel(3.0, -1.0)
    _, v_right, _ = P.rover_to_pixel(3.0, -1.0, roll_deg=2.0)  # right side up: right floor drops in the image
    assert v_right > v_right0


def test_pixels_above_horizon_never_hit_the_floor():
    x, y, ok = P.pixel_to_rover(np.array([0, 160, 319]), np.array([0, 40, 79]))
    assert not ok.any()
    assert np.isnan(x).all()


def test_fov_masks():
    m = P.ground_fov_mask(P.MAP_RANGE_M)
    assert m.shape == (160, 320) and m.dtype == bool
    assert not m[:80].any()  # sky side of a level camera
    assert m[-1].all()  # bottom row is floor ~0.75 m ahead
    assert P.ground_fov_mask(3.0).sum() < m.sum() < P.ground_fov_mask(12.0).sum()
    top = P.topdown_fov_mask()
    assert top.any()
    xs = P._GRID_X[top]
    assert xs.min() >= P.GRID_MIN_FORWARD_M
    # the view widens with distance (about +-54 deg horizontal FOV)
    angles = np.abs(P._GRID_ANGLE[top])
    assert math.radians(45) < angles.max() < math.radians(60)
