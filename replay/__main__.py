"""``python -m replay LOG [--ground-truth MAP] [--video out.mp4] [--map out.png] [--json out.json]``.

Runs the live client's perception over a recorded simulator log and reports how
good the resulting map is (Mapped %, Fidelity %, rocks located).  Exit status:
0 success, 2 bad input (not a log, no usable frames, unreadable ground truth),
1 could not write an output.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

EXIT_OK, EXIT_OUTPUT_ERROR, EXIT_BAD_INPUT = 0, 1, 2  # process exit codes

log = logging.getLogger("replay")


def _parse_args(argv):
    p = argparse.ArgumentParser(prog="python -m replay",
                                description="Replay a simulator log (robot_log.csv or its folder) through "
                                            "the client's perception and score the map.")
    p.add_argument("log", help="robot_log.csv or the folder holding it (frames are looked up in IMG/ beside it)")
    p.add_argument("--ground-truth", metavar="MAP",
                   help="ground-truth map PNG (default: the shared map_bw.png when present)")
    p.add_argument("--no-ground-truth", action="store_true", help="do not score against any map")
    p.add_argument("--video", metavar="OUT.mp4", help="write a mosaic video (camera, thresholds, top-down, map)")
    p.add_argument("--video-every", type=int, default=1, metavar="N", help="put every Nth frame in the video")
    p.add_argument("--map", metavar="OUT.png", help="write the final map scored against the ground truth")
    p.add_argument("--json", metavar="OUT.json", help="write the metrics as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar, warnings only")
    return p.parse_args(argv)


def _load_truth(args):
    from evaluation.metrics import load_ground_truth

    if args.no_ground_truth:
        return None, None
    if args.ground_truth:
        path = Path(args.ground_truth)
    else:
        import shared_data

        path = shared_data.ground_truth_map_path()
        if not path.is_file():
            log.warning("no ground truth at %s: metrics will be n/a (use --ground-truth MAP)", path)
            return None, None
    if not path.is_file():
        raise ValueError(f"ground-truth map {path} not found")
    truth = load_ground_truth(path)
    if truth.shape != (200, 200):
        raise ValueError(f"ground-truth map {path} is {truth.shape[1]}x{truth.shape[0]}, expected 200x200")
    return truth, path


def _fmt(v, unit="%"):
    return "n/a" if v is None or v != v else f"{v:.1f}{unit}"


def main(argv=None) -> int:
    args = _parse_args(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    from replay.log_format import LogFormatError, read_log

    try:
        data = read_log(args.log)
        truth, truth_path = _load_truth(args)
    except (LogFormatError, ValueError, OSError) as exc:
        log.error("%s", exc)
        return EXIT_BAD_INPUT

    from replay import outputs
    from replay.runner import replay

    video = outputs.MosaicVideo(args.video) if args.video else None
    every = max(1, args.video_every)
    counter = {"n": 0}

    def on_frame(rover, frame):
        counter["n"] += 1
        if video is not None and (counter["n"] - 1) % every == 0:
            video.add(rover, frame)

    try:
        result, rover, trajectory = replay(data, truth, on_frame=on_frame, progress=not args.quiet)
    except OSError as exc:
        if video is not None:
            video.close(keep=False)
        log.error("%s", exc)
        return EXIT_OUTPUT_ERROR
    except KeyboardInterrupt:
        if video is not None:
            video.close(keep=False)
        log.error("interrupted")
        return 130
    if result.frames_used == 0:
        if video is not None:
            video.close(keep=False)
        log.error("%s: none of the %d frames could be decoded (unreadable images)", data.log_path,
                  len(data.frames))
        return EXIT_BAD_INPUT

    summary = [
        f"frames used {result.frames_used}/{result.frames_total} (skipped in log {result.frames_skipped_log}: "
        f"{data.corrupt_rows} corrupt, {data.duplicate_rows} duplicate, {data.missing_images} missing; "
        f"unreadable {result.frames_unreadable}; mapped frames {result.frames_mapped})",
        f"Mapped {_fmt(result.mapped_pct)}  Fidelity {_fmt(result.fidelity_pct)}  "
        f"rocks located {result.rocks_located}  perception {result.perception_ms_median:.3f} ms/frame median",
    ]
    for line in summary:
        log.info("%s", line)
    status = EXIT_OK
    try:
        if video is not None:
            video.close(keep=True)
            log.info("video: %s (%d frames)", args.video, video.frames)
        if args.map:
            title = [f"{Path(args.log).name}: Mapped {_fmt(result.mapped_pct)}  Fidelity {_fmt(result.fidelity_pct)}"
                     f"  rocks {result.rocks_located}", f"ground truth: {truth_path or 'none'}"]
            outputs.write_png(args.map, outputs.map_image(rover.worldmap, truth, rover.rocks_world, trajectory,
                                                          title))
            log.info("map: %s", args.map)
        if args.json:
            payload = result.as_dict()
            payload["ground_truth"] = str(truth_path) if truth_path else None
            payload["log_warnings"] = len(data.warnings)
            outputs.write_json(args.json, payload)
            log.info("json: %s", args.json)
    except OSError as exc:
        log.error("cannot write output: %s", exc)
        status = EXIT_OUTPUT_ERROR
    if args.quiet:  # the result line must show even when INFO is hidden
        log.warning("RESULT mapped=%s fidelity=%s rocks=%d frames=%d", _fmt(result.mapped_pct),
                    _fmt(result.fidelity_pct), result.rocks_located, result.frames_used)
    return status


if __name__ == "__main__":
    sys.exit(main())
