"""The canyon's sample spots: used only on the canyon, ruled out by looks and collections, reached from floor."""
import math

import numpy as np
import pytest

import decision
from navigation import grid, sample_spots as S, search_plan
from rover_state import RoverState


def test_the_spots_are_the_canyons_only_when_the_mission_starts_at_its_start():
    assert len(S.spots_for_start(S.CANYON_START_XY)) == 33
    assert len(S.spots_for_start((S.CANYON_START_XY[0] + 0.6, S.CANYON_START_XY[1] - 0.6))) == 33
    assert len(S.spots_for_start((100.0, 100.0))) == 0  # a procedural world starts elsewhere
    assert len(S.spots_for_start((float("nan"), 85.0))) == 0
    assert len(S.spots_for_start(None)) == 0 and len(S.spots_for_start(("x", 1))) == 0
    assert len(S.spots_for_start(S.CANYON_START_XY, enabled=False)) == 0


def test_the_spots_lie_in_the_canyon_around_its_start():
    spots = S.CANYON_SPOTS
    assert spots.shape == (33, 2) and len({tuple(p) for p in spots}) == 33
    assert (spots > 0).all() and (spots < grid.GRID_SIZE).all()
    far = np.hypot(spots[:, 0] - S.CANYON_START_XY[0], spots[:, 1] - S.CANYON_START_XY[1])
    assert far.min() > 5 and far.max() < 120  # none on the start, all within the canyon's arms


def _views(n_spots, tabled):
    """SpotViews of n_spots with no view but ``tabled`` {(spot, bearing index, range index): px}."""
    px = np.zeros((n_spots, 36, 11), np.int16)
    for (k, i, j), v in tabled.items():
        px[k, i, j] = v
    return S.SpotViews(10, np.arange(2.0, 7.01, 0.5), px)


def test_a_spot_counts_as_seen_only_when_faced_from_where_it_shows_well():
    spots = np.array([(50.0, 50.0), (80.0, 80.0)])
    assert S.in_view(spots, (47.0, 50.0), 0.0).tolist() == [True, False]  # no table: 3 m west, facing it
    assert not S.in_view(spots, (47.0, 50.0), 180.0).any()  # facing away
    assert not S.in_view(spots, (44.0, 50.0), 0.0).any()  # 6 m: too small to show
    views = _views(2, {(0, 18, 2): 20, (0, 18, 4): 5, (0, 27, 2): 20})  # from the west at 3 m (20 px) and 4 m (5 px), from the south at 3 m
    assert S.in_view(spots, (47.0, 50.0), 0.0, views)[0]
    assert not S.in_view(spots, (46.0, 50.0), 0.0, views)[0]  # 4 m: 5 px, under SPOT_SEEN_MIN_PX
    assert not S.in_view(spots, (50.0, 47.0), 0.0, views)[0]  # south, but facing east
    assert S.in_view(spots, (50.0, 47.0), 90.0, views)[0]
    assert not S.in_view(spots, (53.0, 50.0), 180.0, views)[0]  # east: a rock hides it there
    assert not S.in_view(spots, (float("nan"), 50.0), 0.0, views).any()
    assert S.taken_spots(spots, [(51.0, 51.0)]).tolist() == [True, False]


def test_an_open_spot_is_glimpsed_farther_but_only_from_a_bearing_it_shows_from():
    spots = np.array([(50.0, 50.0), (60.0, 50.0)])
    open_west = {(0, i, 2): 20 for i in range(9, 27)}  # spot 0 shows well from 90-260 deg: an open spot
    views = _views(2, {**open_west, (1, 18, 2): 20})  # spot 1 only from due west: a hidden spot
    assert views.open_spots().tolist() == [True, False]
    assert S.glimpse_candidates(spots, (45.0, 50.0), views).tolist() == [True, False]  # 5 m: may be glimpsed, not seen
    assert not S.in_view(spots, (45.0, 50.0), 0.0, views)[0]
    assert not S.glimpse_candidates(spots, (50.0, 45.0), views)[0]  # from the south it never shows
    assert not S.glimpse_candidates(spots, (42.0, 50.0), views)[0]  # 8 m: beyond any glimpse
    assert not S.glimpse_candidates(spots, (55.0, 50.0), views)[1]  # the hidden spot, from its one bearing: only a close look counts


def test_the_view_table_loads_only_for_the_spots_it_was_written_for(tmp_path, caplog):
    views = S.load_views()
    assert views is not None and views.px.shape == (33, 36, 11)  # the table the client ships
    assert (views.px >= S.SPOT_SEEN_MIN_PX).any(axis=(1, 2)).all()  # every spot shows well from somewhere
    assert S.load_views(tmp_path / "missing.json") is None
    (tmp_path / "bad.json").write_text("{not json")
    assert S.load_views(tmp_path / "bad.json") is None
    assert S.load_views(S.VIEWS_PATH, spots=S.CANYON_SPOTS + 1.0) is None
    assert "checked by range and heading alone" in caplog.text


def test_the_east_nook_shows_from_few_bearings_and_an_open_spot_from_many():
    views = S.load_views()
    shows = (views.px >= S.SPOT_SEEN_MIN_PX).any(axis=2).sum(axis=1)
    nook = int(np.argmin(np.hypot(*(S.CANYON_SPOTS - (148.78, 109.56)).T)))
    west_tip = int(np.argmin(np.hypot(*(S.CANYON_SPOTS - (21.72, 102.18)).T)))
    assert shows[nook] <= 8 and shows[west_tip] >= 12


def _corridor():
    """A floor corridor y 50-52 from x 40 to 70, every cell reachable (dist = path length from x 40)."""
    free = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE), bool)
    free[50:53, 40:71] = True
    dist = np.where(free, np.arange(grid.GRID_SIZE)[None, :] - 40.0, np.inf)
    return free, dist


def test_without_a_view_table_a_spots_stand_is_the_nearest_reachable_floor():
    free, dist = _corridor()
    spots = np.array([(60.5, 54.5), (55.5, 51.5), (60.5, 61.5), (90.5, 51.5)])
    stands = S.spot_stands(spots, free, dist)
    assert tuple(stands[0]) == (52, 60, 1)  # beside the wall foot 2 m north of the corridor
    assert tuple(stands[1]) == (51, 55, 1)  # on floor: the spot's own cell
    assert stands[2, 2] == 0  # 9 m from any floor
    assert stands[3, 2] == 0  # 20 m past the corridor's end
    dist[52, 60] = np.inf  # that cell cannot be reached: the next nearest can
    assert tuple(S.spot_stands(spots[:1], free, dist)[0]) in {(52, 59, 1), (52, 61, 1)}
    assert S.spot_stands(spots, free, dist, only=[False, True, False, False])[:, 2].tolist() == [0, 1, 0, 0]


def test_with_a_view_table_the_stand_is_where_the_spot_shows_best():
    free, dist = _corridor()
    spots = np.array([(60.5, 54.5)])
    south = {(0, 27, j): 10 for j in range(11)}  # from due south (270 deg), 2-7 m: the corridor lies 2-4 m south
    views = _views(1, {**south, (0, 27, 1): 30, (0, 9, 2): 30})  # best from 2.5 m south; north: no floor there
    row, col, ok = S.spot_stands(spots, free, dist, views)[0]
    assert ok and (row, col) == (52, 60)  # the 2.5 m place, though 3-4 m ones are cheaper to reach
    views = _views(1, south)
    row, col, ok = S.spot_stands(spots, free, dist, views)[0]
    assert ok and col == 60 and row in (50, 51, 52) and 54.5 - row >= S.SPOT_STAND_MIN_M  # the 2.5 m place lies in row 52
    row, col, ok = S.spot_stands(spots, free, dist, _views(1, {(0, 9, 2): 30}))[0]  # shows only from where no floor is mapped
    assert ok and (row, col) == (52, 60)  # the nearest mapped floor, as without a table


def test_the_rover_turns_to_face_a_spot_unless_it_already_does():
    assert S.face_heading((10.0, 0.0), (0.0, 0.0), 0.0) is None
    assert S.face_heading((0.0, 10.0), (0.0, 0.0), 0.0) == pytest.approx(90.0)
    assert S.face_heading((-5.0, 0.0), (0.0, 0.0), 170.0) is None  # 10 deg off: within the tolerance
    assert S.face_heading((0.2, 0.1), (0.0, 0.0), 0.0) is None  # standing on it


def _searching_rover(pos, home):
    """A rover whose map is complete with one sample missing, on a corridor of floor around ``pos``."""
    r = RoverState()
    r.pos, r.yaw, r.total_time, r.vel = pos, 0.0, 600.0, 0.0
    r.samples_remaining = 1
    wm = np.zeros((grid.GRID_SIZE, grid.GRID_SIZE, 3), np.uint8)
    wm[:, :, 0] = 255
    wm[int(pos[1]) - 1:int(pos[1]) + 2, int(pos[0]) - 2:int(pos[0]) + 25] = (0, 0, 255)
    r.worldmap = wm
    r.nav = decision.NavMemory()
    r.nav.home, r.nav.explored = home, True
    return r


def test_on_the_canyon_the_search_drives_to_an_unchecked_spot_first(monkeypatch):
    spot = (20.0, 101.0)  # the west tip's spot (21.72, 102.18) region; the rover stands 12 m east of it
    monkeypatch.setattr(S, "CANYON_SPOTS", np.array([spot, (150.0, 150.0)]))
    r = _searching_rover((8.5, 101.5), S.CANYON_START_XY)
    search_plan.plan_search(r, r.nav, decision._read_inputs(r))
    assert r.nav.path_goal is not None and r.nav.path_goal[0] == "spot"
    row, col = r.nav.path_goal[1]
    assert math.hypot(col + 0.5 - spot[0], row + 0.5 - spot[1]) < 1.0 and r.nav.spot_goal == 0
    elsewhere = _searching_rover((8.5, 101.5), (100.0, 100.0))  # a procedural world: no spots
    search_plan.plan_search(elsewhere, elsewhere.nav, decision._read_inputs(elsewhere))
    assert len(elsewhere.nav.spots) == 0 and elsewhere.nav.path_goal[0] != "spot"


def test_a_reached_spot_is_faced_held_then_checked(monkeypatch):
    monkeypatch.setattr(S, "CANYON_SPOTS", np.array([(12.5, 105.5)]))  # 2 m north of the stand, the floor's edge cell (row 103)
    r = _searching_rover((12.5, 102.6), S.CANYON_START_XY)
    search_plan.plan_search(r, r.nav, decision._read_inputs(r))
    assert r.nav.path_goal[0] == "spot"
    decision.mode_search(r, r.nav, decision._read_inputs(r))
    assert r.nav.rotate_heading == pytest.approx(90.0, abs=15.0)  # the turn to face it
    r.nav.rotate_heading, r.yaw = None, 90.0  # the turn is done
    decision.mode_search(r, r.nav, decision._read_inputs(r))
    assert not r.nav.spot_done[0]  # holding still: the camera gets its frames
    r.total_time += S.SPOT_HOLD_S + 0.1
    decision.mode_search(r, r.nav, decision._read_inputs(r))
    assert r.nav.spot_done[0] and r.nav.spot_goal is None


def test_a_spot_along_a_clear_line_of_sight_is_seen_one_behind_a_wall_is_not(monkeypatch):
    monkeypatch.setattr(S, "CANYON_SPOTS", np.array([(15.5, 101.5), (15.5, 104.5)]))  # 5 m ahead on floor; 3 m into the wall
    r = _searching_rover((10.5, 101.5), S.CANYON_START_XY)
    rng = np.random.default_rng(0)
    r.nav_angles, r.nav_dists = rng.uniform(-0.6, 0.6, 2000), rng.uniform(1.0, 8.0, 2000)  # the frame shows floor ahead
    decision._check_spots(r, r.nav, decision._read_inputs(r))
    assert r.nav.spot_done.tolist() == [True, False]
