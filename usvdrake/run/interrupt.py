"""Stopping a run cleanly on SIGINT (Ctrl-C) or SIGTERM: :func:`stop_on_signals` replaces the
default handlers (a traceback from wherever Python was, and no outputs) with one that only asks
the simulation loop to stop; the runner then writes every output, marked ``interrupted``, and the
command exits 128 + the signal's number (130, 143). A second signal while stopping raises
KeyboardInterrupt, so a stuck run can still be broken off."""

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_received: list[int] = []  # the signal that asked to stop, if any (a list: set from the handler)


def _ask_to_stop(signum, frame) -> None:
    if _received:  # asked twice: stop now, without outputs
        raise KeyboardInterrupt
    _received.append(signum)


def stop_signal() -> int | None:
    """The number of the signal that asked the run to stop, or None."""
    return _received[0] if _received else None


def stop_reason() -> str | None:
    """``"SIGINT"`` / ``"SIGTERM"`` once a run was asked to stop, else None."""
    s = stop_signal()
    return None if s is None else signal.Signals(s).name


def request_stop(signum: int = signal.SIGINT) -> None:
    """Ask the running simulation to stop as if ``signum`` had arrived (tests, notebooks)."""
    if not _received:
        _received.append(signum)


@contextmanager
def stop_on_signals() -> Iterator[None]:
    """While inside, SIGINT and SIGTERM ask the simulation to stop instead of killing the
    process (main thread only: Python delivers signals there; elsewhere it does nothing)."""
    _received.clear()
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, _ask_to_stop) for s in _SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
