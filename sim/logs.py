"""Find a simulator log by name or path: the one rule every twin check (realism, map realism, physics windows) uses.

NAME is `test_dataset` (../shared/udacity-rover/test_dataset) or a folder under ../shared/real-logs;
anything else is read as a log folder or a robot_log.csv path.
"""
from __future__ import annotations

from pathlib import Path

import shared_data

TEST_DATASET_NAME = "test_dataset"  # the CLI recording shipped with the starter project


def find_log(name_or_path) -> Path:
    """robot_log.csv of a log name or path; FileNotFoundError (saying where names are looked up) if none."""
    from replay.log_format import LogFormatError, resolve_log_path

    p = Path(str(name_or_path)).expanduser()
    if not p.exists():
        if str(name_or_path) == TEST_DATASET_NAME:
            p = shared_data.test_dataset_dir()
        else:
            p = shared_data.real_logs_dir() / str(name_or_path)
    try:
        return resolve_log_path(p)
    except LogFormatError as exc:
        raise FileNotFoundError(f"{exc} (log names are {TEST_DATASET_NAME!r} or folders under "
                                f"{shared_data.real_logs_dir()})") from None


def log_label(log_path) -> str:
    """Short name of a log for tables: its folder name."""
    return Path(log_path).parent.name
