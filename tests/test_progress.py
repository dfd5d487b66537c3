"""The progress bar: drawn on a terminal, silent otherwise."""

from __future__ import annotations

import io
import os
import pty
import subprocess
import sys

import pytest
import shapes
from files import write_ply

from meshlab_sharp.progress import Progress


def test_bar_draws_steps_and_ends_the_line():
    stream = io.StringIO()
    bar = Progress(4, enabled=True, stream=stream)
    bar.step("scale 12")
    bar.step("scale 16", n=3)
    bar.close()
    text = stream.getvalue()
    assert "scale 12" in text and "1/4" in text
    assert "4/4" in text and "#" * 30 in text
    assert text.endswith("\n")


def test_disabled_bar_writes_nothing():
    stream = io.StringIO()
    bar = Progress(3, enabled=False, stream=stream)
    bar.step("x")
    bar.close()
    assert stream.getvalue() == ""


def _run_with_terminal_stderr(args):
    master, slave = pty.openpty()
    proc = subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", *args],
        stdout=subprocess.PIPE,
        stderr=slave,
        check=False,
    )
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    return proc.returncode, b"".join(chunks).decode()


@pytest.mark.slow
def test_cli_draws_the_bar_on_a_terminal_unless_quiet(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    code, err = _run_with_terminal_stderr(["detect", str(src)])
    assert code == 0
    # the library's stages, the label cut to the bar's 28 characters
    assert "neighbours and projected dis" in err and "[" in err and "#" in err
    code, err = _run_with_terminal_stderr(["detect", str(src), "--force", "--quiet"])
    assert code == 0
    assert err == ""


def test_an_error_after_the_bar_starts_on_its_own_line(tmp_path):
    src = write_ply(tmp_path / "c.ply", shapes.cube_grid_points(9))
    code, err = _run_with_terminal_stderr(["detect", str(src), "--scales", "12,500"])
    assert code == 1
    lines = err.splitlines()
    assert lines[-1].startswith("meshlab-sharp: error: ")  # not after the bar's last line
    assert "fewer than the largest scale" in lines[-1]


def test_close_without_drawing_writes_nothing_and_twice_once():
    stream = io.StringIO()
    bar = Progress(3, enabled=True, stream=stream)
    bar.close()
    assert stream.getvalue() == ""
    bar = Progress(3, enabled=True, stream=stream)
    bar.step("x")
    bar.close()
    bar.close()
    assert stream.getvalue().count("\n") == 1


def test_the_clock_moves_while_a_stage_runs():
    """The neighbourhood stage is one long call: the bar names it and redraws its clock
    instead of sitting at the last finished step."""
    import time

    stream = io.StringIO()
    bar = Progress(12, enabled=True, stream=stream, tick=0.02)
    bar.step("cleaned")
    bar.stage("neighbourhoods")
    time.sleep(0.3)
    bar.close()
    frames = stream.getvalue().split("\r")[1:]
    running = [f for f in frames if f.startswith("neighbourhoods...")]
    assert frames[0].startswith("cleaned") and len(running) >= 3
    clocks = [float(f.split()[-1].rstrip("s\n")) for f in running]
    assert clocks == sorted(clocks) and clocks[-1] > clocks[0]
    assert all(" 1/12 " in f for f in running)
    after = stream.getvalue()
    time.sleep(0.1)
    assert stream.getvalue() == after  # closed: no more redraws


def test_a_bar_without_a_tick_draws_only_when_told():
    """The library's own bars have no thread: nothing redraws after an error."""
    import threading
    import time

    stream = io.StringIO()
    before = threading.active_count()
    bar = Progress(4, enabled=True, stream=stream)
    bar.stage("neighbourhoods")
    drawn = stream.getvalue()
    time.sleep(0.2)
    assert stream.getvalue() == drawn and threading.active_count() == before
    bar.close()
