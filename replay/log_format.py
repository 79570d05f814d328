"""The simulator's Training-mode log format: a safe writer and a forgiving reader.

Format (fact sheet section 7): ``robot_log.csv`` with a ``;`` separator and the header
``Path;SteerAngle;Throttle;Brake;Speed;X_Position;Y_Position;Pitch;Yaw;Roll``,
plus ``IMG/robocam_YYYY_MM_DD_HH_MM_SS_fff.jpg`` frames.  ``Path`` is absolute,
numbers use .NET's default float ``ToString`` (7 significant digits, ``E-07``
style exponents), pitch/yaw/roll are raw 0..360 Unity angles.

Writer: used by the live server and the twin.  It never deletes or overwrites
anything (the simulator does: it wipes the folder), every image lands
atomically (temp file + ``os.replace``) so a crash never leaves half a JPEG, and
a failed write (a full disk) leaves no temp file and no half row (safe_write.py).

Reader: real logs found in the wild differ (``;`` or ``,``; CRLF, LF or CR-only
line ends; absolute paths of other machines; corrupt fields such as ``___.01``;
duplicate rows; missing images).  It resolves each frame by its file name in
``IMG/`` next to the log, skips bad rows with counted warnings, and raises
:class:`LogFormatError` with a clear message for input that is not a log.
"""
from __future__ import annotations

import csv
import datetime as _dt
import io
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional

from safe_write import AppendFile, atomic_write, remove_quietly

log = logging.getLogger(__name__)

LOG_NAME = "robot_log.csv"  # the simulator's log file name
IMG_DIR = "IMG"  # frame folder beside the log
COLUMNS = ("Path", "SteerAngle", "Throttle", "Brake", "Speed",
           "X_Position", "Y_Position", "Pitch", "Yaw", "Roll")  # header, in order
SEPARATOR = ";"  # the simulator's csvSeparatorChar
LINE_END = "\r\n"  # the simulator runs on Windows/.NET: CRLF
FLOAT_DIGITS = 7  # .NET float.ToString() significant digits
FRAME_PREFIX = "robocam_"  # frame file name prefix
FRAME_TIME_FORMAT = "%Y_%m_%d_%H_%M_%S"  # frame file name stamp before _fff (ms)
MAX_WARNINGS_LOGGED = 10  # per reason, further warnings are only counted
SNIFF_BYTES = 4096  # bytes read to guess separator and line ends


class LogFormatError(ValueError):
    """The file is not a readable simulator log (message says why)."""


# --------------------------------------------------------------------------- writer
def format_float(value) -> str:
    """A number as .NET's float.ToString() prints it (e.g. ``2.093137E-07``, ``0``)."""
    v = float(value)
    if not math.isfinite(v):
        return "NaN" if math.isnan(v) else ("Infinity" if v > 0 else "-Infinity")
    if v == 0.0:
        return "0"
    return "%.*G" % (FLOAT_DIGITS, v)


def _angle_0_360(deg) -> float:
    """Unity euler angles are logged wrapped into [0, 360)."""
    a = float(deg) % 360.0
    return 0.0 if a >= 360.0 else a


def _unique_folder(folder: Path) -> Path:
    """``folder`` if empty/absent, else a fresh timestamped subfolder (never reuse data)."""
    if not folder.exists() or (folder.is_dir() and not any(folder.iterdir())):
        return folder
    if not folder.is_dir():
        raise LogFormatError(f"{folder} exists and is not a folder")
    stamp = _dt.datetime.now().strftime("run_%Y%m%d_%H%M%S")
    candidate, n = folder / stamp, 1
    while candidate.exists():
        candidate = folder / f"{stamp}_{n}"
        n += 1
    return candidate


class LogWriter:
    """Record frames + telemetry into a simulator-format log folder.

    ``LogWriter(folder)`` records into ``folder`` when it is absent or empty and
    into a new timestamped subfolder otherwise (``.folder`` tells where).
    ``write(jpeg_bytes, steer, throttle, brake, speed, x, y, pitch, yaw, roll,
    when=None)`` stores the JPEG bytes exactly as received; ``when`` is a
    ``datetime`` or POSIX seconds (default: now) used for the file name, which is
    bumped by a millisecond when it would repeat, so names stay unique and ordered.
    """

    def __init__(self, folder):
        self.folder = _unique_folder(Path(folder).expanduser().resolve())
        self.img_dir = self.folder / IMG_DIR
        self.img_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = self.folder / LOG_NAME
        # our own file (created exclusively), written a whole row at a time: a
        # failed write (full disk) is cut back, never left half a row
        self._csv = AppendFile(self.log_path, exclusive=True)
        try:
            self._csv.append((SEPARATOR.join(COLUMNS) + LINE_END).encode("utf-8"))
        except OSError:
            self._csv.close()
            remove_quietly(self.log_path)  # empty and ours: no litter from a failed start
            raise
        self._last_ms: Optional[int] = None
        self.frames = 0
        log.info("recording simulator log into %s", self.folder)

    def _frame_name(self, when) -> str:
        if when is None:
            when = _dt.datetime.now()
        elif not isinstance(when, _dt.datetime):
            when = _dt.datetime.fromtimestamp(float(when))
        ms = int(round(when.timestamp() * 1000.0))
        if self._last_ms is not None and ms <= self._last_ms:
            ms = self._last_ms + 1
        # files from another writer in the same folder (not ours): skip over them
        while True:
            stamp = _dt.datetime.fromtimestamp(ms / 1000.0)
            name = f"{FRAME_PREFIX}{stamp.strftime(FRAME_TIME_FORMAT)}_{ms % 1000:03d}.jpg"
            if not (self.img_dir / name).exists():
                break
            ms += 1
        self._last_ms = ms
        return name

    def write(self, jpeg_bytes: bytes, steer, throttle, brake, speed, x, y,
              pitch, yaw, roll, when=None) -> Path:
        """Store one frame and its log row; returns the image path."""
        if self._csv is None:
            raise ValueError("LogWriter is closed")
        name = self._frame_name(when)
        final = atomic_write(self.img_dir / name, bytes(jpeg_bytes))  # no temp file left on failure
        values = [steer, throttle, brake, speed, x, y,
                  _angle_0_360(pitch), _angle_0_360(yaw), _angle_0_360(roll)]
        row = SEPARATOR.join([str(final)] + [format_float(v) for v in values])
        try:
            self._csv.append((row + LINE_END).encode("utf-8"))
        except BaseException:
            remove_quietly(final)  # the frame we just wrote, without its row: keep log and IMG/ in step
            raise
        self.frames += 1
        return final

    def close(self):
        if self._csv is not None:
            self._csv.close()
            self._csv = None
            log.info("closed log %s (%d frames)", self.log_path, self.frames)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __del__(self):  # best effort; never raise from a finaliser
        try:
            self.close()
        except Exception:
            pass


# --------------------------------------------------------------------------- reader
@dataclass
class LogFrame:
    """One usable row: the resolved image path and the logged telemetry."""
    image_path: Path
    steer: float
    throttle: float
    brake: float
    speed: float
    x: float
    y: float
    pitch: float  # raw logged value, 0..360 (positive = nose down)
    yaw: float
    roll: float
    row_number: int  # 1-based data row in the file (header excluded)


@dataclass
class LogData:
    """Everything read from a log plus the counts of what was skipped and why."""
    log_path: Path
    separator: str
    frames: List[LogFrame] = field(default_factory=list)
    rows: int = 0  # data rows seen (non-blank)
    corrupt_rows: int = 0  # unparsable numbers / wrong field count
    duplicate_rows: int = 0  # repeated image file names (first kept)
    missing_images: int = 0  # image not found beside the log
    warnings: List[str] = field(default_factory=list)

    @property
    def skipped(self) -> int:
        return self.corrupt_rows + self.duplicate_rows + self.missing_images

    def summary(self) -> str:
        return (f"{self.log_path}: {self.rows} rows, {len(self.frames)} usable, "
                f"{self.corrupt_rows} corrupt, {self.duplicate_rows} duplicate, "
                f"{self.missing_images} missing images")


_NUMBER_RE = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def parse_number(text: str, decimal_comma: bool = False) -> Optional[float]:
    """A logged number (plain or scientific), or None when corrupt (``___.01``).

    ``decimal_comma``: the log came from a comma-decimal locale (``0,25`` in a
    ``;``-separated file, as .NET's float.ToString writes it on e.g. de-DE).
    """
    t = text.strip()
    if decimal_comma and "," in t and "." not in t:
        t = t.replace(",", ".", 1)
    if not _NUMBER_RE.match(t):
        return None
    v = float(t)
    return v if math.isfinite(v) else None


def resolve_log_path(path) -> Path:
    """robot_log.csv itself, or the one inside a log folder; LogFormatError when there is none."""
    p = Path(path).expanduser()
    if p.is_dir():
        p = p / LOG_NAME
    if not p.exists():
        raise LogFormatError(f"{p}: no such log file (give robot_log.csv or its folder)")
    if not p.is_file():
        raise LogFormatError(f"{p}: not a file")
    return p


def _read_text(p: Path) -> str:
    raw = p.read_bytes()
    if b"\x00" in raw[:SNIFF_BYTES]:
        raise LogFormatError(f"{p}: binary data, not a simulator log (robot_log.csv)")
    text = raw.decode("utf-8-sig", errors="replace")
    # normalise CRLF, CR-only and LF line ends to LF
    return text.replace("\r\n", "\n").replace("\r", "\n")


def _sniff_separator(header: str, p: Path) -> str:
    counts = {sep: header.count(sep) for sep in (";", ",", "\t")}
    sep = max(counts, key=counts.get)
    if counts[sep] == 0:
        raise LogFormatError(f"{p}: first line has no ';' or ',' separators: not a simulator log")
    return sep


def _check_header(fields: List[str], p: Path) -> dict:
    """Map column name -> index; the 10 simulator columns must all be present."""
    names = [f.strip() for f in fields]
    lower = {n.lower(): i for i, n in enumerate(names)}
    missing = [c for c in COLUMNS if c.lower() not in lower]
    if missing:
        raise LogFormatError(
            f"{p}: not a simulator log: header lacks {', '.join(missing)} "
            f"(expected {SEPARATOR.join(COLUMNS)}; got {SEPARATOR.join(names)[:200]!r})")
    return {c: lower[c.lower()] for c in COLUMNS}


def _looks_like_data_row(fields: List[str]) -> bool:
    """A first line that is really a data row: 10 fields, a .jpg path, then numbers."""
    return (len(fields) == len(COLUMNS) and fields[0].strip().lower().endswith(".jpg")
            and all(parse_number(f, True) is not None for f in fields[1:]))


def _frame_file_name(path_field: str) -> str:
    """File name of a logged path from any OS (``C:\\a\\b.jpg`` or ``/a/b.jpg``)."""
    return re.split(r"[\\/]", path_field.strip())[-1]


class _Warner:
    """Log the first few warnings of each kind, count all."""

    def __init__(self, data: LogData):
        self.data, self.seen = data, {}

    def __call__(self, kind: str, msg: str):
        n = self.seen.get(kind, 0) + 1
        self.seen[kind] = n
        self.data.warnings.append(msg)
        if n <= MAX_WARNINGS_LOGGED:
            log.warning(msg)
        elif n == MAX_WARNINGS_LOGGED + 1:
            log.warning("further %s warnings are counted, not shown", kind)


def read_log(path, require_images: bool = True) -> LogData:
    """Read a simulator log (file or folder holding robot_log.csv).

    Frames are resolved by file name inside ``IMG/`` beside the log (the logged
    absolute path usually belongs to another machine); the logged path itself is
    tried as a fallback.  Raises LogFormatError when the file is not a log or has
    no usable rows.
    """
    p = resolve_log_path(path)
    text = _read_text(p)
    lines = [ln for ln in text.split("\n") if ln.strip()]
    if not lines:
        raise LogFormatError(f"{p}: empty file, not a simulator log")
    sep = _sniff_separator(lines[0], p)
    header = next(csv.reader(io.StringIO(lines[0]), delimiter=sep))
    data = LogData(log_path=p, separator=sep)
    warn = _Warner(data)
    if _looks_like_data_row(header):  # header line lost (hand-edited or concatenated logs)
        warn("header", f"{p}: no header line; assuming the simulator's column order {SEPARATOR.join(COLUMNS)}")
        header = list(COLUMNS)
        lines = [SEPARATOR.join(COLUMNS)] + lines
    cols = _check_header(header, p)
    decimal_comma = sep != ","
    img_dir = p.parent / IMG_DIR
    seen_names = set()
    numeric = COLUMNS[1:]
    n_fields = len(header)
    for row_no, fields in enumerate(csv.reader(io.StringIO("\n".join(lines[1:])), delimiter=sep), 1):
        data.rows += 1
        if len(fields) != n_fields:
            data.corrupt_rows += 1
            warn("corrupt", f"row {row_no}: {len(fields)} fields, expected {n_fields}; skipped")
            continue
        values = {}
        bad = None
        for c in numeric:
            v = parse_number(fields[cols[c]], decimal_comma)
            if v is None:
                bad = (c, fields[cols[c]])
                break
            values[c] = v
        if bad is not None:
            data.corrupt_rows += 1
            warn("corrupt", f"row {row_no}: corrupt {bad[0]} field {bad[1]!r}; skipped")
            continue
        name = _frame_file_name(fields[cols["Path"]])
        if not name:
            data.corrupt_rows += 1
            warn("corrupt", f"row {row_no}: empty Path; skipped")
            continue
        if name in seen_names:
            data.duplicate_rows += 1
            warn("duplicate", f"row {row_no}: duplicate frame {name}; skipped")
            continue
        seen_names.add(name)
        image = img_dir / name
        if require_images and not image.is_file():
            alt = Path(fields[cols["Path"]].strip())
            if alt.is_file():
                image = alt
            else:
                data.missing_images += 1
                warn("missing", f"row {row_no}: image {name} not found in {img_dir}; skipped")
                continue
        data.frames.append(LogFrame(
            image_path=image, steer=values["SteerAngle"], throttle=values["Throttle"],
            brake=values["Brake"], speed=values["Speed"], x=values["X_Position"],
            y=values["Y_Position"], pitch=values["Pitch"], yaw=values["Yaw"],
            roll=values["Roll"], row_number=row_no))
    if data.rows == 0:
        raise LogFormatError(f"{p}: header only, no data rows")
    if not data.frames:
        raise LogFormatError(f"{p}: no usable rows ({data.summary()})")
    if data.skipped:
        log.warning("%s", data.summary())
    else:
        log.info("%s", data.summary())
    return data
