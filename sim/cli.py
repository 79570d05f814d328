"""Command-line plumbing shared by every tool (drive_rover.py, the twin's tools, the dashboard).

Why one place: every tool should fail the same way on a bad option, in one
line that names the option, with exit status 2 and before any work starts
(argparse's default prints a usage block first, and a bad folder would
otherwise surface as a traceback minutes into a mission).
"""
from __future__ import annotations

import argparse
import errno
import logging
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Optional

LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"  # time, level and module on every line
LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")  # accepted --log-level names
USAGE_EXIT = 2  # exit status of a bad command line (argparse's convention)
INTERRUPTED_EXIT = 130  # exit status after Ctrl-C (128 + SIGINT), partial results written


class ToolParser(argparse.ArgumentParser):
    """argparse with one-line errors: ``prog: error: --opt: why (see prog --help)``, exit 2."""

    def error(self, message):
        self.exit(USAGE_EXIT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def tool_parser(prog: str, description: str, **kwargs) -> ToolParser:
    """A parser whose help and errors show how the tool is really run (``python -m sim.mission``)."""
    return ToolParser(prog=prog, description=description, **kwargs)


# ------------------------------------------------------------------ argument types
def log_level(text: str) -> str:
    name = str(text).upper()
    if name not in LOG_LEVELS:
        raise argparse.ArgumentTypeError(f"{text!r} is not a log level (use one of {', '.join(LOG_LEVELS)})")
    return name


def _parsed(text: str, convert, what: str):
    """convert(text), or the one-line argparse error "'text' is not <what>"."""
    try:
        return convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None


def seed_number(text: str) -> int:
    """A scene seed: a whole number >= 0."""
    v = _parsed(text, int, "a whole number")
    if v < 0:
        raise argparse.ArgumentTypeError(f"seeds are >= 0, got {v}")
    return v


def port_number(text: str) -> int:
    """A TCP port 0..65535 (0 = any free port)."""
    v = _parsed(text, int, "a port number")
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"ports are 0..65535, got {v}")
    return v


def positive_number(text: str, what: str = "a positive number") -> float:
    """A finite number > 0; ``what`` names it in the range error (e.g. "a positive number of seconds")."""
    v = _parsed(text, float, "a number")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
    return v


def positive_int(text: str) -> int:
    v = _parsed(text, int, "a whole number")
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def non_negative_int(text: str) -> int:
    v = _parsed(text, int, "a whole number")
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {v}")
    return v


# ------------------------------------------------------------------ output locations
def _why(exc: OSError) -> str:
    if exc.errno == errno.EROFS:
        return "the disk is read-only"
    if exc.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if exc.errno == errno.ENOSPC:
        return "the disk is full"
    return exc.strerror or str(exc)


def folder_problem(path) -> Optional[str]:
    """None when ``path`` is (or can be made) a folder we can write into, else why not.

    Creates the folder (and parents) when absent; never removes anything."""
    p = Path(path).expanduser()
    if p.exists() and not p.is_dir():
        return f"{p} is a file, not a folder"
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return f"cannot create folder {p}: {_why(exc)}"
    try:
        fd, probe = tempfile.mkstemp(dir=p, prefix=".write-test-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        return f"cannot write into {p}: {_why(exc)}"
    return None


def file_problem(path) -> Optional[str]:
    """None when a file can be written at ``path`` (its folder is created), else why not."""
    p = Path(path).expanduser()
    if p.is_dir():
        return f"{p} is a folder, not a file name"
    return folder_problem(p.parent if str(p.parent) else ".")


def check_paths(parser: argparse.ArgumentParser, args, folders=(), files=()):
    """parser.error (one line, exit 2) for the first option whose output location is unusable.
    ``folders``/``files``: option names (``--out``) whose value, when given, must be writable."""
    for options, check in ((folders, folder_problem), (files, file_problem)):
        for option in options:
            value = getattr(args, option.lstrip("-").replace("-", "_"), None)
            if value:
                problem = check(value)
                if problem:
                    parser.error(f"{option}: {problem}")


# ------------------------------------------------------------------ logging and options
def add_log_level_option(parser: argparse.ArgumentParser):
    parser.add_argument("--log-level", type=log_level, default="INFO", metavar="LEVEL",
                        help=f"{', '.join(LOG_LEVELS)} (default %(default)s)")


def configure_logging(level: str):
    logging.basicConfig(level=getattr(logging, level, logging.INFO), format=LOG_FORMAT)


def parse_with_logging(parser: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Add --log-level, parse argv and configure logging, so every tool logs the same way."""
    add_log_level_option(parser)
    args = parser.parse_args(argv)
    configure_logging(args.log_level)
    return args


def add_shadows_option(parser: argparse.ArgumentParser):
    """--shadows on|off: the simulator's graphics quality decides whether terrain casts shadows.

    Off by default, as the twin issue asks and as megalphian shows; royalejandro, dimaga and
    test_dataset do show cast shadows (docs/twin-realism.md, round 3), so both are evaluated.
    """
    parser.add_argument("--shadows", choices=("on", "off"), default="off",
                        help="terrain cast shadows as at the simulator's Simple..Fantastic quality (on, "
                             "as in the test_dataset, royalejandro and dimaga drives) or none as at "
                             "Fastest/Fast (off, the default, as in the megalphian drive)")


def fail(message: str) -> int:
    """Print one error line to stderr and return the usage exit status (for checks after parsing)."""
    print(message, file=sys.stderr)
    return USAGE_EXIT
