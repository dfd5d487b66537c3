"""The compiled kernels report a failed allocation or a bad index as a Python error.

Each allocation in the native library (``native/src``) is checked: the library returns an
error code and the wrapper raises MemoryError (or InputError for a face index outside the
vertices) instead of writing through a null pointer. Memory is made to run out in a subprocess
whose address space is limited just above what the wrapper's numpy arrays need, so
that only the kernel's own allocation (the mesh adjacency's fill pointers) fails.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from meshlab_sharp import _kernels
from meshlab_sharp.errors import InputError

pytestmark = pytest.mark.skipif(not _kernels.available(), reason="compiled kernels not built")

#: What both subprocesses start with: the address space in use now (VmSize).
_PRELUDE = """
import resource
import numpy as np

def vm_bytes():
    with open("/proc/self/status") as f:
        return next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmSize:"))
"""

_UNDER_LIMIT = """
from meshlab_sharp import _kernels

n = 16_000_000
faces = np.array([[0, 1, 2]], dtype=np.int64)
arrays = (n + 1) * 8 + 6 * 4  # ptr and idx; the kernel then needs n * 4 more (64 MB)
resource.setrlimit(resource.RLIMIT_AS, (vm_bytes() + arrays + 16 * 2**20,) * 2)
try:
    _kernels.adjacency(faces, n)
except MemoryError as e:
    print("MemoryError:", e)
"""


def _run(
    script: str,
    timeout: float,
    env: dict[str, str] | None = None,
    preexec_fn: Callable[[], None] | None = None,
) -> subprocess.CompletedProcess[str]:
    """``script`` after :data:`_PRELUDE` in a Python subprocess at the checkout's root,
    which, like ``tests/``, is on its path, with ``env`` added to this environment."""
    root = Path(__file__).resolve().parent.parent
    path = {"PYTHONPATH": f"{root}{os.pathsep}{root / 'tests'}"}
    return subprocess.run(
        [sys.executable, "-c", _PRELUDE + script],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=root,
        env={**os.environ, **path, **(env or {})},
        preexec_fn=preexec_fn,
    )


def test_out_of_memory_is_a_memory_error():
    run = _run(_UNDER_LIMIT, 60, {"OPENBLAS_NUM_THREADS": "1"})
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("MemoryError: out of memory"), run.stdout + run.stderr


@pytest.mark.parametrize("bad", [-1, 3])
def test_adjacency_rejects_face_index_outside_vertices(bad):
    faces = np.array([[0, 1, 2], [0, 2, bad]], dtype=np.int64)
    with pytest.raises(InputError, match="outside the 3 vertices"):
        _kernels.adjacency(faces, 3)


def test_cloud_statistics_need_fewer_than_2_31_points():
    """The pass's statistics hold int32 indices: a cloud of 2**31 points is refused
    before any array is made (a zero-stride view stands in for the points)."""
    huge = np.broadcast_to(np.zeros(3), (2**31, 3))
    tree = _kernels.KdTree(huge, np.zeros(0, np.int64), np.zeros((1, 6)), 0)
    with pytest.raises(ValueError, match=r"fewer than 2\*\*31 points"):
        _kernels.cloud_projected_distances(tree, (8,), relative=True, noise_k=7)


_THREADS_CANNOT_START = """
import meshlab_sharp as ms
from shapes import box_cylinder_points, cube_grid_mesh

inputs = [(box_cylinder_points(3000), None), cube_grid_mesh(6)]  # a cloud, a mesh
free = [ms.detect(*a).mask for a in inputs]
vm = vm_bytes()
# each new thread's stack is RLIMIT_STACK's 1 GB (read at start-up): none fits any more
resource.setrlimit(resource.RLIMIT_AS, (vm + 256 * 2**20, resource.RLIM_INFINITY))
for a, mask in zip(inputs, free):
    print(int(mask.sum()), bool(np.array_equal(mask, ms.detect(*a).mask)))
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one CPU: no thread to start")
def test_threads_that_cannot_start_leave_their_work_to_the_caller():
    """``ms_detect`` on a machine where no new thread fits in the address space (a 1 GB
    stack each, 256 MB left): the calling thread does all the work, with the same
    result, instead of failing with EAGAIN, on a cloud and on a mesh (whose sharp edges
    otherwise take a thread of their own)."""
    gb = 2**30
    run = _run(
        _THREADS_CANNOT_START,
        120,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_STACK, (gb, gb)),
    )
    assert run.returncode == 0, run.stderr
    lines = [line.split() for line in run.stdout.splitlines()]
    assert len(lines) == 2, run.stdout
    for found, same in lines:
        assert int(found) > 0 and same == "True", run.stdout
