"""Outputs never replace what is not a regular file, and are claimed against other runs.

An existing character device, FIFO, or a symbolic link to one is written through (its
node stays); a socket or block device is refused. Without ``--force`` each new output is
claimed (an exclusive, locked placeholder) before any work, so of two runs writing the
same outputs at once one wins and the other fails in one line, and the files on disk
always come from one run.
"""

from __future__ import annotations

import os
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import shapes
from files import write_ply

import meshlab_sharp
from meshlab_sharp.cli import PAUSE_ENV

CLOUD = shapes.cube_grid_points(9)


def run_detect(*args: object, **kwargs) -> subprocess.CompletedProcess:
    """``meshlab-sharp detect ARGS`` in a child process (output captured as text)."""
    return subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", "detect", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        **kwargs,
    )


def one_error_line(proc: subprocess.CompletedProcess) -> str:
    """The one ``meshlab-sharp: error:`` line of a run that failed with status 1."""
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("meshlab-sharp: error: "), proc.stderr
    return lines[0]


@pytest.fixture(scope="module")
def expected_indices() -> str:
    """The features of :data:`CLOUD`, as ``--indices`` writes them."""
    mask = meshlab_sharp.detect(CLOUD).mask
    return "".join(f"{i}\n" for i in np.flatnonzero(mask))


@pytest.fixture
def cloud(tmp_path: Path) -> Path:
    return write_ply(tmp_path / "c.ply", CLOUD)


def _is_dev_null(path: Path) -> bool:
    st = os.stat(path)
    return stat.S_ISCHR(st.st_mode) and os.major(st.st_rdev) == 1 and os.minor(st.st_rdev) == 3


@pytest.mark.parametrize("force", [True, False])
def test_dev_null_is_written_through_with_or_without_force(cloud, force):
    assert _is_dev_null(Path("/dev/null"))
    proc = run_detect(cloud, "-q", "--indices", "/dev/null", *(["--force"] if force else []))
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert _is_dev_null(Path("/dev/null"))
    assert not os.path.islink("/dev/null")


@pytest.mark.parametrize("via", ["/dev/stdout", "/dev/fd/1", "link to /proc/self/fd/1"])
def test_stdout_receives_the_indices(tmp_path, cloud, expected_indices, via):
    path = Path(via)
    if via.startswith("link"):
        path = tmp_path / "out.txt"
        path.symlink_to("/proc/self/fd/1")
    proc = run_detect(cloud, "-q", "--indices", path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == expected_indices
    assert os.path.islink(path) and os.path.islink("/dev/stdout")


def test_dev_stdout_redirected_to_a_file_writes_into_that_file(tmp_path, cloud):
    """``--indices /dev/stdout > out.txt``: out.txt (a regular file, existing) receives
    the indices then the summary, in order, without --force; nothing is replaced."""
    out = tmp_path / "out.txt"
    with out.open("w") as fh:
        proc = subprocess.run(
            [sys.executable, "-m", "meshlab_sharp", "detect", str(cloud)]
            + ["--indices", "/dev/stdout", "--scales", "12,16"],
            stdout=fh,
            stderr=subprocess.PIPE,
            text=True,
            timeout=120,
            check=False,
        )
    assert (proc.returncode, proc.stderr) == (0, "")
    expected = meshlab_sharp.detect(CLOUD, scales=[12, 16]).mask
    indices = "".join(f"{i}\n" for i in np.flatnonzero(expected))
    text = out.read_text()
    assert text.startswith(indices)
    assert text[len(indices) :].startswith("  k =  12: threshold")
    assert os.path.islink("/dev/stdout")


@pytest.mark.skipif(os.geteuid() != 0, reason="mknod of a character device needs root")
@pytest.mark.parametrize("force", [True, False])
def test_a_device_node_stays_a_device(tmp_path, cloud, force):
    node = tmp_path / "nulldev"
    os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    proc = run_detect(
        cloud, "-q", "--indices", node, "-o", tmp_path / "nd.ply", *["--force"][:force]
    )
    assert proc.returncode == 0, proc.stderr
    assert _is_dev_null(node)
    assert (tmp_path / "nd.ply").read_bytes().startswith(b"ply\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply", "nd.ply", "nulldev"]


def test_a_fifo_is_written_through_to_its_reader(tmp_path, cloud, expected_indices):
    fifo = tmp_path / "features.fifo"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    proc = run_detect(cloud, "-q", "--force", "--indices", fifo)
    reader.join(timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert received == [expected_indices.encode()]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_link_to_dev_null_stays_a_link(tmp_path, cloud):
    link = tmp_path / "report.json"
    link.symlink_to("/dev/null")
    proc = run_detect(cloud, "-q", "--force", "--report", link)
    assert proc.returncode == 0, proc.stderr
    assert os.readlink(link) == "/dev/null"
    assert _is_dev_null(Path("/dev/null"))


@pytest.mark.slow
def test_a_link_to_a_regular_file_stays_a_link_and_its_file_is_replaced(
    tmp_path, cloud, expected_indices
):
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / "f.txt"
    target.write_text("old\n")
    link = tmp_path / "f.txt"
    link.symlink_to(target)
    assert "f.txt exists; use --force" in one_error_line(run_detect(cloud, "-q", "--indices", link))
    assert target.read_text() == "old\n"
    proc = run_detect(cloud, "-q", "--force", "--indices", link)
    assert proc.returncode == 0, proc.stderr
    assert os.readlink(link) == str(target)
    assert target.read_text() == expected_indices
    assert sorted(p.name for p in (tmp_path / "real").iterdir()) == ["f.txt"]


def test_a_socket_is_refused(tmp_path, cloud):
    path = tmp_path / "s.txt"
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(path))
        line = one_error_line(run_detect(cloud, "-q", "--force", "--indices", path))
        assert line == f"meshlab-sharp: error: cannot write {path}: it is a socket"
        assert stat.S_ISSOCK(os.lstat(path).st_mode)
    assert not (tmp_path / "c_sharp.ply").exists()


def _start(args: list[object], pause: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "meshlab_sharp", "detect", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, PAUSE_ENV: str(pause)},
    )


def _wait_for(path: Path, proc: subprocess.Popen) -> None:
    end = time.monotonic() + 60
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < end, "the run never reached its renames"
        time.sleep(0.02)


@pytest.mark.slow
def test_a_second_run_fails_while_the_first_holds_the_outputs(tmp_path, cloud):
    other = write_ply(tmp_path / "other.ply", shapes.cube_grid_points(11))
    out, txt = tmp_path / "race.ply", tmp_path / "race.txt"
    pause = tmp_path / "flag" / "paused"
    pause.parent.mkdir()
    first = _start([cloud, "-q", "-o", out, "--indices", txt], pause)
    _wait_for(pause, first)
    assert out.read_bytes() == b"" and txt.read_bytes() == b""  # the placeholders
    second = run_detect(other, "-q", "-o", out, "--indices", txt)
    line = one_error_line(second)
    assert line.endswith("race.ply is being written by another meshlab-sharp run"), line
    pause.unlink()
    assert first.wait(timeout=60) == 0, first.communicate()
    first.communicate()
    assert len(meshlab_sharp.load(out).vertices) == len(CLOUD)
    assert txt.read_text() != ""
    # once written, the outputs are files like any other
    assert "race.ply exists; use --force" in one_error_line(run_detect(other, "-q", "-o", out))


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_run_removes_its_placeholders(tmp_path, cloud, sig):
    pause = tmp_path / "flag" / "paused"
    pause.parent.mkdir()
    proc = _start([cloud, "-q", "--indices", tmp_path / "c.txt"], pause)
    _wait_for(pause, proc)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig
    assert err == f"meshlab-sharp: interrupted by {sig.name}; no output was written\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.ply", "flag"]


def test_a_failed_run_removes_its_placeholders(tmp_path):
    src = write_ply(tmp_path / "few.ply", shapes.cube_grid_points(2))  # 8 points < k
    one_error_line(run_detect(src, "-q", "--indices", tmp_path / "few.txt"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["few.ply"]


@pytest.mark.slow
def test_two_runs_at_once_leave_one_runs_outputs(tmp_path):
    """Two 200,000-point runs started together, neither with --force: one writes both
    outputs, the other fails in one line and writes nothing."""
    rng = np.random.default_rng(3)
    inputs = []
    for i, n in enumerate((200_000, 150_000)):
        points = rng.random((n, 3)) * [1.0, 2.0, 3.0]
        inputs.append(write_ply(tmp_path / f"in{i}.ply", points, binary=True))
    out, txt = tmp_path / "race.ply", tmp_path / "race.txt"
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "meshlab_sharp", "detect", str(src), "-q"]
            + ["-o", str(out), "--indices", str(txt), "--scales", "12,16"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for src in inputs
    ]
    results = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    codes = sorted(code for code, _, _ in results)
    assert codes == [0, 1], results
    winner = next(i for i, (code, _, _) in enumerate(results) if code == 0)
    loser_err = results[1 - winner][2].splitlines()
    assert len(loser_err) == 1 and loser_err[0].startswith("meshlab-sharp: error: "), loser_err
    expected = meshlab_sharp.detect(inputs[winner], scales=[12, 16])
    assert len(meshlab_sharp.load(out).vertices) == len(expected.mask)
    assert txt.read_text() == "".join(f"{i}\n" for i in np.flatnonzero(expected.mask))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
