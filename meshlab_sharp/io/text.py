"""Text files as numpy token tables: where each token starts and ends, and on which line.

The readers of the text formats (point lists, OBJ, OFF, ASCII PLY and STL) work on these
tables with numpy instead of Python loops over lines, and convert only the tokens they
need. Every conversion error names the line and the token.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

_BLOCK = 1 << 18  # tokens converted at a time (bounds the temporary index arrays)
#: Longest token read as a number: 17 significant digits with sign, point, exponent and
#: leading zeros fit easily; the bound keeps a giant token from costing gigabytes.
MAX_NUMBER_LENGTH = 64
_SHORT_DIGITS = 15  # decimals with at most this many digits are parsed in numpy
_POWERS_OF_TEN = 10.0 ** np.arange(_SHORT_DIGITS + 1)


def _byte_table(chars: bytes) -> np.ndarray:
    table = np.zeros(256, dtype=bool)
    table[list(chars)] = True
    return table


_SPACE = _byte_table(b" \t\n\r\x0b\x0c")


@dataclass(frozen=True)
class Tokens:
    """The whitespace-separated tokens of a text, as offsets into its bytes.

    Attributes
    ----------
    buf : (b,) uint8
        The text.
    start, end : (t,) int64
        Offsets of each token's first byte and one past its last.
    line : (t,) int64
        1-based line number of each token.
    """

    buf: np.ndarray
    start: np.ndarray
    end: np.ndarray
    line: np.ndarray

    def __len__(self) -> int:
        return len(self.start)

    def text(self, i: int) -> str:
        """Token ``i`` as printable text (shortened when long), for messages."""
        raw = self.buf[self.start[i] : min(self.end[i], self.start[i] + 24)].tobytes()
        more = "..." if self.end[i] - self.start[i] > 24 else ""
        return raw.decode("ascii", "backslashreplace") + more

    def take(self, keep: np.ndarray) -> Tokens:
        """The tokens selected by a boolean mask or an index array."""
        return Tokens(self.buf, self.start[keep], self.end[keep], self.line[keep])

    def line_starts(self) -> np.ndarray:
        """(t,) bool: True for the first token of each line."""
        first = np.ones(len(self), dtype=bool)
        first[1:] = self.line[1:] != self.line[:-1]
        return first

    def equals(self, word: bytes) -> np.ndarray:
        """(t,) bool: True where the token is exactly ``word``."""
        same = (self.end - self.start) == len(word)
        for k, byte in enumerate(word):
            idx = np.minimum(self.start + k, len(self.buf) - 1)
            same &= self.buf[idx] == byte
        return same


def tokenize(
    data: bytes, *, separators: bytes = b"", comments: tuple[bytes, ...] = (b"#",)
) -> Tokens:
    """Split ``data`` at whitespace (and ``separators``); drop comments. Lines end at
    LF (or CR in a file without LF).

    Parameters
    ----------
    data : bytes
        The text.
    separators : bytes
        Extra single-byte separators, e.g. ``b",;"`` for point lists.
    comments : tuple of bytes
        Marks that begin a comment: a token that starts with one is dropped with the
        rest of its line.

    Returns
    -------
    Tokens
    """
    buf = np.frombuffer(data, dtype=np.uint8)
    space = _SPACE if not separators else _SPACE | _byte_table(separators)
    is_space = space[buf]
    edges = np.diff(is_space.view(np.int8), prepend=np.int8(1), append=np.int8(1))
    del is_space
    start = np.flatnonzero(edges == -1)
    end = np.flatnonzero(edges == 1)
    del edges
    breaks = b"\n" if b"\n" in data or b"\r" not in data else b"\r"  # old Mac: CR only
    newlines = np.flatnonzero(buf == breaks[0])
    per_line = np.diff(np.searchsorted(start, newlines), prepend=0, append=len(start))
    line = np.repeat(np.arange(1, len(newlines) + 2), per_line)
    tokens = Tokens(buf, start, end, line)
    for mark in comments:
        tokens = _drop_comments(tokens, mark)
    return tokens


def _drop_comments(tokens: Tokens, mark: bytes) -> Tokens:
    """Drop each token that starts with ``mark`` and the tokens after it on its line."""
    if len(tokens) == 0:
        return tokens
    opens = tokens.buf[tokens.start] == mark[0]
    for k, byte in enumerate(mark[1:], start=1):
        idx = np.minimum(tokens.start + k, len(tokens.buf) - 1)
        opens &= (tokens.end - tokens.start > k) & (tokens.buf[idx] == byte)
    begin = np.flatnonzero(opens)
    if len(begin) == 0:
        return tokens
    stop = np.searchsorted(tokens.line, tokens.line[begin], side="right")
    depth = np.zeros(len(tokens) + 1, dtype=np.int64)
    np.add.at(depth, begin, 1)
    np.add.at(depth, stop, -1)
    return tokens.take(np.cumsum(depth[:-1]) == 0)


def numbers(tokens: Tokens, index: np.ndarray, dtype: type, name: str) -> np.ndarray:
    """Convert the tokens at ``index`` to ``dtype`` (np.float64 or np.int64).

    Only plain decimal numbers are accepted: no hex, no ``_`` digit separators, and no
    ``nan``/``inf``: a non-finite value, including an overflow (``1e400``), is an error.

    Parameters
    ----------
    tokens : Tokens
    index : int array, any shape
        Positions of the tokens to convert.
    dtype : np.float64 or np.int64
    name : str
        The file, for messages.

    Returns
    -------
    ndarray of ``dtype``, the shape of ``index``

    Raises
    ------
    InputError
        Naming the line and token of the first token that is not a number.
    """
    flat = np.asarray(index, dtype=np.int64).ravel()
    if len(flat) == 0:
        return np.empty(np.shape(index), dtype=dtype)
    inverse = None
    if not (np.diff(flat) > 0).all():
        flat, inverse = np.unique(flat, return_inverse=True)
    length = tokens.end[flat] - tokens.start[flat]
    odd = (length == 0) | (length > MAX_NUMBER_LENGTH)
    if dtype is np.int64:  # numpy would join a lone sign to the next number
        first = tokens.buf[np.minimum(tokens.start[flat], len(tokens.buf) - 1)]
        odd |= (length == 1) & ((first == ord("+")) | (first == ord("-")))
    if odd.any():
        raise _not_a_number(tokens, int(flat[np.argmax(odd)]), name, dtype)
    values = np.empty(len(flat), dtype=dtype)
    for lo in range(0, len(flat), _BLOCK):
        block = flat[lo : lo + _BLOCK]
        parsed = np.empty(len(block), dtype=dtype)
        rest = np.ones(len(block), dtype=bool)
        if dtype is np.float64:
            parsed, rest = _short_decimals(tokens, block)
        if rest.any():
            slow = _parse(_compact(tokens, block[rest]), dtype)
            if len(slow) != rest.sum():
                bad = _first_unconvertible(tokens, block[rest], dtype)
                raise _not_a_number(tokens, bad, name, dtype)
            parsed[rest] = slow
        values[lo : lo + _BLOCK] = parsed
    if dtype is np.float64:
        finite = np.isfinite(values)
        if not finite.all():
            raise _overflow(tokens, int(flat[np.argmin(finite)]), name)
    return (values if inverse is None else values[inverse]).reshape(np.shape(index))


def _short_decimals(tokens: Tokens, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parse the tokens written ``[+-]digits[.digits]`` with at most 15 digits, in numpy.

    Such a token is m / 10^f with integers m < 2^53 and f <= 15, both exact in float64,
    so one division gives the correctly rounded value, as ``float()`` does (Clinger's
    fast path). The others (exponents, more digits, anything malformed) are left to the
    general parser.

    Returns
    -------
    values : (k,) float64
        The values of the short decimals (anything elsewhere).
    rest : (k,) bool
        The tokens left to the general parser.
    """
    values = np.empty(len(index))
    rest = np.ones(len(index), dtype=bool)
    short = np.flatnonzero(tokens.end[index] - tokens.start[index] <= _SHORT_DIGITS + 2)
    if len(short) == 0:
        return values, rest
    start = tokens.start[index[short]]
    length = tokens.end[index[short]] - start
    rows = np.arange(int(length.max()))[:, None]  # one row per character position
    inside = rows < length
    chars = tokens.buf[np.minimum(start + rows, len(tokens.buf) - 1)]
    signed = (chars[0] == ord("-")) | (chars[0] == ord("+"))
    body = inside
    body[0] &= ~signed
    value = chars.astype(np.int64) - ord("0")
    digit = body & (value >= 0) & (value <= 9)
    dot = body & (chars == ord("."))
    n_digits = digit.sum(axis=0)
    simple = ((digit | dot) == body).all(axis=0) & (dot.sum(axis=0) <= 1)
    simple &= (n_digits >= 1) & (n_digits <= _SHORT_DIGITS)
    value[~digit] = 0
    scale = np.where(digit, 10, 1)
    mantissa = np.zeros(len(short), dtype=np.int64)
    for j in range(len(rows)):  # overflows only where not simple, and those are discarded
        mantissa *= scale[j]
        mantissa += value[j]
    has_dot = dot.any(axis=0)  # a simple token's digits after its dot end the token:
    fraction = np.where(has_dot, length - 1 - np.argmax(dot, axis=0), 0)
    parsed = mantissa / _POWERS_OF_TEN[np.minimum(fraction, _SHORT_DIGITS)]
    values[short] = np.where(chars[0] == ord("-"), -parsed, parsed)
    rest[short] = ~simple
    return values, rest


def _compact(tokens: Tokens, index: np.ndarray) -> bytes:
    """The tokens ``index``, each followed by one space."""
    start = tokens.start[index]
    width = tokens.end[index] - start + 1
    at = np.cumsum(width) - width
    source = np.repeat(start - at, width) + np.arange(int(width.sum()))
    text = tokens.buf[np.minimum(source, len(tokens.buf) - 1)]
    text[at + width - 1] = ord(" ")
    return text.tobytes()


def _parse(text: bytes, dtype: type) -> np.ndarray:
    """Numbers separated by spaces; fewer than there are words when one does not parse."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)  # numpy < 2: partial read
            return np.fromstring(text, dtype=dtype, sep=" ")
    except (ValueError, DeprecationWarning):
        return np.empty(0, dtype=dtype)


def _first_unconvertible(tokens: Tokens, index: np.ndarray, dtype: type) -> int:
    """The first token of ``index`` that Python cannot parse as ``dtype`` (the first
    token if all parse: numpy's parser is the stricter)."""
    parse = float if dtype is np.float64 else int
    for i in index:
        try:
            parse(tokens.buf[tokens.start[i] : tokens.end[i]].tobytes())
        except ValueError:
            return int(i)
    return int(index[0])


def _not_a_number(tokens: Tokens, i: int, name: str, dtype: type) -> InputError:
    word = tokens.text(i)
    where = f"{name}: line {tokens.line[i]}"
    if word.lower().lstrip("+-").startswith(("nan", "inf")):
        return InputError(f"{where}: non-finite coordinate (NaN or inf): {word}")
    kind = "a number" if dtype is np.float64 else "an integer"
    return InputError(f"{where}: {word!r} is not {kind}")


def _overflow(tokens: Tokens, i: int, name: str) -> InputError:
    word = tokens.text(i)
    if word.lower().lstrip("+-").startswith(("nan", "inf")):
        return _not_a_number(tokens, i, name, np.float64)
    return InputError(
        f"{name}: line {tokens.line[i]}: non-finite coordinate {word} (overflows float64)"
    )


#: How much of a file is looked at before it is read whole.
HEAD_BYTES = 1 << 16
_CHUNK_BYTES = 1 << 26
_CONTROL = _byte_table(bytes(range(32)) + b"\x7f") & ~_SPACE


def read_text(path: Path, name: str, what: str, offset: int = 0) -> bytes:
    """The bytes of a text file from ``offset``, read in chunks, each checked before the
    next is read: binary content is refused from its first 64 KiB, or as soon as it
    appears, never after reading the whole file.

    Raises
    ------
    InputError
        NUL or other control bytes.
    """
    chunks = []
    size = HEAD_BYTES
    with path.open("rb") as fh:
        fh.seek(offset)
        while chunk := fh.read(size):
            check_text(chunk, name, what, offset)
            chunks.append(chunk)
            offset += len(chunk)
            size = _CHUNK_BYTES
    return b"".join(chunks)


def check_text(data: bytes, name: str, what: str, offset: int = 0) -> None:
    """Raise :class:`InputError` if ``data`` (at ``offset`` in its file) holds control
    bytes (binary content)."""
    control = _CONTROL[np.frombuffer(data, dtype=np.uint8)]
    if control.any():
        at = int(np.argmax(control))
        raise InputError(
            f"{name}: not a text {what} (binary or garbage content: byte "
            f"0x{data[at]:02x} at offset {offset + at})"
        )


def line_table(tokens: Tokens) -> tuple[np.ndarray, np.ndarray]:
    """Where each non-empty line's tokens start, and how many it has.

    Returns
    -------
    first : (l,) int64
        Index (into ``tokens``) of the first token of each non-empty line.
    count : (l,) int64
        Number of tokens on that line.
    """
    first = np.flatnonzero(tokens.line_starts())
    count = np.diff(first, append=len(tokens))
    return first, count
