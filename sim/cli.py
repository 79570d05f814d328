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
    """--shadows on|off: the simulator's graphics quality decides whether terrain casts shadows."""
    parser.add_argument("--shadows", choices=("on", "off"), default="on",
                        help="terrain cast shadows as at the simulator's Simple..Fantastic quality (on, "
                             "as in test_dataset) or none as at Fastest/Fast (off, as in the megalphian drive)")


def add_home_by_option(parser: argparse.ArgumentParser):
    """--home-by SECONDS: the client's return deadline (drive_rover.py's option of the same name)."""
    from decision import HOME_BY_S
    from drive_rover import positive_seconds

    parser.add_argument("--home-by", type=positive_seconds, default=None, metavar="SECONDS",
                        help=f"client heads home so as to arrive by this mission time (default: its own, "
                             f"{HOME_BY_S:.0f} s for a 600 s mission; e.g. 870 with --time-limit 900)")
