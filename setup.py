"""Build the native library (native/: plain C, loaded with ctypes; no Python headers).

The sources native/src/*.c, compiled with the flags native/CMakeLists.txt gives them for
the MeshLab plugin, into the package's ``_ckernels`` module. Everything else is configured
in pyproject.toml. ``optional=True``: without a C compiler the package still installs and
runs the numpy reference path.
"""

import platform
import sys
from pathlib import Path

from setuptools import Extension, setup

# glibc's vector math library (exp of two doubles at once) on x86-64 Linux.
libmvec = sys.platform == "linux" and platform.machine() in ("x86_64", "AMD64")
# Relative paths, as setuptools wants them.
native = Path("native")
sources = sorted(str(path) for path in (native / "src").glob("*.c"))
headers = [str(native / "include" / "meshlab_sharp.h")]
headers += sorted(str(path) for path in (native / "src").glob("*.h"))

setup(
    ext_modules=[
        Extension(
            "meshlab_sharp._ckernels",
            sources=sources,
            depends=headers,
            include_dirs=[str(native / "include")],
            # No fused multiply-add and no fast-math: products and sums rounded as numpy
            # rounds them (docs/implementation-notes.md).
            extra_compile_args=["-O3", "-ffp-contract=off", "-fno-math-errno", "-std=c99"],
            define_macros=[("MS_LIBMVEC", "1")] if libmvec else [],
            libraries=["mvec", "m"] if libmvec else ["m"],
            optional=True,
        )
    ]
)
