"""A small progress bar on stderr, shown only on a terminal.

The pipeline reports its stages through a :class:`Progress`; the CLI turns it on when
stderr is a terminal and ``--quiet`` is not given. The library default is silent.
"""

from __future__ import annotations

import sys
import time
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

#: The bars whose line is drawn and not yet ended.
_DRAWN: weakref.WeakSet[Progress] = weakref.WeakSet()


class Progress:
    """Draw ``label [#####.....] done/total`` on one line of a stream.

    Parameters
    ----------
    total : int
        Number of steps of the whole job.
    enabled : bool, default False
        Draw nothing when False.
    stream : TextIO, optional
        Where to draw; ``sys.stderr`` by default.
    width : int, default 30
        Width of the bar in characters.
    """

    def __init__(
        self, total: int, *, enabled: bool = False, stream: TextIO | None = None, width: int = 30
    ) -> None:
        self.total = max(int(total), 1)
        self.enabled = enabled
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.done = 0
        self._start = time.perf_counter()
        self._drawn = False
        self._width = 0

    def step(self, label: str, n: int = 1) -> None:
        """Advance by ``n`` steps and show ``label`` as the current stage."""
        self.done = min(self.done + n, self.total)
        if not self.enabled:
            return
        filled = round(self.width * self.done / self.total)
        elapsed = time.perf_counter() - self._start
        bar = "#" * filled + "." * (self.width - filled)
        line = f"{label[:28]:<28} [{bar}] {self.done}/{self.total} {elapsed:6.1f}s"
        self.stream.write(f"\r{line}")
        self.stream.flush()
        self._drawn = True
        self._width = len(line)
        _DRAWN.add(self)

    def close(self) -> None:
        """End the line of the bar, if one was drawn, and draw no more (a second call
        does nothing, so a command can close the bar before printing an error)."""
        if self._drawn:
            self.stream.write("\n")
            self.stream.flush()
        self.enabled = self._drawn = False
        _DRAWN.discard(self)

    def clear(self) -> None:
        """Erase the bar's line, if one was drawn, and draw no more."""
        if self._drawn:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
        self.enabled = self._drawn = False
        _DRAWN.discard(self)


@contextmanager
def cleared_on_error() -> Iterator[None]:
    """Erase every bar still drawn when the block ends with an exception (an error,
    Ctrl-C): the message or the prompt that follows starts on a clean line."""
    try:
        yield
    except BaseException:
        for bar in list(_DRAWN):
            bar.clear()
        raise
