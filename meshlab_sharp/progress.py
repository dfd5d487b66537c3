"""A small progress bar on stderr, shown only on a terminal.

The pipeline reports its stages through a :class:`Progress`; the CLI turns it on when
stderr is a terminal and ``--quiet`` is not given. The library default is silent.
While a long stage runs (the neighbourhoods of a large input take seconds in one call),
the bar names it; with a ``tick`` (the CLI's bar) its clock keeps moving too: a
background thread redraws the line until :meth:`Progress.close`, which the owner of
such a bar must call (the CLI does, in a ``finally``).
"""

from __future__ import annotations

import sys
import threading
import time
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

#: The bars whose line is drawn and not yet ended.
_DRAWN: weakref.WeakSet[Progress] = weakref.WeakSet()

#: Seconds between redraws of the clock while a stage runs.
TICK = 0.5


class Progress:
    """Draw ``label [#####.....] done/total  elapsed`` on one line of a stream.

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
    tick : float, optional
        Seconds between redraws of the elapsed time while nothing else is reported
        (:data:`TICK` for the CLI); None: drawn only when reported to, no thread.
    """

    def __init__(
        self,
        total: int,
        *,
        enabled: bool = False,
        stream: TextIO | None = None,
        width: int = 30,
        tick: float | None = None,
    ) -> None:
        self.total = max(int(total), 1)
        self.enabled = enabled
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.done = 0
        self._start = time.perf_counter()
        self._drawn = False
        self._label = ""
        self._tick = tick
        self._lock = threading.RLock()  # close() may run in a signal handler's unwinding
        self._closed = threading.Event()
        self._ticker: threading.Thread | None = None
        self._width = 0

    def step(self, label: str, n: int = 1) -> None:
        """Advance by ``n`` steps and show ``label`` as the stage just done."""
        self.done = min(self.done + n, self.total)
        self._show(label)

    def stage(self, label: str) -> None:
        """Show ``label`` as the stage now running, without advancing (``label...``)."""
        self._show(f"{label}...")

    def _show(self, label: str) -> None:
        if not self.enabled:
            return
        with self._lock:
            self._label = label
            self._draw()
        if self._ticker is None and self._tick is not None:
            self._ticker = threading.Thread(target=self._run_ticker, daemon=True)
            self._ticker.start()

    def _draw(self) -> None:
        """Write the line (the caller holds the lock)."""
        filled = round(self.width * self.done / self.total)
        elapsed = time.perf_counter() - self._start
        bar = "#" * filled + "." * (self.width - filled)
        line = f"{self._label[:28]:<28} [{bar}] {self.done}/{self.total} {elapsed:6.1f}s"
        self.stream.write(f"\r{line}")
        self.stream.flush()
        self._drawn = True
        self._width = len(line)
        _DRAWN.add(self)

    def _run_ticker(self) -> None:
        """Redraw the clock every ``tick`` seconds until :meth:`close`."""
        assert self._tick is not None
        while not self._closed.wait(self._tick):
            with self._lock:
                if self.enabled:
                    self._draw()

    def close(self) -> None:
        """End the line of the bar, if one was drawn, and draw no more (a second call
        does nothing, so a command can close the bar before printing an error)."""
        self._end("\n")

    def clear(self) -> None:
        """Erase the bar's line, if one was drawn, and draw no more."""
        self._end("\r" + " " * self._width + "\r")

    def _end(self, text: str) -> None:
        """Write ``text`` if the line was drawn, and stop drawing (the clock too)."""
        self._closed.set()
        with self._lock:
            if self._drawn:
                self.stream.write(text)
                self.stream.flush()
            self.enabled = self._drawn = False
            _DRAWN.discard(self)
        if self._ticker is not None and self._ticker is not threading.current_thread():
            self._ticker.join()


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
