"""Build the compiled kernels (a plain C library loaded with ctypes; no Python headers).

Everything else is configured in pyproject.toml. ``optional=True``: without a C compiler
the package still installs and runs the numpy reference path.
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "meshlab_sharp._ckernels",
            sources=["meshlab_sharp/_ckernels.c"],
            # No fused multiply-add and no fast-math: products and sums rounded as numpy
            # rounds them (docs/implementation-notes.md).
            extra_compile_args=["-O3", "-ffp-contract=off", "-fno-math-errno", "-std=c99"],
            libraries=["m"],
            optional=True,
        )
    ]
)
