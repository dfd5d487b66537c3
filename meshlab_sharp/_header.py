"""The method's constants, read from the native library's header where they are defined.

The native library, the MeshLab plugin (which links the same library) and this package
share one definition of every constant and default option: the public header
``native/include/meshlab_sharp.h`` (:data:`PATH`). Each ``#define MS_NAME value`` line of
its detection constants is ``NAME`` here (see :data:`KERNELS`), each ``#define
MS_CURVE_NAME value`` line of the feature curves' constants ``NAME`` of :data:`CURVES`.
Reading a header needs no compiler, so the numpy reference path (no compiled library) has
the same constants.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

#: A constant's value: an integer, a floating-point number, or a list of either.
Value = int | float | tuple[int, ...] | tuple[float, ...]

_OPERATORS = {ast.Div: float.__truediv__, ast.Mult: float.__mul__}


def _value(node: ast.expr, known: dict[str, Value], where: str) -> Value:
    """A number (negative ones too), an earlier constant's full name, a quotient or product of two
    floating-point numbers or names, or a tuple of integers or of floating-point numbers."""
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        value = _value(node.operand, known, where)
        if isinstance(value, int | float):
            return -value
    if isinstance(node, ast.Name) and node.id in known:
        return known[node.id]
    if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
        left, right = _value(node.left, known, where), _value(node.right, known, where)
        if isinstance(left, float) and isinstance(right, float):
            return _OPERATORS[type(node.op)](left, right)
    if isinstance(node, ast.Tuple) and all(isinstance(e, ast.Constant) for e in node.elts):
        items = tuple(e.value for e in node.elts)  # type: ignore[attr-defined]
        if {type(v) for v in items} in ({int}, {float}):
            return items
    raise ValueError(f"{where}: unsupported constant {ast.unparse(node)!r}")


def parse(text: str, prefix: str = "MS_", where: str = "meshlab_sharp.h") -> dict[str, Value]:
    """The constants ``<prefix>NAME`` of a header's text, by name without the prefix.

    A value is a C number, an earlier constant (its full name, prefix included),
    ``(a / b)`` or ``(a * b)`` of two floating-point numbers or earlier constants
    (evaluated as C folds it: one correctly rounded operation), or ``{a, b, ...}`` of
    integers or of floating-point numbers (a tuple). ``where`` names the header in
    errors.
    """
    define = re.compile(rf"^#define ({re.escape(prefix)}([A-Z0-9_]+)) (.+)$", re.MULTILINE)
    known: dict[str, Value] = {}
    out: dict[str, Value] = {}
    for full, name, expr in define.findall(text):
        source = expr.strip().replace("{", "(").replace("}", ",)")
        try:
            tree = ast.parse(source, mode="eval")
        except SyntaxError:
            raise ValueError(f"{where}: unsupported constant {expr.strip()!r}") from None
        known[full] = out[name] = _value(tree.body, known, where)
    return out


class Header:
    """The constants ``<prefix>NAME`` of the C header ``path``, by ``NAME``.

    Parameters
    ----------
    path : Path
        The header.
    prefix : str
        The prefix of its constants' C names.
    """

    def __init__(self, path: Path, prefix: str) -> None:
        self.path = path
        self.prefix = prefix
        self.constants = parse(path.read_text(), prefix, path.name)

    def _typed(self, name: str, kind: type, item: type | None = None) -> Value:
        value = self.constants[name]
        if type(value) is not kind or (
            item is not None and not all(type(v) is item for v in value)  # type: ignore[union-attr]
        ):
            what = kind.__name__ if item is None else f"{kind.__name__} of {item.__name__}"
            raise TypeError(f"{self.path.name}: {self.prefix}{name} is {value!r}, not {what}")
        return value

    def integer(self, name: str) -> int:
        """The integer constant ``<prefix><name>``."""
        return int(self._typed(name, int))  # type: ignore[arg-type]

    def real(self, name: str) -> float:
        """The floating-point constant ``<prefix><name>``."""
        return float(self._typed(name, float))  # type: ignore[arg-type]

    def integers(self, name: str) -> tuple[int, ...]:
        """The integer list ``<prefix><name>``."""
        return tuple(self._typed(name, tuple, int))  # type: ignore[arg-type]

    def reals(self, name: str) -> tuple[float, ...]:
        """The floating-point list ``<prefix><name>``."""
        return tuple(self._typed(name, tuple, float))  # type: ignore[arg-type]


def header_path() -> Path:
    """The native library's public header: under ``_sources/native`` in an installed
    package (a wheel), or ``native`` beside the package (a checkout, editable install)."""
    package = Path(__file__).resolve().parent
    candidates = (package / "_sources" / "native", package.parent / "native")
    for folder in candidates:
        header = folder / "include" / "meshlab_sharp.h"
        if header.is_file():
            return header
    raise FileNotFoundError(
        f"meshlab_sharp.h is missing (looked in {' and '.join(map(str, candidates))}); "
        "reinstall meshlab-sharp"
    )


#: The native library's public header, ``native/include/meshlab_sharp.h``.
PATH = header_path()
#: Detection: the ``MS_`` constants (the curves' ``MS_CURVE_`` ones among them, as
#: ``CURVE_NAME``).
KERNELS = Header(PATH, "MS_")
#: The feature curves: the ``MS_CURVE_`` constants (native/src/curves.cpp uses them).
CURVES = Header(PATH, "MS_CURVE_")

#: The kernels' header and its constants, by name without the ``MS_`` prefix.
HEADER = KERNELS.path
CONSTANTS = KERNELS.constants
integer = KERNELS.integer
real = KERNELS.real
integers = KERNELS.integers
reals = KERNELS.reals
