"""Failures of the scanner-file libraries (laspy, lazrs, pye57) as one-line errors.

These libraries raise their own exception types, numpy's, or OS errors, often with
several lines of debugging context; the blocks of a :class:`~meshlab_sharp.io.source.
PointSource` are read lazily, so the failure may come long after the file was opened.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from ..errors import InputError


def library_message(exc: BaseException) -> str:
    """The first non-empty line of a library's exception, or its type's name."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0] if lines else type(exc).__name__


def guarded(
    blocks: Callable[[int], Iterator[np.ndarray]], name: str, what: str
) -> Callable[[int], Iterator[np.ndarray]]:
    """``blocks`` whose library failures are an :class:`InputError`
    (``"NAME: cannot read the WHAT file: ..."``) and whose numpy warnings are silenced
    (non-finite results are refused by the consumers). MemoryError passes through."""

    def checked(size: int) -> Iterator[np.ndarray]:
        inner = blocks(size)
        while True:
            try:
                with np.errstate(all="ignore"):  # only while the library runs
                    block = next(inner)
            except StopIteration:
                return
            except (MemoryError, InputError):
                raise
            except Exception as exc:  # laspy, lazrs, pye57, numpy and OS errors
                raise InputError(
                    f"{name}: cannot read the {what} file: {library_message(exc)}"
                ) from None
            yield block

    return checked


def require_utf8_name(name: str, what: str) -> None:
    """Refuse a path that is not valid UTF-8: the compiled readers take UTF-8 names."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError(
            f"{name!a}: the file name is not valid UTF-8, which the {what} reader "
            "needs; rename the file"
        ) from None
