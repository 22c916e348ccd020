"""Threads for work that releases the GIL: file reads and hashes.

The work a wrap can split is row-independent: each file read, each hash, gives the
same answer alone as in a batch.  (libigl's tree builds and queries hold the GIL,
and its queries already use every core: they gain nothing here.)
:func:`thread_map` runs such work
on the cores this process may use, in a small pool made once, and gives the answers
in order, so results do not depend on the number of threads.

How many threads: the cores of this process's affinity mask (what ``taskset`` or a
container allows), capped by ``OMP_NUM_THREADS`` when it is set — the convention
of BLAS and OpenMP, which batches (:mod:`facewrap.batch.engines`) and Dask workers
set to 1 so that parallel jobs do not oversubscribe the machine.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor

__all__ = ["usable_cores", "usable_threads", "thread_map", "run_on", "in_background"]

_pool: ThreadPoolExecutor | None = None
_pool_size = 0
_lock = threading.Lock()


def usable_cores() -> int:
    """Cores this process may run on (its affinity mask; all of them off Linux).

    Examples
    --------
    >>> usable_cores() >= 1
    True
    """
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def usable_threads() -> int:
    """Threads worth starting for CPU work: :func:`usable_cores`, capped by a
    positive integer ``OMP_NUM_THREADS``.

    Examples
    --------
    >>> before = os.environ.get("OMP_NUM_THREADS")
    >>> os.environ["OMP_NUM_THREADS"] = "1"
    >>> usable_threads()
    1
    >>> _ = os.environ.pop("OMP_NUM_THREADS") if before is None else \\
    ...     os.environ.update(OMP_NUM_THREADS=before)
    """
    cores = usable_cores()
    cap = os.environ.get("OMP_NUM_THREADS", "").strip()
    if cap.isdigit() and int(cap) > 0:
        return min(cores, int(cap))
    return cores


def _executor(size: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size < size:
            # the smaller pool is dropped, not shut down: another thread may still be
            # submitting to it (a shut-down pool refuses new work); its threads end
            # once nothing refers to it
            _pool = ThreadPoolExecutor(max_workers=size, thread_name_prefix="facewrap")
            _pool_size = size
        return _pool


def thread_map(func, items, threads: int | None = None) -> list:
    """``[func(x) for x in items]``, on up to ``threads`` threads, in order.

    Worth it only when ``func`` spends its time in code that releases the GIL
    (libigl's tree queries, numpy on large arrays, hashlib on large buffers).  With
    one thread, or one item, it is the plain loop in this thread.

    Parameters
    ----------
    func : callable
    items : sequence
    threads : int, optional
        Default :func:`usable_threads`.

    Returns
    -------
    list
        ``func(item)`` for each item, in the order of ``items``; the first exception
        raised by a call is raised here.

    Examples
    --------
    >>> thread_map(lambda x: x * x, [1, 2, 3], threads=2)
    [1, 4, 9]
    """
    items = list(items)
    threads = usable_threads() if threads is None else threads
    if threads <= 1 or len(items) <= 1:
        return [func(x) for x in items]
    return list(_executor(min(threads, len(items))).map(func, items))


def run_on(executor, func, *args) -> Future:
    """``func(*args)`` submitted to ``executor``; without one (None), run here and
    now, its answer (or its exception) kept for ``.result()`` as a thread's is.

    Examples
    --------
    >>> run_on(None, max, 2, 5).result()
    5
    """
    if executor is not None:
        return executor.submit(func, *args)
    done: Future = Future()
    try:
        done.set_result(func(*args))
    except Exception as exc:
        done.set_exception(exc)
    return done


def in_background(func, *args) -> Future:
    """``func(*args)`` started on a thread of the pool, its answer (or its
    exception) at ``.result()``; with one usable thread, run here and now.

    Worth it for work that releases the GIL (an image's decoding) beside work that
    holds it (reading and checking a mesh).  Never for work that calls
    :func:`thread_map` itself: it would wait for the pool it holds a thread of.

    Examples
    --------
    >>> in_background(sum, [1, 2, 3]).result()
    6
    """
    threads = usable_threads()
    return run_on(_executor(threads) if threads > 1 else None, func, *args)
