"""Run a block of numpy/scipy linear algebra with a given number of BLAS threads.

The RPCA solvers make many small LAPACK calls (QR and SVD of tall, thin matrices). Multi-threaded
OpenBLAS synchronises its threads at every call; on a machine whose cores are busy with other
work, that made a 768 x 64 QR 80x slower than single-threaded (0.27 s against 3 ms, measured on
the 2-core development machine under load), and a whole RPCA solve 5-10x slower.

:func:`blas_threads` uses ``threadpoolctl`` when it is installed; otherwise it calls the thread
controls of the OpenBLAS libraries already loaded into the process (the ones numpy and scipy
wheels bundle) through ctypes. If neither is available it does nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
from collections.abc import Iterator
from functools import lru_cache

log = logging.getLogger(__name__)

# (setter, getter) symbol pairs of the OpenBLAS builds seen in numpy/scipy wheels and distributions.
_SYMBOLS = (
    ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
    ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
    ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
    ("openblas_set_num_threads", "openblas_get_num_threads"),
)


@lru_cache(maxsize=1)
def _openblas_controls() -> tuple[tuple[ctypes._CFuncPtr, ctypes._CFuncPtr], ...]:
    """(set, get) function pairs of every OpenBLAS library mapped into this process."""
    import numpy  # noqa: F401  (make sure the libraries are loaded)
    import scipy.linalg  # noqa: F401

    paths: set[str] = set()
    try:
        with open("/proc/self/maps", encoding="utf-8") as maps:
            for line in maps:
                parts = line.split()
                if len(parts) >= 6 and "openblas" in parts[-1].lower() and ".so" in parts[-1]:
                    paths.add(parts[-1])
    except OSError:
        return ()
    controls = []
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for set_name, get_name in _SYMBOLS:
            setter, getter = getattr(lib, set_name, None), getattr(lib, get_name, None)
            if setter is not None and getter is not None:
                getter.restype = ctypes.c_int
                controls.append((setter, getter))
                break
    return tuple(controls)


@contextlib.contextmanager
def blas_threads(count: int | None) -> Iterator[None]:
    """Limit BLAS to ``count`` threads inside the block (None: leave as is); restores afterwards."""
    if count is None:
        yield
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=count, user_api="blas"):
            yield
        return
    controls = _openblas_controls()
    previous = [int(getter()) for _, getter in controls]
    for setter, _ in controls:
        setter(int(count))
    try:
        yield
    finally:
        for (setter, _), value in zip(controls, previous):
            setter(value)
