"""The ``companion`` console script (and ``python -m companion``): native thread pools
limited to one thread, then the command line.

Importing the package sets no environment variable; this entry point does, before numpy
loads (a value already in the environment wins).  The pipeline runs its own threads -- the
frame worker, a second track thread, the background lane, the simulated camera -- and
OpenBLAS/OpenMP pools on top of those oversubscribe a small board's cores: on this
project's 2-core machine the demo's capture -> wire p99 fell from 50-52 to 22-24 ms and its
CPU from 0.69-0.76 to 0.44 cores with one thread each (together with
``cv2.setNumThreads(1)`` in a flight; docs/decisions.md, "Native threads").  A program that
embeds the package sets its own.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

LIBRARY_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_library_threads() -> None:
    """One thread per native pool unless the environment already says otherwise."""
    for var in LIBRARY_THREAD_VARS:
        os.environ.setdefault(var, "1")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: set the thread limits, then import and run the command line."""
    limit_library_threads()
    from companion.cli import main as cli_main  # after the limits, on purpose

    return cli_main(argv)
