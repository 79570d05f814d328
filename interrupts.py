"""Ctrl-C must stop a mission even when it lands inside a compiled kernel.

Numba turns a KeyboardInterrupt raised while it loads or runs a cached kernel into a SystemError
whose cause is the interrupt; the "never raise, stop safely" handlers of the client would then
swallow the user's Ctrl-C and the mission would run on (seen in a fresh clone, cold numba cache).
"""

MAX_CHAIN = 32  # exception causes / contexts followed at most (a guard against cycles)


def caused_by_interrupt(exc: BaseException) -> bool:
    """True when exc is, or was raised because of, a KeyboardInterrupt."""
    seen = 0
    while exc is not None and seen < MAX_CHAIN:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return False


def reraise_interrupt(exc: BaseException) -> None:
    """Raise KeyboardInterrupt (from exc) when exc hides one; otherwise return."""
    if caused_by_interrupt(exc):
        raise KeyboardInterrupt from exc
