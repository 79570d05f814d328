"""Replay recorded simulator logs through the live client's perception.

``replay.log_format`` holds the log writer and reader; ``python -m replay LOG``
runs perception over a log and scores the resulting map.
"""
from replay.log_format import LogData, LogFormatError, LogFrame, LogWriter, read_log  # noqa: F401
