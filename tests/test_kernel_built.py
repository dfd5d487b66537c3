"""The compiled fast path is built by the set-up (it installs gcc).

``tests/test_equivalence.py`` skips when the kernel is missing; this test makes that
situation a failure instead of a silent skip.
"""

from meshlab_sharp import _kernels


def test_the_compiled_kernel_is_built():
    assert _kernels.available(), "compiled kernels not built: pip install -e . (needs gcc)"
