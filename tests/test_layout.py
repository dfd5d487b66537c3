"""The package's layout: no import circle in ``meshlab_sharp`` or ``evaluation``, and the
installed package imports nothing that is not installed (``evaluation``, ``scripts``,
``tests``). The graph is read from the sources with :mod:`ast`, every ``import`` statement
counted wherever it stands (module level, inside a function, under ``TYPE_CHECKING``),
and the package's lazily imported names (``_EXPORTS`` of ``meshlab_sharp/__init__.py``:
name -> submodule) as imports of those submodules."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("meshlab_sharp", "evaluation")
OUTSIDE = ("evaluation", "scripts", "tests")


def module_name(path: Path) -> str:
    """``meshlab_sharp/io/ply.py`` -> ``meshlab_sharp.io.ply``; a package's
    ``__init__.py`` -> the package."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    """Every module of :data:`PACKAGES`, by name."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            found[module_name(path)] = path
    return found


def imported(name: str, path: Path) -> set[str]:
    """The absolute names that module ``name`` (at ``path``) imports: ``import a.b`` gives
    ``a.b``; ``from a import b`` gives ``a.b`` (a module or a name of ``a``); relative
    imports resolved against the module's package; a lazy table ``_EXPORTS = {name:
    submodule}`` gives ``package.submodule``."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if (
            isinstance(node, ast.Assign)
            and [getattr(t, "id", None) for t in node.targets] == ["_EXPORTS"]
            and isinstance(node.value, ast.Dict)
        ):
            out.update(f"{package}.{ast.literal_eval(v)}" for v in node.value.values)
        elif isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            origin = node.module or ""
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                origin = ".".join(base + ([node.module] if node.module else []))
            out.update(f"{origin}.{alias.name}" for alias in node.names)
    return out


@functools.cache
def import_graph() -> dict[str, set[str]]:
    """Module -> the modules of :data:`PACKAGES` it imports: of each imported name, the
    nearest module that holds it (``from .io import Geometry`` -> ``meshlab_sharp.io``,
    ``from . import robust`` -> ``meshlab_sharp.robust``)."""
    known = modules()
    graph: dict[str, set[str]] = {}
    for name, path in known.items():
        targets = set()
        for target in imported(name, path):
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                targets.add(target)
        graph[name] = targets
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` as a list of modules (first == last), or None."""
    state: dict[str, int] = {}  # 1: on the stack, 2: done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)) is not None:
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)) is not None:
            return found
    return None


def test_the_graph_is_read() -> None:
    """The graph holds edges it must hold (a broken reader would find no circle either)."""
    graph = import_graph()
    assert "meshlab_sharp.pipeline" in graph["meshlab_sharp"]  # lazily, through _EXPORTS
    assert "meshlab_sharp.result" in graph["meshlab_sharp"]
    assert "meshlab_sharp.reference.neighbourhoods" in graph["meshlab_sharp.neighbourhoods"]
    assert "evaluation.scoring" in graph["evaluation.groundtruth"]
    assert "meshlab_sharp.tiles" in graph["meshlab_sharp.pipeline"]  # inside detect()
    assert "meshlab_sharp.io.readers" in graph["meshlab_sharp.io.stream"]  # in a function
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_circle() -> None:
    assert find_cycle(import_graph()) is None


def test_the_package_imports_nothing_outside_it() -> None:
    bad = {
        (name, target)
        for name, path in modules().items()
        if name.startswith("meshlab_sharp")
        for target in imported(name, path)
        if target.split(".")[0] in OUTSIDE
    }
    assert not bad


def test_the_reference_stands_alone() -> None:
    """The numpy reference (``meshlab_sharp.reference``) imports none of the product
    modules that dispatch to it: only other reference modules, the constants, the
    kernels' thread pool, the errors and the input's types. The Python-driven sequence
    (``reference.detect``) is the one exception: it runs the product's steps, each with
    the backend of the call, and no product module but the entry point imports it."""
    allowed = {
        "meshlab_sharp._header",
        "meshlab_sharp._kernels",
        "meshlab_sharp.defaults",
        "meshlab_sharp.errors",
        "meshlab_sharp.io",
    }
    graph = import_graph()
    sequence = "meshlab_sharp.reference.detect"
    reference = [
        name for name in graph if name.startswith("meshlab_sharp.reference") and name != sequence
    ]
    assert len(reference) >= 7
    users = {name for name in graph if sequence in graph[name]}
    assert users <= {"meshlab_sharp.pipeline"}, users
    bad = {
        (name, target)
        for name in reference
        for target in graph[name]
        if not target.startswith("meshlab_sharp.reference") and target not in allowed
    }
    assert not bad


def test_no_private_numpy_api() -> None:
    """No module of the package reaches into NumPy's private names (``np._x``,
    ``numpy.core._x``)."""
    bad = []
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (
                isinstance(node, ast.Attribute)
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
                and isinstance(node.value, ast.Name)
                and node.value.id in ("np", "numpy")
            ):
                bad.append((name, node.attr))
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("numpy"):
                bad += [(name, a.name) for a in node.names if a.name.startswith("_")]
                if any(p.startswith("_") for p in (node.module or "").split(".")):
                    bad.append((name, node.module))
    assert not bad
