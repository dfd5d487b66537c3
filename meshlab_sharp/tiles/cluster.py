"""Connecting to a Dask scheduler with bounds: a checked address, a time limit, workers.

``dask.distributed.Client`` on an address that is not a scheduler can wait forever (a
server that accepts and never answers) or read a few bytes of garbage as the length of
a message and try to allocate it (exabytes). :func:`connect` first reads the scheduler's
greeting itself, with a time limit and a bound on its size, then opens the client with
the same limit and waits, with the same limit again, for a worker.
"""

from __future__ import annotations

import re
import socket
import struct
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import CancelledError
from contextlib import contextmanager
from typing import Any

from ..errors import ClusterError, InputError
from ..extras import require
from ..io.scanner import library_message

#: Seconds to reach a scheduler, and then to wait for its first worker, by default.
DEFAULT_CONNECT_TIMEOUT = 30.0
#: Seconds a run waits with no worker left (all lost or silent) before it fails.
WORKERLESS_PATIENCE = 30.0
#: Seconds without a heartbeat after which a worker counts as lost for that wait (a
#: stopped or frozen worker: the scheduler itself keeps one for its worker-ttl, 5
#: minutes by default). Workers send one every 0.5 s in clusters of up to 10 workers,
#: every few seconds in clusters of thousands.
SILENT_WORKER = 30.0
#: Most bytes of a scheduler's greeting (its handshake is a few hundred).
_GREETING_MOST = 1 << 16
_ADDRESS = re.compile(r"tcp://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):([0-9]{1,5})")


def check_address(address: str) -> tuple[str, int]:
    """``tcp://HOST:PORT`` -> (host, port), or an :class:`InputError` saying what to
    write."""
    match = _ADDRESS.fullmatch(address)
    port = int(match.group(2)) if match else 0
    if match is None or not 0 < port < 65536:
        raise InputError(f"--dask {address!r}: write local:N or tcp://HOST:PORT (a port 1-65535)")
    return match.group(1).strip("[]"), port


def _read(sock: socket.socket, n: int, deadline: float) -> bytes:
    """Exactly ``n`` bytes before ``deadline`` (monotonic), or TimeoutError/EOFError."""
    data = bytearray()
    while len(data) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError
        sock.settimeout(left)
        part = sock.recv(n - len(data))
        if not part:
            raise EOFError
        data += part
    return bytes(data)


def probe_scheduler(address: str, timeout: float) -> None:
    """Check that ``address`` answers as a Dask scheduler within ``timeout`` seconds:
    it sends a greeting of bounded size that names the pickle protocol.

    Raises
    ------
    InputError
        Malformed address, nothing listening, no answer in time, or an answer that is
        not a scheduler's.
    """
    host, port = check_address(address)
    deadline = time.monotonic() + timeout
    where = f"--dask {address}"
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            (size,) = struct.unpack("<Q", _read(sock, 8, deadline))
            if not 0 < size <= _GREETING_MOST:
                raise InputError(f"{where}: not a Dask scheduler (it answered something else)")
            if b"pickle-protocol" not in _read(sock, size, deadline):
                raise InputError(f"{where}: not a Dask scheduler (it answered something else)")
    except TimeoutError:
        raise InputError(
            f"{where}: no answer from a Dask scheduler within {timeout:g} s "
            "(--dask-timeout sets the limit)"
        ) from None
    except EOFError:
        raise InputError(f"{where}: not a Dask scheduler (it closed the connection)") from None
    except OSError as exc:
        raise InputError(f"{where}: cannot reach the scheduler: {exc.strerror or exc}") from None


def connect(address: str, timeout: float = DEFAULT_CONNECT_TIMEOUT) -> Any:
    """A ``dask.distributed.Client`` of the scheduler at ``tcp://HOST:PORT`` with at
    least one worker, or an :class:`InputError` within about ``3 * timeout`` seconds
    (reaching it, opening the client, waiting for a worker). The caller closes it."""
    if not timeout > 0:
        raise InputError(f"the Dask timeout must be a positive number of seconds, got {timeout}")
    distributed = require("dask.distributed", "--dask", "dask")
    probe_scheduler(address, timeout)
    try:
        client = distributed.Client(address, timeout=timeout)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"--dask {address}: cannot reach the scheduler: {exc}") from None
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (OSError, TimeoutError):
        client.close()
        raise InputError(
            f"--dask {address}: no worker joined the scheduler within {timeout:g} s "
            "(--dask-timeout sets the limit)"
        ) from None
    except BaseException:
        client.close()
        raise
    return client


@contextmanager
def cluster_failures(stage: str) -> Iterator[None]:
    """Turn the ways a cluster fails while it runs tasks (the scheduler lost, workers
    killed again and again, a connection closed or timed out) into a
    :class:`~meshlab_sharp.errors.ClusterError` naming ``stage``."""
    distributed = require("dask.distributed", "--dask", "dask")
    from distributed.comm import CommClosedError

    # a task's own OSError (a full scratch disk) is not the cluster's: it passes;
    # futures cancelled (the scheduler lost) are concurrent.futures' CancelledError
    failures = (
        distributed.KilledWorker,
        CancelledError,
        CommClosedError,
        ConnectionError,
        TimeoutError,
    )
    try:
        yield
    except failures as exc:
        raise ClusterError(
            f"--dask: the Dask cluster failed during the tiles' {stage!r} step: "
            f"{library_message(exc)}"
        ) from None


def completed(
    client: Any, futures: Sequence[Any], patience: float = WORKERLESS_PATIENCE
) -> Iterator[Any]:
    """``futures`` as they complete; a :class:`~meshlab_sharp.errors.ClusterError` once
    the cluster has had no live worker for ``patience`` seconds (the tasks of lost
    workers run again on the others, or on workers that join in time). A worker whose
    heartbeat the scheduler has not seen change for :data:`SILENT_WORKER` seconds
    (stopped, frozen) is not live."""
    distributed = require("dask.distributed", "--dask", "dask")
    pending = list(futures)
    alone_since: float | None = None
    heard: dict[str, tuple[float, float]] = {}  # worker: (its last_seen, when it changed)
    while pending:
        try:
            done, rest = distributed.wait(pending, timeout=1.0, return_when="FIRST_COMPLETED")
        except TimeoutError:
            now = time.monotonic()
            workers = client.scheduler_info(n_workers=-1)["workers"]
            for name, info in workers.items():
                seen = float(info.get("last_seen", 0.0))
                if name not in heard or heard[name][0] != seen:
                    heard[name] = (seen, now)  # the scheduler's clock: compared, not read
            if any(now - heard[name][1] <= SILENT_WORKER for name in workers):
                alone_since = None
            elif alone_since is None:
                alone_since = now
            elif now - alone_since > patience:
                raise ClusterError(
                    f"--dask: no live worker in the Dask cluster for {patience:g} s "
                    f"(every worker lost, or silent for {SILENT_WORKER:g} s)"
                ) from None
            continue
        pending = list(rest)
        yield from done
