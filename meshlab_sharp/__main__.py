"""``python -m meshlab_sharp`` and the ``meshlab-sharp`` script: the command line.

The signal handlers are set here, before the command line's imports (numpy, scipy,
pymeshlab: a good part of a second), so that SIGINT, SIGTERM or SIGHUP at any moment
ends the process with one line and status 128 + the signal's number.
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType

#: The signals that end the command with one line.
_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _exit_now(signum: int, frame: FrameType | None) -> None:
    """While the modules load nothing is written yet: say so and end at once (an
    exception could be caught by the code being imported)."""
    name = signal.Signals(signum).name
    os.write(2, f"meshlab-sharp: interrupted by {name}; no output was written\n".encode())
    os._exit(128 + signum)


def run() -> int:
    """Entry point of the ``meshlab-sharp`` script; returns the exit status
    (:func:`meshlab_sharp.cli.main`, with the signals handled from the start)."""
    for s in _SIGNALS:
        signal.signal(s, _exit_now)
    from .cli import main

    return main(end_after_out_of_memory=True)


if __name__ == "__main__":
    sys.exit(run())
