"""A point cloud read in blocks (:mod:`meshlab_sharp.io.stream` opens files as one)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from ..errors import InputError


class PointSource:
    """A point cloud read in blocks.

    Parameters
    ----------
    n : int
        Number of points.
    blocks : callable
        ``blocks(size)`` yields the coordinates, (c, 3) float64 blocks of at most
        ``size`` points, in order; it may be called several times.
    name : str
        For messages.
    """

    def __init__(self, n: int, blocks: Callable[[int], Iterator[np.ndarray]], name: str) -> None:
        self.n = n
        self._blocks = blocks
        self.name = name

    def blocks(self, size: int) -> Iterator[np.ndarray]:
        """The coordinates, (c, 3) float64 blocks of at most ``size`` points, in order.

        Raises
        ------
        InputError
            The file holds more or fewer points than its header says (the same error
            whoever reads it, in memory or out of core).
        """
        seen = 0
        for block in self._blocks(size):
            seen += len(block)
            if seen > self.n:
                break
            yield block
        if seen != self.n:
            raise InputError(f"{self.name}: {seen} points read, the header says {self.n}")

    @classmethod
    def from_array(cls, points: np.ndarray, name: str = "array") -> PointSource:
        """A source over an (n, 3) array already in memory."""

        def blocks(size: int) -> Iterator[np.ndarray]:
            for s in range(0, len(points), size):
                yield np.ascontiguousarray(points[s : s + size], dtype=np.float64)

        return cls(len(points), blocks, name)
