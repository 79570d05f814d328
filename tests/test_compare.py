"""evaluation.compare: two sim.evaluate runs paired mission by mission (no shared data needed)."""
import json

import pytest

from evaluation import compare


def _mission(seed, mapped, fidelity=96.0, time_s=500.0, home=True, collected=6):
    return dict(seed=seed, mapped_pct=mapped, fidelity_pct=fidelity, time_s=time_s, returned_home=home,
                collected=collected, samples=6)


def _write(folder, missions):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / compare.EVALUATION_FILE).write_text(json.dumps({"meta": {}, "summary": {}, "missions": missions}))


def test_a_matrix_pairs_by_condition_and_seed_and_counts_the_split(tmp_path):
    base, cand = tmp_path / "base", tmp_path / "cand"
    _write(base / "shadows-off", [_mission(s, 97.0) for s in range(12)])
    _write(cand / "shadows-off", [_mission(s, 97.5 if s < 10 else 97.0) for s in range(11)])  # seed 11 only in base
    _write(base / "shadows-on", [_mission(0, 96.0)])  # no such condition in cand: left out
    pairs = compare.pair_runs(compare.load_run(base), compare.load_run(cand))
    assert [p.condition for p in pairs] == ["shadows-off"] and pairs[0].seeds == list(range(11))
    r = compare.compare(pairs[0])
    mapped = r["figures"]["mapped_pct"]
    assert r["missions"] == 11 and r["changed"] == 10
    assert (mapped["better"], mapped["worse"]) == (10, 0)
    assert mapped["cand_median"] == 97.5 and mapped["base_worst"] == 97.0
    assert mapped["p"] == pytest.approx(2 / 2 ** 10)
    assert r["figures"]["time_s"]["better"] == 0 and r["figures"]["time_s"]["p"] == 1.0


def test_time_is_better_when_lower_and_lost_missions_are_named(tmp_path):
    base, cand = tmp_path / "base", tmp_path / "cand"
    _write(base, [_mission(0, 97.0, time_s=600.0), _mission(1, 97.0, time_s=500.0)])
    _write(cand, [_mission(0, 97.0, time_s=550.0), _mission(1, 97.0, time_s=870.0, home=False, collected=5)])
    r = compare.compare(compare.pair_runs(compare.load_run(base), compare.load_run(cand))[0])
    t = r["figures"]["time_s"]
    assert (t["better"], t["worse"]) == (1, 1) and t["base_worst"] == 600.0 and t["cand_worst"] == 870.0
    assert (r["base_home"], r["cand_home"], r["lost"], r["gained"]) == (2, 1, [1], [])
    text = compare.markdown([r], "base", "cand")
    assert "lost 1" in text and "| time s | 550.0 -> 710.0 |" in text


def test_the_sign_test_is_exact_and_symmetric():
    assert compare.sign_test_p(0, 0) == 1.0
    assert compare.sign_test_p(3, 3) == 1.0
    assert compare.sign_test_p(5, 0) == pytest.approx(2 / 32)
    assert compare.sign_test_p(21, 33) == pytest.approx(compare.sign_test_p(33, 21))
    assert 0.13 < compare.sign_test_p(21, 33) < 0.14


def test_bad_folders_give_a_clear_error_and_exit_code(tmp_path, capsys):
    with pytest.raises(compare.CompareError, match="no such folder"):
        compare.load_run(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(compare.CompareError, match="no evaluation.json"):
        compare.load_run(tmp_path / "empty")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / compare.EVALUATION_FILE).write_text("{not json")
    with pytest.raises(compare.CompareError, match="not a sim.evaluate summary"):
        compare.load_run(tmp_path / "bad")
    _write(tmp_path / "a", [_mission(0, 97.0)])
    _write(tmp_path / "b", [_mission(1, 97.0)])
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "b")]) == 2  # no seed in common


def test_the_command_writes_the_table(tmp_path, capsys):
    _write(tmp_path / "a", [_mission(0, 97.0), _mission(1, 96.0)])
    _write(tmp_path / "b", [_mission(0, 97.2), _mission(1, 96.0)])
    out = tmp_path / "cmp.md"
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(out)]) == 0
    text = out.read_text()
    assert text == capsys.readouterr().out
    assert "| (one run) | 2 (1) | 2 -> 2 | mapped % | 96.50 -> 96.60 |" in text
