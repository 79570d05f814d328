"""sim/backend.py: missions on a Dask cluster give the local results; module constants are scoped."""
import numpy as np
import pytest

from sim.backend import (MissionTask, comparable, constants_set, evaluate_tasks, resolve_constant, run_task,
                         timing_fields)

WORLD = "procedural:0"  # needs no ../shared
TIME_LIMIT_S = 4.0  # simulated seconds per mission: enough to move, cheap in CI


def test_local_cluster_evaluation_equals_the_local_one(tmp_path):
    distributed = pytest.importorskip("distributed")
    from sim.evaluate import evaluate

    seeds = [0, 1]
    local = evaluate(seeds, WORLD, jobs=1, time_limit=TIME_LIMIT_S, out=tmp_path / "local", progress=False,
                     shadows=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        remote = evaluate_tasks(seeds, WORLD, time_limit=TIME_LIMIT_S, out=tmp_path / "dask", progress=False,
                                shadows=False, scheduler=cluster.scheduler_address)
    assert [r["seed"] for r in remote["missions"]] == seeds
    assert all(r["distance_m"] > 0 for r in remote["missions"])  # they drove
    assert [comparable(r) for r in remote["missions"]] == [comparable(r) for r in local["missions"]]
    for s in seeds:  # files shipped back from the worker land where a local run puts them
        np.testing.assert_array_equal(np.load(tmp_path / "dask" / f"seed-{s}" / "worldmap.npy"),
                                      np.load(tmp_path / "local" / f"seed-{s}" / "worldmap.npy"))
        assert (tmp_path / "dask" / f"seed-{s}" / "mission.png").stat().st_size > 0
    assert (tmp_path / "dask" / "evaluation.md").read_text().count("\n| ") >= 2
    assert remote["meta"]["backend"] == cluster.scheduler_address


def test_constants_are_set_for_the_mission_and_restored_with_tables_rebuilt():
    import perception

    before = perception.NAV_MAJORITY
    with constants_set([("perception.NAV_MAJORITY", 0.45)]):
        assert perception.NAV_MAJORITY == 0.45
    assert perception.NAV_MAJORITY == before
    for bad in ("NAV_MAJORITY", "perception.nav_majority", "perception.NO_SUCH", "no_such_module.X"):
        with pytest.raises(ValueError):
            resolve_constant(bad)


def test_a_failing_mission_comes_back_as_an_error_row():
    answer = run_task(MissionTask(seed=0, world="no-such-world.png", time_limit=1.0))
    assert answer["result"]["seed"] == 0 and answer["result"]["end_reason"].startswith("error:")
    assert answer["files"] == {}


def test_the_timing_model_travels_with_the_task():
    from sim.timing import Timing

    lock = run_task(MissionTask(seed=0, world=WORLD, time_limit=1.0, keep_files=False,
                                timing=timing_fields(Timing("lockstep"))))["result"]
    unity = run_task(MissionTask(seed=0, world=WORLD, time_limit=1.0, keep_files=False,
                                 timing=timing_fields(Timing("unity", fps=20.0))))["result"]
    assert lock["timing"] == "lockstep" and unity["timing"] == "unity" and unity["fps"] == 20.0
    assert lock["frames"] != unity["frames"]  # 0.04 s lockstep frames vs 0.05 s render frames
