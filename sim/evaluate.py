"""Many missions, both cores, one summary table.

    python -m sim.evaluate --seeds 0-19 [--world real|procedural:K|PNG] [--jobs 2]
                           [--time-limit S] [--out DIR] [--timing unity|lockstep] [--fps 30]
                           [--latency-ms MS] [--compute-ms MS]
                           [--client PATH/drive_rover.py] [--scheduler tcp://HOST:8786]
    python -m sim.evaluate --matrix [--seeds 0-19] [--jobs 2] [--out DIR]

Each seed is a full in-process mission (sim.mission.run_mission) in a worker
process; per-seed outputs land in `<out>/seed-N/`, the summary in
`<out>/evaluation.{json,csv,md}` (atomic writes).  A failing seed is reported as
an error row, never aborts the others.  `--client` (a third-party client, over
the wire in real time) and `--scheduler` (a Dask cluster) go through sim/backend.py.
Every mission runs the real simulator's
loop (unity timing, sim/timing.py) unless `--timing lockstep` asks for the easier one.

`--matrix` runs the seeds under each of MATRIX_CONDITIONS (issue 27's real-simulator
conditions) into `<out>/<condition>/` and prints one table, also written as
`<out>/matrix.{md,json}`.

To add an option: put it on the parser in `main`, carry it in `MissionOptions`
(per mission) or `WorldOptions` (per worker's world), and pass it on in `_run_seed`
or `_init_worker`; the outputs name whatever `MissionOptions.describe()` returns.
"""
from __future__ import annotations

import argparse
import csv
import io
import logging
import math
import multiprocessing as mp
import os
import statistics
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from drive_rover import add_home_by_option
from sim.backend import add_backend_options, evaluate_tasks
from sim.cli import add_shadows_option, parse_with_logging
from sim.mission import TIME_LIMIT_S, timing_label
from sim.mission_parts import write_json_atomic
from sim.timing import Timing, add_timing_options, timing_from_args

log = logging.getLogger(__name__)

DEFAULT_JOBS = 2  # worker processes (the target machine has 2 cores)
DEFAULT_OUT = "out/evaluation"  # summary folder
COLUMNS = ("seed", "mapped_pct", "fidelity_pct", "located", "collected", "samples", "returned_home",
           "completed", "time_s", "stuck_time_s", "longest_stuck_s", "frames", "distance_m",
           "frames_per_s", "end_reason")  # table columns, in order
SUMMARY_COLUMNS = ("mapped_pct", "fidelity_pct", "located", "collected", "returned_home", "time_s",
                   "stuck_time_s", "longest_stuck_s", "frames_per_s")  # columns with median/min rows


@dataclass(frozen=True)
class WorldOptions:
    """How each worker builds its world (once per worker)."""

    spec: str = "default"  # real | procedural:K | PATH.png
    shadows: bool = False  # terrain cast shadows (off by default, as sim.cli)

    def describe(self) -> dict:
        return {"shadows": "on" if self.shadows else "off"}


@dataclass(frozen=True)
class MissionOptions:
    """How each mission runs (handed to sim.mission.run_mission)."""

    time_limit: float = TIME_LIMIT_S  # simulated s
    home_by: float | None = None  # the client's return deadline, s
    timing: Timing = field(default_factory=Timing)

    def describe(self) -> dict:
        return {"time_limit_s": self.time_limit, "home_by_s": self.home_by, **self.timing.describe()}

    def run_kwargs(self) -> dict:
        return {"time_limit": self.time_limit, "home_by": self.home_by, "timing": self.timing}


@dataclass(frozen=True)
class Condition:
    """One cell of the evaluation matrix."""

    name: str  # folder name and table label
    shadows: bool
    timing: Timing


# issue 27's conditions, all under the real simulator's loop (unity timing, no sim_time)
MATRIX_CONDITIONS = (
    Condition("shadows-off-30fps", False, Timing(fps=30.0)),
    Condition("shadows-on-30fps", True, Timing(fps=30.0)),
    Condition("shadows-off-15fps-60ms", False, Timing(fps=15.0, latency_ms=60.0)),
)
HOME_TARGET = "all six and home"  # the matrix's count column

_WORLD = None  # per-worker cached World


def parse_seeds(text: str) -> list:
    """'0-19', '1,4,9', '3' or mixes like '0-4,10' -> sorted unique ints."""
    seeds = set()
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        if "-" in part[1:]:
            lo, hi = part.split("-", 1) if not part.startswith("-") else (part, part)
            lo, hi = int(lo), int(hi)
            if hi < lo:
                raise ValueError(f"bad seed range {part!r}")
            seeds.update(range(lo, hi + 1))
        else:
            seeds.add(int(part))
    if not seeds:
        raise ValueError(f"no seeds in {text!r}")
    return sorted(seeds)


def _init_worker(world: WorldOptions, quiet=True):
    global _WORLD
    if quiet:  # worker processes: only warnings, the parent shows progress
        logging.basicConfig(level=logging.WARNING)
        logging.getLogger().setLevel(logging.WARNING)
    import cv2

    cv2.setNumThreads(1)  # one worker per core: no thread oversubscription
    from sim.world import load_world, with_shadows

    _WORLD = with_shadows(load_world(world.spec), world.shadows)


def _run_seed(args):
    seed, out, options = args
    from sim.mission import run_mission

    t0 = time.perf_counter()
    try:
        return run_mission(seed, _WORLD, out=Path(out) / f"seed-{seed}", progress=False, **options.run_kwargs())
    except Exception as exc:  # one bad seed must not sink the batch
        logging.getLogger(__name__).exception("seed %d failed", seed)
        return {"seed": seed, "end_reason": f"error: {type(exc).__name__}: {exc}",
                "wall_s": round(time.perf_counter() - t0, 1)}


def _num(v):
    if isinstance(v, bool):
        return float(v)
    if isinstance(v, (int, float)) and math.isfinite(v):
        return float(v)
    return None


def summarise(results: list) -> dict:
    """Median and min over seeds of the numeric columns (booleans count as 0/1)."""
    out = {}
    for key in SUMMARY_COLUMNS:
        vals = [x for x in (_num(r.get(key)) for r in results) if x is not None]
        out[key] = {"median": statistics.median(vals) if vals else None,
                    "min": min(vals) if vals else None}
    return out


def _cell(v):
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.1f}"
    return str(v)


def markdown_table(results: list, summary: dict) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in results:
        lines.append("| " + " | ".join(_cell(r.get(c)) for c in COLUMNS) + " |")
    for stat in ("median", "min"):
        row = [stat] + [_cell(summary[c][stat]) if c in summary else "" for c in COLUMNS[1:]]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def _write_text_atomic(path: Path, text: str):
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_outputs(out: Path, results, summary, meta):
    write_json_atomic(out / "evaluation.json", {"meta": meta, "summary": summary, "missions": results})
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(COLUMNS), extrasaction="ignore")
    w.writeheader()
    for r in results:
        w.writerow({c: r.get(c) for c in COLUMNS})
    _write_text_atomic(out / "evaluation.csv", buf.getvalue())
    md = (f"# Twin evaluation: world {meta['world']}, shadows {meta.get('shadows', 'on')}, seeds {meta['seeds']}, "
          f"{timing_label(meta)}, time limit {meta['time_limit_s']:.0f} s"
          + (f", client home by {meta['home_by_s']:.0f} s" if meta.get("home_by_s") else "")
          + (f", client {meta['client']}" if meta.get("client") else "")
          + (f", Dask scheduler {meta['backend']}" if meta.get("backend", "local") != "local" else "")
          + "\n\n" + markdown_table(results, summary))
    _write_text_atomic(out / "evaluation.md", md)
    return md


def evaluate(seeds, world_spec="default", jobs=DEFAULT_JOBS, time_limit=TIME_LIMIT_S, out=DEFAULT_OUT,
             progress=True, shadows=False, home_by=None, timing: Timing | None = None) -> dict:
    """Run the seeds (in worker processes when jobs > 1), write the outputs, return them."""
    world = WorldOptions(world_spec, bool(shadows))
    options = MissionOptions(time_limit, home_by, timing or Timing())
    return run_batch(seeds, world, options, jobs, out, progress)


def run_batch(seeds, world: WorldOptions, options: MissionOptions, jobs=DEFAULT_JOBS, out=DEFAULT_OUT,
              progress=True, desc="missions") -> dict:
    from tqdm import tqdm

    out = Path(out)
    tasks = [(s, str(out), options) for s in seeds]
    jobs = max(1, min(int(jobs), len(tasks)))
    t0 = time.perf_counter()
    results = []
    with tqdm(total=len(tasks), unit="mission", disable=not progress, desc=desc) as bar:
        if jobs == 1:
            _init_worker(world, quiet=False)
            for t in tasks:
                results.append(_run_seed(t))
                bar.update(1)
        else:
            # spawn, not fork: numba/OpenCV thread pools started in this process (e.g. by
            # the procedural world) deadlock a forked child
            ctx = mp.get_context("spawn")
            with ctx.Pool(jobs, initializer=_init_worker, initargs=(world, True)) as pool:
                for r in pool.imap_unordered(_run_seed, tasks):
                    results.append(r)
                    bar.update(1)
                pool.close()  # let workers exit cleanly (terminate() leaks their semaphores)
                pool.join()
    results.sort(key=lambda r: r["seed"])
    summary = summarise([r for r in results if "mapped_pct" in r])
    world_name = next((r.get("world") for r in results if r.get("world")), world.spec)
    meta = {"world": world_name, "seeds": f"{seeds[0]}-{seeds[-1]}" if len(seeds) > 1 else str(seeds[0]),
            "count": len(seeds), **world.describe(), "jobs": jobs, **options.describe(),
            "wall_s": round(time.perf_counter() - t0, 1)}
    md = write_outputs(out, results, summary, meta)
    return {"meta": meta, "summary": summary, "missions": results, "markdown": md}


# ----------------------------------------------------------------------------- the matrix
def matrix_row(condition: Condition, res: dict) -> dict:
    """One condition's line: medians and worst seeds of what issue 27 asks for."""
    done = [m for m in res["missions"] if "mapped_pct" in m]

    def vals(key):
        return [v for v in (_num(m.get(key)) for m in done) if v is not None]

    def stat(fn, key):
        v = vals(key)
        return fn(v) if v else None

    home = sum(1 for m in done if m.get("returned_home"))
    return {"condition": condition.name, "shadows": "on" if condition.shadows else "off",
            **condition.timing.describe(), "seeds": len(res["missions"]), "errors": len(res["missions"]) - len(done),
            "mapped_median": stat(statistics.median, "mapped_pct"), "mapped_min": stat(min, "mapped_pct"),
            "fidelity_median": stat(statistics.median, "fidelity_pct"), "fidelity_min": stat(min, "fidelity_pct"),
            "home": home, "time_median": stat(statistics.median, "time_s"), "time_max": stat(max, "time_s"),
            "longest_stuck_max": stat(max, "longest_stuck_s"), "wall_s": res["meta"]["wall_s"]}


MATRIX_COLUMNS = (("condition", "condition"), ("shadows", "shadows"), ("fps", "fps"), ("latency_ms", "latency ms"),
                  ("mapped_median", "mapped % median"), ("mapped_min", "worst"),
                  ("fidelity_median", "fidelity % median"), ("fidelity_min", "worst"),
                  ("home", HOME_TARGET), ("time_median", "time s median"), ("time_max", "worst"),
                  ("longest_stuck_max", "longest stuck s"), ("errors", "errors"))  # (key, header)


def matrix_markdown(rows: list, seeds: list, time_limit: float) -> str:
    lines = [f"# Evaluation matrix: seeds {seeds[0]}-{seeds[-1]} ({len(seeds)}), unity timing "
             f"(the real simulator's loop, no sim_time), time limit {time_limit:.0f} s", "",
             "| " + " | ".join(h for _, h in MATRIX_COLUMNS) + " |", "|" + "---|" * len(MATRIX_COLUMNS)]
    for r in rows:
        cells = []
        for key, _ in MATRIX_COLUMNS:
            v = r.get(key)
            cells.append(f"{v}/{r['seeds']}" if key == "home" else _cell(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def run_matrix(seeds, world_spec="default", jobs=DEFAULT_JOBS, out=DEFAULT_OUT, progress=True,
               options: MissionOptions | None = None, conditions=MATRIX_CONDITIONS) -> dict:
    """Every condition over the seeds, one after the other; one table."""
    options = options or MissionOptions()
    out = Path(out)
    rows = []
    for cond in conditions:
        log.info("matrix: %s (%s)", cond.name, cond.timing.label())
        res = run_batch(seeds, WorldOptions(world_spec, cond.shadows), replace(options, timing=cond.timing),
                        jobs, out / cond.name, progress, desc=cond.name)
        rows.append(matrix_row(cond, res))
        _write_matrix(out, rows, seeds, options)  # partial tables survive an interrupted run
    return {"rows": rows, "markdown": matrix_markdown(rows, seeds, options.time_limit)}


def _write_matrix(out: Path, rows, seeds, options: MissionOptions):
    write_json_atomic(out / "matrix.json", {"seeds": seeds, "time_limit_s": options.time_limit,
                                            "home_by_s": options.home_by, "rows": rows})
    _write_text_atomic(out / "matrix.md", matrix_markdown(rows, seeds, options.time_limit))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Run many twin missions and summarise them.")
    p.add_argument("--seeds", default="0-19", help="e.g. 0-19 or 1,5,9")
    p.add_argument("--world", default="default", help="real | procedural:K | PATH.png (default: real if present)")
    p.add_argument("--jobs", type=int, default=DEFAULT_JOBS, help="worker processes")
    p.add_argument("--time-limit", type=float, default=TIME_LIMIT_S, help="simulated seconds per mission")
    p.add_argument("--out", default=DEFAULT_OUT)
    p.add_argument("--matrix", action="store_true",
                   help="run the seeds under each condition of " + ", ".join(c.name for c in MATRIX_CONDITIONS)
                        + " (unity timing; overrides --shadows/--timing/--fps/--latency-ms) and print one table")
    add_home_by_option(p)
    add_shadows_option(p)
    add_backend_options(p)
    add_timing_options(p)
    p.add_argument("--no-progress", action="store_true")
    a = parse_with_logging(p, argv)
    try:
        seeds = parse_seeds(a.seeds)
        timing = timing_from_args(a)
    except ValueError as exc:
        p.error(str(exc))
    if not (a.time_limit > 0 and math.isfinite(a.time_limit)):
        p.error("--time-limit must be a positive number of seconds")
    try:
        from sim.world import load_world

        load_world(a.world)  # fail early and clearly on a bad --world
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    options = MissionOptions(a.time_limit, a.home_by, timing)
    t0 = time.perf_counter()
    if a.matrix:
        res = run_matrix(seeds, a.world, a.jobs, a.out, progress=not a.no_progress, options=options)
        print(res["markdown"])
        log.info("wrote %s/matrix.{md,json} and one folder per condition in %.0f s", a.out,
                 time.perf_counter() - t0)
        return 0
    log.info("timing: %s", timing.label())
    if a.client or a.scheduler:  # another client and/or a Dask cluster: sim/backend.py
        if timing != Timing():
            p.error("--timing/--fps/--latency-ms/--compute-ms are not passed through sim/backend.py yet: "
                    "with --scheduler/--client every mission runs the default (unity, 30 fps)")
        try:
            res = evaluate_tasks(seeds, a.world, a.jobs, a.time_limit, a.out, progress=not a.no_progress,
                                 shadows=a.shadows == "on", home_by=a.home_by, client=a.client,
                                 scheduler=a.scheduler)
        except (ValueError, FileNotFoundError) as exc:
            log.error("%s", exc)
            return 2
        log.info("\n%s", res["markdown"])
        log.info("wrote %s/evaluation.{json,csv,md} in %.0f s", a.out, res["meta"]["wall_s"])
        return 0
    res = run_batch(seeds, WorldOptions(a.world, a.shadows == "on"), options, a.jobs, a.out,
                    progress=not a.no_progress)
    log.info("\n%s", res["markdown"])
    log.info("wrote %s/evaluation.{json,csv,md} in %.0f s", a.out, res["meta"]["wall_s"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
