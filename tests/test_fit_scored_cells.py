"""The scored map's cell model: its fit recovers a known model, and the tool runs on a real log."""
import re

import numpy as np
import pytest

import perception as P
from evaluation import fit_scored_cells as F


def test_logistic_fit_recovers_the_weights_that_drew_the_labels():
    rng = np.random.default_rng(3)
    X = rng.uniform(0, 1, (20000, 4)) * np.array([1, 1, 1, 8])
    true_w, true_b = np.array([3.0, 2.0, -1.5, 0.4]), -2.5
    y = (rng.random(len(X)) < 1 / (1 + np.exp(-(X @ true_w + true_b)))).astype(float)
    w, b = F.fit_logistic(X, y)
    assert np.allclose(w, true_w, atol=0.25) and b == pytest.approx(true_b, abs=0.3)


def test_memory_files_round_trip_and_a_foreign_file_is_refused(tmp_path):
    mem = P.PerceptionMemory()
    mem.nav_votes[10, 20], mem.band_votes[2, 10, 20] = 5.0, 7.0
    F.save_memory(mem, tmp_path / "a.npz")
    back = F.load_memory(tmp_path / "a.npz")
    assert back.nav_votes[10, 20] == 5.0 and back.band_votes[2, 10, 20] == 7.0
    np.savez(tmp_path / "b.npz", nav_votes=np.zeros((200, 200)))
    with pytest.raises(ValueError, match="obs_votes"):
        F.load_memory(tmp_path / "b.npz")
    older = {f: getattr(mem, f) for f in F.MEMORY_FIELDS if f != "near_sand_votes"}  # a file from before round 9
    np.savez(tmp_path / "c.npz", **older)
    with pytest.raises(ValueError, match="collect it again"):
        F.load_memory(tmp_path / "c.npz")


def test_the_model_map_is_the_scored_map(tmp_path):
    """The tool scores a drive with the same verdicts as perception's own scored map."""
    rng = np.random.default_rng(1)
    mem = P.PerceptionMemory()
    mem.nav_votes[...] = rng.uniform(0, 10, mem.nav_votes.shape) * (rng.random(mem.nav_votes.shape) < 0.7)
    mem.obs_votes[...] = rng.uniform(0, 10, mem.obs_votes.shape)
    mem.shade_votes[...] = mem.obs_votes * rng.random(mem.obs_votes.shape) * 0.5
    seen, X = F.cell_table(mem)
    weights, bias, min_p = F.shipped_weights()
    blue = F.model_map(seen, X, weights, bias, min_p)[:, :, 2]
    mismatch = np.count_nonzero(blue != P.render_worldmap(mem)[:, :, 2])
    assert mismatch <= 0.001 * seen.sum()  # float64 here, float32 there: a cell on the threshold may differ


def test_collect_and_fit_on_a_real_log(tmp_path, test_dataset_dir, ground_truth_path, capsys):
    assert F.main(["collect", "--log", f"td={test_dataset_dir}", "--out", str(tmp_path)]) == 0
    mem = F.load_memory(tmp_path / "td.npz")
    assert (mem.nav_votes > 0).sum() > 300
    assert F.main(["fit", str(tmp_path), "--fit", "td", "--truth", str(ground_truth_path)]) == 0
    out = capsys.readouterr().out
    assert "fitted on 1 drive (" in out and "| td | fitted |" in out
    shown, best = re.search(r"fitted model, p > ([0-9./ ]+) \(best on the fitted drives: ([0-9.]+)\)", out).groups()
    assert best in shown.split(" / ")  # the per-drive table brackets the threshold the fitted drives score best at
    rows = {float(r[0]): float(r[1]) for r in re.findall(r"^\| ([0-9.]+) \| ([0-9.]+) \|", out, re.M)}
    assert rows[float(best)] == min(rows.values())
    with pytest.raises(SystemExit, match="not in"):
        F.main(["fit", str(tmp_path), "--fit", "nope", "--truth", str(ground_truth_path)])
    assert F.main(["trade", str(tmp_path), "--truth", str(ground_truth_path)]) == 0
    out = capsys.readouterr().out
    assert f"| {P.SCORED_CELL_MIN_P:.3f}* |" in out  # the shipped line is marked
    seen_floor = float(re.search(r"^\| td \| ([0-9.]+) \|", out, re.M).group(1))
    assert 15 < seen_floor < 40  # the 282-frame drive sees about a quarter of the canyon


def _drive_with_known_truth():
    """(seen, X) of a random drive and a truth map on which its cells' light share tells floor from wall."""
    rng = np.random.default_rng(5)
    mem = P.PerceptionMemory()
    truth = np.zeros(mem.nav_votes.shape, bool)
    truth[50:150, 60:140] = True
    light = np.where(truth, rng.uniform(0.3, 1.0, truth.shape), rng.uniform(0.0, 0.5, truth.shape))
    votes = rng.uniform(5, 15, truth.shape) * (rng.random(truth.shape) < 0.8)
    mem.nav_votes[...], mem.obs_votes[...] = votes * light, votes * (1 - light)
    return F.cell_table(mem), truth


def test_the_trade_maps_more_and_less_truly_as_the_line_falls():
    drive, truth = _drive_with_known_truth()
    scores = F.trade_scores(drive, truth)
    mapped = [sc.mapped_pct for sc in scores]
    fidelity = [sc.fidelity_pct for sc in scores]
    assert mapped == sorted(mapped, reverse=True) and mapped[0] > mapped[-1]  # lines run from 0.05 upward
    assert fidelity[0] < fidelity[-1]
    ceiling = F.seen_truth_pct(drive[0], truth)
    assert 75 < ceiling < 85 and max(mapped) <= ceiling  # 80 % of cells seen; nothing unseen can be mapped
    report = F.trade_report({"synthetic": drive}, truth)
    row = re.search(r"^\| synthetic \| ([0-9.]+) \| ([0-9.na]+) \| ([0-9.na]+) \| ([0-9.na]+) \| ([0-9.na]+) \|$",
                    report, re.M).groups()
    assert float(row[0]) == pytest.approx(ceiling, abs=0.01)
    fine = F.trade_scores(drive, truth, F.TRADE_FINE_LINES)
    at_96 = max(sc.mapped_pct for sc in fine if sc.fidelity_pct >= 96)
    assert float(row[1]) == pytest.approx(at_96, abs=0.01) and at_96 >= max(m for m, f in zip(mapped, fidelity) if f >= 96)


def test_best_under_reads_only_lines_that_reach_the_floor():
    from evaluation.metrics import MapScore

    scores = [MapScore(98.5, 93.0, 0, 0, 0, 0), MapScore(96.0, 96.5, 0, 0, 0, 0), MapScore(94.0, 98.0, 0, 0, 0, 0)]
    assert F.best_under(scores, "fidelity_pct", 96.0, "mapped_pct") == 96.0
    assert F.best_under(scores, "mapped_pct", 95.0, "fidelity_pct") == 96.5
    assert np.isnan(F.best_under(scores, "mapped_pct", 99.0, "fidelity_pct"))


@pytest.mark.parametrize("argv", [["collect", "--log", "no-name-given", "--out", "X"],
                                  ["collect", "--log", "a/b=somewhere", "--out", "X"],
                                  ["collect", "--twin", "3:maybe:30:5", "--out", "X"],
                                  ["collect", "--twin", "3:off:0:5", "--out", "X"]])
def test_bad_drive_specs_are_refused_before_anything_runs(argv, tmp_path):
    argv = [str(tmp_path / "out") if a == "X" else a for a in argv]
    with pytest.raises(SystemExit) as exit_:
        F.main(argv)
    assert exit_.value.code == 2 and not (tmp_path / "out").exists()


def test_a_missing_log_truth_map_or_a_foreign_votes_file_is_a_clear_error(tmp_path, ground_truth_path):
    assert F.main(["collect", "--log", f"gone={tmp_path / 'nothing'}", "--out", str(tmp_path)]) == 2
    np.savez(tmp_path / "foreign.npz", something=np.zeros(3))
    with pytest.raises(SystemExit, match="cannot read ground-truth map"):
        F.main(["fit", str(tmp_path), "--fit", "foreign", "--truth", str(tmp_path / "t.png")])
    with pytest.raises(SystemExit, match="cannot read the map votes"):
        F.main(["fit", str(tmp_path), "--fit", "foreign", "--truth", str(ground_truth_path)])
