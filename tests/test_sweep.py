"""sim.sweep: value parsing, and constants reaching the mission (tables rebuilt) with outputs written."""
import json

import numpy as np
import pytest

from sim.sweep import parse_spec, split_values, sweep


def test_values_split_on_top_level_commas_and_parse_as_literals():
    assert split_values("1,2.5,(3,4),'a,b'") == ["1", "2.5", "(3,4)", "'a,b'"]
    name, values, current = parse_spec("perception.NAV_MAJORITY=0.15, 0.2,1")
    assert name == "perception.NAV_MAJORITY" and values == [0.15, 0.2, 1] and current == 0.2
    for bad in ("perception.NAV_MAJORITY", "perception.NAV_MAJORITY=", "perception.NAV_MAJORITY=0.1,,0.2",
                "perception.NAV_MAJORITY=abc", "perception.NAV_MAJORITY=(1,2", "perception.NOPE=1"):
        with pytest.raises(ValueError):
            parse_spec(bad)


def test_sweep_sets_the_constant_inside_the_mission_and_writes_table_and_plot(tmp_path):
    import perception

    before = perception.MAP_RANGE_M
    res = sweep(["perception.MAP_RANGE_M=2.0,9.0"], seeds=[0], world="procedural:0", time_limit=3.0, jobs=1,
                out=tmp_path, progress=False)
    assert perception.MAP_RANGE_M == before  # restored after the missions
    short, normal = (g[0] for g in res["missions"])
    assert short["mapped_pct"] < 0.6 * normal["mapped_pct"]  # a 2 m map range maps far less: the tables were rebuilt
    assert "9.0 (current)" in res["markdown"]
    for name in ("sweep.md", "sweep.csv", "sweep.json", "sweep.png"):
        assert (tmp_path / name).stat().st_size > 0
    rows = json.loads((tmp_path / "sweep.json").read_text())["rows"]
    assert [r["values"]["perception.MAP_RANGE_M"] for r in rows] == ["2.0", "9.0"]
    assert np.isclose(rows[1]["mapped_median"], normal["mapped_pct"])
