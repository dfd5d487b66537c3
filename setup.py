"""Build the native library (native/: C kernels and C++ behind a C ABI, loaded with ctypes;
no Python headers).

The sources native/src/*.c and *.cpp, compiled with the flags native/CMakeLists.txt gives
them for the MeshLab plugin, into two ctypes libraries: ``_ckernels`` (the C kernels and
the detection sequence behind ms_detect) and ``_ccurves`` (the feature curves,
native/src/curves*.cpp, behind ms_curves_extract). The C++ is compiled with hidden
visibility: each library exports its C ABI alone. Everything else is configured in
pyproject.toml. ``optional=True``: without a compiler the package still installs and runs
the numpy reference path.
"""

import os
import platform
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

# glibc's vector math library (exp of two doubles at once) on x86-64 Linux.
libmvec = sys.platform == "linux" and platform.machine() in ("x86_64", "AMD64")
# Relative paths, as setuptools wants them.
native = Path("native")
curves = sorted(str(path) for path in (native / "src").glob("curves*.cpp"))
kernels = sorted(
    str(path)
    for pattern in ("*.c", "*.cpp")
    for path in (native / "src").glob(pattern)
    if str(path) not in curves
)
headers = [str(native / "include" / "meshlab_sharp.h")]
headers += sorted(str(path) for path in (native / "src").glob("*.h"))

#: Flags by language, as native/CMakeLists.txt gives them; the C++ hidden but for the C ABI
#: (meshlab_sharp.h declares it with default visibility).
LANGUAGE_FLAGS = {
    ".c": ["-std=c99"],
    ".cpp": ["-std=c++14", "-Wall", "-Wno-unused-parameter", "-fvisibility=hidden"],
}


#: Set to 1 to keep the debug information (also ``build_ext --debug``); by default the
#: libraries are built without it (Python's own flags ask for ``-g``): a tenth of the size.
DEBUG_ENV = "MESHLAB_SHARP_DEBUG"


class BuildNative(build_ext):
    """build_ext with each source's language flags (C99 for .c, C++14 for .cpp), and no
    debug information unless a debug build is asked for."""

    def build_extensions(self) -> None:
        compile_one = self.compiler._compile
        debug = bool(self.debug) or os.environ.get(DEBUG_ENV) == "1"
        no_debug = [] if debug or sys.platform == "win32" else ["-g0"]

        def compile_with_language(obj, src, ext, cc_args, extra_postargs, pp_opts):
            flags = [*extra_postargs, *LANGUAGE_FLAGS[Path(src).suffix], *no_debug]
            compile_one(obj, src, ext, cc_args, flags, pp_opts)

        self.compiler._compile = compile_with_language
        super().build_extensions()


def native_library(name: str, sources: list[str]) -> Extension:
    """One ctypes library of the native sources, linked as C++."""
    return Extension(
        name,
        sources=sources,
        depends=headers,
        include_dirs=[str(native / "include")],
        # No fused multiply-add and no fast-math: products and sums rounded as numpy
        # rounds them (docs/contributing.md).
        extra_compile_args=["-O3", "-ffp-contract=off", "-fno-math-errno"],
        extra_link_args=["-pthread"],
        define_macros=[("MS_LIBMVEC", "1")] if libmvec else [],
        libraries=["mvec", "m"] if libmvec else ["m"],
        language="c++",
        optional=True,
    )


setup(
    cmdclass={"build_ext": BuildNative},
    ext_modules=[
        native_library("meshlab_sharp._ckernels", kernels),
        native_library("meshlab_sharp._ccurves", curves),
    ],
)
