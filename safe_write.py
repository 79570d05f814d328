"""Writing files so that a failed write (a full disk, a quota, a pulled drive)
leaves neither litter nor half a file.

Why: the recorder writes thousands of frames and ``--save-map`` rewrites the
map every few seconds; on a full disk each failure used to leave a
``.*.tmp`` behind.  Here a whole file is written to a temp file beside the
target and renamed over it, and the temp file is removed on *any* failure; a
line appended to a log is either all there or truncated away again.

All writes go through ``os_write`` (a module attribute) so tests can inject a
full disk without mounting one.
"""
from __future__ import annotations

import os
from pathlib import Path

os_write = os.write  # the one place bytes reach the disk (tests replace it to simulate ENOSPC)
FILE_MODE = 0o644  # permissions of files we create (before the umask)


def write_all(fd: int, data: bytes) -> None:
    """Write every byte of ``data`` or raise (a short write is retried, as POSIX allows)."""
    view = memoryview(data)
    while view:
        written = os_write(fd, view)
        if written <= 0:
            raise OSError(f"write returned {written}")
        view = view[written:]


def remove_quietly(path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def temp_path(path: Path) -> Path:
    """The temp name used beside ``path`` (hidden, so a reader listing the folder skips it)."""
    return path.with_name(f".{path.name}.tmp")


def atomic_write(path, data: bytes) -> Path:
    """Replace ``path`` by ``data`` atomically; on failure nothing new is left
    on disk and the old file (if any) is untouched."""
    path = Path(path)
    tmp = temp_path(path)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, FILE_MODE)
        try:
            write_all(fd, data)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        remove_quietly(tmp)
        raise
    return path


class AppendFile:
    """A file written by whole lines: ``append(data)`` adds all of ``data`` or,
    when the write fails, cuts the file back to where it was and raises."""

    def __init__(self, path, exclusive: bool = True):
        self.path = Path(path)
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | (os.O_EXCL if exclusive else 0)
        self._fd = os.open(self.path, flags, FILE_MODE)

    def append(self, data: bytes) -> None:
        if self._fd is None:
            raise ValueError(f"{self.path} is closed")
        start = os.lseek(self._fd, 0, os.SEEK_END)
        try:
            write_all(self._fd, data)
        except BaseException:
            try:
                os.ftruncate(self._fd, start)
            except OSError:
                pass
            raise

    @property
    def closed(self) -> bool:
        return self._fd is None

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)
