"""Log writer and reader: simulator format, never destroys data, survives real-world logs."""
import datetime as dt
import logging

import pytest

from replay.log_format import (COLUMNS, LogFormatError, LogWriter, format_float, parse_number,
                               read_log)

HEADER = ";".join(COLUMNS)


def _row(name, sep=";", steer="0", speed="1.5", prefix="C:\\Users\\x\\run\\IMG\\"):
    return sep.join([prefix + name, steer, "1", "0", speed, "99.67", "85.59",
                     "0.0002364085", "56.82555", "2.093137E-07"])


def _make_log(folder, rows, images=(), sep=";", line_end="\r\n", header=None):
    (folder / "IMG").mkdir(parents=True, exist_ok=True)
    for name in images:
        (folder / "IMG" / name).write_bytes(b"\xff\xd8fake")
    head = header if header is not None else HEADER.replace(";", sep)
    text = line_end.join([head] + list(rows)) + line_end
    (folder / "robot_log.csv").write_bytes(text.encode())
    return folder / "robot_log.csv"


NAMES = [f"robocam_2017_05_02_11_16_21_{i:03d}.jpg" for i in range(5)]


def test_format_float_like_dotnet():
    assert format_float(0.0) == "0"
    assert format_float(1.0) == "1"
    assert format_float(2.0931372e-07) == "2.093137E-07"
    assert format_float(99.669991) == "99.66999"
    assert format_float(0.0002364085) == "0.0002364085"


def test_parse_number_rejects_corrupt_fields():
    assert parse_number("2.093137E-07") == pytest.approx(2.093137e-07)
    assert parse_number("-15") == -15
    for bad in ("___.01", "____.82", "", "abc", "1.2.3", "nan"):
        assert parse_number(bad) is None


def test_writer_writes_simulator_format_and_reader_reads_it(tmp_path):
    when = dt.datetime(2026, 1, 2, 3, 4, 5, 678000)
    with LogWriter(tmp_path / "run") as w:
        p1 = w.write(b"\xff\xd8one", 1.5, 0.2, 0, 1.25, 99.67, 85.5, -0.5, 56.8, 2e-7, when=when)
        p2 = w.write(b"\xff\xd8two", 0, 0, 1, 0, 99.67, 85.5, 0, 56.8, 0, when=when)
    assert p1.name == "robocam_2026_01_02_03_04_05_678.jpg"
    assert p2.name == "robocam_2026_01_02_03_04_05_679.jpg"  # same ms: still unique
    assert p1.read_bytes() == b"\xff\xd8one"
    raw = (tmp_path / "run" / "robot_log.csv").read_bytes()
    lines = raw.decode().split("\r\n")
    assert lines[0] == HEADER
    first = lines[1].split(";")
    assert first[0] == str(p1) and first[0].startswith("/")
    assert first[1:] == ["1.5", "0.2", "0", "1.25", "99.67", "85.5", "359.5", "56.8", "2E-07"]
    assert not list((tmp_path / "run" / "IMG").glob("*.tmp"))
    data = read_log(tmp_path / "run")
    assert [f.image_path.name for f in data.frames] == [p1.name, p2.name]
    assert data.frames[0].pitch == pytest.approx(359.5)


def test_writer_never_overwrites_existing_recording(tmp_path):
    folder = tmp_path / "rec"
    with LogWriter(folder) as w:
        w.write(b"a", 0, 0, 0, 0, 1, 2, 0, 0, 0)
    before = (folder / "robot_log.csv").read_bytes()
    with LogWriter(folder) as w2:
        w2.write(b"b", 0, 0, 0, 0, 1, 2, 0, 0, 0)
    assert w2.folder != folder and w2.folder.parent == folder
    assert (folder / "robot_log.csv").read_bytes() == before
    assert len(list((folder / "IMG").iterdir())) == 1


@pytest.mark.parametrize("line_end", ["\r\n", "\n", "\r"])
@pytest.mark.parametrize("sep", [";", ","])
def test_reader_line_ends_and_separators(tmp_path, line_end, sep):
    path = _make_log(tmp_path, [_row(n, sep=sep) for n in NAMES[:3]], NAMES[:3], sep, line_end)
    data = read_log(path)
    assert len(data.frames) == 3 and data.skipped == 0
    assert data.separator == sep
    assert data.frames[0].image_path == tmp_path / "IMG" / NAMES[0]
    assert data.frames[0].roll == pytest.approx(2.093137e-07)


def test_reader_counts_corrupt_duplicate_and_missing(tmp_path, caplog):
    rows = [_row(NAMES[0]), _row(NAMES[1], speed="___.01"), _row(NAMES[0]),
            _row(NAMES[2]), _row(NAMES[3]), "garbage;1;2"]
    path = _make_log(tmp_path, rows, NAMES[:3], line_end="\r")
    with caplog.at_level(logging.WARNING):
        data = read_log(path)
    assert [f.image_path.name for f in data.frames] == [NAMES[0], NAMES[2]]
    assert data.corrupt_rows == 2
    assert data.duplicate_rows == 1
    assert data.missing_images == 1
    assert "___.01" in caplog.text


@pytest.mark.parametrize("content", [b"", b"\r\n\r\n", HEADER.encode() + b"\r\n",
                                     b"a,b,c\n1,2,3\n", b"\x00\x01\x02binary",
                                     b"just some text without separators\n"])
def test_reader_rejects_non_logs(tmp_path, content):
    path = tmp_path / "robot_log.csv"
    path.write_bytes(content)
    with pytest.raises(LogFormatError):
        read_log(path)


def test_reader_rejects_missing_path_and_all_missing_images(tmp_path):
    with pytest.raises(LogFormatError):
        read_log(tmp_path / "nope.csv")
    with pytest.raises(LogFormatError):
        read_log(tmp_path)  # folder without robot_log.csv
    path = _make_log(tmp_path, [_row(NAMES[0])], images=())
    with pytest.raises(LogFormatError, match="no usable rows"):
        read_log(path)


def test_dimaga_log_parses_with_counted_skips(real_logs_dir):
    data = read_log(real_logs_dir / "dimaga")
    assert data.corrupt_rows >= 10
    assert len(data.frames) + data.skipped == data.rows
    assert len(data.frames) > 1000


def test_megalphian_log_resolves_foreign_paths(real_logs_dir):
    data = read_log(real_logs_dir / "megalphian")
    assert len(data.frames) == 6150
    assert data.duplicate_rows == 2


def test_reader_accepts_decimal_comma_locale(tmp_path):
    row = ";".join(["C:\\rec\\IMG\\" + NAMES[0], "-1,5", "0,2", "0", "1,25", "99,67", "85,59",
                    "359,5", "56,8", "2,093137E-07"])
    data = read_log(_make_log(tmp_path, [row], NAMES[:1]))
    f = data.frames[0]
    assert (f.steer, f.throttle, f.speed, f.x, f.pitch) == (-1.5, 0.2, 1.25, 99.67, 359.5)
    assert f.roll == pytest.approx(2.093137e-07)


def test_reader_accepts_a_log_without_header(tmp_path, caplog):
    path = _make_log(tmp_path, [_row(n) for n in NAMES[1:3]], NAMES[:3], header=_row(NAMES[0]))
    with caplog.at_level(logging.WARNING):
        data = read_log(path)
    assert [f.image_path.name for f in data.frames] == NAMES[:3]
    assert "no header" in caplog.text
