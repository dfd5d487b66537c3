"""Per-point arrays on disk, shared by the tiles (and by Dask workers on other machines).

Every array is a raw file ``<root>/<name>.bin`` whose first axis runs over the points in
tile order. A range of rows is read from the file; any other access maps the file,
copies what it needs and unmaps it again, so that a long run never keeps file pages in
the process's resident memory: the peak memory of a tiled run is that of one tile, not
of the whole cloud.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ScratchError

#: :meth:`Store.write_at` writes fewer runs of consecutive rows than this (or than an
#: eighth of the rows) one by one.
RUNS = 64
#: Start of a scratch folder's name; then ``PID@HOST-`` of the process that owns it and
#: :func:`tempfile.mkdtemp`'s random part.
SCRATCH_PREFIX = "meshlab-sharp-tiles-"
_SCRATCH_NAME = re.compile(re.escape(SCRATCH_PREFIX) + r"([0-9]+)@(.+)-[^-]+")


def _host() -> str:
    """This machine's name as it appears in scratch folder names."""
    return re.sub(r"[^A-Za-z0-9.]", "_", socket.gethostname()) or "localhost"


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (another user's counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def remove_stale_scratch(folder: str | os.PathLike[str] | None = None) -> list[str]:
    """Remove the scratch folders in ``folder`` (default: the temp folder) left by runs
    that were killed: named for a process of this machine that no longer exists.

    Returns
    -------
    list of str
        The folders removed.
    """
    where = Path(folder if folder is not None else tempfile.gettempdir())
    host, removed = _host(), []
    try:
        entries = list(os.scandir(where))
    except OSError:
        return removed
    for entry in entries:
        match = _SCRATCH_NAME.fullmatch(entry.name)
        if match is None or match.group(2) != host or _alive(int(match.group(1))):
            continue
        if entry.is_dir(follow_symlinks=False) and entry.stat().st_uid == os.getuid():
            shutil.rmtree(entry.path, ignore_errors=True)
            removed.append(entry.path)
    return removed


def make_scratch(folder: str | os.PathLike[str] | None = None) -> str:
    """A new scratch folder in ``folder`` (default: the temp folder), named for this
    process and machine, after removing the stale ones (:func:`remove_stale_scratch`)."""
    remove_stale_scratch(folder)
    return tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}@{_host()}-", dir=folder)


@dataclass
class Store:
    """A folder of named per-point arrays (picklable: a path and the arrays' layouts).

    Attributes
    ----------
    root : str
        The folder; with Dask on several machines, a path every worker can reach.
    arrays : dict of str to (shape, dtype str)
    """

    root: str
    arrays: dict[str, tuple[tuple[int, ...], str]] = field(default_factory=dict)

    def path(self, name: str) -> Path:
        """The file of array ``name``."""
        return Path(self._file(name))

    def _file(self, name: str) -> str:
        """:meth:`path` as a string (many calls: no Path object)."""
        return os.path.join(self.root, f"{name}.bin")

    @contextmanager
    def _writing(self) -> Iterator[None]:
        """A failed write of the scratch arrays (a full disk, a file size limit) as a
        :class:`~meshlab_sharp.errors.ScratchError` naming the scratch folder's place."""
        try:
            yield
        except OSError as exc:
            where = os.path.dirname(os.path.abspath(self.root))
            raise ScratchError(
                f"cannot write the tiles' scratch arrays in {where}: {exc.strerror or exc} "
                "(--scratch DIR or TMPDIR chooses the folder)"
            ) from None

    def create(self, name: str, shape: tuple[int, ...], dtype: np.dtype | str) -> None:
        """A new array of zeros, its disk space reserved: a full disk fails here, not
        later in a write through a map of the file (which would end the process with
        SIGBUS)."""
        dt = np.dtype(dtype)
        size = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
        with self._writing(), open(self._file(name), "wb") as f:
            f.truncate(size)
            if size and hasattr(os, "posix_fallocate"):  # not on macOS
                os.posix_fallocate(f.fileno(), 0, size)
        self.arrays[name] = (tuple(int(s) for s in shape), dt.str)

    def _map(self, name: str, mode: str) -> np.ndarray:
        shape, dtype = self.arrays[name]
        if shape[0] == 0:
            return np.zeros(shape, dtype)
        return np.memmap(self._file(name), dtype=np.dtype(dtype), mode=mode, shape=shape)

    def read(self, name: str, start: int, stop: int) -> np.ndarray:
        """A copy of rows ``start:stop`` (read from the file, not mapped)."""
        shape, dtype = self.arrays[name]
        dt = np.dtype(dtype)
        count = max(min(stop, shape[0]) - start, 0)
        if count == 0:
            return np.zeros((0, *shape[1:]), dt)
        row = self._row_bytes(name)
        out = np.fromfile(self._file(name), dt, count * row // dt.itemsize, offset=start * row)
        return out.reshape((count, *shape[1:]))

    def read_at(self, name: str, rows: np.ndarray) -> np.ndarray:
        """A copy of the given rows (any order)."""
        m = self._map(name, "r")
        out = np.array(m[np.asarray(rows, np.int64)])
        del m
        return out

    def write(self, name: str, start: int, values: np.ndarray) -> None:
        """Rows ``start:start + len(values)`` := ``values`` (written to the file, not
        mapped: no page of it stays in this process)."""
        shape, dtype = self.arrays[name]
        data = np.ascontiguousarray(values, np.dtype(dtype))
        if data.shape[1:] != shape[1:] or not 0 <= start <= shape[0] - len(data):
            raise ValueError(
                f"{name}: rows {start}:{start + len(data)} of shape {data.shape[1:]} "
                f"do not fit an array of shape {shape}"
            )
        with self._writing(), open(self._file(name), "r+b") as f:
            _pwrite(f.fileno(), start * self._row_bytes(name), _bytes(data))

    def write_at(self, name: str, rows: np.ndarray, values: np.ndarray) -> None:
        """The given rows (distinct) := ``values``. Rows that form runs of consecutive
        rows (a tile's own points, gaps at its duplicates) are written run by run; others
        through a map of the file, flushed."""
        if len(rows) == 0:
            return
        shape, dtype = self.arrays[name]
        rows = np.asarray(rows, np.int64)
        values = np.broadcast_to(values, (len(rows), *shape[1:]))
        if len(rows) > 1 and not (rows[1:] > rows[:-1]).all():
            order = np.argsort(rows, kind="stable")
            rows, values = rows[order], values[order]
        cuts = np.flatnonzero(rows[1:] != rows[:-1] + 1) + 1
        if len(cuts) < max(RUNS, len(rows) // 8) and rows[0] >= 0 and rows[-1] < shape[0]:
            data = _bytes(np.ascontiguousarray(values, np.dtype(dtype)))
            row = self._row_bytes(name)
            with self._writing(), open(self._file(name), "r+b") as f:
                for a, b in zip([0, *cuts], [*cuts, len(rows)], strict=True):
                    _pwrite(f.fileno(), int(rows[a]) * row, data[a * row : b * row])
            return
        with self._writing():
            m = self._map(name, "r+")
            m[rows] = values
            m.flush()
            del m

    def _row_bytes(self, name: str) -> int:
        """Bytes of one row of array ``name``."""
        shape, dtype = self.arrays[name]
        return np.dtype(dtype).itemsize * int(np.prod(shape[1:], dtype=np.int64))

    def remove(self, name: str) -> None:
        """Delete array ``name`` and its file."""
        self.path(name).unlink()
        del self.arrays[name]

    def put(self, name: str, key: int, values: np.ndarray) -> None:
        """A per-tile array (not per point): ``values`` under ``name`` and ``key``."""
        with self._writing():
            np.save(Path(self.root) / f"{name}-{key}.npy", values, allow_pickle=False)

    def get(self, name: str, key: int) -> np.ndarray:
        """The array :meth:`put` saved under ``name`` and ``key``."""
        return np.load(Path(self.root) / f"{name}-{key}.npy", allow_pickle=False)


def _bytes(data: np.ndarray) -> memoryview:
    """The bytes of a C-contiguous array, flat."""
    return memoryview(data.reshape(-1)).cast("B")


def _pwrite(fd: int, at: int, view: memoryview) -> None:
    """All of ``view`` to file ``fd`` at byte ``at``."""
    while len(view):
        done = os.pwrite(fd, view, at)
        view, at = view[done:], at + done
