"""Many missions, both cores, one summary table.

    python -m sim.evaluate --seeds 0-19 [--world real|procedural:K|PNG] [--jobs 2]
                           [--time-limit S] [--out DIR]
                           [--client PATH/drive_rover.py] [--scheduler tcp://HOST:8786]

Each seed is a full in-process mission (sim.mission.run_mission) in a worker
process; per-seed outputs land in `<out>/seed-N/`, the summary in
`<out>/evaluation.{json,csv,md}` (atomic writes).  A failing seed is reported as
an error row, never aborts the others.  `--client` (a third-party client, over
the wire in real time) and `--scheduler` (a Dask cluster) go through sim/backend.py.
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
from pathlib import Path

from drive_rover import add_home_by_option
from sim.backend import add_backend_options, evaluate_tasks
from sim.cli import add_shadows_option, parse_with_logging
from sim.mission import TIME_LIMIT_S

log = logging.getLogger(__name__)

DEFAULT_JOBS = 2  # worker processes (the target machine has 2 cores)
DEFAULT_OUT = "out/evaluation"  # summary folder
COLUMNS = ("seed", "mapped_pct", "fidelity_pct", "located", "collected", "samples", "returned_home",
           "completed", "time_s", "stuck_time_s", "longest_stuck_s", "frames", "distance_m",
           "frames_per_s", "end_reason")  # table columns, in order
SUMMARY_COLUMNS = ("mapped_pct", "fidelity_pct", "located", "collected", "returned_home", "time_s",
                   "stuck_time_s", "longest_stuck_s", "frames_per_s")  # columns with median/min rows

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


def _init_worker(world_spec, quiet=True, shadows=False):
    global _WORLD
    if quiet:  # worker processes: only warnings, the parent shows progress
        logging.basicConfig(level=logging.WARNING)
        logging.getLogger().setLevel(logging.WARNING)
    import cv2

    cv2.setNumThreads(1)  # one worker per core: no thread oversubscription
    from sim.world import load_world, with_shadows

    _WORLD = with_shadows(load_world(world_spec), shadows)


def _run_seed(args):
    seed, time_limit, out, home_by = args
    from sim.mission import run_mission

    t0 = time.perf_counter()
    try:
        return run_mission(seed, _WORLD, time_limit, out=Path(out) / f"seed-{seed}", progress=False,
                           home_by=home_by)
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
    from sim.mission import write_json_atomic

    write_json_atomic(out / "evaluation.json", {"meta": meta, "summary": summary, "missions": results})
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(COLUMNS), extrasaction="ignore")
    w.writeheader()
    for r in results:
        w.writerow({c: r.get(c) for c in COLUMNS})
    _write_text_atomic(out / "evaluation.csv", buf.getvalue())
    md = (f"# Twin evaluation: world {meta['world']}, shadows {meta.get('shadows', 'on')}, seeds {meta['seeds']}, "
          f"time limit {meta['time_limit_s']:.0f} s"
          + (f", client home by {meta['home_by_s']:.0f} s" if meta.get("home_by_s") else "")
          + (f", client {meta['client']}" if meta.get("client") else "")
          + (f", Dask scheduler {meta['backend']}" if meta.get("backend", "local") != "local" else "")
          + "\n\n" + markdown_table(results, summary))
    _write_text_atomic(out / "evaluation.md", md)
    return md


def evaluate(seeds, world_spec="default", jobs=DEFAULT_JOBS, time_limit=TIME_LIMIT_S, out=DEFAULT_OUT,
             progress=True, shadows=False, home_by=None) -> dict:
    from tqdm import tqdm

    out = Path(out)
    tasks = [(s, time_limit, str(out), home_by) for s in seeds]
    jobs = max(1, min(int(jobs), len(tasks)))
    t0 = time.perf_counter()
    results = []
    with tqdm(total=len(tasks), unit="mission", disable=not progress, desc="missions") as bar:
        if jobs == 1:
            _init_worker(world_spec, quiet=False, shadows=shadows)
            for t in tasks:
                results.append(_run_seed(t))
                bar.update(1)
        else:
            # spawn, not fork: numba/OpenCV thread pools started in this process (e.g. by
            # the procedural world) deadlock a forked child
            ctx = mp.get_context("spawn")
            with ctx.Pool(jobs, initializer=_init_worker, initargs=(world_spec, True, shadows)) as pool:
                for r in pool.imap_unordered(_run_seed, tasks):
                    results.append(r)
                    bar.update(1)
                pool.close()  # let workers exit cleanly (terminate() leaks their semaphores)
                pool.join()
    results.sort(key=lambda r: r["seed"])
    summary = summarise([r for r in results if "mapped_pct" in r])
    world_name = next((r.get("world") for r in results if r.get("world")), world_spec)
    meta = {"world": world_name, "seeds": f"{seeds[0]}-{seeds[-1]}" if len(seeds) > 1 else str(seeds[0]),
            "count": len(seeds), "shadows": "on" if shadows else "off", "jobs": jobs, "time_limit_s": time_limit,
            "home_by_s": home_by,
            "wall_s": round(time.perf_counter() - t0, 1)}
    md = write_outputs(out, results, summary, meta)
    return {"meta": meta, "summary": summary, "missions": results, "markdown": md}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="Run many twin missions and summarise them.")
    p.add_argument("--seeds", default="0-19", help="e.g. 0-19 or 1,5,9")
    p.add_argument("--world", default="default", help="real | procedural:K | PATH.png (default: real if present)")
    p.add_argument("--jobs", type=int, default=DEFAULT_JOBS, help="worker processes")
    p.add_argument("--time-limit", type=float, default=TIME_LIMIT_S, help="simulated seconds per mission")
    p.add_argument("--out", default=DEFAULT_OUT)
    add_home_by_option(p)
    add_shadows_option(p)
    add_backend_options(p)
    p.add_argument("--no-progress", action="store_true")
    a = parse_with_logging(p, argv)
    try:
        seeds = parse_seeds(a.seeds)
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
    if a.client or a.scheduler:  # another client and/or a Dask cluster: sim/backend.py
        try:
            res = evaluate_tasks(seeds, a.world, a.jobs, a.time_limit, a.out, progress=not a.no_progress,
                                 shadows=a.shadows == "on", home_by=a.home_by, client=a.client,
                                 scheduler=a.scheduler)
        except (ValueError, FileNotFoundError) as exc:
            log.error("%s", exc)
            return 2
    else:
        res = evaluate(seeds, a.world, a.jobs, a.time_limit, a.out, progress=not a.no_progress,
                       shadows=a.shadows == "on", home_by=a.home_by)
    log.info("\n%s", res["markdown"])
    log.info("wrote %s/evaluation.{json,csv,md} in %.0f s", a.out, res["meta"]["wall_s"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
