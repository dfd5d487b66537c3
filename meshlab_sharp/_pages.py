"""NumPy's huge pages, off while ``detect`` runs.

NumPy asks the kernel for 2 MB pages (``madvise(MADV_HUGEPAGE)``) on every array of
4 MB or more. ``detect`` makes and frees many such arrays (per-scale rows, outputs of
the compiled pass); on a virtual machine that hands freed memory back to its host, each
fresh huge page can cost a fault on the host too: on the 2-core development machine, a
1M-point cloud took 0.3 to 1.3 s of system time a run with them and 0.1 to 0.2 s
without (docs/benchmark.md, "Read the system seconds"). :func:`small_pages` turns the
advice off for the duration of a call and restores it after, unless the user chose
with the environment variable ``NUMPY_MADVISE_HUGEPAGE`` (then it is left alone).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager

try:  # a private NumPy switch (numpy >= 1.20); without it nothing is changed
    from numpy._core.multiarray import _set_madvise_hugepage
except ImportError:  # pragma: no cover - older NumPy layouts
    try:
        from numpy.core.multiarray import _set_madvise_hugepage
    except ImportError:
        _set_madvise_hugepage = None

_lock = threading.Lock()
_depth = 0
_before = False


@contextmanager
def small_pages() -> Iterator[None]:
    """Within the block, NumPy does not advise huge pages for new arrays; nested and
    concurrent blocks (threads) restore the setting when the last one ends."""
    global _depth, _before
    if _set_madvise_hugepage is None or "NUMPY_MADVISE_HUGEPAGE" in os.environ:
        yield
        return
    with _lock:
        if _depth == 0:
            _before = bool(_set_madvise_hugepage(False))
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _set_madvise_hugepage(_before)
