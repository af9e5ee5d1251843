"""Logging and progress of the ``calib`` commands.

Every message goes through the standard :mod:`logging` package under the ``calib``
logger (``calib.workflow``, ``calib.diagnosis.command``, ``calib.history`` ...), so a program that
imports calib configures it as it likes. The commands (``calib run``, ``calib diagnose``,
``calib demo``) call :func:`command_logging`, which for the duration of the command

- writes everything (DEBUG and up, with time stamps) to ``calib.log`` in the output
  folder (appended: a resumed run continues the same log);
- prints INFO and up on standard output as plain lines (``--quiet``: warnings and errors
  only; ``--verbose``: DEBUG too, e.g. every optimizer iteration and model call);
- shows a one-line progress display on the terminal for long loops (simulations,
  Jacobians, candidate fits) when standard error is a terminal, and nothing otherwise.

Library calls without :func:`command_logging` print their progress lines as before
(``progress=True``): :func:`say` prints only when no ``calib`` console handler is active.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import time
from pathlib import Path
from typing import Iterator

LOGGER = "calib"
LOG_FILE = "calib.log"
_state = {"console": None, "level": logging.INFO}


class _StdoutHandler(logging.StreamHandler):
    """A handler on whatever ``sys.stdout`` is at the time of the message (pytest swaps it)."""

    def __init__(self):
        super().__init__(sys.stdout)

    @property
    def stream(self):
        return sys.stdout

    @stream.setter
    def stream(self, value):
        pass


def add_output_arguments(parser, verbose_help: str) -> None:
    """``--no-history`` and the exclusive ``-v/--verbose``, ``-q/--quiet`` of the long-running commands."""
    parser.add_argument("--no-history", action="store_true", help="do not keep DIR/history (no resume possible)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("-v", "--verbose", action="store_true", help=verbose_help)
    group.add_argument("-q", "--quiet", action="store_true", help="print warnings and errors only")


def level_of(verbose: bool = False, quiet: bool = False) -> int:
    """The console level of the ``--verbose`` / ``--quiet`` flags."""
    return logging.DEBUG if verbose else logging.WARNING if quiet else logging.INFO


@contextlib.contextmanager
def command_logging(out_dir: str | Path | None, verbose: bool = False, quiet: bool = False) -> Iterator[Path | None]:
    """Log to the console and to ``out_dir/calib.log`` while the block runs.

    Parameters
    ----------
    out_dir : str or Path, optional
        Output folder of the command (created if missing); None: console only.
    verbose, quiet : bool
        Console level DEBUG / WARNING instead of INFO. The file always gets DEBUG.

    Yields
    ------
    Path or None
        The log file.
    """
    logger = logging.getLogger(LOGGER)
    console = _StdoutHandler()
    console.setLevel(level_of(verbose, quiet))
    console.setFormatter(logging.Formatter("%(message)s"))
    handlers = [console]
    path = None
    if out_dir is not None:
        path = Path(out_dir) / LOG_FILE
        path.parent.mkdir(parents=True, exist_ok=True)
        fileh = logging.FileHandler(path, mode="a", encoding="utf-8")
        fileh.setLevel(logging.DEBUG)
        fileh.setFormatter(logging.Formatter("%(asctime)s %(levelname)-7s %(name)s: %(message)s"))
        handlers.append(fileh)
    old_level, old_state = logger.level, dict(_state)
    logger.setLevel(logging.DEBUG)
    for h in handlers:
        logger.addHandler(h)
    _state.update(console=console, level=console.level)
    try:
        yield path
    finally:
        for h in handlers:
            logger.removeHandler(h)
            h.close()
        logger.setLevel(old_level)
        _state.update(old_state)


def say(logger: logging.Logger, line: str, progress: bool = True, level: int = logging.INFO) -> None:
    """Log ``line``; also print it when ``progress`` and no command console is active.

    Library calls (``run_workflow(progress=True)``) keep printing their progress lines;
    under :func:`command_logging` the console handler prints them (once).
    """
    logger.log(level, line)
    if progress and _state["console"] is None and level >= logging.INFO:
        print(line, flush=True)


class ProgressLine:
    """A one-line ``label: done/total (elapsed, ETA)`` display on a terminal.

    Drawn on standard error, only when it is a terminal and the console shows INFO;
    otherwise silent (the log file gets a DEBUG line when a loop ends). Redrawn at most
    every ``interval`` seconds.

    Parameters
    ----------
    interval : float
        Shortest time between redraws [s].
    """

    def __init__(self, interval: float = 0.2):
        self.interval = interval
        self._t0: dict[str, float] = {}
        self._last = 0.0
        self._drawn = False
        self.log = logging.getLogger(f"{LOGGER}.progress")

    @property
    def active(self) -> bool:
        stream = sys.stderr
        return (_state["console"] is not None and _state["level"] <= logging.INFO
                and hasattr(stream, "isatty") and stream.isatty())

    def __call__(self, done: int, total: int, label: str = "") -> None:
        now = time.monotonic()
        t0 = self._t0.setdefault(label, now)
        if done >= total:
            self._t0.pop(label, None)
            self.log.debug("%s: %d/%d in %.1f s", label, done, total, now - t0)
        if not self.active:
            return
        if done < total and now - self._last < self.interval:
            return
        self._last = now
        elapsed = now - t0
        eta = elapsed / done * (total - done) if done else float("nan")
        text = f"{label}: {done}/{total} ({elapsed:.0f} s" + (f", {eta:.0f} s left)" if done and done < total else ")")
        sys.stderr.write("\r\x1b[2K" + text[:150])
        if done >= total:
            sys.stderr.write("\r\x1b[2K")
        sys.stderr.flush()


#: The display the commands share.
progress_line = ProgressLine()
