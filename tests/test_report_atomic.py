"""Ctrl-C during report writing never leaves a truncated file under a final name.

Unit tests interrupt the writers deterministically (an exception half-way through the
bytes); the end-to-end test sends SIGINT to a child process that writes the figures (SVG
and PNG) and the HTML report of a saved result in a loop, right after it announces each
write, and checks the folder after every interrupt: no temporary file left, every PNG
decodes, every SVG parses, the report ends with ``</html>``. A control run of the same
child writing straight to the final names shows that the check finds the truncated file.
"""

import os
import queue
import signal
import subprocess
import sys
import textwrap
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from twin_model import TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.measurements import synthesize
from calib.report import atomic
from calib.report import figures as F
from calib.report.atomic import atomic_path, is_temporary
from calib.report.html import write_report
from calib.report.interrupts import interrupts_as_keyboard_interrupt
from calib.types import nominal_vector

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def result():
    model = TwinModel(channels=("power", "thrust"))
    p_true = nominal_vector(model.parameters)
    p_true[:model.grid.n_lift] = 0.05 * np.sin(np.arange(model.grid.n_lift))
    meas = synthesize(model, p_true, twin_conditions(), relative_sigma={"power": 0.005, "thrust": 0.005}, seed=3)
    return Calibrator(model, meas, CalibrationSettings(sigma_bar=0.3), name="twin").run()


def broken_files(folder: Path) -> list[tuple[str, str]]:
    """(name, reason) of every file in ``folder`` that is temporary or not complete."""
    bad = []
    for p in sorted(folder.iterdir()):
        if is_temporary(p):
            bad.append((p.name, "temporary file left behind"))
            continue
        try:
            if p.suffix == ".png":
                with Image.open(p) as im:
                    im.load()
            elif p.suffix == ".svg":
                ET.parse(p)
            elif p.suffix == ".html":
                if not p.read_text(encoding="utf-8").rstrip().endswith("</html>"):
                    raise ValueError("no </html> at the end")
        except Exception as exc:  # noqa: BLE001 - any failure to read back is a broken file
            bad.append((p.name, f"{type(exc).__name__}: {exc}"))
    return bad


# ----------------------------------------------------------------------------- unit tests
def test_atomic_path_renames_in_the_same_folder(tmp_path, monkeypatch):
    moves = []
    real_replace = os.replace

    def spy(src, dst):
        moves.append((Path(src), Path(dst)))
        real_replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", spy)
    target = tmp_path / "sub" / "a.txt"
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent and is_temporary(tmp) and not target.exists()
        tmp.write_text("complete")
    assert target.read_text() == "complete"
    assert moves == [(tmp, target)]
    assert [p.name for p in target.parent.iterdir()] == ["a.txt"]


@pytest.mark.parametrize("exc", [KeyboardInterrupt, RuntimeError])
def test_interrupted_atomic_write_keeps_the_old_file_and_no_temporary(tmp_path, exc):
    target = tmp_path / "a.txt"
    target.write_text("old and complete")
    with pytest.raises(exc):
        with atomic_path(target) as tmp:
            tmp.write_text("new but only half")
            raise exc()
    assert target.read_text() == "old and complete"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_figure_interrupted_half_way_leaves_nothing_truncated(result, tmp_path):
    F.save_figure(F.plot_fit(result), tmp_path, "fit", formats=("png", "svg"))
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    fig = F.plot_fit(result)
    real_savefig = fig.savefig

    def savefig_interrupted(f, format, **kw):
        real_savefig(f, format=format, **kw)
        f.truncate(f.tell() // 2)                         # half the bytes are written...
        raise KeyboardInterrupt                           # ...when Ctrl-C arrives

    fig.savefig = savefig_interrupted
    for fmt in ("svg", "png"):
        with pytest.raises(KeyboardInterrupt):
            F.save_figure(fig, tmp_path, "fit", formats=(fmt,))
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    assert broken_files(tmp_path) == []
    # a figure never written before is simply absent
    with pytest.raises(KeyboardInterrupt):
        F.save_figure(fig, tmp_path, "new", formats=("svg",))
    assert not (tmp_path / "new.svg").exists() and broken_files(tmp_path) == []


def test_report_interrupted_half_way_keeps_the_previous_report(result, tmp_path, monkeypatch):
    path = write_report(tmp_path / "report.html", results={"twin": result})
    previous = path.read_text(encoding="utf-8")
    real_write_bytes = Path.write_bytes

    def write_half_then_interrupt(self, data):
        real_write_bytes(self, data[: len(data) // 2])
        raise KeyboardInterrupt

    monkeypatch.setattr(Path, "write_bytes", write_half_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        write_report(tmp_path / "report.html", title="another title", results={"twin": result})
    monkeypatch.undo()
    assert path.read_text(encoding="utf-8") == previous
    assert broken_files(tmp_path) == []


@pytest.fixture
def python_sigint_handler():
    """Python's default SIGINT handler for the test (a runner may have installed its own)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def test_a_sigint_is_deferred_to_the_end_of_the_block(python_sigint_handler):
    finished = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_as_keyboard_interrupt():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.2)                              # the default handler would raise here
            finished.append(True)
    assert finished == [True]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_second_sigint_interrupts_and_an_error_after_it_arrives_as_keyboard_interrupt(
        python_sigint_handler):
    # matplotlib can report a Ctrl-C inside a transform as its own ValueError
    with pytest.raises(KeyboardInterrupt) as info:
        with interrupts_as_keyboard_interrupt():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.2)
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1.0)                          # the handler raises here
            except KeyboardInterrupt:
                raise ValueError("Invalid affine transformation matrix")
    assert isinstance(info.value.__cause__, ValueError)
    # without a SIGINT an error stays what it is, and the handler is restored either way
    with pytest.raises(ValueError):
        with interrupts_as_keyboard_interrupt():
            raise ValueError("a real error")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


# ----------------------------------------------------------------------------- SIGINT end to end
CHILD = textwrap.dedent('''
    import faulthandler
    import signal
    import sys
    from pathlib import Path

    faulthandler.register(signal.SIGUSR1)        # the parent asks for the stack if the child stalls


    if sys.argv[3] == "atomic":
        # Python's own handler, as in a user's `calib` process (set explicitly: a child started from
        # a background job inherits SIGINT ignored). The figure writer defers a Ctrl-C only under
        # this handler; a handler of the test's own (it used to count SIGINTs) made it leave the
        # Ctrl-C alone, and one raised inside a matplotlib weakref callback stalled drawing (CI).
        signal.signal(signal.SIGINT, signal.default_int_handler)
    else:
        # the control writer dies by the signal where it stands, as a process without a handler does:
        # a KeyboardInterrupt raised inside one of matplotlib's weakref callbacks is swallowed and can
        # leave its transform tree half-updated, after which drawing hung (seen once in CI)
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    import contextlib

    import matplotlib
    matplotlib.use("Agg")
    from calib.report import figures as F
    from calib.report.interrupts import interrupts_as_keyboard_interrupt
    from calib.report.html import write_report
    from calib.calibration.result_files import load_result

    result_dir, out, mode, rounds = sys.argv[1], Path(sys.argv[2]), sys.argv[3], int(sys.argv[4])
    res = load_result(result_dir)
    out.mkdir(parents=True, exist_ok=True)
    NAMES = ("eigenshapes_lift", "fit", "polars")     # the heaviest figures, and a quick pass


    def save(fig, name, fmt):
        print(f"start {name}.{fmt}", flush=True)
        if mode == "atomic":
            F.save_figure(fig, out, name, formats=(fmt,))
        else:                                   # control: straight to the final name
            fig.savefig(out / f"{name}.{fmt}", format=fmt)


    def one_pass():
        figs = {}
        for name in NAMES:
            # drawn under the same deferral as calib.report.figures.write_figures draws them
            with interrupts_as_keyboard_interrupt() if mode == "atomic" else contextlib.nullcontext():
                fig = F.FIGURES[name](res)
            for fmt in ("svg", "png"):
                save(fig, name, fmt)
            figs[name] = {"png": out / f"{name}.png"}
        print("start report.html", flush=True)
        if mode == "atomic":
            write_report(out / "report.html", results={res.name: res}, figures={res.name: figs})


    caught = 0
    print("ready", flush=True)
    while True:
        try:
            one_pass()
            print("pass", flush=True)
        except KeyboardInterrupt as exc:
            # inside the deferral, a Ctrl-C that surfaced inside matplotlib as another error (seen:
            # ValueError "Invalid affine transformation matrix") arrives as KeyboardInterrupt too
            caught += 1
            if caught >= rounds:
                print("interrupted, exiting", flush=True)
                raise KeyboardInterrupt from exc   # the last Ctrl-C ends the process, as a user's would
            print("interrupted", flush=True)
            sys.stdin.readline()                # wait until the parent has checked the folder
''')


class Child:
    """The writer child with its stdout read by a thread (lines in a queue)."""

    def __init__(self, tmp_path: Path, result_dir: Path, out: Path, mode: str, rounds: int):
        script = tmp_path / "writer.py"
        script.write_text(CHILD)
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.proc = subprocess.Popen([sys.executable, str(script), str(result_dir), str(out), mode, str(rounds)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env, cwd=str(tmp_path))
        self.lines: queue.Queue = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self):
        for line in self.proc.stdout:
            self.lines.put(line.rstrip("\n"))
        self.lines.put(None)

    def read_until(self, wanted, timeout: float = 60.0) -> list[str]:
        """Lines up to and including the first one ``wanted(line)`` accepts."""
        seen, deadline = [], time.monotonic() + timeout
        while True:
            try:
                line = self.lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                self.proc.send_signal(signal.SIGUSR1)
                time.sleep(1.0)
                self.kill()
                pytest.fail(f"writer child silent for {timeout} s after {seen[-5:]}; its stack:\n"
                            f"{self.proc.stderr.read()[-4000:]}")
            if line is None:
                err = self.proc.stderr.read()
                pytest.fail(f"writer child ended early after {seen[-5:]}:\n{err[-2000:]}")
            seen.append(line)
            if wanted(line):
                return seen

    def interrupt_at(self, marker: str, delay: float) -> str:
        """SIGINT ``delay`` s after the child announces ``marker``; returns the write it interrupted."""
        self.read_until(lambda line: line == marker)
        time.sleep(delay)
        self.proc.send_signal(signal.SIGINT)
        lines = self.read_until(lambda line: line.startswith("interrupted"))
        self.last = lines[-1]
        starts = [line for line in lines if line.startswith("start ")]
        return starts[-1][6:] if starts else marker[6:]

    def drain(self, timeout: float = 60.0) -> list[str]:
        """The lines the child writes until its output ends."""
        seen, deadline = [], time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                break
            if line is None:
                return seen
            seen.append(line)
        self.kill()
        pytest.fail(f"writer child still writing {timeout} s after the signal: {seen[-5:]}")

    def resume(self):
        self.proc.stdin.write("\n")
        self.proc.stdin.flush()

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=30)


@pytest.fixture(scope="module")
def saved_result(result, tmp_path_factory):
    folder = tmp_path_factory.mktemp("saved")
    result.save(folder)
    return folder


def test_sigint_during_report_writing_leaves_no_truncated_file(saved_result, tmp_path):
    out = tmp_path / "out"
    # interrupt SVG and PNG writes of the heaviest figures and the report, at different
    # delays after the write starts
    targets = [("start eigenshapes_lift.svg", 0.05), ("start polars.png", 0.03), ("start report.html", 0.0),
               ("start fit.svg", 0.02)]
    child = Child(tmp_path, saved_result, out, "atomic", rounds=len(targets))
    try:
        child.read_until(lambda line: line == "pass")          # one complete set first
        complete = sorted(p.name for p in out.iterdir())
        assert complete == ["eigenshapes_lift.png", "eigenshapes_lift.svg", "fit.png", "fit.svg", "polars.png",
                            "polars.svg", "report.html"]
        interrupted = []
        for k, (marker, delay) in enumerate(targets):
            interrupted.append(child.interrupt_at(marker, delay))
            assert sorted(p.name for p in out.iterdir() if not is_temporary(p)) == complete
            if k < len(targets) - 1:
                assert broken_files(out) == [], f"after Ctrl-C during {interrupted[-1]}"
                child.resume()
        child.proc.wait(timeout=60)
    finally:
        child.kill()
    assert child.proc.returncode != 0 and child.last == "interrupted, exiting"   # the last Ctrl-C ended it
    assert broken_files(out) == [], f"after the final Ctrl-C during {interrupted[-1]}"
    assert sorted(p.name for p in out.iterdir()) == complete
    assert any(name.endswith(".svg") for name in interrupted)               # SVGs were hit mid-write


def test_the_sigint_check_finds_a_writer_that_writes_to_final_names(saved_result, tmp_path):
    """Control: without the temporary name, a SIGINT half-way through a write leaves a truncated
    SVG (the control child has no SIGINT handler and dies where it stands)."""
    out = tmp_path / "out"
    child = Child(tmp_path, saved_result, out, "naive", rounds=1)
    try:
        child.read_until(lambda line: line == "ready")
        child.read_until(lambda line: line == "start eigenshapes_lift.svg")
        target, deadline = out / "eigenshapes_lift.svg", time.monotonic() + 10.0
        while not target.exists() and time.monotonic() < deadline:    # the write has begun
            time.sleep(0.001)
        child.proc.send_signal(signal.SIGINT)
        rest = child.drain()
        child.proc.wait(timeout=60)
    finally:
        child.kill()
    assert child.proc.returncode == -signal.SIGINT
    assert not [line for line in rest if line.startswith("start ")], rest   # it died in that write
    assert ("eigenshapes_lift.svg" in [name for name, _ in broken_files(out)]), broken_files(out)
