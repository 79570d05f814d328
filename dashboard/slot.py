"""A one-item mailbox between the control loop and the web page.

Why: the control loop must never wait for a browser.  It overwrites the newest
state (older ones are simply dropped) and returns at once; page threads wait on
the slot for anything newer than what they last sent, at their own pace.
"""
from __future__ import annotations

import threading
from typing import Any, Optional, Tuple


class LatestSlot:
    """Holds the newest item and a version number that grows by one per put."""

    def __init__(self):
        self._cond = threading.Condition()
        self._item: Any = None
        self._version = 0
        self.closed = False

    def put(self, item) -> int:
        """Replace the held item (never blocks for long: one lock, no I/O)."""
        with self._cond:
            self._item = item
            self._version += 1
            self._cond.notify_all()
            return self._version

    def latest(self) -> Tuple[int, Any]:
        with self._cond:
            return self._version, self._item

    def wait_newer(self, version: int, timeout: float) -> Optional[Tuple[int, Any]]:
        """(version, item) once something newer than ``version`` is held, None on timeout or close."""
        with self._cond:
            if not self._cond.wait_for(lambda: self._version > version or self.closed, timeout):
                return None
            if self.closed:
                return None
            return self._version, self._item

    def close(self):
        with self._cond:
            self.closed = True
            self._cond.notify_all()
