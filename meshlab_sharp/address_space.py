"""What loading the detection's libraries needs of an address-space limit (``ulimit -v``).

Under RLIMIT_AS the libraries' loading fails in ways no Python code can turn into the
command line's one line: numpy's OpenBLAS prints its own message and ends the process
when it cannot map a thread's buffer, and scipy's OpenBLAS, in the same case, retries
for ever (SIGTERM cannot end it). :func:`check_address_space` therefore compares the
limit with what loading needs before any of those libraries is imported, and refuses a
limit that is too low with the out-of-memory line. Nothing here imports numpy.

The estimate (:func:`loading_need`), all in address space (VmSize), not resident memory:

* what the process maps already (``/proc/self/status`` VmSize: the interpreter and the
  command line's own modules, about 23 MB);
* :data:`LIBRARIES`: what importing numpy, scipy, pymeshlab and the compiled kernels
  adds, without OpenBLAS's per-thread mappings (400 MB, measured: VmPeak after the
  command line's loading with ``OPENBLAS_NUM_THREADS=1``, 455.7 MB, less the 23.3 MB
  before it and the calling thread's 32 MB buffer);
* per OpenBLAS copy (numpy's and scipy's, :data:`OPENBLAS_COPIES`), with T threads
  (``OPENBLAS_NUM_THREADS``, else ``GOTO_NUM_THREADS``, else ``OMP_NUM_THREADS``, at
  most the CPUs this process may run on, as OpenBLAS counts them): T - 1 worker threads,
  each with its stack (RLIMIT_STACK's soft limit, 8 MB by default; 2 MB when unlimited)
  and its :data:`OPENBLAS_BUFFER`, mapped at import;
* the calling thread's buffer in numpy's copy, mapped when the command line warms
  OpenBLAS up (scipy's copy maps its own at its first product, which the detection does
  not call);
* :data:`MARGIN`, for other library builds than the measured ones.

On a 2-CPU machine with 8 MB stacks that is 23 + 400 + 2 x (32 + 8) + 32 + 32 = about
567 MB; loading maps 536 to 549 MB at its peak there, from one process to another
(``OPENBLAS_NUM_THREADS=1``: 456 to 467 MB, and the estimate 487 MB; a 16 MB stack
limit: 552 MB, the estimate 583 MB). The figures come from::

    python -c "import meshlab_sharp.cli as c; c._load_libraries(); \\
        print(open('/proc/self/status').read())" | grep -E 'VmSize|VmPeak'
"""

from __future__ import annotations

import os
import resource

from .errors import OutOfMemory

#: Address space that importing numpy, scipy, pymeshlab and the compiled kernels adds,
#: bytes, without OpenBLAS's per-thread mappings (measured; see the module's text).
LIBRARIES = 400 << 20
#: OpenBLAS's buffer for each of its threads (BUFFER_SIZE on x86-64), bytes.
OPENBLAS_BUFFER = 32 << 20
#: OpenBLAS copies loaded: numpy's and scipy's, each with its own threads and buffers.
OPENBLAS_COPIES = 2
#: A thread's stack when RLIMIT_STACK is unlimited (glibc's default there), bytes.
UNLIMITED_STACK = 2 << 20
#: Room for library builds that map more than the measured ones, bytes.
MARGIN = 32 << 20
#: OpenBLAS's environment variables for its thread count, in the order it reads them.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def mapped_now() -> int:
    """The address space this process maps now (VmSize), bytes; 0 where /proc has no
    status to read."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmSize:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def openblas_threads() -> int:
    """The threads each OpenBLAS copy starts: the first positive value of
    :data:`THREAD_VARIABLES`, else one per CPU, at most the CPUs this process may run
    on (OpenBLAS counts them the same way)."""
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    cpus = max(cpus or 1, 1)
    for name in THREAD_VARIABLES:
        try:
            asked = int(os.environ.get(name, ""))
        except ValueError:
            continue
        if asked > 0:
            return min(asked, cpus)
    return cpus


def thread_stack() -> int:
    """The stack a new thread maps (RLIMIT_STACK's soft limit), bytes."""
    soft, _ = resource.getrlimit(resource.RLIMIT_STACK)
    return UNLIMITED_STACK if soft == resource.RLIM_INFINITY else int(soft)


def loading_need(threads: int | None = None) -> int:
    """The address space the process needs to load the detection's libraries and warm
    up OpenBLAS, bytes (the estimate in the module's text), with ``threads`` OpenBLAS
    threads (default: :func:`openblas_threads`)."""
    workers = OPENBLAS_COPIES * ((threads or openblas_threads()) - 1)
    openblas = OPENBLAS_BUFFER + workers * (OPENBLAS_BUFFER + thread_stack())
    return mapped_now() + LIBRARIES + openblas + MARGIN


def check_address_space() -> None:
    """Raise :class:`~meshlab_sharp.errors.OutOfMemory` when RLIMIT_AS's soft limit is
    below :func:`loading_need` (nothing happens without a limit): the message names the
    limit, the need and the ``ulimit -v`` that would do (or ``OPENBLAS_NUM_THREADS=1``,
    where one thread would fit)."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return
    need = loading_need()
    if soft >= need:
        return
    hint = f"raise it to at least ulimit -v {-(-need // 1024)} (KB), or unlimited"
    if soft >= loading_need(1):
        hint += ", or run OpenBLAS on one thread (OPENBLAS_NUM_THREADS=1)"
    raise OutOfMemory(
        f"out of memory: loading the libraries needs about {need / 2**20:.0f} MB of "
        f"address space, and the limit (ulimit -v) is {soft / 2**20:.0f} MB; {hint}"
    )
