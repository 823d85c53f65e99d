"""BLAS thread limits for the application's numeric work, through threadpoolctl.

The RPCA solvers (denoising, single shot, the phase and fringe-order corrections) make many
small LAPACK calls (QR and SVD of tall, thin matrices). Multi-threaded OpenBLAS synchronises its
threads at every call; on a machine whose cores are busy with other work, that made a 768 x 64 QR
80x slower than single-threaded (0.27 s against 3 ms, measured on the 2-core development machine
under load), and a whole RPCA solve 5-10x slower. ``processing`` never changes the process-wide
thread count itself: the pipeline, the study and the benchmarks set it here, around the stages
that solve RPCA problems, and restore it afterwards.
"""

from __future__ import annotations

import contextlib
import sys
import threading
from collections.abc import Iterator
from typing import Any

# BLAS threads for RPCA-heavy work (see the module docstring).
RPCA_BLAS_THREADS = 1
# BLAS threads for the fused pass's small per-block products (3 x N weights by N x 16k-pixel frames):
# OpenBLAS's second thread only synchronises there (the pass ran 28 ms with it against 22.5 ms without
# on the 2-core development machine, quiet).
KERNEL_BLAS_THREADS = 1

_controller: Any = None
_controller_modules = -1
_controller_lock = threading.Lock()


def _blas_controller() -> Any:
    """One threadpoolctl controller, scanned again only after new modules were imported (a new module may
    load another BLAS): scanning the loaded libraries costs ~0.5 ms a call, a kept controller ~0.04 ms."""
    global _controller, _controller_modules
    from threadpoolctl import ThreadpoolController

    with _controller_lock:
        if _controller is None or _controller_modules != len(sys.modules):
            _controller = ThreadpoolController()
            _controller_modules = len(sys.modules)
        return _controller


@contextlib.contextmanager
def blas_threads(count: int | None) -> Iterator[None]:
    """Limit BLAS to ``count`` threads inside the block (None: leave as is); restores afterwards."""
    if count is None:
        yield
        return
    if isinstance(count, bool) or int(count) != count or count < 1:
        raise ValueError(f"count: expected a positive number of threads or None, found {count!r}")
    with _blas_controller().limit(limits=int(count), user_api="blas"):
        yield


def rpca_blas() -> contextlib.AbstractContextManager[None]:
    """The BLAS limit for RPCA solves (:data:`RPCA_BLAS_THREADS` threads)."""
    return blas_threads(RPCA_BLAS_THREADS)


def kernel_blas() -> contextlib.AbstractContextManager[None]:
    """The BLAS limit for the fused pass (:data:`KERNEL_BLAS_THREADS` threads)."""
    return blas_threads(KERNEL_BLAS_THREADS)
