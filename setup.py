"""Build the native library (native/: plain C and C++ behind a C ABI, loaded with ctypes;
no Python headers).

The sources native/src/*.c, compiled with the flags native/CMakeLists.txt gives them for
the MeshLab plugin, into the package's ``_ckernels`` module; the feature curves,
native/src/curves*.cpp, into ``_ccurves``. Everything else is configured
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
            # rounds them (docs/contributing.md).
            extra_compile_args=["-O3", "-ffp-contract=off", "-fno-math-errno", "-std=c99"],
            define_macros=[("MS_LIBMVEC", "1")] if libmvec else [],
            libraries=["mvec", "m"] if libmvec else ["m"],
            optional=True,
        ),
        # The feature curves (C++ behind the C ABI of native/include/meshlab_sharp.h),
        # compiled as the plugin compiles them: the same bits.
        Extension(
            "meshlab_sharp._ccurves",
            sources=sorted(str(p) for p in Path("native/src").glob("curves*.cpp")),
            depends=[
                "native/include/meshlab_sharp.h",
                "native/src/curves.h",
                "native/src/curves_types.h",
            ],
            include_dirs=["native/include"],
            extra_compile_args=[
                "-std=c++14",
                "-O3",
                "-ffp-contract=off",
                "-fno-math-errno",
                "-fvisibility=hidden",  # the C ABI alone is exported (curves_api.cpp)
            ],
            language="c++",
            optional=True,
        ),
    ]
)
