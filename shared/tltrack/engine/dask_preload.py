"""Dask worker preload: compile (or load) the particle-filter kernels once, when a worker starts.

    dask worker tcp://SCHEDULER:8786 --nthreads 1 --preload tltrack.engine.dask_preload

Dask calls :func:`dask_setup` before the worker registers with its scheduler, so a worker takes
batches only once its kernels are ready, instead of compiling them inside its first batch (and
side by side with the other workers of its host).

numba keeps compiled kernels in a cache directory, which must be writable, and which it reuses
only on the same CPU model. The cache is ``$NUMBA_CACHE_DIR`` when set (it must be writable; the
worker refuses to start otherwise). When unset, numba's own cache beside the sources serves if
it is writable (a development install), else a per-user directory under the temporary directory
(an image whose packages belong to root). A worker started without this preload gives the same
results; it only compiles at its first batch.

The nanny sets the OpenMP, MKL and OpenBLAS thread counts to the worker's thread count, but not
``NUMBA_NUM_THREADS``; the kernels run on one thread each (no ``parallel=True``), so one worker
thread per core (``--nthreads 1`` and ``--nworkers`` = cores) keeps every core busy.

The nanny also starts each worker with ``MALLOC_TRIM_THRESHOLD_=65536``, so that freed memory goes
back to the system at once. Setting it turns off glibc's sliding mmap threshold
(``mallopt(3)``): every array over 128 KiB is then mapped afresh and its pages faulted in, at each
of the thousands of particle arrays a batch allocates. That made a batch 1.6 times slower here
(2.68 s against 1.65 s, N = 6000, 11 runs). :func:`keep_freed_memory` fixes the two thresholds where
glibc's sliding ones would end (arrays up to 32 MiB from the heap, the heap trimmed past 64 MiB):
1.52 s for that batch.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import importlib.util
import logging
import os
import tempfile
import time
from pathlib import Path
from typing import Any

# under "distributed", so that a worker's log shows it beside Dask's own lines
log = logging.getLogger("distributed.preloading.tltrack")


def cache_dir() -> Path | None:
    """Where numba should cache the kernels: None for numba's default beside the sources."""
    if env := os.environ.get("NUMBA_CACHE_DIR"):
        return Path(env)
    spec = importlib.util.find_spec("tltrack.filters")
    roots = list(spec.submodule_search_locations or []) if spec else []
    if roots and _writable(Path(roots[0]) / "__pycache__"):
        return None
    return Path(tempfile.gettempdir()) / f"tltrack-numba-{os.getuid()}"


def _writable(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
    except OSError:
        return False
    return True


#: glibc's ``mallopt`` parameters (``<malloc.h>``) and the upper ends of its sliding thresholds on
#: 64-bit systems: ``DEFAULT_MMAP_THRESHOLD_MAX`` and twice that, as glibc itself trims
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 2 * MMAP_THRESHOLD


def keep_freed_memory() -> bool:
    """Undo the nanny's ``MALLOC_TRIM_THRESHOLD_`` in this process; False without glibc."""
    name = ctypes.util.find_library("c")
    try:
        mallopt = ctypes.CDLL(name).mallopt if name else None
    except (OSError, AttributeError):  # musl and others have no mallopt
        mallopt = None
    if mallopt is None:
        return False
    return bool(
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD) and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )


def prepare() -> tuple[Path | None, float]:
    """Point numba at a writable cache and load or compile every kernel; (cache, seconds)."""
    where = cache_dir()
    if where is not None:
        if not _writable(where):
            raise RuntimeError(
                f"NUMBA_CACHE_DIR={where} is not writable: numba could not keep the compiled "
                "kernels, and every worker would compile them again at every start"
            )
        os.environ["NUMBA_CACHE_DIR"] = str(where)
        import numba.core.config

        numba.core.config.reload_config()  # in case numba was imported before this module
    t0 = time.perf_counter()
    importlib.import_module("tltrack.engine.montecarlo")  # what a batch needs: not in batch 1
    from tltrack.filters.warm import warm_up

    warm_up()
    return where, time.perf_counter() - t0


def dask_setup(worker: Any) -> None:
    """Dask's preload hook: runs in the worker process before it registers."""
    malloc = "32 MiB / 64 MiB" if keep_freed_memory() else "unchanged (no glibc)"
    where, seconds = prepare()
    log.info(
        "tltrack kernels ready in %.1f s (numba cache: %s, malloc thresholds: %s) on worker %s, "
        "pid %d",
        seconds,
        where or "beside the sources",
        malloc,
        getattr(worker, "address", "?"),
        os.getpid(),
    )
