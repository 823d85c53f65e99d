"""Two independent whole-map steps run side by side.

numpy releases the GIL in its loops, so two steps that each take milliseconds over a full map
overlap on two cores (measured: the noise estimate and the region pooling of ``auto``, 17 and
60 ms alone, take 75 ms together instead of 89 on a 2-core machine). Fine-grained work does not
gain: calls of a few microseconds spend their time handing the GIL over.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

First = TypeVar("First")
Second = TypeVar("Second")


def available_cpus() -> int:
    """CPUs this process may run on (its affinity set where the OS has one), at least 1."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# Threads for side-by-side steps: 1 runs everything in the caller's thread (rig's Dask workers
# set it: they already run one worker per core).
THREADS = min(2, available_cpus())
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="processing-side")
        return _pool


def side_by_side(first: Callable[[], First], second: Callable[[], Second]) -> tuple[First, Second]:
    """``(first(), second())``, ``second`` on a helper thread while ``first`` runs in this one.

    Both always run to the end; an exception of either is raised here (``first``'s if both
    raise). With :data:`THREADS` = 1, or called from the helper thread itself, they run one
    after the other in this thread.
    """
    if THREADS <= 1 or threading.current_thread().name.startswith("processing-side"):
        return first(), second()
    future = _executor().submit(second)
    try:
        result = first()
    except BaseException:
        future.exception()  # wait: the second step must not outlive the call
        raise
    return result, future.result()
