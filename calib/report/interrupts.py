"""Ctrl-C while figures are drawn stops cleanly, after the figure in hand.

Python raises ``KeyboardInterrupt`` from its SIGINT handler at the next bytecode, which can
be anywhere inside matplotlib: in a callback of compiled code (a transform's
``get_matrix``, reported by the C++ converter as ``ValueError: Invalid affine
transformation matrix``) or in a weakref callback, where Python can only print "Exception
ignored in ..." and the Ctrl-C is lost while drawing carries on in a half-updated state
(a CI run saw the SVG writer stall there for a minute).

Inside :func:`interrupts_as_keyboard_interrupt` the first Ctrl-C is therefore *deferred*:
it is recorded, the figure in hand is finished (about a second), and ``KeyboardInterrupt``
is raised when the block ends. A second Ctrl-C interrupts at once; any exception that
follows it is re-raised as ``KeyboardInterrupt`` (chained to the original). Files are
written through temporary names either way (:mod:`calib.report.atomic`), so an interrupt
never leaves a truncated file under a final name.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator


@contextlib.contextmanager
def interrupts_as_keyboard_interrupt() -> Iterator[None]:
    """Within the block, Ctrl-C is deferred to its end; a second Ctrl-C interrupts at once.

    Only active in the main thread and while Python's default SIGINT handler is installed
    (a program with its own handler, an enclosing block of this kind, or SIGINT ignored are
    left alone). The previous handler is restored on leaving the block.

    Raises
    ------
    KeyboardInterrupt
        At the end of the block if a SIGINT arrived during it; at once on the second one.
    """
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    received = []

    def on_sigint(signum, frame):
        received.append(signum)
        if len(received) > 1:
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
    if received:
        raise KeyboardInterrupt("interrupted (after finishing the figure in hand)")
