"""Logging and progress (calib.logs): standard logging under "calib", OUT/calib.log,
--verbose / --quiet, a progress line on terminals only."""

from __future__ import annotations

import io
import logging

import pytest

from calib.logs import LOG_FILE, ProgressLine, command_logging, say
from test_resume import small_workflow


class FakeTerminal(io.StringIO):
    def __init__(self, tty: bool):
        super().__init__()
        self.tty = tty

    def isatty(self):
        return self.tty


def test_command_logging_writes_the_log_file_and_filters_the_console(tmp_path, capsys):
    log = logging.getLogger("calib.test")
    with command_logging(tmp_path, quiet=True) as path:
        say(log, "an info line")
        log.debug("a debug line")
        log.warning("a warning")
    out = capsys.readouterr().out
    assert out == "a warning\n"          # --quiet: warnings only, printed once
    text = path.read_text()
    assert path == tmp_path / LOG_FILE
    assert "INFO    calib.test: an info line" in text and "DEBUG   calib.test: a debug line" in text
    with command_logging(tmp_path, verbose=True):
        log.debug("second run")
    assert capsys.readouterr().out == "second run\n"
    assert "second run" in path.read_text() and "an info line" in path.read_text()    # appended
    # outside a command: nothing stays attached, library progress lines print as before
    assert not logging.getLogger("calib").handlers
    say(log, "library line")
    say(log, "not printed", progress=False)
    assert capsys.readouterr().out == "library line\n"


@pytest.mark.parametrize("tty", [True, False])
def test_progress_line_only_on_a_terminal(monkeypatch, tmp_path, tty):
    term = FakeTerminal(tty)
    monkeypatch.setattr("sys.stderr", term)
    bar = ProgressLine(interval=0.0)
    with command_logging(tmp_path):
        for k in range(1, 5):
            bar(k, 4, "jacobian")
    text = term.getvalue()
    if tty:
        assert "jacobian: 1/4" in text and "jacobian: 4/4" in text and text.endswith("\r\x1b[2K")
    else:
        assert text == ""
    assert "jacobian: 4/4" in (tmp_path / LOG_FILE).read_text()
    term2 = FakeTerminal(True)
    monkeypatch.setattr("sys.stderr", term2)
    with command_logging(tmp_path, quiet=True):           # --quiet: no progress line either
        bar(1, 2, "x")
    assert term2.getvalue() == ""


# `calib run --verbose` (iterations printed, every model call in calib.log) and `--quiet` (nothing
# printed) are checked on the runs of tests/test_resume.py::test_killed_calibration_resumes_to_...


def test_run_errors_reach_the_log_file(tmp_path, capsys):
    from calib.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text(small_workflow(tmp_path).read_text().replace('name = "phase_vi"', 'name = "no_such_rotor"'))
    out = tmp_path / "o"
    assert main(["run", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no_such_rotor" in err
    assert "no_such_rotor" in (out / LOG_FILE).read_text()
