"""replay.vote_sources: the kept votes rebuild the replay's own map, and leaving votes out is measured."""
import numpy as np

from evaluation.metrics import score_map
from replay.vote_sources import attribute, collect, error_image, rebuild


def test_votes_rebuild_the_replayed_map_and_attribute_every_class(test_dataset_dir, ground_truth):
    votes = collect(test_dataset_dir, ground_truth)
    # the attribution sees exactly the votes perception cast: same scored map, cell for cell
    assert np.array_equal(rebuild(votes)[:, :, 2], votes.worldmap[:, :, 2])
    report = attribute(votes, ground_truth)
    base = score_map(votes.worldmap, ground_truth)
    assert report["all"]["false_cells"] == base.marked_cells - base.good_cells
    ranges = report["factors"]["range"]
    assert abs(sum(r["votes_pct"] for r in ranges) - 100.0) < 0.5
    # leaving out the far band (half of all votes) changes the map: removal is really applied
    assert ranges[-1]["without_mapped_pct"] < report["all"]["mapped_pct"] - 1.0
    img = error_image(votes.worldmap, ground_truth, votes.features)
    assert img.shape[2] == 3 and (img[:, :, 2] == 255).any()  # some false navigable cells are drawn red


def test_near_confirmation_only_turns_down_cells_near_views_saw_without_sand(test_dataset_dir, ground_truth):
    from replay.vote_sources import _memory, _render, near_confirmation, near_veto

    votes = collect(test_dataset_dir, ground_truth)
    mem, near, near_sand = _memory(votes)
    base = _render(mem)
    assert np.array_equal(near_veto(base, near, near_sand, 0.0), base)  # a zero share turns nothing down
    strict = near_veto(base, near, near_sand, 1.01)  # every navigable cell with enough near votes goes
    gone = (base[:, :, 2] > 0) & (strict[:, :, 2] == 0)
    assert gone.sum() > 20 and (near[gone] >= 2.0).all() and not ((strict[:, :, 2] > 0) & (base[:, :, 2] == 0)).any()
    assert (near_sand <= near + 1e-3).all() and near.sum() < votes.votes[:, :2].sum()
    report = near_confirmation(votes, ground_truth)
    assert len(report["share_curve"]) > 10 and all("gain_at_equal_mapped" in c for c in report["checks"])
    # the curve varies what decides the scored map (the cell model's threshold), so it is not one flat point
    assert len({(m, f) for _, m, f in report["share_curve"]}) > 3


def test_wrong_cells_are_split_by_the_rule_that_marked_them_and_by_shadow():
    import perception as P
    from replay.vote_sources import wrong_cells_by_rule

    truth = np.zeros((200, 200), np.uint8)
    truth[50:60, 50:60] = 255  # a floor square
    mem = P.PerceptionMemory()
    mem.nav_votes[50:60, 50:60] = 90  # the square: sunlit floor ...
    mem.obs_votes[50:60, 50:60] = 10
    mem.obs_votes[50:60, 59] = 90  # ... but its east column is dark, half of it in shadow: missed
    mem.nav_votes[50:60, 59] = 0
    mem.shade_votes[50:55, 59] = 60
    mem.nav_votes[60, 50:60] = 80  # a sunlit fringe row north of it: false by the light share
    mem.obs_votes[60, 50:60] = 20
    mem.shade_votes[40, 40] = mem.obs_votes[40, 40] = 10  # a cell of shadowed sand only: false by the majority
    w = wrong_cells_by_rule(mem, truth)
    assert w["false"] == {"cells": 11, "light": 10, "shade": 1, "model": 0, "shadow_share_over_0.05": 1,
                          "shadow_share_over_0.2": 1}
    # the dark half of the east column is missed; its shadowed half (0.67 sand, floor beside it) the cell model maps
    assert w["missed"] == {"cells": 5, "seen": 5, "shadow_share_over_0.05": 0, "shadow_share_over_0.2": 0}
    assert (P.render_worldmap(mem)[50:55, 59, 2] == 255).all()
    score = score_map(P.render_worldmap(mem), truth)
    assert w["false"]["cells"] == score.marked_cells - score.good_cells
