"""Sweep module constants x seeds on the twin: which threshold is best, measured, not guessed.

    python -m sim.sweep perception.NAV_MAJORITY=0.15,0.2,0.25 --seeds 0-19
                        [MODULE.CONSTANT=v1,v2 ...] [--world SPEC] [--shadows on|off]
                        [--time-limit S] [--home-by S] [--jobs 2] [--scheduler tcp://HOST:8786]
                        [--timing unity|lockstep ...] [--out out/sweep]

Every combination of the listed values (a cartesian product when several
constants are given) runs one full in-process mission per seed, on local worker
processes or a Dask cluster (sim/backend.py); each constant is set inside the
worker process before the client is built and restored afterwards.  Values are
Python literals (`0.2`, `130`, `(160,160,160)`; commas inside brackets belong to
the value).  Prints one row per combination (median / min over seeds) and writes
`<out>/sweep.{md,csv,json,png}`; the plot shows every seed's mapped, fidelity and
collected figure per combination with the median marked.

Only constants read while the client runs take effect: a constant copied into
another module at import time (`from perception import X`) or baked into a
table is not seen, except perception's own tables, which are rebuilt
(`perception._build_tables`).
"""
from __future__ import annotations

import argparse
import ast
import csv
import io
import itertools
import logging
import math
import os
import statistics
import time
from pathlib import Path

import numpy as np

from drive_rover import add_home_by_option
from sim.backend import (MissionTask, add_scheduler_option, code_fingerprint, resolve_constant, run_tasks,
                         timing_fields)
from sim.cli import add_shadows_option, parse_with_logging
from sim.evaluate import format_seeds, parse_seeds
from sim.mission import TIME_LIMIT_S, timing_label
from sim.timing import Timing, add_timing_options, timing_from_args

log = logging.getLogger(__name__)

DEFAULT_OUT = "out/sweep"  # output folder
DEFAULT_JOBS = 2  # local worker processes (the target machine has 2 cores)
PLOT_METRICS = (("mapped_pct", "mapped %"), ("fidelity_pct", "fidelity %"), ("collected", "samples collected"))
MISSION_COLUMNS = ("seed", "mapped_pct", "fidelity_pct", "collected", "samples", "returned_home", "time_s",
                   "longest_stuck_s", "distance_m", "end_reason")  # per-mission CSV columns after the constants


# ----------------------------------------------------------------------------- parsing
def split_values(text: str) -> list:
    """'1,2,(3,4)' -> ['1', '2', '(3,4)']: commas inside brackets or quotes belong to the value."""
    parts, depth, quote, cur = [], 0, None, []
    for ch in text:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append("".join(cur).strip())
            cur = []
            continue
        cur.append(ch)
    parts.append("".join(cur).strip())
    if any(p == "" for p in parts) or depth != 0 or quote:
        raise ValueError(f"cannot split values {text!r} (empty value or unbalanced brackets/quotes)")
    return parts


def parse_spec(spec: str):
    """'perception.NAV_MAJORITY=0.15,0.2' -> ('perception.NAV_MAJORITY', [0.15, 0.2], current value)."""
    name, eq, values_text = spec.partition("=")
    name = name.strip()
    if not eq or not values_text.strip():
        raise ValueError(f"{spec!r}: expected MODULE.CONSTANT=v1,v2,...")
    _, _, current = resolve_constant(name)
    values = []
    for raw in split_values(values_text):
        try:
            value = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            if not isinstance(current, str):
                raise ValueError(f"{name}: {raw!r} is not a Python literal") from None
            value = raw
        if isinstance(current, (int, float)) and not isinstance(current, bool) \
                and not (isinstance(value, (int, float)) and not isinstance(value, bool)):
            raise ValueError(f"{name} is a number ({current!r}); {raw!r} is not")
        if isinstance(current, np.ndarray):  # keep array constants arrays (code may do array maths on them)
            value = np.asarray(value, dtype=current.dtype)
            if value.shape != current.shape:
                raise ValueError(f"{name} has shape {current.shape}; {raw!r} does not")
        values.append(value)
    return name, values, current


def same_value(a, b) -> bool:
    """Equality that also works for array constants."""
    try:
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    except (TypeError, ValueError):
        return a == b


# ----------------------------------------------------------------------------- running
def build_tasks(names, value_lists, seeds, world, shadows, time_limit, home_by, timing=None):
    """(combinations, tasks): every value combination x every seed."""
    combos = list(itertools.product(*value_lists))
    fp = code_fingerprint()
    tasks = [MissionTask(seed=s, world=world, shadows=shadows, time_limit=time_limit, home_by=home_by,
                         constants=tuple(zip(names, combo)), keep_files=False, fingerprint=fp,
                         timing=timing_fields(timing),
                         extra={"combo": i})
             for i, combo in enumerate(combos) for s in seeds]
    return combos, tasks


def _median(vals):
    vals = [float(v) for v in vals if isinstance(v, (int, float)) and math.isfinite(v)]
    return statistics.median(vals) if vals else None


def _min(vals):
    vals = [float(v) for v in vals if isinstance(v, (int, float)) and math.isfinite(v)]
    return min(vals) if vals else None


def summarise_combo(missions: list) -> dict:
    ok = [m for m in missions if "mapped_pct" in m]
    full = [m for m in ok if m.get("returned_home")]
    return {"missions": len(missions), "errors": len(missions) - len(ok),
            "mapped_median": _median(m["mapped_pct"] for m in ok), "mapped_min": _min(m["mapped_pct"] for m in ok),
            "fidelity_median": _median(m["fidelity_pct"] for m in ok),
            "collected_median": _median(m["collected"] for m in ok),
            "all_home": f"{len(full)}/{len(missions)}",
            "time_median": _median(m["time_s"] for m in ok),
            "longest_stuck_max": max((m["longest_stuck_s"] for m in ok), default=None)}


def _label(v) -> str:
    """A value as the user typed it (arrays as lists)."""
    return repr(v.tolist()) if isinstance(v, np.ndarray) else repr(v)


def _fmt(v):
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.1f}"
    return str(v)


def markdown(names, combos, rows, currents) -> str:
    cols = ["mapped median", "mapped min", "fidelity median", "collected median", "all six + home",
            "time median s", "longest stuck s", "errors"]
    keys = ["mapped_median", "mapped_min", "fidelity_median", "collected_median", "all_home", "time_median",
            "longest_stuck_max", "errors"]
    lines = ["| " + " | ".join(list(names) + cols) + " |", "|" + "---|" * (len(names) + len(cols))]
    for combo, row in zip(combos, rows):
        vals = [_label(v) + (" (current)" if same_value(v, cur) else "") for v, cur in zip(combo, currents)]
        lines.append("| " + " | ".join(vals + [_fmt(row[k]) for k in keys]) + " |")
    return "\n".join(lines) + "\n"


def plot(path: Path, names, combos, grouped, title: str) -> None:
    """Per-seed points and the median per combination, one panel per metric (Agg backend, atomic)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [", ".join(f"{n.rpartition('.')[2]}={_label(v)}" for n, v in zip(names, combo)) for combo in combos]
    fig, axes = plt.subplots(1, len(PLOT_METRICS), figsize=(4.2 * len(PLOT_METRICS), 4.2), squeeze=False)
    for ax, (key, label) in zip(axes[0], PLOT_METRICS):
        for i, missions in enumerate(grouped):
            vals = [m[key] for m in missions if isinstance(m.get(key), (int, float)) and m.get(key) is not None]
            if not vals:
                continue
            jitter = [(j - (len(vals) - 1) / 2) * 0.25 / max(1, len(vals)) for j in range(len(vals))]
            ax.scatter([i + d for d in jitter], vals, s=12, alpha=0.6, color="tab:blue")
            ax.hlines(statistics.median(vals), i - 0.3, i + 0.3, color="tab:red", lw=2)
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)


def _write_text_atomic(path: Path, text: str):
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def sweep(specs, seeds, world="default", shadows=False, time_limit=TIME_LIMIT_S, home_by=None, jobs=DEFAULT_JOBS,
          scheduler=None, out=DEFAULT_OUT, progress=True, timing=None) -> dict:
    """Run the sweep and write its outputs; returns {"meta", "rows", "missions", "markdown"}."""
    from sim.mission import write_json_atomic

    parsed = [parse_spec(s) for s in specs]
    names = [p[0] for p in parsed]
    if len(set(names)) != len(names):
        raise ValueError("each constant may be listed once")
    currents = [p[2] for p in parsed]
    timing = timing or Timing()
    combos, tasks = build_tasks(names, [p[1] for p in parsed], seeds, world, shadows, time_limit, home_by, timing)
    t0 = time.perf_counter()
    grouped = [[] for _ in combos]
    for answer in run_tasks(tasks, scheduler=scheduler, jobs=jobs, progress=progress, desc="sweep"):
        grouped[answer["task"]["extra"]["combo"]].append(answer["result"])
    for g in grouped:
        g.sort(key=lambda m: m["seed"])
    rows = [summarise_combo(g) for g in grouped]
    out = Path(out)
    md = markdown(names, combos, rows, currents)
    seeds_text = format_seeds(seeds)
    world = next((m["world"] for g in grouped for m in g if m.get("world")), world)  # "default" -> its name
    title = (f"sweep on {world}, seeds {seeds_text}, time limit {time_limit:.0f} s, shadows {'on' if shadows else 'off'}, "
             f"{timing_label(timing.describe())}")
    meta = {"constants": names, "current_values": [_label(c) for c in currents], "seeds": seeds_text, "world": world,
            "shadows": shadows, "time_limit_s": time_limit, "home_by_s": home_by, **timing.describe(), "backend": scheduler or "local",
            "code": code_fingerprint(), "wall_s": round(time.perf_counter() - t0, 1)}
    _write_text_atomic(out / "sweep.md", f"# {title}\n\n{md}")
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(list(names) + list(MISSION_COLUMNS))
    for combo, missions in zip(combos, grouped):
        for m in missions:
            w.writerow([_label(v) for v in combo] + [m.get(c) for c in MISSION_COLUMNS])
    _write_text_atomic(out / "sweep.csv", buf.getvalue())
    write_json_atomic(out / "sweep.json", {"meta": meta, "rows": [
        {"values": dict(zip(names, map(_label, combo))), **row} for combo, row in zip(combos, rows)],
        "missions": [{"values": dict(zip(names, map(_label, combo))), **m}
                     for combo, missions in zip(combos, grouped) for m in missions]})
    plot(out / "sweep.png", names, combos, grouped, title)
    return {"meta": meta, "rows": rows, "combos": combos, "missions": grouped, "markdown": md}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim.sweep", description="Sweep module constants x seeds on the twin (local processes or Dask).")
    p.add_argument("specs", nargs="+", metavar="MODULE.CONSTANT=v1,v2,...",
                   help="e.g. perception.NAV_MAJORITY=0.15,0.2,0.25 (several: every combination)")
    p.add_argument("--seeds", default="0-19", help="e.g. 0-19 or 1,5,9")
    p.add_argument("--world", default="default", help="real | procedural:K | PATH.png (default: real if present)")
    p.add_argument("--time-limit", type=float, default=TIME_LIMIT_S, help="simulated seconds per mission")
    p.add_argument("--jobs", type=int, default=DEFAULT_JOBS, help="local worker processes (without --scheduler)")
    p.add_argument("--out", default=DEFAULT_OUT)
    add_home_by_option(p)
    add_shadows_option(p)
    add_scheduler_option(p)
    add_timing_options(p)
    p.add_argument("--no-progress", action="store_true")
    a = parse_with_logging(p, argv)
    try:
        seeds = parse_seeds(a.seeds)
        timing = timing_from_args(a)
        for spec in a.specs:
            parse_spec(spec)
    except ValueError as exc:
        p.error(str(exc))
    if not (a.time_limit > 0 and math.isfinite(a.time_limit)):
        p.error("--time-limit must be a positive number of seconds")
    try:
        from sim.world import load_world

        load_world(a.world)  # fail early and clearly on a bad --world
        res = sweep(a.specs, seeds, a.world, a.shadows == "on", a.time_limit, a.home_by, a.jobs, a.scheduler,
                    a.out, progress=not a.no_progress, timing=timing)
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    print(res["markdown"])
    log.info("wrote %s/sweep.{md,csv,json,png} in %.0f s", a.out, res["meta"]["wall_s"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
