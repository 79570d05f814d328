"""Reader entry point named in ARCHITECTURE.md; the implementation lives in log_format."""
from replay.log_format import LogData, LogFormatError, LogFrame, parse_number, read_log  # noqa: F401
