"""The ctypes binding cannot drift from the native library's header: every ``ms_``
function that ``native/include/meshlab_sharp.h`` declares is bound in
``_kernels._SIGNATURES`` with the same arity and the same kinds of arguments and result,
nothing else is bound, and the built library exports exactly these functions."""

from __future__ import annotations

import ctypes
import re
import shutil
import subprocess

import pytest

from meshlab_sharp import _header, _kernels
from meshlab_sharp.curves import _native as curves_native

#: C scalar types of the ABI and the ctypes type that passes each; any pointer passes as
#: c_void_p (numpy arrays' addresses, structs by address).
SCALARS = {"int": ctypes.c_int, "int64_t": ctypes.c_int64, "double": ctypes.c_double}

Signature = tuple[type | None, list[type]]


def declared(text: str) -> dict[str, Signature]:
    """The ctypes signature of every ``ms_`` prototype in a header's text, by name.

    Raises ValueError on a parameter or result type outside :data:`SCALARS`, pointers
    and ``void``."""

    def kind(c_type: str, where: str) -> type | None:
        c_type = re.sub(r"\bconst\b", "", c_type).strip()
        if c_type.endswith("*") or re.fullmatch(r"ms_\w+_fn", c_type):
            return ctypes.c_void_p  # a callback (a ms_..._fn typedef) is a pointer too
        if c_type == "void":
            return None
        if c_type not in SCALARS:
            raise ValueError(f"{where}: no ctypes kind for C type {c_type!r}")
        return SCALARS[c_type]

    code = re.sub(r"/\*.*?\*/", " ", text, flags=re.DOTALL)
    out: dict[str, Signature] = {}
    for ret, name, params in re.findall(r"([\w \t]+?[\s*])(ms_\w+)\s*\(([^)]*)\)\s*;", code):
        args = []
        for param in params.split(","):
            # the type is the parameter less its name: "const double *p" -> "const double *"
            c_type = re.sub(r"\w+\s*$", "", " ".join(param.split()))
            arg = kind(c_type, name)
            if arg is None:
                raise ValueError(f"{name}: a void parameter")
            args.append(arg)
        out[name] = (kind(ret, name), args)
    return out


def _name(kind: type | None) -> str:
    return "void" if kind is None else kind.__name__


def mismatches(header: dict[str, Signature], bound: dict[str, Signature]) -> list[str]:
    """What differs between the header's signatures and the bound ones, one line each."""
    problems = [f"{name}: declared, not bound" for name in sorted(set(header) - set(bound))]
    problems += [f"{name}: bound, not declared" for name in sorted(set(bound) - set(header))]
    for name in sorted(set(header) & set(bound)):
        (ret, args), (bound_ret, bound_args) = header[name], bound[name]
        if ret is not bound_ret:
            problems.append(f"{name}: returns {_name(ret)}, bound as {_name(bound_ret)}")
        if len(args) != len(bound_args):
            problems.append(f"{name}: {len(args)} arguments, bound with {len(bound_args)}")
        for i, (arg, given) in enumerate(zip(args, bound_args, strict=False)):
            if arg is not given:
                problems.append(f"{name}: argument {i} is {_name(arg)}, bound as {_name(given)}")
    return problems


DECLARED = declared(_header.PATH.read_text())
#: The feature curves' functions (``ms_curves_``), in their own library (C++ sources).
CURVES = {name: sig for name, sig in DECLARED.items() if name.startswith("ms_curves_")}
#: The kernels' functions: the rest.
HEADER = {name: sig for name, sig in DECLARED.items() if name not in CURVES}


def test_the_header_declares_the_abi():
    """Known prototypes read as their C says (68 functions: the parser misses none)."""
    i32, i64, f64, ptr = ctypes.c_int, ctypes.c_int64, ctypes.c_double, ctypes.c_void_p
    assert len(HEADER) == 68
    assert HEADER["ms_noise_floor"] == (f64, [ptr])
    assert HEADER["ms_scale_floor"] == (f64, [ptr, i32, i32, f64])
    assert HEADER["ms_stage_curved"] == (i64, [ptr, ptr, i64, i64, i32, i32, ptr])
    assert HEADER["ms_face_windings"] == (i64, [ptr, i64, i64, ptr])
    assert HEADER["ms_dedup"] == (i64, [ptr, i64, ptr, i64, ptr, ptr, ptr])
    assert HEADER["ms_scale_vote"] == (f64, [ptr, i64, i32, f64, i32, f64, ptr, ptr, ptr])
    assert HEADER["ms_bit_histogram"] == (i64, [ptr, i64, i64, ptr])
    assert HEADER["ms_noise_factor"] == (f64, [f64])
    assert HEADER["ms_support_free_score"] == (i32, [i32, f64, ptr])
    assert HEADER["ms_robust_plan"] == (i32, [f64, i64, ptr, i32, i32, ptr])
    assert HEADER["ms_plan_thresholds"] == (None, [ptr, ptr, ptr])
    assert HEADER["ms_stage_decide"] == (
        None,
        [ptr, i64, i64, i32, i64, i64, ptr, ptr, f64, ptr, ptr, ptr, ptr, ptr],
    )
    assert HEADER["ms_detect"] == (i32, [ptr, i64, ptr, i64, ptr, ptr, ptr, ptr, ptr, i32])
    assert HEADER["ms_parse_scales"] == (i32, [ptr, i32, ptr, i32, ptr, i32])
    assert HEADER["ms_detection_details"] == (i32, [ptr, ptr, ptr])


def test_every_header_function_is_bound_as_declared():
    assert mismatches(HEADER, _kernels._SIGNATURES) == []
    assert mismatches(CURVES, curves_native.SIGNATURES) == []


def _replace(name: str, ret: type | None = None, args: dict[int, type | None] | None = None):
    """A change of the bound table: ``name`` returning ``ret`` (when given), its argument i
    of kind args[i] (None: the argument dropped)."""

    def change(signatures: dict[str, Signature]) -> None:
        old_ret, old_args = signatures[name]
        new_args = list(old_args)
        for i, kind in sorted((args or {}).items(), reverse=True):
            if kind is None:
                del new_args[i]
            else:
                new_args[i] = kind
        signatures[name] = (old_ret if ret is None else ret, new_args)

    return change


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (lambda s: s.pop("ms_thin"), "ms_thin: declared, not bound"),
        (lambda s: s.update(ms_extra=(None, [])), "ms_extra: bound, not declared"),
        (_replace("ms_extent", ret=ctypes.c_int), "ms_extent: returns void, bound as c_int"),
        (_replace("ms_adjacency", args={4: None}), "ms_adjacency: 5 arguments, bound with 4"),
        (
            _replace("ms_ring_pdis", args={1: ctypes.c_int}),
            f"ms_ring_pdis: argument 1 is {ctypes.c_int64.__name__}, bound as c_int",
        ),
        (
            _replace("ms_supported", args={5: ctypes.c_int64}),
            f"ms_supported: argument 5 is c_double, bound as {ctypes.c_int64.__name__}",
        ),
        (
            _replace("ms_isolated", args={0: ctypes.c_double}),
            "ms_isolated: argument 0 is c_void_p, bound as c_double",
        ),
    ],
)
def test_a_drifted_binding_is_caught(change, expected):
    """The check fails on a missing or extra function, a wrong result, a missing argument
    and a wrong argument kind."""
    signatures = dict(_kernels._SIGNATURES)
    change(signatures)
    assert mismatches(HEADER, signatures) == [expected]


def test_the_parser_refuses_an_unknown_type():
    with pytest.raises(ValueError, match="ms_f: no ctypes kind for C type 'float'"):
        declared("void ms_f(float x);")
    assert declared("/* void ms_g(int); */ int64_t ms_h(const char *s,\n  int k);") == {
        "ms_h": (ctypes.c_int64, [ctypes.c_void_p, ctypes.c_int])
    }


@pytest.mark.skipif(shutil.which("nm") is None, reason="needs nm")
@pytest.mark.parametrize(
    ("library", "functions"),
    [(_kernels._LIB, HEADER), (curves_native._LIB, CURVES)],
    ids=["kernels", "curves"],
)
def test_the_library_exports_exactly_the_header(library, functions):
    """Each built library's exported functions are its part of the header: the private
    internal functions of native/src stay hidden, and no declared function is missing."""
    if library is None:
        pytest.skip("the compiled library is not built")
    listing = subprocess.run(
        ["nm", "-D", "--defined-only", library._name], capture_output=True, text=True, check=True
    ).stdout
    exported = {line.split()[-1] for line in listing.splitlines() if " T " in line}
    assert exported == set(functions)
