"""Two independent whole-map steps run side by side, or one task on several threads at once.

numpy releases the GIL in its loops, so two steps that each take milliseconds over a full map
overlap on two cores (measured: the noise estimate and the region pooling of ``auto``, 17 and
60 ms alone, take 75 ms together instead of 89 on a 2-core machine). Fine-grained work does not
gain: calls of a few microseconds spend their time handing the GIL over.

The helper threads are kept for the life of the process, not started per call: a thread keeps
its thread-local buffers (the fused pass's block scratch, 4 MiB) and its allocator arena from one
call to the next. A thread started per call allocated its buffers afresh each time, and once other
threads of the process had taken over the arena it left (an OpenMP pool of another library, for
one), those pages were faulted in again.
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
# Most helper threads one call of on_threads() uses (the kept pool grows to what calls ask, up to this).
MAX_HELPERS = 32
_HELPER_PREFIX = "processing-side"
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()

Result = TypeVar("Result")


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=MAX_HELPERS, thread_name_prefix=_HELPER_PREFIX)
        return _pool


def _on_helper() -> bool:
    """Whether this is one of the kept helper threads (whose nested calls run here, not wait on the pool)."""
    return threading.current_thread().name.startswith(_HELPER_PREFIX)


def side_by_side(first: Callable[[], First], second: Callable[[], Second]) -> tuple[First, Second]:
    """``(first(), second())``, ``second`` on a helper thread while ``first`` runs in this one.

    Both always run to the end; an exception of either is raised here (``first``'s if both
    raise). With :data:`THREADS` = 1, or called from the helper thread itself, they run one
    after the other in this thread.
    """
    if THREADS <= 1 or _on_helper():
        return first(), second()
    future = _executor().submit(second)
    try:
        result = first()
    except BaseException:
        future.exception()  # wait: the second step must not outlive the call
        raise
    return result, future.result()


def on_threads(task: Callable[[], Result], count: int) -> list[Result]:
    """``task()`` run at once in this thread and on ``count - 1`` kept helper threads; every result, this thread's first.

    For work that the calls share out among themselves (e.g. blocks taken from a common queue).
    All calls run to the end; an exception is raised here once they have (this thread's first).
    Called from a helper thread, or with ``count`` 1, it runs once, here.
    """
    helpers = 0 if _on_helper() else max(0, min(int(count), MAX_HELPERS + 1) - 1)
    if helpers == 0:
        return [task()]
    pool = _executor()
    futures = [pool.submit(task) for _ in range(helpers)]
    try:
        mine = task()
    except BaseException:
        for future in futures:
            future.exception()  # wait: no call may outlive this one
        raise
    return [mine, *(future.result() for future in futures)]


def on_blocks(run: Callable[[Callable[[], int | None]], object], pixels: int, block: int, threads: int) -> None:
    """``run(take)`` on up to ``threads`` threads (this one among them), ``take()`` handing out the first pixel of
    the next block of ``block`` pixels (None once all ``pixels`` are taken).

    Blocks are handed out one at a time rather than in fixed shares: on a machine whose cores are busy with
    other work, a thread the OS pauses holds up no block another thread could take. The other threads are
    the kept helpers (:func:`on_threads`), whose thread-local scratch stays allocated from call to call.
    """
    starts = iter(range(0, pixels, block))
    workers = max(1, min(int(threads), -(-pixels // block)))
    if workers == 1:
        run(lambda: next(starts, None))
        return
    lock = threading.Lock()

    def take() -> int | None:
        with lock:
            return next(starts, None)

    on_threads(lambda: run(take), workers)
