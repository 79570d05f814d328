import numpy as np

from evaluation.metrics import score_map


def test_score_map_counts_good_marked_and_truth_cells():
    truth = np.zeros((200, 200), np.uint8)
    truth[10:20, 10:20] = 255  # 100 truth cells
    world = np.zeros((200, 200, 3), np.uint8)
    world[10:15, 10:20, 2] = 255  # 50 good
    world[30:35, 30:40, 2] = 255  # 50 wrong
    s = score_map(world, truth)
    assert (s.good_cells, s.marked_cells, s.truth_cells) == (50, 100, 100)
    assert s.mapped_pct == 50.0 and s.fidelity_pct == 50.0


def test_score_map_without_truth_is_nan_and_locates_rocks():
    world = np.zeros((200, 200, 3), np.uint8)
    world[50, 60, 1] = 255
    s = score_map(world, None, samples_xy=[(61.9, 50.2), (100, 100)])
    assert np.isnan(s.mapped_pct) and np.isnan(s.fidelity_pct)
    assert s.located == 1
