"""Two evaluation runs side by side, mission by mission: ``python -m evaluation.compare BASE CAND``.

Why: routes are chaotic. A constant tweaked in one place moves every later turn, so a row's median can move
a few tenths of a point either way by chance alone. Pairing the two runs' missions by condition and seed
shows how many missions changed at all, how many got better or worse, and whether the split is more lopsided
than a coin would make it (an exact two-sided sign test over the missions that changed).

BASE and CAND are folders written by ``python -m sim.evaluate`` (``evaluation.json``) or by
``sim.evaluate --matrix`` (one such folder per condition). Missions present in only one run are left out.
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

log = logging.getLogger(__name__)

EVALUATION_FILE = "evaluation.json"  # what sim.evaluate writes in each run (or condition) folder
SAME_TOL = 1e-6  # figures closer than this count as unchanged (a byte-identical mission repeats them exactly)
FIGURES = (("mapped_pct", "mapped %", True), ("fidelity_pct", "fidelity %", True),
           ("time_s", "time s", False))  # (mission.json key, label, higher is better)


class CompareError(ValueError):
    """The folders cannot be compared (missing, unreadable, or no mission in common)."""


@dataclass
class Paired:
    """One condition's missions present in both runs, in seed order."""

    condition: str
    seeds: List[int]
    base: List[dict]
    cand: List[dict]


def load_run(folder) -> Dict[str, Dict[int, dict]]:
    """{condition: {seed: mission dict}} of an evaluate folder ("" as the condition) or a matrix folder."""
    root = Path(folder)
    if not root.is_dir():
        raise CompareError(f"{root}: no such folder")
    files = [root / EVALUATION_FILE] if (root / EVALUATION_FILE).is_file() else \
        sorted(p for p in root.glob(f"*/{EVALUATION_FILE}"))
    if not files:
        raise CompareError(f"{root}: no {EVALUATION_FILE} in it or in its condition folders "
                           "(is it a sim.evaluate output folder?)")
    run = {}
    for f in files:
        try:
            missions = json.loads(f.read_text())["missions"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise CompareError(f"{f}: not a sim.evaluate summary ({exc})") from exc
        condition = "" if f.parent == root else f.parent.name
        run[condition] = {int(m["seed"]): m for m in missions if isinstance(m, dict) and "seed" in m}
    return run


def pair_runs(base: Dict[str, Dict[int, dict]], cand: Dict[str, Dict[int, dict]]) -> List[Paired]:
    """The missions both runs hold, by condition (a plain run pairs with a one-condition matrix too)."""
    if list(base) == [""] and len(cand) == 1:
        cand = {"": next(iter(cand.values()))}
    elif list(cand) == [""] and len(base) == 1:
        base = {"": next(iter(base.values()))}
    pairs = []
    for condition in sorted(set(base) & set(cand)):
        seeds = sorted(set(base[condition]) & set(cand[condition]))
        if seeds:
            pairs.append(Paired(condition, seeds, [base[condition][s] for s in seeds],
                                [cand[condition][s] for s in seeds]))
    if not pairs:
        raise CompareError("the two runs have no condition and seed in common")
    return pairs


def sign_test_p(better: int, worse: int) -> float:
    """Exact two-sided sign test: the chance that a fair coin splits better + worse missions at least this
    unevenly (1.0 when nothing changed)."""
    n = better + worse
    if n == 0:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(min(better, worse) + 1))
    return min(1.0, 2.0 * tail / 2.0 ** n)


def _value(m: dict, key: str) -> Optional[float]:
    v = m.get(key)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def six_and_home(m: dict) -> bool:
    """All samples collected and back at the start (the issue's "all six and home")."""
    return bool(m.get("returned_home")) and m.get("collected") is not None and m.get("collected") == m.get("samples")


def figure_change(pair: Paired, key: str, higher_is_better: bool) -> dict:
    """Medians, worst values and the per-mission split of one figure."""
    rows = [(_value(b, key), _value(c, key)) for b, c in zip(pair.base, pair.cand)]
    rows = [(b, c) for b, c in rows if b is not None and c is not None]
    if not rows:
        return {}
    deltas = [c - b for b, c in rows]
    sign = 1.0 if higher_is_better else -1.0
    better = sum(1 for d in deltas if sign * d > SAME_TOL)
    worse = sum(1 for d in deltas if sign * d < -SAME_TOL)
    worst = min if higher_is_better else max
    return dict(base_median=statistics.median(b for b, _ in rows), cand_median=statistics.median(c for _, c in rows),
                base_worst=worst(b for b, _ in rows), cand_worst=worst(c for _, c in rows),
                better=better, worse=worse, mean_change=statistics.fmean(deltas), p=sign_test_p(better, worse))


def compare(pair: Paired) -> dict:
    """One condition's comparison: missions changed, six and home, and each figure's change."""
    changed = sum(1 for b, c in zip(pair.base, pair.cand)
                  if any(abs((_value(b, k) or 0.0) - (_value(c, k) or 0.0)) > SAME_TOL for k, _, _ in FIGURES))
    return dict(condition=pair.condition or "(one run)", missions=len(pair.seeds), changed=changed,
                base_home=sum(map(six_and_home, pair.base)), cand_home=sum(map(six_and_home, pair.cand)),
                lost=[s for s, b, c in zip(pair.seeds, pair.base, pair.cand) if six_and_home(b) and not six_and_home(c)],
                gained=[s for s, b, c in zip(pair.seeds, pair.base, pair.cand) if six_and_home(c) and not six_and_home(b)],
                figures={key: figure_change(pair, key, hib) for key, _, hib in FIGURES})


def markdown(results: List[dict], base_name: str, cand_name: str) -> str:
    """The comparison as a markdown table, one row per condition and figure."""
    lines = [f"# {cand_name} against {base_name}, mission by mission", "",
             "better / worse: missions whose figure moved the good / bad way; p: exact two-sided sign test over them "
             "(small = more lopsided than a coin).", "",
             "| condition | missions (changed) | six and home | figure | median | worst | better / worse | mean change | p |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        home = f"{r['base_home']} -> {r['cand_home']}"
        if r["lost"] or r["gained"]:
            home += "".join(f"; lost {s}" for s in r["lost"]) + "".join(f"; gained {s}" for s in r["gained"])
        first = True
        for key, label, _ in FIGURES:
            f = r["figures"].get(key)
            if not f:
                continue
            digits = 1 if key == "time_s" else 2
            lead = f"| {r['condition']} | {r['missions']} ({r['changed']}) | {home} " if first else "| | | "
            lines.append(f"{lead}| {label} | {f['base_median']:.{digits}f} -> {f['cand_median']:.{digits}f} "
                         f"| {f['base_worst']:.{digits}f} -> {f['cand_worst']:.{digits}f} | {f['better']} / {f['worse']} "
                         f"| {f['mean_change']:+.{digits}f} | {f['p']:.2f} |")
            first = False
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m evaluation.compare", description=__doc__.splitlines()[0])
    p.add_argument("base", help="the run to compare against (a sim.evaluate or sim.evaluate --matrix output folder)")
    p.add_argument("cand", help="the run to judge (same kind of folder)")
    p.add_argument("--out", help="also write the table to this markdown file")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        results = [compare(pair) for pair in pair_runs(load_run(a.base), load_run(a.cand))]
    except CompareError as exc:
        log.error("%s", exc)
        return 2
    text = markdown(results, a.base, a.cand)
    sys.stdout.write(text)
    if a.out:
        from safe_write import atomic_write

        atomic_write(Path(a.out), text.encode())
        log.info("wrote %s", a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
