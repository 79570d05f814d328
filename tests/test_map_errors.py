"""evaluation.map_errors: which cells an evaluation's missions get wrong, and how often (no shared data needed)."""
import json

import numpy as np
import pytest

from evaluation import map_errors

N = 40  # side of the synthetic worlds, cells


def _truth():
    t = np.zeros((N, N), bool)
    t[10:30, 10:30] = True  # 400 truth cells
    return t


def _worldmap(nav, obstacle):
    wm = np.zeros((N, N, 3), np.uint8)
    wm[..., 2] = np.where(nav, 255, 0)
    wm[..., 0] = np.where(obstacle & ~nav, 255, 0)
    return wm


def _mission_map(extra_false=(), extra_missed=(), unseen=()):
    """Truth mapped except the listed cells; every mission also gets (9, 9) false and (10, 10) missed."""
    t = _truth()
    nav, obstacle = t.copy(), ~t
    for y, x in ((9, 9),) + tuple(extra_false):
        nav[y, x] = True
    for y, x in ((10, 10),) + tuple(extra_missed):
        nav[y, x], obstacle[y, x] = False, True
    for y, x in unseen:
        nav[y, x] = obstacle[y, x] = False
    return _worldmap(nav, obstacle)


def _write_run(folder, maps, world="real"):
    for seed, wm in enumerate(maps):
        d = folder / f"seed-{seed}"
        d.mkdir(parents=True)
        np.save(d / "worldmap.npy", wm)
        np.savez(d / "timeline.npz", truth=np.where(_truth(), 255, 0).astype(np.uint8))
        (d / "mission.json").write_text(json.dumps({"seed": seed, "world": world}))


def test_counts_split_false_from_missed_and_missed_into_obstacle_and_unseen():
    maps = [_mission_map(), _mission_map(extra_false=[(30, 15)], extra_missed=[(20, 20)], unseen=[(25, 25)])]
    false_nav, m_obs, m_unseen, rows = map_errors.count_errors(maps, _truth())
    assert false_nav[9, 9] == 2 and false_nav[30, 15] == 1 and false_nav.sum() == 3
    assert m_obs[10, 10] == 2 and m_obs[20, 20] == 1 and m_obs.sum() == 3
    assert m_unseen[25, 25] == 1 and m_unseen.sum() == 1
    assert rows == [{"false": 1, "missed_obstacle": 1, "missed_unseen": 0},
                    {"false": 2, "missed_obstacle": 2, "missed_unseen": 1}]


def test_systematic_cells_are_those_wrong_in_at_least_the_share_of_missions():
    counts = np.array([[0, 1, 2, 3]])
    assert map_errors.systematic(counts, 4, 0.5).tolist() == [[False, False, True, True]]
    assert map_errors.systematic(counts, 4, 0.25).tolist() == [[False, True, True, True]]


def test_remaining_scores_count_only_the_systematic_errors():
    truth = _truth()
    sys_missed = np.zeros_like(truth)
    sys_missed[10, 10:14] = True  # 4 of 400 truth cells
    sys_false = np.zeros_like(truth)
    sys_false[9, 9:13] = True  # 4 cells outside the truth
    mapped, fidelity = map_errors.remaining_scores(truth, sys_false, sys_missed)
    assert mapped == pytest.approx(100 * 396 / 400) and fidelity == pytest.approx(100 * 396 / 400)


def test_terrain_classes_sort_cells_by_what_their_centre_holds():
    mask = np.ones((1, 4), bool)
    floor = np.array([[False, True, True, True]])
    sand = np.array([[1.0, 0.5, 0.8, 0.74]])
    classes = map_errors.terrain_classes(mask, floor, sand, light_sand=0.735)
    assert list(classes.values()) == [1, 1, 2]


def test_a_matrix_folder_is_read_per_condition_and_summarised(tmp_path):
    run = tmp_path / "run"
    _write_run(run / "shadows-off", [_mission_map(), _mission_map(), _mission_map(extra_missed=[(15, 15)])])
    _write_run(run / "shadows-on", [_mission_map(extra_false=[(30, 20)])])
    conditions = map_errors.find_conditions(run)
    assert sorted(conditions) == ["shadows-off", "shadows-on"]
    ce = map_errors.load_condition("shadows-off", conditions["shadows-off"], None)
    assert ce.missions == 3 and [r["seed"] for r in ce.per_mission] == [0, 1, 2]
    s = map_errors.summary(ce, 0.5)
    assert (s["systematic_false"], s["systematic_missed"]) == (1, 1)  # (15, 15) was missed once in three
    assert s["missed_share_systematic"] == pytest.approx(3 / 4)
    assert s["missed_cells"] == [[10, 10, 3]]
    assert s["remaining_mapped_pct"] == pytest.approx(100 * 399 / 400)


def test_missions_on_different_worlds_are_refused(tmp_path):
    run = tmp_path / "run"
    _write_run(run, [_mission_map(), _mission_map()])
    other = np.zeros((N, N), np.uint8)
    other[5:8, 5:8] = 255
    np.savez(run / "seed-1" / "timeline.npz", truth=other)
    with pytest.raises(map_errors.MapErrorsError, match="different worlds"):
        map_errors.load_condition("run", run, None)


def test_the_picture_has_north_up_and_colours_false_red_and_missed_blue():
    maps = [_mission_map(extra_false=[(30, 20)], extra_missed=[(28, 20)])] * 2
    false_nav, m_obs, m_unseen, rows = map_errors.count_errors(maps, _truth())
    ce = map_errors.ConditionErrors("c", "real", 2, _truth(), false_nav, m_obs, m_unseen, rows)
    img = map_errors.error_image(ce, 0.5)
    s, margin = map_errors.IMAGE_SCALE, map_errors.CROP_MARGIN_CELLS
    y0, x0 = max(0, 9 - margin), max(0, 9 - margin)  # the crop's south-west corner (truth and false cells start at 9)
    y1 = min(N, 30 + 1 + margin)

    def pixel(y, x):  # a cell's corner pixel (the centre holds the systematic dot) in the flipped, cropped image
        return img[(y1 - 1 - y) * s, (x - x0) * s]

    assert pixel(30, 20).tolist() == [0, 0, 255]  # false in both missions: full red (BGR)
    assert pixel(28, 20).tolist() == [255, 0, 0]  # missed in both: full blue
    assert pixel(15, 15).tolist() == [map_errors.TRUTH_GREY] * 3
    assert pixel(30, 20).tolist() != pixel(y0, x0).tolist()


def test_main_writes_the_pictures_and_json_and_refuses_a_folder_without_missions(tmp_path, capsys):
    run = tmp_path / "run"
    _write_run(run, [_mission_map(), _mission_map(extra_false=[(30, 20)])], world="procedural:1")
    out = tmp_path / "out"
    assert map_errors.main([str(run), "--out", str(out)]) == 0
    assert (out / "map-errors-run.png").stat().st_size > 0
    summary = json.loads((out / "map-errors.json").read_text())["conditions"][0]
    assert summary["missions"] == 2 and summary["systematic_false"] == 2  # (9, 9) twice, (30, 20) once of two
    assert "systematic_false_terrain" not in summary  # terrain classes only on the real world
    assert "| run | 2 |" in capsys.readouterr().out
    (tmp_path / "empty").mkdir()
    assert map_errors.main([str(tmp_path / "empty"), "--out", str(out)]) == 2
    assert map_errors.main([str(run), "--min-share", "0", "--out", str(out)]) == 2
