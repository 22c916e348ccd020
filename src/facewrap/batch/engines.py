"""Where the jobs of a batch run: a local process pool or a Dask cluster.

Both call one function per job (:func:`facewrap.batch.runner.run_one`) and hand
each summary row to ``report`` as it arrives.  A worker that dies (crash, out of
memory) fails only its job; a lost Dask worker fails its job with the cluster's
error.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import threading
import time
from multiprocessing.connection import wait
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

from facewrap.batch.summary import DONE, FAILED, SKIPPED, summary_row
from facewrap.parallel import usable_cores

__all__ = ["default_workers", "single_threaded_blas", "run_in_pool", "run_on_dask"]


def default_workers() -> int:
    """Cores this process may use (one job each)."""
    return usable_cores()


@contextlib.contextmanager
def single_threaded_blas():
    """Workers started inside get one BLAS/OpenMP thread each (as Dask's do)."""
    names = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
    old = {n: os.environ.get(n) for n in names}
    for n in names:
        os.environ.setdefault(n, "1")
    try:
        yield
    finally:
        for n, v in old.items():
            if v is None:
                os.environ.pop(n, None)
            else:
                os.environ[n] = v


# flags "job i has started", shared with the pool's workers (set by their initializer)
_started = None
# whether this process already watches its parent (exit_with_parent)
_watching = False


def _pool_init(started) -> None:
    global _started
    _started = started
    exit_with_parent()
    os.environ["FACEWRAP_PROGRESS"] = "0"  # workers draw no bars: the batch draws one


def exit_with_parent() -> None:
    """End this worker as soon as the process that started the pool is gone.

    A killed (or interrupted) batch must not leave workers that go on running the
    jobs already queued to them: a daemon thread waits on the parent's sentinel
    (closed by the kernel when that process dies, whatever killed it) and ends the
    worker at once.  Its job's outputs are staged, so nothing partial is left, and
    it has no done-record, so a re-run does it again.
    """
    global _watching
    parent = multiprocessing.parent_process()
    if parent is None or _watching:  # not a multiprocessing child, or watched already
        return
    _watching = True

    def watch():
        wait([parent.sentinel])
        os._exit(1)

    threading.Thread(target=watch, name="facewrap-exit-with-parent", daemon=True).start()


def _run_tracked(func, bj) -> dict:
    """Mark the job started in shared memory (survives the worker's death)."""
    if _started is not None:
        _started[bj.index] = 1
    return func(bj)


def _pool_context():
    """A fork server with facewrap imported once (workers start in milliseconds);
    spawn where there is none.  Never plain fork: the parent may hold threads."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["facewrap.batch.runner", "facewrap.jobs",
                                    "facewrap.wrapping"])
        return ctx
    return multiprocessing.get_context("spawn")


def _after_break(batch, finished, started, report, idle_breaks):
    """Sort the jobs of a broken pool: (isolated, todo, idle_breaks)."""
    left = [bj for bj in batch if bj.index not in finished]
    isolated = [bj for bj in left if started[bj.index]]
    todo = [bj for bj in left if not started[bj.index]]
    idle_breaks = 0 if len(todo) < len(left) else idle_breaks + 1
    if idle_breaks >= 2:  # workers die before any job starts
        for bj in todo:
            report(summary_row(bj, FAILED, error="worker processes die on start"))
        todo = []
    return isolated, todo, idle_breaks


def run_in_pool(jobs, workers: int, report, func) -> None:
    """Run ``func(job)`` for every job in a process pool; ``report(row)`` per result.

    When the pool breaks (a worker died), the jobs that had started and not
    finished are retried one at a time in a single-worker pool (a second death
    marks that job failed) and the others go back to a new pool.

    Parameters
    ----------
    jobs : list of BatchJob
    workers : int
        Processes at most.
    report : callable
        Called with each summary row.
    func : callable
        ``func(BatchJob) -> row``, picklable (a module-level function).
    """
    ctx = _pool_context()
    started = ctx.RawArray("b", max((bj.index for bj in jobs), default=0) + 1)
    todo, isolated, idle_breaks = list(jobs), [], 0
    while todo or isolated:
        if isolated:
            batch, alone = [isolated.pop(0)], True
        else:
            batch, todo, alone = todo, [], False
        finished = set()
        for bj in batch:
            started[bj.index] = 0
        with single_threaded_blas():
            pool = ProcessPoolExecutor(max_workers=1 if alone else min(workers, len(batch)),
                                       mp_context=ctx, initializer=_pool_init,
                                       initargs=(started,))
            futures = {pool.submit(_run_tracked, func, bj): bj for bj in batch}
        try:
            for fut in as_completed(futures):
                row = fut.result()
                finished.add(row["index"])
                if alone and row["status"] == SKIPPED:
                    # it had finished (done-record written) in the pool that broke,
                    # before its result reached us: done in this run, not before it
                    row = {**row, "status": DONE}
                report(row)
        except KeyboardInterrupt:
            # Ctrl-C: stop the workers now rather than after their running jobs
            # (their outputs are staged: nothing partial is left behind)
            for worker in multiprocessing.active_children():
                worker.terminate()
            raise
        except BrokenProcessPool:
            if alone:
                report(summary_row(batch[0], FAILED, error="the worker process died "
                                   "(crash or out of memory) while running this job"))
                continue
            more, todo, idle_breaks = _after_break(batch, finished, started, report,
                                                   idle_breaks)
            isolated += more
        finally:
            # waited for even when interrupted: the workers are gone by then, and a
            # pool left running with dead workers makes its manager thread fail at
            # the interpreter's exit ("Exception ignored in: <module 'threading'>",
            # CPython gh-132969 on 3.11), after our one line "interrupted"
            pool.shutdown(wait=True, cancel_futures=True)


def _local_dask_task(func, bj) -> dict:
    """``func(bj)`` on a worker of the batch's own LocalCluster.

    The worker is a process the batch started: it ends as soon as the batch does
    (:func:`exit_with_parent`; a SIGKILL of the batch gives Dask no chance to stop
    it) and draws no progress bars (the batch draws one).
    """
    exit_with_parent()
    os.environ["FACEWRAP_PROGRESS"] = "0"
    return func(bj)


def _quiet_task(func, bj) -> dict:
    """``func(bj)`` on a worker of a cluster given by address: no progress bars."""
    os.environ["FACEWRAP_PROGRESS"] = "0"
    return func(bj)


def _silence_dask_logs() -> None:
    """No shutdown noise: Dask's own, and tornado's callbacks cancelled mid-close.
    Every logger below them too: distributed's logging config gives some their own
    level (``tornado.application: error``), which a parent's does not override."""
    names = [name for name in list(logging.root.manager.loggerDict)
             if name.startswith(("distributed.", "tornado."))]
    for name in ("distributed", "tornado", *names):
        logging.getLogger(name).setLevel(logging.CRITICAL)


@contextlib.contextmanager
def quiet_dask_on_interrupt():
    """Silence Dask's logs the moment SIGINT arrives, before the interrupt unwinds.

    A Ctrl-C inside ``distributed.utils.sync`` schedules a cancel callback on the
    client's loop thread straight away; when the wait had not yet made its future,
    that callback fails (``NameError: ... 'future'``) and tornado logs a traceback
    from the other thread, racing our ``except KeyboardInterrupt``.  A signal
    handler runs before the interrupt is raised, so the loggers are quiet in time.
    """
    previous = signal.getsignal(signal.SIGINT)
    if not callable(previous) or threading.current_thread() is not threading.main_thread():
        yield   # SIGINT ignored or default, or not ours to handle: nothing to do
        return

    def on_sigint(signum, frame):
        _silence_dask_logs()
        previous(signum, frame)   # default_int_handler: raises KeyboardInterrupt

    signal.signal(signal.SIGINT, on_sigint)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _stop_local_workers() -> None:
    """Ctrl-C: end the LocalCluster's worker processes now (their jobs' outputs are
    staged, so nothing partial is left), before Dask's orderly close."""
    _silence_dask_logs()
    for worker in multiprocessing.active_children():
        worker.kill()


def run_on_dask(jobs, address, workers: int, report, func) -> None:
    """Run ``func(job)`` for every job on a Dask cluster; ``report(row)`` per result.

    Parameters
    ----------
    jobs : list of BatchJob
    address : str or distributed.Client
        ``"local"`` (a LocalCluster of ``workers`` processes, closed afterwards), a
        scheduler address, or a connected Client (left open).
    workers : int
    report, func : callable
        As for :func:`run_in_pool`.
    """
    from distributed import Client, LocalCluster  # optional dependency, slow to import
    cluster = None
    if address == "local":
        # the dashboard on a free port: another cluster on 8787 would print a warning
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0")
        client = Client(cluster)
    elif isinstance(address, str):
        client = Client(address)
    else:  # a Client given by the caller
        client, address = address, None
    task = _local_dask_task if cluster is not None else _quiet_task
    try:
        with quiet_dask_on_interrupt():
            _gather_on_dask(client, jobs, task, report, func)
    except KeyboardInterrupt:
        if cluster is not None:
            _stop_local_workers()
        raise
    finally:
        if address is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def _gather_on_dask(client, jobs, task, report, func) -> None:
    """Submit every job to ``client``; ``report`` each row as its job ends."""
    from distributed import as_completed as dask_completed
    futures = {}
    for bj in jobs:
        fut = client.submit(task, func, bj, key=f"facewrap-job-{bj.index}-"
                            f"{os.getpid()}-{time.time_ns()}", pure=False)
        futures[fut] = bj
    for fut in dask_completed(list(futures)):
        bj = futures[fut]
        try:
            report(fut.result())
        except Exception as exc:  # noqa: BLE001 - worker lost, cancelled...
            report(summary_row(bj, FAILED, error=f"{type(exc).__name__} on the Dask "
                               f"cluster: {' '.join(str(exc).split())}"))
