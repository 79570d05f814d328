"""Where missions run: worker processes on this machine, or a Dask cluster.

One `MissionTask` is one mission, described by plain values (seed, world spec,
module constants to set, ...), so it can be shipped to any worker that has the
same checkout.  `run_task` runs it inside the worker and returns the result dict
plus the mission's files as bytes; the caller writes them under its own output
folder, so a remote worker's disk never matters.  `run_tasks` runs a list on a
backend: `scheduler=None` -> a spawn process pool of `jobs` workers, otherwise
a `dask.distributed` scheduler address (`tcp://HOST:8786`).

Module constants (`("perception.NAV_MAJORITY", 0.25)`) are set inside the worker
right before the client is built and restored afterwards; a module that derives
tables from its constants (`perception._build_tables`) has them rebuilt.  Missions
in one worker process run one at a time (a process-wide lock), because module
constants are process-wide: start Dask workers with `--nthreads 1`.
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib
import logging
import os
import shutil
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)

PROJECT_DIR = Path(__file__).resolve().parent.parent
CODE_DIRS = (".", "sim", "navigation", "evaluation", "replay")  # folders whose *.py make up the code fingerprint
VOLATILE_KEYS = ("wall_s", "frames_per_s", "files")  # result fields that differ between identical runs
MISSION_FILES = {"mission.png": "png", "worldmap.npy": "worldmap", "client.log": "client_log"}  # shipped back: file -> result["files"] key
TABLE_HOOK = "_build_tables"  # a module function rebuilt after its constants change

_WORLDS: dict = {}  # (spec, shadows) -> World, per worker process
_MISSION_LOCK = threading.Lock()  # one mission per process at a time (module constants are global)
_FINGERPRINT = None


@dataclass(frozen=True)
class MissionTask:
    """Everything a worker needs to run one mission (plain values only: it is pickled)."""

    seed: int
    world: str = "default"
    shadows: bool = False
    time_limit: float = 900.0
    home_by: float | None = None
    client: str | None = None  # a third-party drive_rover.py (its own process, on the wire); None = ours in-process
    constants: tuple = ()  # (("module.NAME", value), ...) set before the client is built
    timing: dict | None = None  # sim.timing.Timing fields (model, fps, latency_ms, compute_ms); None = Timing()
    keep_files: bool = True  # ship mission.png / worldmap.npy back
    fingerprint: str | None = None  # the caller's code fingerprint; a worker with other code says so
    extra: dict = field(default_factory=dict)  # labels the caller wants back (e.g. the sweep combination)

    def as_dict(self):
        return asdict(self)


# ----------------------------------------------------------------------------- worker side
def code_fingerprint() -> str:
    """Short hash of the project's Python sources: workers must run the caller's code."""
    global _FINGERPRINT
    if _FINGERPRINT is None:
        h = hashlib.sha1()
        for d in CODE_DIRS:
            for path in sorted((PROJECT_DIR / d).glob("*.py")):
                h.update(path.name.encode())
                h.update(path.read_bytes())
        _FINGERPRINT = h.hexdigest()[:12]
    return _FINGERPRINT


def cached_world(spec: str, shadows: bool):
    """The world `spec` with cast shadows on or off, loaded once per process (workers run many tasks on it)."""
    from sim.world import load_world, with_shadows

    key = (spec, bool(shadows))
    if key not in _WORLDS:
        _WORLDS[key] = with_shadows(load_world(spec), shadows)
    return _WORLDS[key]


def resolve_constant(name: str):
    """('perception.NAV_MAJORITY') -> (module, attribute name, current value); ValueError when bad."""
    module_name, _, attr = str(name).rpartition(".")
    if not module_name or not attr:
        raise ValueError(f"{name!r}: expected MODULE.CONSTANT, e.g. perception.NAV_MAJORITY")
    if not attr.isupper():
        raise ValueError(f"{name!r}: only module constants (UPPER_CASE names) can be set")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"{name!r}: cannot import module {module_name!r} ({exc})") from None
    if not hasattr(module, attr):
        raise ValueError(f"{name!r}: module {module_name!r} has no constant {attr!r}")
    return module, attr, getattr(module, attr)


@contextlib.contextmanager
def constants_set(pairs):
    """Set module constants for the duration of the block, then restore them (tables rebuilt both ways)."""
    saved = []
    try:
        for name, value in pairs:
            module, attr, old = resolve_constant(name)
            saved.append((module, attr, old))
            setattr(module, attr, value)
        _rebuild({m for m, _, _ in saved})
        yield
    finally:
        for module, attr, old in reversed(saved):
            setattr(module, attr, old)
        _rebuild({m for m, _, _ in saved})


def _rebuild(modules):
    for module in modules:
        hook = getattr(module, TABLE_HOOK, None)
        if callable(hook):
            hook()


def run_task(task: MissionTask) -> dict:
    """Run one mission in this process: {"result": dict, "files": {name: bytes}, "task": dict}.

    Never raises: a failing mission comes back as an error row, so one bad seed
    cannot sink a batch.
    """
    t0 = time.perf_counter()
    files = {}
    try:
        import cv2

        cv2.setNumThreads(1)  # one mission per core
        world = cached_world(task.world, task.shadows)
        tmp = tempfile.mkdtemp(prefix=f"mission-seed{task.seed}-")
        try:
            with _MISSION_LOCK, constants_set(task.constants):
                result = _run_mission(task, world, tmp)
            if task.keep_files:
                for name in MISSION_FILES:
                    path = Path(tmp) / name
                    if path.exists():
                        files[name] = path.read_bytes()
        finally:
            shutil.rmtree(tmp, ignore_errors=True)  # our own temp folder
    except Exception as exc:  # reported as a row, logged with its traceback in the worker
        log.exception("seed %d failed", task.seed)
        result = {"seed": task.seed, "end_reason": f"error: {type(exc).__name__}: {exc}",
                  "wall_s": round(time.perf_counter() - t0, 1)}
    fp = code_fingerprint()
    if task.fingerprint and task.fingerprint != fp:
        result["code_mismatch"] = f"worker code {fp} differs from the caller's {task.fingerprint}"
    return {"result": result, "files": files, "task": task.as_dict()}


def task_timing(task: MissionTask):
    from sim.timing import Timing

    return Timing(**task.timing) if task.timing else Timing()


def _run_mission(task: MissionTask, world, out: str) -> dict:
    timing = task_timing(task)
    if task.client:
        from sim.any_client import run_client_mission

        if not timing.unity:  # such clients time themselves with the wall clock: only the real-time loop fits
            raise ValueError("a third-party client runs under unity timing only (over the wire, in real time)")
        return run_client_mission(world, task.seed, task.client, time_limit=task.time_limit, out=out,
                                  progress=False, write_files=task.keep_files, fps=timing.fps)
    from sim.mission import run_mission

    return run_mission(task.seed, world, task.time_limit, out=out, progress=False, home_by=task.home_by,
                       write_files=task.keep_files, timing=timing)


def _quiet_worker():
    logging.basicConfig(level=logging.WARNING)
    logging.getLogger().setLevel(logging.WARNING)


def _pool_worker(task):
    return run_task(task)


# ----------------------------------------------------------------------------- caller side
def run_tasks(tasks, scheduler: str | None = None, jobs: int = 2, progress: bool = True, desc="missions"):
    """Run tasks on a backend; yields each `run_task` answer as it finishes (any order)."""
    from tqdm import tqdm

    tasks = list(tasks)
    with tqdm(total=len(tasks), unit="mission", disable=not progress, desc=desc) as bar:
        for answer in (_run_dask(tasks, scheduler) if scheduler else _run_local(tasks, jobs)):
            mismatch = answer["result"].get("code_mismatch")
            if mismatch:
                log.warning("seed %s: %s: results may not match a local run", answer["result"].get("seed"), mismatch)
            bar.update(1)
            yield answer


def _run_local(tasks, jobs):
    import multiprocessing as mp

    jobs = max(1, min(int(jobs), len(tasks)))
    if jobs == 1:
        for t in tasks:
            yield run_task(t)
        return
    # spawn, not fork: numba/OpenCV thread pools in this process deadlock a forked child
    with mp.get_context("spawn").Pool(jobs, initializer=_quiet_worker) as pool:
        yield from pool.imap_unordered(_pool_worker, tasks)
        pool.close()
        pool.join()


def connect(scheduler):
    """A dask.distributed Client for an address (`tcp://HOST:8786`) or an existing cluster object."""
    try:
        from distributed import Client
    except ImportError:
        raise ValueError("--scheduler needs dask[distributed]: pip install 'dask[distributed]'") from None
    try:
        return Client(scheduler, timeout="20s")
    except (OSError, TimeoutError) as exc:
        raise ValueError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None


def _run_dask(tasks, scheduler):
    from distributed import as_completed

    client = connect(scheduler)
    try:
        if not client.scheduler_info().get("workers"):
            log.warning("the scheduler at %s has no workers yet; tasks wait until one joins", scheduler)
        futures = client.map(run_task, tasks, pure=False, key=[f"mission-{i}-seed{t.seed}" for i, t in enumerate(tasks)])
        for future in as_completed(futures):
            yield future.result()
    finally:
        client.close()


def store_answer(answer: dict, out_dir) -> dict:
    """Write a worker's shipped files into out_dir (atomically) and return its result with local paths."""
    from sim.mission import write_json_atomic

    result = dict(answer["result"])
    if not answer.get("files"):
        return result
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, data in answer["files"].items():
        path = out_dir / name
        tmp = path.with_name(f".{name}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, path)
        paths[MISSION_FILES.get(name, name)] = str(path)
    paths["json"] = str(out_dir / "mission.json")
    result["files"] = paths
    write_json_atomic(out_dir / "mission.json", result)
    return result


def comparable(result: dict) -> dict:
    """A result without the fields that differ between two runs of the same mission (wall time, paths)."""
    return {k: v for k, v in result.items() if k not in VOLATILE_KEYS}


# ----------------------------------------------------------------------------- evaluations
def add_backend_options(parser) -> None:
    """--client and --scheduler for sim.evaluate (and sim.sweep's --scheduler)."""
    parser.add_argument("--client", default=None, metavar="PATH/drive_rover.py",
                        help="evaluate a third-party starter-style client, unchanged, in its own process over the "
                             "wire in real time (docs/evaluate-any-client.md); default: ours, in-process")
    add_scheduler_option(parser)


def add_scheduler_option(parser) -> None:
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:8786",
                        help="run each mission as a task on this Dask scheduler instead of local processes")


def timing_fields(timing) -> dict | None:
    """A Timing as the plain dict a MissionTask carries (None for the default)."""
    if timing is None:
        return None
    from dataclasses import asdict as dc_asdict

    return dc_asdict(timing)


def evaluate_tasks(seeds, world_spec="default", jobs=2, time_limit=900.0, out="out/evaluation", progress=True,
                   shadows=False, home_by=None, client=None, scheduler=None, timing=None) -> dict:
    """sim.evaluate on a backend (local processes or Dask) and/or for a third-party client.

    Same outputs as `sim.evaluate.evaluate`: per-seed folders, evaluation.{json,csv,md}.
    """
    from sim.evaluate import format_seeds, summarise, write_outputs

    if client:
        client = str(Path(client).resolve())
        if not Path(client).is_file():
            raise FileNotFoundError(f"--client: no such file {client}")
        log.info("third-party client missions run in real time: about %.0f s of wall time per seed at most",
                 time_limit)
    fp = code_fingerprint()
    from sim.timing import Timing

    timing = timing or Timing()
    if client and not timing.unity:
        raise ValueError("--client runs under unity timing only (the client times itself with the wall clock)")
    tasks = [MissionTask(seed=s, world=world_spec, shadows=shadows, time_limit=time_limit, home_by=home_by,
                         client=client, timing=timing_fields(timing), fingerprint=fp) for s in seeds]
    out = Path(out)
    t0 = time.perf_counter()
    results = [store_answer(a, out / f"seed-{a['result']['seed']}")
               for a in run_tasks(tasks, scheduler=scheduler, jobs=jobs, progress=progress)]
    results.sort(key=lambda r: r["seed"])
    done = [r for r in results if "mapped_pct" in r]
    summary = summarise(done)
    world_name = next((r.get("world") for r in results if r.get("world")), world_spec)
    meta = {"world": world_name, "seeds": format_seeds(seeds),
            "count": len(seeds), "finished": len(done), "shadows": "on" if shadows else "off", "jobs": jobs,
            "time_limit_s": time_limit, "home_by_s": home_by, **timing.describe(), "client": client,
            "backend": scheduler or "local", "code": fp, "interrupted": False,
            "failed": sum(str(r.get("end_reason", "")).startswith("error") for r in results),
            "wall_s": round(time.perf_counter() - t0, 1)}
    md = write_outputs(out, results, summary, meta)
    return {"meta": meta, "summary": summary, "missions": results, "markdown": md}
