"""Exceptions raised by meshlab-sharp.

Every problem with the user's input or options is an :class:`InputError`: the CLI
prints its message on one line and exits with a non-zero status, never a traceback.
"""

from __future__ import annotations


class MeshlabSharpError(Exception):
    """Base class of every error meshlab-sharp raises on purpose."""


class InputError(MeshlabSharpError, ValueError):
    """The input geometry, file or options cannot be processed as given."""


class OutputError(MeshlabSharpError, OSError):
    """An output file cannot be written; the message names the destination, not the
    hidden temporary file."""


class InputWarning(UserWarning):
    """The input was read, but likely not as its author meant (decimal commas in a point
    list, say): the command line prints it as one ``meshlab-sharp: warning:`` line."""
