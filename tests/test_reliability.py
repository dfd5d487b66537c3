"""Hostile conditions end in exit 0 or one line, within a bounded time, leaving nothing.

Each case runs the command line as its own process: out of memory under a real address
space limit, signals from the first instructions, Dask with real schedulers, workers
and sockets that are not schedulers, a killed out-of-core run's scratch, bounds checked
before any work; and the library's errors for wrong arguments.
"""

from __future__ import annotations

import _thread
import contextlib
import io
import os
import re
import resource
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pymeshlab
import pytest
import shapes

import meshlab_sharp
from meshlab_sharp.address_space import MARGIN
from meshlab_sharp.errors import ScratchError
from meshlab_sharp.io.source import PointSource
from meshlab_sharp.progress import Progress
from meshlab_sharp.tiles.layout import build_layout
from meshlab_sharp.tiles.store import SCRATCH_PREFIX, Store, remove_stale_scratch

ONE_LINE = re.compile(r"meshlab-sharp: error: [^\n]+\n")


def _cli(*args: object, env: dict[str, str] | None = None, timeout: float = 120, **kw):
    """``python -m meshlab_sharp ARGS`` to its end: the CompletedProcess."""
    return subprocess.run(
        [sys.executable, "-m", "meshlab_sharp", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, **(env or {})},
        **kw,
    )


def _one_error_line(proc: subprocess.CompletedProcess, *fragments: str) -> None:
    """Exit 1 with exactly one ``meshlab-sharp: error:`` line holding ``fragments``."""
    assert proc.returncode == 1, proc.stderr
    assert ONE_LINE.fullmatch(proc.stderr), proc.stderr
    for fragment in fragments:
        assert fragment in proc.stderr, proc.stderr


def _cube_cloud(n: int, seed: int = 1) -> np.ndarray:
    """``n`` random points on the faces of the unit cube."""
    rng = np.random.default_rng(seed)
    p = rng.random((n, 3))
    p[np.arange(n), rng.integers(0, 3, n)] = rng.integers(0, 2, n)
    return p


def _binary_ply(path: Path, points: np.ndarray) -> Path:
    """Write ``points`` as a binary PLY of doubles."""
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\n"
        "property double x\nproperty double y\nproperty double z\nend_header\n"
    )
    path.write_bytes(head.encode() + points.astype("<f8").tobytes())
    return path


@pytest.fixture(scope="module")
def big_cloud(tmp_path_factory) -> Path:
    """A 1,000,000-point cloud as a binary PLY."""
    return _binary_ply(tmp_path_factory.mktemp("big") / "cube1m.ply", _cube_cloud(1_000_000))


# ---------------------------------------------------------------- out of memory


#: The line that refuses an address-space limit below what loading the libraries needs.
_LOADING = re.compile(
    r"meshlab-sharp: error: out of memory: loading the libraries needs about ([0-9]+) MB "
    r"of address space, and the limit \(ulimit -v\) is ([0-9]+) MB; raise it to at least "
    r"ulimit -v [0-9]+ \(KB\), or unlimited[^\n]*\n"
)


@pytest.mark.slow
@pytest.mark.parametrize(
    "options, limits_gb",
    [
        ((), (0.55, 0.65, 0.75, 0.85)),
        (("--mode", "paper"), (0.6, 0.75)),
        (("--max-memory", "300MB"), (0.5, 0.7)),
        (("--curves", "{tmp}/curves.obj"), (0.55, 0.75, 0.85)),
    ],
    ids=["robust", "paper", "tiled", "curves"],
)
def test_out_of_memory_is_one_line(tmp_path, big_cloud, options, limits_gb):
    """Under an address-space limit (setrlimit in the child), at limits that end in
    every stage (reading, detection, the compiled kernels, writing): exit 0 with every
    output, or one ``out of memory`` line with the estimate and the hint, and nothing
    written."""
    options = [o.format(tmp=tmp_path) for o in options]
    failed = 0
    for gb in limits_gb:
        limit = int(gb * 2**30)
        out = tmp_path / f"out{gb}.ply"
        proc = _cli(
            "detect",
            big_cloud,
            "-q",
            "-o",
            out,
            *options,
            "--force",
            preexec_fn=lambda limit=limit: resource.setrlimit(resource.RLIMIT_AS, (limit, limit)),
        )
        if proc.returncode == 0:
            assert out.is_file() and not proc.stderr
            if "--curves" in options:
                (tmp_path / "curves.obj").unlink()  # there, and gone before the next limit
            continue
        assert not out.exists() and not list(tmp_path.glob(".*")), "output or temporary left"
        if _LOADING.fullmatch(proc.stderr):
            continue  # below what loading the libraries needs: refused before it
        failed += 1
        _one_error_line(proc, "error: out of memory: ", "--max-memory")
        assert re.search(r"needs about [0-9]+ MB|did not fit", proc.stderr), proc.stderr
        assert not out.exists() and not (tmp_path / "curves.obj").exists()
        assert not list(tmp_path.glob(".*")), "a temporary file was left"
    assert failed, "no limit ran out of memory: the test tests nothing"


def _sample_under(tmp_path: Path, limit_mb: int) -> tuple[subprocess.CompletedProcess, Path]:
    """``detect --sample`` under an address-space limit of ``limit_mb`` MB: the finished
    process (killed after a minute: a hang fails the test) and its output's path."""
    out = tmp_path / f"out{limit_mb}.ply"
    limit = limit_mb << 20
    proc = _cli(
        "detect",
        "--sample",
        "-q",
        "-o",
        out,
        timeout=60,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (limit, limit)),
    )
    return proc, out


@pytest.mark.parametrize("limit_mb", [300, 425, 450])
def test_a_limit_below_loading_is_refused_first(tmp_path, limit_mb):
    """Limits where loading the libraries used to hang (scipy's OpenBLAS retrying for
    ever for its threads' buffers, 403-465 MB on 2 CPUs) or end in OpenBLAS's own
    message: one out-of-memory line naming the need and the limit, status 1, nothing
    written (the guard runs before numpy, scipy or pymeshlab is imported)."""
    proc, out = _sample_under(tmp_path, limit_mb)
    assert proc.returncode == 1, proc.stderr
    said = _LOADING.fullmatch(proc.stderr)
    assert said, proc.stderr
    assert int(said[2]) == limit_mb and int(said[1]) > limit_mb
    assert not out.exists() and not list(tmp_path.iterdir())


@pytest.mark.slow
def test_a_limit_just_above_loading_runs(tmp_path):
    """The need the refusal names is enough: 1 MB under it is refused the same way, and
    8 MB over it the sample part is detected (or runs out of memory with the ordinary
    line, never a library's message or a hang)."""
    proc, _ = _sample_under(tmp_path, 300)
    need = int(_LOADING.fullmatch(proc.stderr)[1])
    below, out = _sample_under(tmp_path, need - 1)
    assert below.returncode == 1 and _LOADING.fullmatch(below.stderr), below.stderr
    assert not out.exists()
    above, out = _sample_under(tmp_path, need + 8)
    if above.returncode == 0:
        assert out.is_file() and not above.stderr
    else:
        _one_error_line(above, "error: out of memory: ", "--max-memory")
        assert not out.exists()


_NEED_AND_PEAK = """
import meshlab_sharp.cli as cli
from meshlab_sharp.address_space import loading_need
need = loading_need()
cli._load_libraries()
peak = next(l for l in open("/proc/self/status") if l.startswith("VmPeak:"))
print(need, int(peak.split()[1]) * 1024)
"""


@pytest.mark.parametrize("threads", ["1", ""])
def test_the_loading_estimate_covers_loading(threads):
    """What the command line's loading maps at its peak (VmPeak, every library imported
    and OpenBLAS warmed up) stays under the estimate taken before it, with one OpenBLAS
    thread and with one per CPU; the estimate's margin is not all of it."""
    proc = subprocess.run(
        [sys.executable, "-c", _NEED_AND_PEAK],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "OPENBLAS_NUM_THREADS": threads},
        check=True,
    )
    need, peak = map(int, proc.stdout.split())
    assert peak <= need, (peak >> 20, need >> 20)
    assert need - peak < 3 * MARGIN, (peak >> 20, need >> 20)


# ---------------------------------------------------------------- signals


def _catches(pid: int, signum: int) -> bool:
    """Whether process ``pid`` has a handler for ``signum`` (/proc SigCgt)."""
    with contextlib.suppress(OSError):
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("SigCgt:"):
                return bool(int(line.split()[1], 16) >> (signum - 1) & 1)
    return False


def _numpy_loaded(pid: int) -> bool:
    """Whether numpy's compiled core is mapped into process ``pid``."""
    with contextlib.suppress(OSError):
        return "_multiarray_umath" in Path(f"/proc/{pid}/maps").read_text()
    return False


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP])
def test_a_signal_while_importing_is_one_line(tmp_path, signum):
    """The handler is set before numpy loads: a signal as soon as it is set ends the
    command with the promised line and 128 + N, no traceback, nothing written."""
    cloud = tmp_path / "cloud.xyz"
    cloud.write_text("\n".join(f"{x} {y} {z}" for x, y, z in _cube_cloud(500)))
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "meshlab_sharp",
            "detect",
            str(cloud),
            "-o",
            str(tmp_path / "o.ply"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    end = time.monotonic() + 30
    # Python catches SIGINT from its start; the handlers are set together, SIGHUP's last
    while not _catches(proc.pid, signal.SIGHUP) and proc.poll() is None and time.monotonic() < end:
        time.sleep(0.0005)
    early = not _numpy_loaded(proc.pid)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    name = signal.Signals(signum).name
    assert err == f"meshlab-sharp: interrupted by {name}; no output was written\n"
    assert proc.returncode == 128 + signum
    assert early, "numpy was loaded before the handler was set"
    assert not (tmp_path / "o.ply").exists()


# ---------------------------------------------------------------- Dask


@contextlib.contextmanager
def _server(answer: bytes | None) -> Iterator[str]:
    """A loopback server that accepts connections and sends ``answer`` (None: never
    answers; empty: closes the connection at once), closed afterwards; yields its
    ``tcp://`` address."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen()
    sock.settimeout(0.2)
    stop = threading.Event()
    held: list[socket.socket] = []

    def serve() -> None:
        while not stop.is_set():
            try:
                conn, _ = sock.accept()
            except OSError:
                continue
            held.append(conn)
            if answer == b"":
                conn.close()
            elif answer is not None:
                with contextlib.suppress(OSError):
                    conn.sendall(answer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{sock.getsockname()[1]}"
    finally:
        stop.set()
        thread.join()
        for conn in held:
            conn.close()
        sock.close()


def _closed_port() -> str:
    """An address where nothing listens."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    return f"tcp://127.0.0.1:{port}"


@pytest.fixture
def small_cloud(tmp_path) -> Path:
    return _binary_ply(tmp_path / "cloud.ply", _cube_cloud(3000))


@pytest.mark.parametrize("address", ["tcp://", "tcp://host", "garbage", "tcp://127.0.0.1:99999"])
def test_dask_addresses_are_checked(tmp_path, small_cloud, address):
    proc = _cli("detect", small_cloud, "-q", "-o", tmp_path / "o.ply", "--dask", address)
    _one_error_line(proc, "write local:N or tcp://HOST:PORT")
    assert not (tmp_path / "o.ply").exists()


def _dask_run_timed(
    cloud: Path, out: Path, address: str
) -> tuple[subprocess.CompletedProcess, float]:
    """``detect CLOUD -o OUT --dask ADDRESS --dask-timeout 2`` to its end, and its
    seconds."""
    start = time.monotonic()
    proc = _cli("detect", cloud, "-q", "-o", out, "--dask", address, "--dask-timeout", "2")
    return proc, time.monotonic() - start


@pytest.mark.parametrize(
    "answer, message",
    [
        (None, "no answer from a Dask scheduler within 2 s"),
        (os.urandom(64) + b"\xff" * 8, "not a Dask scheduler"),
        (b"\xff" * 8 + b"x" * 64, "not a Dask scheduler"),  # 2**64 - 1 bytes to come
        (b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\n\r\n", "not a Dask scheduler"),
        (b"", "not a Dask scheduler (it closed the connection)"),
    ],
    ids=["silent", "random", "huge-length", "http", "closes"],
)
def test_dask_non_schedulers_fail_in_one_line_within_the_timeout(
    tmp_path, small_cloud, answer, message
):
    with _server(answer) as address:
        proc, took = _dask_run_timed(small_cloud, tmp_path / "o.ply", address)
    _one_error_line(proc, message)
    assert took < 30, took
    assert not (tmp_path / "o.ply").exists()


def test_dask_closed_port_fails_in_one_line(tmp_path, small_cloud):
    proc = _cli("detect", small_cloud, "-q", "-o", tmp_path / "o.ply", "--dask", _closed_port())
    _one_error_line(proc, "cannot reach the scheduler")


@pytest.mark.parametrize("value", ["0", "-1", "inf", "nan", "soon"])
def test_dask_timeout_option_is_checked(tmp_path, small_cloud, value):
    proc = _cli("detect", small_cloud, "-o", tmp_path / "o.ply", "--dask-timeout", value)
    _one_error_line(proc, "--dask-timeout", "positive number of seconds")


def _dask_cli(*args: str) -> list[str]:
    """The ``dask`` command of this environment."""
    return [str(Path(sys.executable).parent / "dask"), *args]


@contextlib.contextmanager
def _scheduler(
    workers: int, worker_setup: Callable[[], None] | None = None
) -> Iterator[tuple[str, subprocess.Popen, list[subprocess.Popen]]]:
    """A real scheduler process on loopback with ``workers`` worker processes, ready
    (the workers joined); killed afterwards. ``worker_setup``: run in each worker
    process before it starts (a resource limit)."""
    pytest.importorskip("distributed")
    from distributed import Client

    address = _closed_port()
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    port = address.rsplit(":", 1)[1]
    scheduler = subprocess.Popen(
        _dask_cli("scheduler", "--host", "127.0.0.1", "--port", port, "--no-dashboard"), **quiet
    )
    pool = [
        subprocess.Popen(
            _dask_cli("worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard"),
            preexec_fn=worker_setup,
            **quiet,
        )
        for _ in range(workers)
    ]
    try:
        with Client(address, timeout=60) as client:
            if workers:
                client.wait_for_workers(workers, timeout=60)
        yield address, scheduler, pool
    finally:
        for p in [*pool, scheduler]:
            p.kill()
            p.wait()


@pytest.mark.slow
def test_dask_scheduler_without_workers_fails_in_one_line(tmp_path, small_cloud):
    with _scheduler(0) as (address, _, _):
        proc, took = _dask_run_timed(small_cloud, tmp_path / "o.ply", address)
    _one_error_line(proc, "no worker joined the scheduler within 2 s")
    assert took < 40, took


@pytest.mark.slow
def test_dask_run_is_quiet_and_gives_the_tiled_answer(tmp_path, small_cloud):
    """A real scheduler and worker: the same bytes as the run in this process, and not
    a line of distributed's logging."""
    alone = _cli("detect", small_cloud, "-q", "-o", tmp_path / "alone.ply", "--max-memory", "1GB")
    assert alone.returncode == 0, alone.stderr
    with _scheduler(1) as (address, _, _):
        proc = _cli("detect", small_cloud, "-q", "-o", tmp_path / "dask.ply", "--dask", address)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "" and proc.stdout == ""
    assert (tmp_path / "dask.ply").read_bytes() == (tmp_path / "alone.ply").read_bytes()


def _scratch_folders(folder: Path) -> list[Path]:
    return sorted(folder.glob(f"{SCRATCH_PREFIX}*"))


def _wait_for_scratch(folder: Path, proc: subprocess.Popen, timeout: float = 120) -> None:
    """Until the run has made its scratch folder and cut its tiles."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        found = _scratch_folders(folder)
        if found and (found[0] / "coords.bin").exists():
            return
        time.sleep(0.05)
    raise AssertionError(f"no scratch folder appeared: {proc.poll()}")


@pytest.fixture(scope="module")
def medium_cloud(tmp_path_factory) -> Path:
    """A 200,000-point cloud as a binary PLY."""
    return _binary_ply(tmp_path_factory.mktemp("medium") / "cube200k.ply", _cube_cloud(200_000))


@pytest.fixture
def scratch(tmp_path) -> Path:
    """An empty folder for a run's ``TMPDIR``: where its tiles' scratch folder goes."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    return folder


def _start_tiled(cloud: Path, out: Path, scratch: Path, dask: str, *more: str) -> subprocess.Popen:
    """``detect CLOUD -o OUT --dask DASK --max-memory 300MB MORE`` started with
    ``TMPDIR=scratch``, its stdout and stderr piped."""
    return subprocess.Popen(
        [sys.executable, "-m", "meshlab_sharp", "detect", str(cloud), "-q", "-o", str(out)]
        + ["--dask", dask, "--max-memory", "300MB", *more],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "TMPDIR": str(scratch)},
    )


def _ended(proc: subprocess.Popen, timeout: float) -> subprocess.CompletedProcess:
    """``proc`` waited for (at most ``timeout`` seconds) as a CompletedProcess."""
    out, err = proc.communicate(timeout=timeout)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.mark.slow
def test_dask_scheduler_lost_mid_run_is_one_line(tmp_path, medium_cloud, scratch):
    with _scheduler(1) as (address, scheduler, _):
        proc = _start_tiled(medium_cloud, tmp_path / "o.ply", scratch, address)
        _wait_for_scratch(scratch, proc)
        scheduler.kill()
        start = time.monotonic()
        ended = _ended(proc, 120)
        took = time.monotonic() - start
    _one_error_line(ended, "--dask: ")
    assert took < 60, took
    assert not (tmp_path / "o.ply").exists()
    assert _scratch_folders(scratch) == []


@pytest.mark.slow
def test_dask_worker_lost_mid_run_resumes_with_the_same_answer(tmp_path, medium_cloud, scratch):
    """One of two workers killed while the tiles run: its tasks run again on the other,
    and the output is the run without Dask's, byte for byte."""
    alone = _cli(
        "detect", medium_cloud, "-q", "-o", tmp_path / "alone.ply", "--max-memory", "300MB"
    )
    assert alone.returncode == 0, alone.stderr
    with _scheduler(2) as (address, _, workers):
        proc = _start_tiled(medium_cloud, tmp_path / "dask.ply", scratch, address)
        _wait_for_scratch(scratch, proc)
        time.sleep(2.0)  # tile tasks on both workers
        assert proc.poll() is None, "the run ended before a worker was lost"
        workers[0].kill()
        ended = _ended(proc, 300)
    assert ended.returncode == 0, ended.stderr
    assert ended.stderr == ""
    assert (tmp_path / "dask.ply").read_bytes() == (tmp_path / "alone.ply").read_bytes()


@pytest.mark.slow
def test_dask_stopped_worker_is_one_line(tmp_path, medium_cloud, scratch):
    """The only worker stopped (SIGSTOP) mid-run, while the scheduler still keeps it
    (its worker-ttl, 5 minutes by default): once it has been silent for 30 s the run
    waits 30 s for another, then fails in one line, well before the scheduler would
    drop it."""
    with _scheduler(1) as (address, _, workers):
        proc = _start_tiled(medium_cloud, tmp_path / "o.ply", scratch, address)
        _wait_for_scratch(scratch, proc)
        assert proc.poll() is None
        workers[0].send_signal(signal.SIGSTOP)
        ended = _ended(proc, 240)
    _one_error_line(ended, "no live worker in the Dask cluster for 30 s", "silent for 30 s")
    assert not (tmp_path / "o.ply").exists()
    assert _scratch_folders(scratch) == []


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_a_signal_during_a_dask_run_is_one_line(tmp_path, medium_cloud, scratch, signum):
    proc = _start_tiled(medium_cloud, tmp_path / "o.ply", scratch, "local:1")
    _wait_for_scratch(scratch, proc)
    time.sleep(1.0)  # the tile tasks are running on the worker
    proc.send_signal(signum)
    ended = _ended(proc, 120)
    name = signal.Signals(signum).name
    assert ended.stderr == f"meshlab-sharp: interrupted by {name}; no output was written\n"
    assert ended.returncode == 128 + signum
    assert not (tmp_path / "o.ply").exists()
    assert _scratch_folders(scratch) == []


#: Largest file a worker may write in the file-size-limit case (RLIMIT_FSIZE; Python
#: ignores SIGXFSZ, so a longer write fails with EFBIG).
_WORKER_FILE_LIMIT = 1 << 20


def _mount_tmpfs(folder: Path, size: str) -> bool:
    """Mount a tmpfs of ``size`` on ``folder``; False where mounting is not permitted."""
    try:
        done = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
            capture_output=True,
        )
    except OSError:  # no mount command
        return False
    return done.returncode == 0


def _limit_file_size() -> None:
    resource.setrlimit(resource.RLIMIT_FSIZE, (_WORKER_FILE_LIMIT, _WORKER_FILE_LIMIT))


@pytest.mark.slow
@pytest.mark.parametrize("full", ["filesystem", "file-size-limit"])
def test_dask_full_scratch_is_one_line(tmp_path, medium_cloud, scratch, full):
    """A real scheduler and worker, and the tiles' scratch folder on a full filesystem
    (a 16 MB tmpfs: the cut tiles fit, the steps' arrays do not; where mounting is not
    permitted, the workers' own writes refused by a file size limit instead), or the
    workers' writes refused: one line naming the scratch folder's place, no worker's
    traceback, no output, no scratch left."""
    if not hasattr(resource, "RLIMIT_FSIZE"):
        pytest.skip("no RLIMIT_FSIZE on this system to refuse the workers' writes")
    mounted = full == "filesystem" and _mount_tmpfs(scratch, "16m")
    try:
        with _scheduler(1, None if mounted else _limit_file_size) as (address, _, _):
            ended = _ended(_start_tiled(medium_cloud, tmp_path / "o.ply", scratch, address), 240)
        left = _scratch_folders(scratch)
    finally:
        if mounted:
            subprocess.run(["umount", str(scratch)], check=True)
    _one_error_line(ended, f"cannot write the tiles' scratch arrays in {scratch}: ", "--scratch")
    assert ("No space left on device" if mounted else "File too large") in ended.stderr
    assert "Traceback" not in ended.stderr and ended.stdout == ""
    assert not (tmp_path / "o.ply").exists()
    assert left == []


def test_dask_argument_of_the_wrong_type_is_a_type_error():
    pytest.importorskip("distributed")
    points = _cube_cloud(500)
    for value in (5, object()):
        with pytest.raises(TypeError, match=r"dask= must be .*, not (int|object)"):
            meshlab_sharp.detect(points, dask=value)


# ---------------------------------------------------------------- bounds before work


@pytest.mark.parametrize(
    "kind, scales, message",
    [
        ("mesh", "1000", "rings must be <= 32, got 1000"),
        ("mesh", "1,2,33", "rings must be <= 32, got 33"),
        ("points", "600", "kNN sizes must be <= 512, got 600"),
    ],
)
def test_scales_above_the_maximum_are_refused_at_once(tmp_path, kind, scales, message):
    v, f = shapes.cube_grid_mesh(30)
    path = tmp_path / "part.obj"
    rows = [f"v {x} {y} {z}" for x, y, z in v]
    if kind == "mesh":
        rows += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    path.write_text("\n".join(rows) + "\n")
    start = time.monotonic()
    proc = _cli("detect", path, "-q", "--scales", scales)
    _one_error_line(proc, message)
    assert time.monotonic() - start < 30
    assert not (tmp_path / "part_sharp.ply").exists()


def test_smoothing_steps_above_the_maximum_are_refused(tmp_path):
    v, f = shapes.cube_grid_mesh(4)
    path = tmp_path / "part.off"
    path.write_text(
        f"OFF\n{len(v)} {len(f)} 0\n"
        + "".join(f"{x} {y} {z}\n" for x, y, z in v)
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in f)
    )
    proc = _cli("detect", path, "-q", "--denoise", "--smoothing-steps", "1000000000")
    _one_error_line(proc, "--smoothing-steps must be <= 1000, got 1000000000")


def _with_far_outliers(n: int, outliers: int) -> np.ndarray:
    """A cube cloud of ``n`` points and ``outliers`` points a million units away."""
    rng = np.random.default_rng(3)
    far = rng.normal(size=(outliers, 3))
    far *= 1e6 / np.linalg.norm(far, axis=1)[:, None]
    return np.concatenate([_cube_cloud(n), far])


def test_far_outliers_do_not_squeeze_the_tiles(tmp_path):
    """With 200 points a million units away, the cloud's tiles still hold at most
    ``tile_points`` points each (the far points in tiles of their own); so do those of
    the cloud without them."""
    points = _with_far_outliers(50_000, 200)
    source = PointSource.from_array(points)
    layout = build_layout(
        len(points), lambda: source.blocks(8192), Store(str(tmp_path)), tile_points=5000,
        source="cloud",
    )  # fmt: skip
    counts = layout.counts()
    assert counts.sum() == len(points)
    assert counts.max() <= 5000, counts
    far = np.abs(layout.boxes).max(axis=(1, 2)) > 10
    assert counts[far].sum() == 200  # every far point is in a tile of far points
    plain = _cube_cloud(50_000)
    (tmp_path / "plain").mkdir()
    source = PointSource.from_array(plain)
    layout = build_layout(
        len(plain), lambda: source.blocks(8192), Store(str(tmp_path / "plain")), tile_points=5000,
        source="cloud",
    )  # fmt: skip
    assert layout.counts().max() <= 5000
    assert (np.abs(layout.boxes) <= 1.0).all()


@pytest.mark.slow
def test_tiled_run_with_far_outliers_stays_fast_and_exact(tmp_path):
    """200,000 points and 200 far outliers under --max-memory: the in-memory answer,
    bit for bit, in bounded time and under the memory given."""
    points = _with_far_outliers(200_000, 200)
    cloud = _binary_ply(tmp_path / "outliers.ply", points)
    start = time.monotonic()
    proc = _cli(
        "detect", cloud, "-q", "-o", tmp_path / "tiled.ply", "--indices", tmp_path / "t.txt",
        "--max-memory", "250MB", "--report", tmp_path / "r.json",
    )  # fmt: skip
    took = time.monotonic() - start
    assert proc.returncode == 0, proc.stderr
    assert took < 120, took
    expected = meshlab_sharp.detect(points)
    got = np.loadtxt(tmp_path / "t.txt", dtype=np.int64, ndmin=1)
    assert np.array_equal(got, np.flatnonzero(expected.mask))


# ---------------------------------------------------------------- stale scratch


@pytest.mark.slow
def test_a_killed_runs_scratch_is_removed_by_the_next_run(tmp_path, medium_cloud, small_cloud):
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "meshlab_sharp", "detect", str(medium_cloud), "-q"]
        + ["-o", str(tmp_path / "o.ply"), "--max-memory", "200MB"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    _wait_for_scratch(scratch, proc)
    proc.kill()
    proc.wait()
    left = _scratch_folders(scratch)
    assert len(left) == 1
    assert left[0].name.startswith(f"{SCRATCH_PREFIX}{proc.pid}@")
    other = scratch / f"{SCRATCH_PREFIX}1@another.host-abcdefgh"  # another machine's
    other.mkdir()
    again = _cli(
        "detect", small_cloud, "-q", "-o", tmp_path / "o2.ply", "--max-memory", "200MB", env=env
    )
    assert again.returncode == 0, again.stderr
    assert _scratch_folders(scratch) == [other]
    assert remove_stale_scratch(scratch) == []


def test_scratch_arrays_on_a_full_filesystem_fail_when_created(tmp_path):
    """On a 1 MB tmpfs: an array that does not fit fails when it is created, with the
    scratch folder's place; the arrays that were created take scattered writes (through
    a map of the file) without SIGBUS, since their space is reserved."""
    folder = tmp_path / "small"
    folder.mkdir()
    if not _mount_tmpfs(folder, "1m"):
        pytest.skip("mounting a tmpfs is not permitted here")
    try:
        store = Store(str(folder / "run"))
        os.mkdir(store.root)
        store.create("a", (100_000,), np.float64)  # 800 kB
        with pytest.raises(ScratchError, match=f"scratch arrays in {folder}: No space left"):
            store.create("b", (100_000,), np.float64)
        rows = np.arange(0, 100_000, 3)
        store.write_at("a", rows, 1.0)  # the map route: many runs of one row
        assert store.read("a", 0, 100_000).sum() == len(rows)
    finally:
        subprocess.run(["umount", str(folder)], check=True)


# ---------------------------------------------------------------- the API


def test_detect_meshset_checks_its_argument():
    with pytest.raises(TypeError, match=r"ms must be a pymeshlab\.MeshSet, not int"):
        meshlab_sharp.detect_meshset(5)
    with pytest.raises(ValueError, match="ms: the MeshSet holds no mesh"):
        meshlab_sharp.detect_meshset(pymeshlab.MeshSet())
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.random.default_rng(0).random((10, 3))))
    ms.set_selection_all()
    ms.meshing_remove_selected_vertices()
    with pytest.raises(ValueError, match="ms: the current mesh has no vertices"):
        meshlab_sharp.detect_meshset(ms)


def test_detect_meshset_without_curves_adds_no_empty_mesh():
    """A flat grid has no curves: pymeshlab cannot hold an empty mesh, none is added."""
    g = np.mgrid[0:30, 0:30].reshape(2, -1).T
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.c_[g, np.zeros(len(g))].astype(float)))
    result = meshlab_sharp.detect_meshset(ms, curves=True)
    assert result.curves == [] and ms.mesh_number() == 1


class _Hostile:
    """An object whose conversion to an array raises."""

    def __array__(self, *args, **kwargs):
        raise RuntimeError("no array here")


def test_an_object_whose_array_raises_is_a_value_error():
    with pytest.raises(ValueError, match="the vertices cannot be read as an array: RuntimeError"):
        meshlab_sharp.detect(_Hostile())
    with pytest.raises(ValueError, match="the faces cannot be read as an array: RuntimeError"):
        meshlab_sharp.detect(np.eye(3), _Hostile())


class _Tripwire(io.StringIO):
    """A bar's stream that interrupts the main thread at the bar's second line (the
    first is then drawn whole; the library's callback or the Python-driven path's
    own)."""

    tripped = False

    def write(self, text: str) -> int:
        written = super().write(text)
        if not self.tripped and self.getvalue().count("[") >= 2:
            self.tripped = True
            _thread.interrupt_main()
        return written


def test_an_interrupt_in_detect_clears_the_progress_bar():
    # Python's own Ctrl-C (KeyboardInterrupt), whatever handler an earlier test left
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _interrupt_detect()
    finally:
        signal.signal(signal.SIGINT, before)


def _interrupt_detect() -> None:
    stream = _Tripwire()
    bar = Progress(12, enabled=True, stream=stream)
    with pytest.raises(KeyboardInterrupt):
        meshlab_sharp.detect(_cube_cloud(20_000), progress=bar)
        time.sleep(5)  # the interrupt lands at the latest here
    drawn = stream.getvalue()
    assert "[" in drawn
    assert drawn.endswith("\r" + " " * (len(drawn.split("\r")[-3])) + "\r")
    bar.step("after")  # the bar draws no more
    assert stream.getvalue() == drawn
