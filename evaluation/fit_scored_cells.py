"""Fit the scored map's cell model: ``python -m evaluation.fit_scored_cells collect|fit``.

The scored map (``rover.worldmap``) calls a seen cell floor when a logistic model of map_bw on six
figures of the cell says so (perception.SCORED_CELL_*; issue 27, perception rounds 8-10): its
light-sand share, its sand share, its shadowed-sand share, its near-hue sand share, how many of its
neighbours the vote-share rules call floor, and whether those lie to its north-east or south-west.  This
tool makes those weights reproducible and keeps fitted and checked drives apart:

- ``collect`` replays real logs (``--log NAME=PATH``) and runs twin missions (``--twin SEED:SHADOWS:FPS:LATENCY``)
  and saves each drive's final map votes as ``DIR/NAME.npz``.  The planner reads the drive map, not the scored
  one (only the sample search's line of sight and its wall-foot looks read it), so other weights move a twin
  mission's route a little, not the kind of votes it collects.
- ``fit DIR --fit NAME ...`` fits the weights on the named drives only, prints them, prints the issue's
  shortfall (points of mapped and fidelity below the targets, summed) for each probability threshold on the
  fitted and on the other (checked) drives, and a table per drive: today's constants, the fitted model.
- ``trade DIR`` moves only the shipped model's probability line and prints, per drive, what it trades: mapped
  against fidelity at each line, the share of map_bw's floor the drive saw at all (the most any cell model can
  map), and the most mapped each fidelity line allows.  It answers whether a target pair can be met by reading
  the same votes more boldly, on drives the model was not fitted on as well as those it was.
"""
from __future__ import annotations

import argparse
import io
import logging
import sys
from pathlib import Path

import numpy as np

import perception
from evaluation.metrics import score_map

log = logging.getLogger(__name__)

MEMORY_FIELDS = ("nav_votes", "obs_votes", "shade_votes", "dim_shade_votes", "near_sand_votes", "look_range",
                 "band_nav_votes", "band_votes")  # PerceptionMemory arrays a drive's file keeps
RIDGE = 1e-3  # L2 penalty on the (standardised) weights, per cell
NEWTON_STEPS = 30  # Newton iterations of the logistic fit (it converges in under ten)
THRESHOLDS = tuple(np.round(np.arange(0.25, 0.651, 0.025), 3))  # model probabilities the shortfall is printed for
TWIN_TARGET = (98.0, 96.0)  # (mapped, fidelity) % the issue asks of twin missions
TRADE_LINES = tuple(np.round(np.arange(0.05, 0.651, 0.05), 3))  # probability lines the trade table prints
TRADE_FINE_LINES = tuple(np.round(np.arange(0.01, 0.951, 0.01), 3))  # ...and the finer grid its summary searches
TRADE_FIDELITY_FLOORS = (96.0, 97.0)  # fidelity lines (the twin's, the real logs') the trade summary reads mapped at, %
TRADE_MAPPED_FLOORS = (95.0, 98.0)  # mapped lines (the real logs', the twin's) the trade summary reads fidelity at, %
REAL_TARGETS = {"megalphian": (95.0, 97.0), "royalejandro": (95.0, 97.0),
                "test_dataset": (0.0, 97.0), "dimaga": (0.0, 97.0)}  # the real-log targets, %


def save_memory(mem, path) -> None:
    """Write a drive's map votes (the arrays the cell model reads) to ``path`` (.npz)."""
    from safe_write import atomic_write

    buf = io.BytesIO()
    np.savez_compressed(buf, **{f: getattr(mem, f) for f in MEMORY_FIELDS})
    atomic_write(Path(path), buf.getvalue())


def load_memory(path) -> perception.PerceptionMemory:
    """A PerceptionMemory holding the votes saved by :func:`save_memory`."""
    mem = perception.PerceptionMemory()
    with np.load(path) as z:
        missing = [f for f in MEMORY_FIELDS if f not in z]
        if missing == ["near_sand_votes"]:
            raise ValueError(f"{path} was collected before near-hue sand (perception's ninth round): collect it again")
        if missing:
            raise ValueError(f"{path} has no {missing[0]!r}: not a map-votes file of this tool")
        for f in MEMORY_FIELDS:
            setattr(mem, f, z[f].astype(np.float32))
    return mem


def cell_table(mem):
    """(seen (200, 200) bool, X (n, 6) float32): the model's inputs for every seen cell, in the map's order."""
    n = perception.WORLD_SIZE
    seen, *figures = perception.scored_cell_features(mem, 0, n, 0, n)
    return seen, np.stack([f[seen] for f in figures], 1)


def fit_logistic(X: np.ndarray, y: np.ndarray):
    """(weights (k,), bias) of the ridge-penalised logistic regression of y on X, by Newton's method."""
    mu, sd = X.mean(0), X.std(0) + 1e-9
    A = np.hstack([(X - mu) / sd, np.ones((len(X), 1))])
    w = np.zeros(A.shape[1])
    penalty = np.r_[np.full(X.shape[1], RIDGE * len(X)), 0.0]
    for _ in range(NEWTON_STEPS):
        p = 1.0 / (1.0 + np.exp(-A @ w))
        grad = A.T @ (p - y) + penalty * w
        hess = (A * (p * (1 - p))[:, None]).T @ A + np.diag(penalty)
        w -= np.linalg.solve(hess, grad)
    weights = w[:-1] / sd
    return weights, float(w[-1] - np.sum(weights * mu))


def model_map(seen, X, weights, bias, min_p) -> np.ndarray:
    """A worldmap whose blue channel is the model's verdict on the seen cells."""
    logit = X @ weights + bias
    wm = np.zeros((*seen.shape, 3), np.uint8)
    blue = np.zeros(seen.shape, bool)
    blue[seen] = logit > perception.scored_logit_min(min_p)
    wm[:, :, 2] = blue * 255
    return wm


def target(name: str):
    """The issue's (mapped, fidelity) targets for a drive named like the real logs or a twin mission."""
    return REAL_TARGETS.get(name, TWIN_TARGET)


def shortfall(name: str, score) -> float:
    """Points of mapped and fidelity below the drive's targets."""
    mapped, fidelity = target(name)
    return max(0.0, mapped - score.mapped_pct) + max(0.0, fidelity - score.fidelity_pct)


def shipped_weights():
    """(weights (6,), bias, probability threshold) of the cell model perception ships."""
    *weights, bias = perception.scored_cell_weights()
    return np.array(weights), bias, perception.SCORED_CELL_MIN_P


def fit_report(drives: dict, fitted: list, truth) -> str:
    """Fit on ``fitted`` (names in ``drives``: name -> (seen, X)) and report fitted and checked drives."""
    X = np.concatenate([drives[n][1] for n in fitted])
    y = np.concatenate([truth[drives[n][0]] for n in fitted]).astype(float)
    weights, bias = fit_logistic(X, y)
    checked = [n for n in drives if n not in fitted]
    lines = [f"fitted on {len(fitted)} drive{'' if len(fitted) == 1 else 's'} ({len(y)} cells): weights light {weights[0]:.3f}, sand {weights[1]:.3f}, "
             f"shade {weights[2]:.3f}, near-hue {weights[3]:.3f}, per neighbour {weights[4]:.3f}, "
             f"floor north-east {weights[5]:.3f}; bias {bias:.3f}",
             "", "| probability | shortfall, fitted drives | shortfall, checked drives |", "|---|---|---|"]
    scores = {n: line_scores(drives[n], truth, weights, bias, THRESHOLDS) for n in drives}
    fitted_shortfall = [sum(shortfall(n, scores[n][i]) for n in fitted) for i in range(len(THRESHOLDS))]
    for i, p in enumerate(THRESHOLDS):
        lines.append(f"| {p:.3f} | {fitted_shortfall[i]:.2f} | {sum(shortfall(n, scores[n][i]) for n in checked):.2f} |")
    best = int(np.argmin(fitted_shortfall))  # the per-drive table brackets the fitted drives' best threshold
    shown = range(max(best - 1, 0), min(best + 2, len(THRESHOLDS)))
    sw, sb, sp = shipped_weights()
    lines += ["", f"| drive | role | today's constants (p > {sp}) | fitted model, p > "
              f"{' / '.join(f'{THRESHOLDS[i]:.3f}' for i in shown)} (best on the fitted drives: {THRESHOLDS[best]:.3f}) |",
              "|---|---|---|---|"]
    for n in drives:
        today = score_map(model_map(*drives[n], sw, sb, sp), truth * 255)
        cols = " / ".join(f"{scores[n][i].mapped_pct:.2f}-{scores[n][i].fidelity_pct:.2f}" for i in shown)
        lines.append(f"| {n} | {'fitted' if n in fitted else 'checked'} | "
                     f"{today.mapped_pct:.2f} / {today.fidelity_pct:.2f} | {cols} |")
    return "\n".join(lines)


def seen_truth_pct(seen, truth) -> float:
    """Share of map_bw's floor cells among a drive's seen cells, %: no cell model can map more."""
    return 100.0 * np.count_nonzero(seen & truth) / max(np.count_nonzero(truth), 1)


def line_scores(drive, truth, weights, bias, lines):
    """[MapScore per probability line]: a cell model (weights, bias) on one drive's (seen, X)."""
    return [score_map(model_map(*drive, weights, bias, p), truth * 255) for p in lines]


def trade_scores(drive, truth, lines=TRADE_LINES):
    """[MapScore per line]: the shipped cell model on one drive's (seen, X), its probability line moved."""
    sw, sb, _ = shipped_weights()
    return line_scores(drive, truth, sw, sb, lines)


def best_under(scores, floor_attr: str, floor: float, best_attr: str) -> float:
    """Highest ``best_attr`` among the scores whose ``floor_attr`` reaches ``floor`` (nan if none does)."""
    ok = [getattr(sc, best_attr) for sc in scores if getattr(sc, floor_attr) >= floor]
    return max(ok) if ok else float("nan")


def trade_report(drives: dict, truth, lines=TRADE_LINES) -> str:
    """Markdown: mapped / fidelity per drive at each probability line of the shipped model, then per drive the
    seen share of the floor and the best mapped (fidelity) each fidelity (mapped) line leaves."""
    fine = {n: trade_scores(drives[n], truth, TRADE_FINE_LINES) for n in drives}
    at = {p: i for i, p in enumerate(TRADE_FINE_LINES)}  # the printed lines lie on the fine grid: scored once
    scores = {n: [fine[n][at[p]] if p in at else trade_scores(drives[n], truth, [p])[0] for p in lines] for n in drives}
    names = list(drives)
    shipped = perception.SCORED_CELL_MIN_P
    lines_md = ["mapped / fidelity % of the shipped cell model as its probability line moves (* = shipped line)", "",
                "| line | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for i, p in enumerate(lines):
        mark = "*" if abs(p - shipped) < 1e-9 else ""
        cells = " | ".join(f"{scores[n][i].mapped_pct:.2f} / {scores[n][i].fidelity_pct:.2f}" for n in names)
        lines_md.append(f"| {p:.3f}{mark} | {cells} |")
    fid_cols = [f"most mapped at fidelity >= {f:g}" for f in TRADE_FIDELITY_FLOORS]
    map_cols = [f"best fidelity at mapped >= {m:g}" for m in TRADE_MAPPED_FLOORS]
    lines_md += ["", "| drive | floor seen at all | " + " | ".join(fid_cols + map_cols) + " |",
                 "|---|---|" + "---|" * (len(fid_cols) + len(map_cols))]
    for n in names:
        row = [f"{best_under(fine[n], 'fidelity_pct', f, 'mapped_pct'):.2f}" for f in TRADE_FIDELITY_FLOORS]
        row += [f"{best_under(fine[n], 'mapped_pct', m, 'fidelity_pct'):.2f}" for m in TRADE_MAPPED_FLOORS]
        lines_md.append(f"| {n} | {seen_truth_pct(drives[n][0], truth):.2f} | " + " | ".join(row) + " |")
    lines_md += ["", f"Summary over lines {TRADE_FINE_LINES[0]:g}-{TRADE_FINE_LINES[-1]:g} in steps of "
                     f"{TRADE_FINE_LINES[1] - TRADE_FINE_LINES[0]:g}; nan: no line reaches it."]
    return "\n".join(lines_md)


def log_spec(text: str):
    """``NAME=PATH`` -> (name, path); the name becomes a file stem, so it may not hold a path separator."""
    name, sep, path = text.partition("=")
    if not sep or not name or not path or "/" in name or "\\" in name:
        raise argparse.ArgumentTypeError(f"{text!r}: give NAME=PATH, e.g. megalphian=../shared/real-logs/megalphian")
    return name, path


def twin_spec(text: str):
    """``SEED:on|off:FPS:LATENCY_MS`` -> (seed, shadows, fps, latency_ms), checked as the twin's timing is."""
    from sim.timing import Timing

    parts = text.split(":")
    try:
        if len(parts) != 4 or parts[1] not in ("on", "off"):
            raise ValueError("four fields, shadows on or off")
        seed, fps, latency = int(parts[0]), float(parts[2]), float(parts[3])
        Timing(fps=fps, latency_ms=latency)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: give SEED:on|off:FPS:LATENCY_MS, e.g. 3:off:30:5 ({exc})")
    return seed, parts[1] == "on", fps, latency


def _collect(args) -> int:
    from replay.log_format import LogFormatError, read_log
    from replay.runner import replay

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, path in args.log or []:
        try:
            _, rover, _ = replay(read_log(path), None, progress=False)
        except (LogFormatError, OSError, ValueError) as exc:
            log.error("%s: %s", name, exc)
            return 2
        save_memory(perception.get_memory(rover), out / f"{name}.npz")
        log.info("%s: votes of %s saved", name, path)
    for seed, shadows, fps, latency in args.twin or []:
        name = f"twin-{seed}-{'on' if shadows else 'off'}-{fps:g}fps-{latency:g}ms"
        _run_twin(seed, shadows, fps, latency, out / f"{name}.npz")
        log.info("%s: votes saved", name)
    return 0


def _run_twin(seed, shadows, fps, latency_ms, path) -> None:
    from sim.mission import run_inprocess
    from sim.timing import Timing
    from sim.world import load_world, with_shadows

    class SaveAtEnd:
        def observe(self, client, event, force=False):
            if force:
                save_memory(perception.get_memory(client.rover), path)

    run_inprocess(with_shadows(load_world("real"), shadows), seed, progress=False, watchers=[SaveAtEnd()],
                  timing=Timing(fps=fps, latency_ms=latency_ms))


def _load_drives(args):
    """(truth, {stem: (seen, X)}) for the .npz files in args.dir; a clear exit when they cannot be read."""
    from evaluation.metrics import load_ground_truth
    import shared_data

    try:
        truth = load_ground_truth(args.truth or shared_data.ground_truth_map_path()) > 0
    except ValueError as exc:
        raise SystemExit(str(exc))
    files = sorted(Path(args.dir).glob("*.npz"))
    if not files:
        raise SystemExit(f"no .npz map-votes files in {args.dir} (run the collect command first)")
    try:
        return truth, {f.stem: cell_table(load_memory(f)) for f in files}
    except (OSError, ValueError) as exc:
        raise SystemExit(f"cannot read the map votes in {args.dir}: {exc}")


def _trade(args) -> int:
    truth, drives = _load_drives(args)
    print(trade_report(drives, truth))
    return 0


def _fit(args) -> int:
    truth, drives = _load_drives(args)
    missing = [n for n in args.fit if n not in drives]
    if missing:
        raise SystemExit(f"not in {args.dir}: {', '.join(missing)}")
    print(fit_report(drives, list(args.fit), truth))
    return 0


def main(argv=None) -> int:
    from sim.cli import parse_with_logging

    p = argparse.ArgumentParser(prog="python -m evaluation.fit_scored_cells", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("collect", help="save the map votes of real logs and twin missions")
    c.add_argument("--log", action="append", type=log_spec, metavar="NAME=PATH",
                   help="a real log to replay (robot_log.csv or its folder)")
    c.add_argument("--twin", action="append", type=twin_spec, metavar="SEED:SHADOWS:FPS:LATENCY_MS",
                   help="a twin mission on the real world, e.g. 3:off:30:5")
    c.add_argument("--out", required=True, help="folder for the .npz files")
    f = sub.add_parser("fit", help="fit the cell model on some drives and check it on the others")
    f.add_argument("dir", help="folder of .npz files from collect")
    f.add_argument("--fit", nargs="+", required=True, metavar="NAME", help="drives (file stems) to fit on")
    f.add_argument("--truth", help="ground-truth map (default: map_bw.png in ../shared)")
    t = sub.add_parser("trade", help="mapped against fidelity per drive as the shipped model's probability line moves")
    t.add_argument("dir", help="folder of .npz files from collect")
    t.add_argument("--truth", help="ground-truth map (default: map_bw.png in ../shared)")
    args = parse_with_logging(p, argv)
    return {"collect": _collect, "fit": _fit, "trade": _trade}[args.cmd](args)


if __name__ == "__main__":
    sys.exit(main())
