"""Command-line plumbing shared by the twin's tools (mission, evaluate, wire)."""
import argparse
import logging

LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"  # time, level and module on every line


def parse_with_logging(parser: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Add --log-level, parse argv and configure logging, so every tool logs the same way."""
    parser.add_argument("--log-level", default="INFO", help="DEBUG, INFO, WARNING or ERROR")
    args = parser.parse_args(argv)
    logging.basicConfig(level=getattr(logging, str(args.log_level).upper(), logging.INFO), format=LOG_FORMAT)
    return args


def add_shadows_option(parser: argparse.ArgumentParser):
    """--shadows on|off: the simulator's graphics quality decides whether terrain casts shadows.

    Off by default: the held-out real drives (megalphian, royalejandro) show no cast shadows;
    only test_dataset does.
    """
    parser.add_argument("--shadows", choices=("on", "off"), default="off",
                        help="terrain cast shadows as at the simulator's Simple..Fantastic quality (on, "
                             "as in test_dataset) or none as at Fastest/Fast (off, the default, as in the "
                             "megalphian and royalejandro drives)")

