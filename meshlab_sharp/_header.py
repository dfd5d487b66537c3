"""The method's constants, read from the C header ``_ckernels.h`` where they are defined.

The compiled kernels, the MeshLab plugin (which compiles the same C file) and this
package share one definition of every constant and default option: each
``#define MS_NAME value`` line of the header's constants block is ``NAME`` here. Reading
the header needs no compiler, so the numpy reference path (no compiled library) has the
same constants.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

#: The header, shipped beside this module.
HEADER = Path(__file__).with_name("_ckernels.h")

_DEFINE = re.compile(r"^#define MS_([A-Z0-9_]+) (.+)$", re.MULTILINE)
_OPERATORS = {ast.Div: float.__truediv__, ast.Mult: float.__mul__}


def _value(node: ast.expr) -> int | float | tuple[int, ...]:
    """A number, a quotient or product of two numbers, or a tuple of integers."""
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return node.value
    if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
        left, right = _value(node.left), _value(node.right)
        if isinstance(left, float) and isinstance(right, float):
            return _OPERATORS[type(node.op)](left, right)
    if isinstance(node, ast.Tuple) and all(
        isinstance(e, ast.Constant) and type(e.value) is int for e in node.elts
    ):
        return tuple(e.value for e in node.elts)  # type: ignore[attr-defined]
    raise ValueError(f"{HEADER.name}: unsupported constant {ast.unparse(node)!r}")


def parse(text: str) -> dict[str, int | float | tuple[int, ...]]:
    """The ``MS_`` constants of a header's text, by name without the prefix.

    A value is a C number, ``(a / b)`` or ``(a * b)`` of two floating-point numbers
    (evaluated as C folds it: one correctly rounded operation), or ``{i, j, ...}`` of
    integers (a tuple).
    """
    out: dict[str, int | float | tuple[int, ...]] = {}
    for name, expr in _DEFINE.findall(text):
        source = expr.strip().replace("{", "(").replace("}", ",)")
        out[name] = _value(ast.parse(source, mode="eval").body)
    return out


CONSTANTS = parse(HEADER.read_text())


def _typed(name: str, kind: type) -> int | float | tuple[int, ...]:
    value = CONSTANTS[name]
    if type(value) is not kind:
        raise TypeError(f"{HEADER.name}: MS_{name} is {value!r}, not {kind.__name__}")
    return value


def integer(name: str) -> int:
    """The integer constant ``MS_<name>``."""
    return int(_typed(name, int))  # type: ignore[arg-type]


def real(name: str) -> float:
    """The floating-point constant ``MS_<name>``."""
    return float(_typed(name, float))  # type: ignore[arg-type]


def integers(name: str) -> tuple[int, ...]:
    """The integer list ``MS_<name>``."""
    return tuple(_typed(name, tuple))  # type: ignore[arg-type]
