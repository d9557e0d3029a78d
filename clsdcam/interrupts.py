"""Ctrl-C held back while the solver's state is between two consistent points.

The driver turns a Ctrl-C inside its loop into the stop reason "interrupted" (the best iterate kept).
Between its runs the solver may be moving the iterates to another space (onto a spectral basis,
or back to the bands); a KeyboardInterrupt there would leave them half moved. Inside
``held_interrupt()`` a SIGINT is only recorded, and raised as KeyboardInterrupt when the block ends.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager


@contextmanager
def held_interrupt():
    """Run the block whole: a SIGINT during it becomes a KeyboardInterrupt after it (main thread, default
    handler only; elsewhere, or under another handler, nothing changes)."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    received = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        raise KeyboardInterrupt
