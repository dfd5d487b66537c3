"""Build the compiled kernels and the native feature curves (plain libraries loaded with
ctypes; no Python headers).

Everything else is configured in pyproject.toml. ``optional=True``: without a C compiler
the package still installs and runs the numpy reference path.
"""

import platform
import sys
from pathlib import Path

from setuptools import Extension, setup

# glibc's vector math library (exp of two doubles at once) on x86-64 Linux.
libmvec = sys.platform == "linux" and platform.machine() in ("x86_64", "AMD64")

setup(
    ext_modules=[
        Extension(
            "meshlab_sharp._ckernels",
            sources=["meshlab_sharp/_ckernels.c"],
            depends=["meshlab_sharp/_ckernels.h"],
            # No fused multiply-add and no fast-math: products and sums rounded as numpy
            # rounds them (docs/implementation-notes.md).
            extra_compile_args=["-O3", "-ffp-contract=off", "-fno-math-errno", "-std=c99"],
            define_macros=[("MS_LIBMVEC", "1")] if libmvec else [],
            libraries=["mvec", "m"] if libmvec else ["m"],
            optional=True,
        ),
        # The feature curves (C++ behind the C ABI of native/include/meshlab_sharp_curves.h),
        # compiled as the plugin compiles them: the same bits.
        Extension(
            "meshlab_sharp._ccurves",
            sources=sorted(str(p) for p in Path("native/src").glob("curves*.cpp")),
            depends=[
                "native/include/meshlab_sharp_curves.h",
                "native/src/curves.h",
                "native/src/curves_types.h",
            ],
            include_dirs=["native/include"],
            extra_compile_args=["-std=c++14", "-O3", "-ffp-contract=off", "-fno-math-errno"],
            language="c++",
            optional=True,
        ),
    ]
)
