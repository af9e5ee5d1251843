"""Ctrl-C while figures are drawn always arrives as :class:`KeyboardInterrupt`.

Python raises ``KeyboardInterrupt`` from its SIGINT handler at the next bytecode, which can
be inside a callback of compiled code. Matplotlib's C++ converters call back into Python
(a transform's ``get_matrix``) and report any failure there as their own error, so a
Ctrl-C during drawing could surface as ``ValueError: Invalid affine transformation
matrix`` and print a traceback instead of stopping cleanly. Inside
:func:`interrupts_as_keyboard_interrupt`, any exception raised after a SIGINT is re-raised
as ``KeyboardInterrupt`` (chained to the original).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator


@contextlib.contextmanager
def interrupts_as_keyboard_interrupt() -> Iterator[None]:
    """Within the block, an exception that follows a SIGINT is raised as ``KeyboardInterrupt``.

    Only active in the main thread and while Python's default SIGINT handler is installed
    (a program with its own handler, or with SIGINT ignored, is left alone). The previous
    handler is restored on leaving the block.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    received = []

    def on_sigint(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, on_sigint)
    try:
        yield
    except KeyboardInterrupt:
        raise
    except BaseException as exc:
        if received:
            raise KeyboardInterrupt(f"interrupted (surfaced as {type(exc).__name__}: {exc})") from exc
        raise
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
