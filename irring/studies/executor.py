"""Scaling out: run independent jobs in this process, a local process pool or a Dask cluster
(:func:`executor`), streamed as they finish (:func:`stream`) or collected in job order
(:func:`run_jobs`). A job is a picklable module-level function applied to a picklable job
that carries everything it needs, so it gives the same result in any process. Start
methods, Dask and determinism: docs/studies.md.
"""

from __future__ import annotations

import contextlib
import itertools
import multiprocessing
import multiprocessing.connection
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Iterator, Sequence

from ..errors import INTERRUPTED, IrringError, UsageError, sigterm_as_interrupt


class SerialExecutor(Executor):
    """Runs each job at ``submit`` in the calling process: the reference for the others."""

    def submit(self, fn: Callable, /, *args: Any, **kwargs: Any) -> Future:
        future: Future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:  # noqa: BLE001 - handed to the caller through the future
            future.set_exception(exc)
        return future


def _start_method() -> str:
    methods = multiprocessing.get_all_start_methods()
    return "forkserver" if "forkserver" in methods else "spawn"


def default_workers() -> int:
    """CPUs this process may use (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


class ExecutorError(UsageError, RuntimeError):
    """An executor that cannot start (no Dask installed, scheduler unreachable): one line."""


class WorkerLost(IrringError, RuntimeError):
    """A worker process ended without handing back its job (the pool's BrokenProcessPool,
    Dask's KilledWorker): killed from outside (the out-of-memory killer, `kill`), like an
    interruption, or crashed. The jobs in flight are lost; what the caller kept stays."""

    status = INTERRUPTED


WORKER_LOST = ("a worker process ended before its run did (killed: out of memory, or `kill`; "
               "or it crashed: if again at the same run, please report it with --debug)")


DASK_CONNECT_TIMEOUT_S = 3.0


def dask_client(address: str, timeout_s: float = DASK_CONNECT_TIMEOUT_S):
    """A ``dask.distributed.Client`` connected to ``address``, or :class:`ExecutorError`
    within about ``timeout_s`` + 2 seconds saying why not (also when what answers there
    is not a Dask scheduler)."""
    try:
        from dask.distributed import Client   # deferred: optional (the dask extra)
    except ImportError:  # pragma: no cover - depends on the install
        raise ExecutorError("--dask needs the optional extra: pip install 'irring[dask]'") \
            from None
    # Dask's timeout covers the TCP connect, not its handshake: a server that accepts and
    # never answers would hang here, and one that answers something else (an HTTP port)
    # has its reply read as a frame length (a MemoryError), hence a thread and a deadline.
    box: dict[str, Any] = {}
    late = threading.Event()

    def connect() -> None:
        try:
            box["client"] = Client(address, timeout=f"{timeout_s}s")
        except BaseException as exc:  # noqa: BLE001 - reported by the caller below
            box["error"] = exc
        if late.is_set() and "client" in box:
            box["client"].close()

    thread = threading.Thread(target=connect, name="irring-dask-connect", daemon=True)
    thread.start()
    wait_s = timeout_s + 2.0  # the TCP connect, then the handshake
    thread.join(wait_s)
    if "client" in box:
        return box["client"]
    exc = box.get("error")
    if exc is None:
        late.set()
        why = (f"connected, but no Dask handshake within {wait_s:g} s (is that the "
               "scheduler's port, not its dashboard's?)")
    elif isinstance(exc, (OSError, TimeoutError, ValueError)):
        why = " ".join(str(exc).split()) or type(exc).__name__
    elif isinstance(exc, Exception):
        why = (f"what answers there does not speak Dask's protocol ({type(exc).__name__}; "
               "the dashboard's port instead of the scheduler's?)")
    else:
        raise exc
    if len(why) > 160:
        why = why[:157] + "…"
    raise ExecutorError(f"cannot reach the Dask scheduler at {address!r}: {why}; is "
                        "`dask scheduler` running there, and is the address "
                        "tcp://HOST:PORT?") from None


@contextlib.contextmanager
def executor(workers: int | None = 1, dask: str | Any | None = None) -> Iterator[Executor]:
    """An executor for :func:`run_jobs`, shut down on exit.

    ``dask``: a scheduler address (``"tcp://…:8786"``) or a ``dask.distributed.Client``
    (used as is, not closed); it wins over ``workers``. Otherwise ``workers`` ≤ 1 runs in
    this process and ``workers`` > 1 starts a local process pool (None: one per CPU).
    An unreachable scheduler raises :class:`ExecutorError` within a few seconds.
    """
    if dask is not None:
        own = isinstance(dask, str)
        client = dask_client(dask) if own else dask
        try:
            yield client.get_executor()
        finally:
            if own:
                client.close()
        return
    n = default_workers() if workers is None else int(workers)
    if n <= 1:
        yield SerialExecutor()
        return
    pool = ProcessPoolExecutor(max_workers=n, initializer=_worker_start,
                               mp_context=multiprocessing.get_context(_start_method()))
    try:
        with sigterm_as_interrupt():
            yield pool
    except (KeyboardInterrupt, SystemExit):   # Ctrl-C: stop the runs in flight, do not wait
        _stop_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _worker_start() -> None:
    """A pool worker leaves Ctrl-C (SIGINT to the whole process group) to the parent, which
    stops the pool; otherwise each worker prints its own KeyboardInterrupt traceback. It
    ends when its parent does (:func:`_end_with_parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_end_with_parent, name="irring-parent-watch", daemon=True).start()


def _end_with_parent() -> None:
    """Wait for the pool's parent to end, then end this worker. A parent killed with SIGKILL
    never shuts its pool down, and the workers' call queue never closes (each worker holds
    its ends), so they idled on with the forkserver they keep alive; the parent's sentinel
    (multiprocessing's, under fork, spawn and forkserver alike) becomes ready when it ends."""
    multiprocessing.connection.wait([multiprocessing.parent_process().sentinel])
    os._exit(1)   # the parent is gone: no one to report to, nothing to flush


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel the queued jobs and terminate the running ones (the pool has no public way)."""
    workers = list((getattr(pool, "_processes", None) or {}).values())  # shutdown forgets them
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in workers:
        proc.terminate()
    for proc in workers:
        proc.join(5)


# a worker's first run starts it (a process, its imports, MuJoCo), the time of many runs
# (README, "Sizing it"): a bar over runs gives its ETA after each worker's first
# (pipeline.progress_bar's warmup, capacity(ex) runs), and this in its place before
WARMUP_NOTE = "ETA after each worker's first run"


def capacity(ex: Executor | None) -> int:
    """How many jobs ``ex`` runs at once (1 in this process; a Dask cluster's threads)."""
    if ex is None or isinstance(ex, SerialExecutor):
        return 1
    if isinstance(ex, ProcessPoolExecutor):
        return int(ex._max_workers)
    client = getattr(ex, "_client", None)   # dask.distributed's ClientExecutor
    if client is not None:
        try:
            return max(1, sum(client.nthreads().values()))
        except Exception:  # noqa: BLE001 - a guess for the window only
            return 8
    return default_workers()


def stream(fn: Callable[[Any], Any], jobs: Sequence[Any], ex: Executor | None = None, *,
           window: int | None = None) -> Iterator[tuple[int, Any]]:
    """``(index, fn(jobs[index]))`` as each job finishes, on ``ex`` (default: this process).

    At most ``window`` jobs are submitted and not yet collected (default: twice
    :func:`capacity`), so memory does not grow with the number of jobs and a study that
    is stopped loses only those. The first job that raises makes this raise, after
    cancelling the jobs not yet started; so does closing the generator early.
    """
    if ex is None or isinstance(ex, SerialExecutor):  # one at a time, so progress moves
        for i, job in enumerate(jobs):
            yield i, fn(job)
        return
    window = max(1, window or 2 * capacity(ex))
    pending: dict[Future, int] = {}
    todo = iter(enumerate(jobs))
    try:
        while True:
            for i, job in itertools.islice(todo, window - len(pending)):
                pending[ex.submit(fn, job)] = i
            if not pending:
                return
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in sorted(finished, key=pending.get):
                i = pending.pop(f)
                yield i, _result(f)
    finally:
        for f in pending:
            f.cancel()


def _result(f: Future) -> Any:
    """``f.result()``; a worker that died under it is :class:`WorkerLost`, not a bug's
    "internal error" (a pool says only BrokenProcessPool; Dask gives up on a job after
    its workers died under it three times)."""
    try:
        return f.result()
    except BrokenProcessPool as exc:
        raise WorkerLost(WORKER_LOST) from exc
    except Exception as exc:
        if type(exc).__name__ == "KilledWorker":   # dask.distributed's, not imported here
            raise WorkerLost(WORKER_LOST) from exc
        raise


def run_jobs(fn: Callable[[Any], Any], jobs: Sequence[Any], ex: Executor | None = None, *,
             progress: Callable[[Any], None] | None = None) -> list[Any]:
    """``[fn(job) for job in jobs]`` on ``ex`` (default: in this process), in job order.

    ``fn`` must be a module-level function and the jobs picklable for a process pool or
    Dask. ``progress(result)`` is called as each job finishes (in completion order). The
    first job that raises makes this raise, after cancelling the jobs not yet started.
    """
    results: list[Any] = [None] * len(jobs)
    for i, result in stream(fn, jobs, ex):
        results[i] = result
        if progress is not None:
            progress(result)
    return results
