"""landmark-companion: track known landmarks, send vision fixes to ArduPilot or PX4."""

import os as _os

__version__ = "0.1.0"

#: Native thread pools limited to one thread, before numpy loads (a value already in the
#: environment wins).  The pipeline runs its own threads -- the frame worker, a second
#: track thread, the background lane, the simulated camera -- and OpenBLAS/OpenMP pools on
#: top of those oversubscribe a small board's cores: on this project's 2-core machine the
#: demo's capture -> wire p99 fell from 50-52 to 22-24 ms and its CPU from 0.69-0.76 to
#: 0.44 cores with one thread each (together with ``cv2.setNumThreads(1)`` in a flight;
#: docs/decisions.md, "Native threads").
LIBRARY_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
for _var in LIBRARY_THREAD_VARS:
    _os.environ.setdefault(_var, "1")
