"""A small progress bar on stderr, shown only on a terminal.

The pipeline reports its stages through a :class:`Progress`; the CLI turns it on when
stderr is a terminal and ``--quiet`` is not given. The library default is silent.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


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

    def step(self, label: str, n: int = 1) -> None:
        """Advance by ``n`` steps and show ``label`` as the current stage."""
        self.done = min(self.done + n, self.total)
        if not self.enabled:
            return
        filled = round(self.width * self.done / self.total)
        elapsed = time.perf_counter() - self._start
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(f"\r{label[:28]:<28} [{bar}] {self.done}/{self.total} {elapsed:6.1f}s")
        self.stream.flush()
        self._drawn = True

    def close(self) -> None:
        """End the line of the bar, if one was drawn, and draw no more (a second call
        does nothing, so a command can close the bar before printing an error)."""
        if self._drawn:
            self.stream.write("\n")
            self.stream.flush()
        self.enabled = self._drawn = False
