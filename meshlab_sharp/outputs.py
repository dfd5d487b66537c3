"""Writing results atomically: temporary siblings, then renames.

Every file written here goes to a hidden temporary sibling (``.NAME.XXXX.part.EXT``) in
the destination's folder first and is renamed into place only when its content is
complete. An :class:`OutputSet` does this for several files at once: all of them are
written to temporary siblings, and only then renamed, one after the other, with the
catchable signals blocked; anything that stops the set before the renames removes every
temporary file, so an output set is all or nothing.

Before any work, :meth:`OutputSet.claim` checks the destinations and claims the new ones
against other processes: it creates each as an empty, locked placeholder (exclusively,
so of two runs that want the same new file only one gets it), and the renames replace
the placeholders. An output that exists and is not a regular file (a character device
such as ``/dev/null``, a FIFO, or a symbolic link to one) is never replaced: its content
is staged in a temporary file and copied into it after the renames. A symbolic link to a
regular file stays a link: the file it points to is replaced. ``/dev/stdout`` and other
names of this process's open descriptors are written through the descriptor itself, so
``--indices /dev/stdout > features.txt`` appends to what the shell opened.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import shutil
import signal
import stat
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import NamedTuple

from .defaults import HELD_SIGNALS
from .errors import OutputError


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Delay :data:`HELD_SIGNALS` until the block ends (they are delivered then)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class _Staged(NamedTuple):
    tmp: Path  # the content
    dest: Path  # the path given, for messages
    target: Path  # what receives the content: ``dest``, or the file a link points to
    through: bool  # copied into an existing device or FIFO instead of renamed


class OutputSet:
    """Files written to hidden temporary siblings, renamed into place together.

    ``claim`` checks the destinations before any work and claims the new ones;
    ``stage`` writes one file's content to a temporary sibling of its destination;
    ``commit`` renames every staged file into place; ``discard`` (also run on leaving a
    ``with`` block) removes the temporary files that were not renamed and the
    placeholders that were not replaced.

    Attributes
    ----------
    written : list of Path
        Destinations renamed into place so far, in order.
    """

    def __init__(self) -> None:
        self._staged: list[_Staged] = []
        self._claims: dict[Path, int] = {}  # placeholder -> descriptor holding its lock
        self.written: list[Path] = []

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.discard()

    def claim(self, paths: Iterable[str | os.PathLike[str]], *, force: bool = False) -> None:
        """Check every destination before any work, and claim the new ones.

        A destination's folder must exist and be writable, and it must not be a folder,
        a block device or a socket. An existing character device or FIFO, or a name of
        one of this process's descriptors (``/dev/stdout``), is accepted as it is (with
        or without ``force``): it is written through, never replaced.
        Without ``force`` no other destination may exist, and each is created as an
        empty placeholder, exclusively and in sorted order, and locked until the set is
        committed or discarded: of two processes claiming the same new file, one gets
        it and the other fails here.

        Parameters
        ----------
        paths : iterable of path-like
            The destinations.
        force : bool, default False
            Existing regular files may be replaced (nothing is claimed).

        Raises
        ------
        OutputError
            One destination cannot be written or is taken; the placeholders created so
            far are removed.
        """
        try:
            with signals_held():  # every placeholder is recorded for discard
                for path in sorted(map(Path, paths), key=_target):
                    self._claim(path, force=force)
        except BaseException:
            self._release()
            raise

    def _claim(self, path: Path, *, force: bool) -> None:
        """:meth:`claim` for one destination."""
        if _written_through(path):
            return
        target = _target(path)
        folder = target.parent
        if not folder.is_dir():
            raise OutputError(f"cannot write {path}: the folder {folder} does not exist")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise OutputError(f"cannot write {path}: the folder {folder} is not writable")
        if target.is_dir():
            raise OutputError(f"cannot write {path}: it is a folder")
        if force:
            return
        try:
            fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666)
        except FileExistsError:
            raise OutputError(_taken(path, target)) from None
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
        self._claims[target] = fd
        fcntl.flock(fd, fcntl.LOCK_EX)

    def stage(self, path: str | os.PathLike[str], write: Callable[[str], None]) -> Path:
        """Write one file's content to a temporary sibling of ``path``.

        Parameters
        ----------
        path : path-like
            Destination. Its folder must exist. An existing character device or FIFO
            gets a temporary file in the system's temporary folder instead, copied into
            it by :meth:`commit`.
        write : callable
            ``write(tmp_path)`` creates the content at ``tmp_path`` (same extension as
            ``path``, so format-sniffing writers such as pymeshlab's work).

        Returns
        -------
        Path
            The destination.

        Raises
        ------
        OutputError
            The folder is missing, or writing failed (disk full, no permission...): the
            message names ``path``.
        """
        dest = Path(path)
        through = _written_through(dest)
        target = dest if through else _target(dest)
        folder = target.parent if str(target.parent) else Path(".")
        if not folder.is_dir():
            raise OutputError(f"cannot write {dest}: the folder {folder} does not exist")
        try:
            with signals_held():  # the temporary file is always recorded for discard
                fd, tmp = tempfile.mkstemp(
                    prefix=f".{dest.stem}.",
                    suffix=f".part{dest.suffix}",
                    dir=None if through else folder,
                )
                self._staged.append(_Staged(Path(tmp), dest, target, through))
            os.close(fd)
            write(tmp)
            os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        except OSError as exc:
            raise OutputError(f"cannot write {dest}: {exc.strerror or exc}") from None
        return dest

    def commit(self) -> list[Path]:
        """Rename every staged file into place, with the catchable signals held, then
        copy the content of those written through into their devices, FIFOs (which may
        wait for a reader) or descriptors, and remove the placeholders that nothing
        replaced.

        Returns
        -------
        list of Path
            The destinations, in the order written.

        Raises
        ------
        OutputError
            A rename or copy failed; the message says which files were written before it.
        """
        with signals_held():
            for item in [s for s in self._staged if not s.through]:
                self._finish(item, os.replace)
        for item in list(self._staged):
            self._finish(item, _copy_into)
        self._release()
        return list(self.written)

    def _finish(self, item: _Staged, move: Callable[[Path, Path], None]) -> None:
        """Move one staged file's content to its target with ``move(tmp, target)``."""
        try:
            move(item.tmp, item.target)
        except OSError as exc:
            done = ", ".join(map(str, self.written))
            note = f" (written: {done}; the others were not)" if done else ""
            raise OutputError(f"cannot write {item.dest}: {exc.strerror or exc}{note}") from None
        with signals_held():
            self._staged.remove(item)
            with contextlib.suppress(FileNotFoundError):
                os.unlink(item.tmp)  # already gone when renamed
            self.written.append(item.dest)

    def discard(self) -> None:
        """Remove the temporary files not renamed into place and the placeholders not
        replaced."""
        with signals_held():
            for item in self._staged:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(item.tmp)
            self._staged.clear()
        self._release()

    def _release(self) -> None:
        """Unlock every claimed placeholder, and remove those still in place."""
        with signals_held():
            for target, fd in self._claims.items():
                with contextlib.suppress(OSError):
                    if os.path.samestat(os.stat(target), os.fstat(fd)):
                        os.unlink(target)
                os.close(fd)
            self._claims.clear()


def _target(path: Path) -> Path:
    """Where ``path``'s content goes: the file a symbolic link points to, not the link."""
    return Path(os.path.realpath(path)) if os.path.islink(path) else path


def _written_through(path: Path) -> bool:
    """True if ``path`` is (or links to) a character device, a FIFO, or a descriptor of
    this process (``/dev/stdout``, ``/dev/fd/N``): written through.

    Raises
    ------
    OutputError
        ``path`` is a block device or a socket, which meshlab-sharp never writes.
    """
    if _own_descriptor(path) is not None:
        return True
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False  # absent, or a dangling link: an ordinary new file
    if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
        return True
    if stat.S_ISBLK(mode) or stat.S_ISSOCK(mode):
        kind = "a block device" if stat.S_ISBLK(mode) else "a socket"
        raise OutputError(f"cannot write {path}: it is {kind}")
    return False


#: A descriptor's name: ``/dev/fd/N`` or ``/proc/self/fd/N`` (or ``/proc/PID/fd/N``).
_DESCRIPTOR = re.compile(r"/(?:dev|proc/(self|thread-self|\d+))/fd/(\d+)")


def _own_descriptor(path: Path) -> int | None:
    """The descriptor of this process that ``path`` names, directly or through links
    (``/dev/stdout`` links to ``/proc/self/fd/1``), or None."""
    name = os.path.abspath(path)
    for _ in range(40):  # the kernel's limit on links followed
        found = _DESCRIPTOR.fullmatch(name)
        if found is not None and found.group(1) in (None, "self", "thread-self", str(os.getpid())):
            return int(found.group(2))
        if not os.path.islink(name):
            return None
        name = os.path.normpath(os.path.join(os.path.dirname(name), os.readlink(name)))
    return None


def _taken(path: Path, target: Path) -> str:
    """Why an existing ``target`` cannot be claimed: another run's locked placeholder,
    or a file the user has (``--force`` replaces it)."""
    with contextlib.suppress(OSError):
        fd = os.open(target, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        try:
            if os.fstat(fd).st_size == 0:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return f"{path} is being written by another meshlab-sharp run"
        finally:
            os.close(fd)
    return f"{path} exists; use --force to overwrite it"


def _copy_into(tmp: Path, target: Path) -> None:
    """Copy ``tmp`` into ``target``: a descriptor of this process (where the file it is
    open on stands, after what this process printed there), or a device or FIFO
    (opened without creating or truncating anything; a FIFO waits for its reader)."""
    own = _own_descriptor(target)
    if own is not None:
        sys.stdout.flush()
        sys.stderr.flush()
        fd = os.dup(own)
    else:
        fd = os.open(target, os.O_WRONLY | os.O_NOCTTY | os.O_CLOEXEC)
    with os.fdopen(fd, "wb") as out:
        mode = os.fstat(fd).st_mode
        if own is None and not (stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)):
            raise OSError(errno.EEXIST, "it is no longer a device or FIFO")
        with open(tmp, "rb") as src:
            shutil.copyfileobj(src, out)


def atomic_write(
    path: str | os.PathLike[str],
    write: Callable[[str], None],
    *,
    into: OutputSet | None = None,
) -> Path:
    """Write a file through a temporary sibling and rename it into place.

    Parameters
    ----------
    path : path-like
        Destination. Its folder must exist.
    write : callable
        ``write(tmp_path)`` creates the content at ``tmp_path`` (same extension as
        ``path``, so format-sniffing writers such as pymeshlab's work).
    into : OutputSet, optional
        Only stage the file in this set; its ``commit`` renames it into place.

    Returns
    -------
    Path
        The destination.

    Raises
    ------
    OutputError
        See :meth:`OutputSet.stage`.
    """
    if into is not None:
        return into.stage(path, write)
    with OutputSet() as single:
        dest = single.stage(path, write)
        single.commit()
    return dest


def _umask() -> int:
    """The process's file-creation mask (reading it means setting it, so set it back)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask
