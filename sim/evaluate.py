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

import csv
import io
import logging
import math
import multiprocessing as mp
import os
import signal
import statistics
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from drive_rover import add_home_by_option
from interrupts import caused_by_interrupt
from sim.backend import add_backend_options, evaluate_tasks
from sim.cli import (INTERRUPTED_EXIT, add_shadows_option, check_paths, parse_with_logging, positive_int,
                     positive_number, tool_parser)
from sim.mission import INTERRUPTED, TIME_LIMIT_S, timing_label
from sim.mission_parts import progress_bar, write_json_atomic
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

PROGRESS_STEP_S = 1.0  # simulated s between a worker's progress reports
PROGRESS_POLL_S = 0.5  # wall s between progress-bar refreshes in the parent
NOT_RUN = "not run (interrupted)"  # end_reason of seeds skipped after Ctrl-C
ERROR_PREFIX = "error"  # end_reason prefix of a seed that raised

_WORLD = None  # per-worker cached World
_COUNTER = None  # per-worker shared simulated-seconds counter (multiprocessing.Value)
_STOP = None  # per-worker shared stop flag (multiprocessing.Value), set by Ctrl-C
_IN_MISSION = [False]  # a mission is running in this worker (Ctrl-C interrupts it)


def parse_seeds(text: str) -> list:
    """'0-19', '1,4,9', '3' or mixes like '0-4,10' -> sorted unique ints (>= 0)."""
    seeds = set()
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            lo, hi = int(lo), int(hi if sep else lo)
        except ValueError:
            raise ValueError(f"{part!r} is not a seed (a whole number >= 0) or a range like 0-19") from None
        if hi < lo:
            raise ValueError(f"range {part!r} runs backwards")
        seeds.update(range(lo, hi + 1))
    if not seeds:
        raise ValueError(f"no seeds in {text!r}")
    return sorted(seeds)


def format_seeds(seeds) -> str:
    """Sorted unique seeds -> the shortest text parse_seeds reads back: [40, 41, 42, 90] -> '40-42,90'.

    Reports used to print first-last, so a run of seeds 40-49 and 90-99 was headed 'seeds 40-99'."""
    ordered = sorted(set(int(s) for s in seeds))
    parts, start = [], None
    for i, seed in enumerate(ordered):
        if start is None:
            start = seed
        if i + 1 == len(ordered) or ordered[i + 1] != seed + 1:
            parts.append(str(seed) if seed == start else f"{start}-{seed}")
            start = None
    return ",".join(parts)


class SimSecondsMeter:
    """Mission watcher that adds simulated seconds to a shared counter every few frames,
    so the parent's progress bar moves per frame, not per finished mission."""

    def __init__(self, counter):
        self.counter, self.sent = counter, 0.0

    def observe(self, client, event=None, force=False):
        t = client.rover.total_time
        if force or t - self.sent >= PROGRESS_STEP_S:
            with self.counter.get_lock():
                self.counter.value += max(0.0, t - self.sent)
            self.sent = t


def _worker_sigint(signum, frame):
    """Ctrl-C in a worker: the running mission stops and writes its partial files; no new ones start."""
    if _STOP is not None:
        _STOP.value = 1
    if _IN_MISSION[0]:
        _IN_MISSION[0] = False  # a second Ctrl-C must not interrupt the writing
        raise KeyboardInterrupt


def _init_worker(world: WorldOptions, quiet=True, counter=None, stop=None):
    global _WORLD, _COUNTER, _STOP
    if quiet:  # worker processes: only warnings, the parent shows progress
        logging.basicConfig(level=logging.WARNING)
        logging.getLogger().setLevel(logging.WARNING)
        signal.signal(signal.SIGINT, _worker_sigint)
    import cv2

    cv2.setNumThreads(1)  # one worker per core: no thread oversubscription
    from sim.world import load_world, with_shadows

    _WORLD = with_shadows(load_world(world.spec), world.shadows)
    _COUNTER, _STOP = counter, stop


def _run_seed(args):
    seed, out, options = args
    from sim.mission import run_mission

    if _STOP is not None and _STOP.value:
        return {"seed": seed, "end_reason": NOT_RUN}
    t0 = time.perf_counter()
    watchers = [SimSecondsMeter(_COUNTER)] if _COUNTER is not None else []
    _IN_MISSION[0] = True
    try:
        return run_mission(seed, _WORLD, out=Path(out) / f"seed-{seed}", progress=False, watchers=watchers,
                           **options.run_kwargs())
    except (KeyboardInterrupt, Exception) as exc:  # one bad seed must not sink the batch
        if caused_by_interrupt(exc):  # Ctrl-C outside the mission loop (loading, scoring; maybe wrapped by numba)
            return {"seed": seed, "end_reason": "interrupted before any result"}
        logging.getLogger(__name__).exception("seed %d failed", seed)
        return {"seed": seed, "end_reason": f"error: {type(exc).__name__}: {exc}",
                "wall_s": round(time.perf_counter() - t0, 1)}
    finally:
        _IN_MISSION[0] = False


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
                    "min": min(vals) if vals else None, "max": max(vals) if vals else None}
        if any(isinstance(r.get(key), bool) for r in results):
            out[key]["yes"] = sum(r.get(key) is True for r in results)
    return out


# evaluation.md: (column, heading, cell format) for people; the CSV/JSON keep the raw field names
MD_COLUMNS = (("seed", "seed", "{}"), ("mapped_pct", "mapped", "{:.1f} %"), ("fidelity_pct", "fidelity", "{:.1f} %"),
              ("located", "located", "{}"), ("collected", "collected", "{}"), ("returned_home", "home", "{}"),
              ("time_s", "time", "{:.0f} s"), ("stuck_time_s", "stuck", "{:.0f} s"),
              ("longest_stuck_s", "longest stuck", "{:.0f} s"), ("distance_m", "driven", "{:.0f} m"),
              ("frames_per_s", "speed", "{:.0f} frames/s"), ("end_reason", "how it ended", "{}"))
MD_INTRO = ("Mapped: share of the true navigable ground the client marked navigable; fidelity: share of its "
            "navigable marks that are right; located: samples with a rock mark within 3 m; collected: samples "
            "picked up; home: all collected and back within 3 m of the start. Time is simulated.\n")
LOWER_IS_BETTER = ("time_s", "stuck_time_s", "longest_stuck_s")  # the "worst" row takes their maximum


def _cell(v, fmt="{}"):
    if v is None:
        return "n/a"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float) and fmt == "{}":
        return f"{v:.1f}"
    try:
        return fmt.format(v)
    except (ValueError, TypeError):
        return str(v)


def _of_samples(r, key):
    v = r.get(key)
    return "n/a" if v is None else f"{v}/{r.get('samples', '?')}"


def markdown_table(results: list, summary: dict) -> str:
    """Per-seed rows, then a median row and a worst row; yes/no columns are counted, not averaged."""
    lines = ["| " + " | ".join(h for _, h, _ in MD_COLUMNS) + " |", "|" + "---|" * len(MD_COLUMNS)]
    for r in results:
        cells = [_of_samples(r, c) if c in ("located", "collected") else _cell(r.get(c), fmt)
                 for c, _, fmt in MD_COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    n = len([r for r in results if "mapped_pct" in r and r.get("end_reason") != INTERRUPTED])  # the summary's rows
    for stat, label in (("median", "median"), ("worst", "worst")):
        row = [label]
        for c, _, fmt in MD_COLUMNS[1:]:
            if c not in summary:
                row.append("")
            elif c == "returned_home":
                row.append(f"{summary[c].get('yes', 0)}/{n} yes" if stat == "median" else "")
            else:
                v = summary[c].get("max" if stat == "worst" and c in LOWER_IS_BETTER else
                                   ("min" if stat == "worst" else "median"))
                row.append(_cell(v, "{:g}" if c in ("located", "collected") else fmt))
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
          + "\n\n" + MD_INTRO
          + (f"\n**Interrupted (Ctrl-C)**: {meta.get('finished', 0)} of {meta['count']} missions finished; "
             "partial missions are listed but not in the median/worst rows.\n" if meta.get("interrupted") else "")
          + "\n" + markdown_table(results, summary))
    _write_text_atomic(out / "evaluation.md", md)
    return md


def evaluate(seeds, world_spec="default", jobs=DEFAULT_JOBS, time_limit=TIME_LIMIT_S, out=DEFAULT_OUT,
             progress=True, shadows=False, home_by=None, timing: Timing | None = None) -> dict:
    """Run the seeds (in worker processes when jobs > 1), write the outputs, return them."""
    world = WorldOptions(world_spec, bool(shadows))
    options = MissionOptions(time_limit, home_by, timing or Timing())
    return run_batch(seeds, world, options, jobs, out, progress)


def run_batch(seeds, world: WorldOptions, options: MissionOptions, jobs=DEFAULT_JOBS, out=DEFAULT_OUT,
              progress=True, desc="evaluation") -> dict:
    """Missions on ``jobs`` worker processes with one progress bar in simulated seconds (moving per
    frame, not per finished mission).  Ctrl-C stops the running missions, which write their partial
    files; the outputs then list them and meta["interrupted"] is True."""
    from tqdm.contrib.logging import logging_redirect_tqdm

    out = Path(out)
    tasks = [(s, str(out), options) for s in seeds]
    jobs = max(1, min(int(jobs), len(tasks)))
    t0 = time.perf_counter()
    results, interrupted = [], False
    with progress_bar(len(tasks) * options.time_limit, progress, desc) as bar, logging_redirect_tqdm():
        if jobs == 1:
            counter = mp.Value("d", 0.0)
            _init_worker(world, quiet=False, counter=counter)
            credited = 0.0
            try:
                for t in tasks:
                    r = _run_seed(t)
                    results.append(r)
                    credited += options.time_limit - float(r.get("time_s") or 0.0)
                    bar.n = min(bar.total, int(counter.value + credited))
                    bar.refresh()
                    if str(r.get("end_reason", "")).startswith(INTERRUPTED):
                        interrupted = True
                        break
            except KeyboardInterrupt:
                interrupted = True
        else:
            results, interrupted = _run_pool(tasks, jobs, world, bar, options.time_limit)
    results = sorted((r for r in results if r.get("end_reason") != NOT_RUN), key=lambda r: r["seed"])
    done = [r for r in results if "mapped_pct" in r and r.get("end_reason") != INTERRUPTED]
    summary = summarise(done)
    world_name = next((r.get("world") for r in results if r.get("world")), world.spec)
    meta = {"world": world_name, "seeds": format_seeds(seeds),
            "count": len(seeds), "finished": len(done), **world.describe(), "jobs": jobs, **options.describe(),
            "interrupted": interrupted,
            "failed": sum(str(r.get("end_reason", "")).startswith(ERROR_PREFIX) for r in results),
            "wall_s": round(time.perf_counter() - t0, 1)}
    md = write_outputs(out, results, summary, meta)
    return {"meta": meta, "summary": summary, "missions": results, "markdown": md}


def _run_pool(tasks, jobs, world: WorldOptions, bar, time_limit):
    """The missions on worker processes; returns (results, interrupted)."""
    # spawn, not fork: numba/OpenCV thread pools started in this process (e.g. by
    # the procedural world) deadlock a forked child
    ctx = mp.get_context("spawn")
    counter, stop = ctx.Value("d", 0.0), ctx.Value("b", 0)
    results, credited, interrupted = [], 0.0, []
    with ctx.Pool(jobs, initializer=_init_worker, initargs=(world, True, counter, stop)) as pool:
        def on_sigint(signum, frame):
            if interrupted:
                return
            interrupted.append(True)
            stop.value = 1
            log.warning("Ctrl-C: the running missions stop and write their partial results")
            for proc in list(getattr(pool, "_pool", [])):  # in case only this process got the signal
                try:
                    os.kill(proc.pid, signal.SIGINT)
                except OSError:
                    pass

        previous = signal.signal(signal.SIGINT, on_sigint)
        try:
            it = pool.imap_unordered(_run_seed, tasks)
            while len(results) < len(tasks):
                try:
                    r = it.next(timeout=PROGRESS_POLL_S)
                    results.append(r)
                    credited += time_limit - float(r.get("time_s") or 0.0)  # a mission that ended early
                except mp.TimeoutError:
                    pass
                bar.n = min(bar.total, int(counter.value + credited))
                bar.refresh()
            pool.close()  # let workers exit cleanly (terminate() leaks their semaphores)
            pool.join()
        finally:
            signal.signal(signal.SIGINT, previous)
    return results, bool(interrupted)


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
    lines = [f"# Evaluation matrix: seeds {format_seeds(seeds)} ({len(seeds)}), unity timing "
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
        if res["meta"].get("interrupted"):  # Ctrl-C: no further conditions
            break
    return {"rows": rows, "markdown": matrix_markdown(rows, seeds, options.time_limit),
            "interrupted": bool(rows) and res["meta"].get("interrupted", False)}


def _write_matrix(out: Path, rows, seeds, options: MissionOptions):
    write_json_atomic(out / "matrix.json", {"seeds": seeds, "time_limit_s": options.time_limit,
                                            "home_by_s": options.home_by, "rows": rows})
    _write_text_atomic(out / "matrix.md", matrix_markdown(rows, seeds, options.time_limit))


def main(argv=None) -> int:
    p = tool_parser("python -m sim.evaluate", "Run many twin missions (both cores) and summarise them in "
                    "<out>/evaluation.{md,csv,json}; per-seed files in <out>/seed-N/.")
    p.add_argument("--seeds", default="0-19", help="e.g. 0-19 or 1,5,9 (default %(default)s)")
    p.add_argument("--world", default="default", help="real | procedural:K | PATH.png (default: real if present)")
    p.add_argument("--jobs", type=positive_int, default=DEFAULT_JOBS, help="worker processes (default %(default)s)")
    p.add_argument("--time-limit", type=positive_number, default=TIME_LIMIT_S, metavar="SECONDS",
                   help="simulated seconds per mission (default %(default).0f)")
    p.add_argument("--out", default=DEFAULT_OUT, help="output folder (default %(default)s)")
    p.add_argument("--matrix", action="store_true",
                   help="run the seeds under each condition of " + ", ".join(c.name for c in MATRIX_CONDITIONS)
                        + " (unity timing; overrides --shadows/--timing/--fps/--latency-ms) and print one table")
    add_home_by_option(p)
    add_shadows_option(p)
    add_backend_options(p)
    add_timing_options(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    a = parse_with_logging(p, argv)
    try:
        seeds = parse_seeds(a.seeds)
    except ValueError as exc:
        p.error(f"--seeds: {exc}")
    try:
        timing = timing_from_args(a)
    except ValueError as exc:
        p.error(str(exc))
    check_paths(p, a, folders=("--out",))
    try:
        from sim.world import load_world

        load_world(a.world)  # fail early and clearly on a bad --world
    except (ValueError, FileNotFoundError) as exc:
        p.error(f"--world: {exc}")
    options = MissionOptions(a.time_limit, a.home_by, timing)
    t0 = time.perf_counter()
    if a.matrix:
        res = run_matrix(seeds, a.world, a.jobs, a.out, progress=not a.no_progress, options=options)
        print(res["markdown"])
        log.info("wrote %s/matrix.{md,json} and one folder per condition in %.0f s", a.out,
                 time.perf_counter() - t0)
        return INTERRUPTED_EXIT if res["interrupted"] else 0
    log.info("timing: %s", timing.label())
    if a.client or a.scheduler:  # another client and/or a Dask cluster: sim/backend.py
        if a.client and not timing.unity:
            p.error("--client runs under unity timing only: the client times itself with the wall clock")
        try:
            res = evaluate_tasks(seeds, a.world, a.jobs, a.time_limit, a.out, progress=not a.no_progress,
                                 shadows=a.shadows == "on", home_by=a.home_by, client=a.client,
                                 scheduler=a.scheduler, timing=timing)
        except (ValueError, FileNotFoundError) as exc:
            log.error("%s", exc)
            return 2
    else:
        res = run_batch(seeds, WorldOptions(a.world, a.shadows == "on"), options, a.jobs, a.out,
                        progress=not a.no_progress)
    return _report(res, a.out)


def _report(res, out) -> int:
    """Print the table; exit status 130 after Ctrl-C, 1 when a mission failed, else 0."""
    meta = res["meta"]
    failed = sum(str(r.get("end_reason", "")).startswith(ERROR_PREFIX) for r in res["missions"])
    print(res["markdown"])
    log.info("wrote %s/evaluation.{json,csv,md} in %.0f s", out, meta["wall_s"])
    if meta.get("interrupted"):
        log.warning("interrupted: %d of %d missions finished; the files above hold them and the partial ones",
                    meta.get("finished", 0), meta["count"])
        return INTERRUPTED_EXIT
    if failed:
        log.error("%d of %d missions failed (see 'how it ended' in evaluation.md)", failed, meta["count"])
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
