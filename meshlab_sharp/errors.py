"""Exceptions raised by meshlab-sharp.

Every problem with the user's input or options is an :class:`InputError`: the CLI
prints its message on one line and exits with a non-zero status, never a traceback.
"""

from __future__ import annotations

TYPE_CHECKING = False
if TYPE_CHECKING:
    from pathlib import Path


class MeshlabSharpError(Exception):
    """Base class of every error meshlab-sharp raises on purpose."""


class InputError(MeshlabSharpError, ValueError):
    """The input geometry, file or options cannot be processed as given."""


class OutOfMemory(MeshlabSharpError, MemoryError):
    """Memory ran out (the command line's message says how much the input needs)."""


class ClusterError(MeshlabSharpError, RuntimeError):
    """The Dask cluster failed while it ran the tiles (scheduler lost, workers lost
    again and again)."""


class OutputError(MeshlabSharpError, OSError):
    """An output file cannot be written; the message names the destination, not the
    hidden temporary file."""


class ScratchError(MeshlabSharpError, OSError):
    """The tiles' scratch arrays cannot be written (a full disk, a file size limit); the
    message names the scratch folder's place and the options that choose it."""


class Interrupted(BaseException):
    """A catchable termination signal (SIGINT, SIGTERM, SIGHUP) stopped the command.

    Attributes
    ----------
    signum : int
        The signal.
    written : list of Path or None
        ``detect``: the outputs renamed into place before the signal (none unless it
        came after the renames). None for commands that write no output set.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum
        self.written: list[Path] | None = None


class InputWarning(UserWarning):
    """The input was read, but likely not as its author meant (decimal commas in a point
    list, say): the command line prints it as one ``meshlab-sharp: warning:`` line."""
