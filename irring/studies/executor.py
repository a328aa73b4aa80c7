"""Scaling out: run independent jobs through a ``concurrent.futures`` executor.

One function, :func:`run_jobs`, maps a picklable module-level function over picklable jobs
on whichever executor it is given and returns the results in job order, so the caller's
results do not depend on who ran them:

* ``executor(workers=1)``: in this process, one job after another (no pickling at all);
* ``executor(workers=N)``: a local process pool of N workers (``forkserver`` start method on
  POSIX: workers fork from a clean server process, never from this one, which may hold
  threads — a Dask client, tqdm's monitor — that a plain ``fork`` would copy mid-flight;
  so, as with any ``spawn``/``forkserver`` pool, a script that starts one needs the
  ``if __name__ == "__main__":`` guard);
* ``executor(dask="tcp://host:8786")``: a Dask cluster through
  ``dask.distributed.Client(address).get_executor()`` (optional extra ``irring[dask]``).
  Workers need ``irring`` installed; jobs carry their scenario as YAML text, so a worker
  needs no access to this machine's files.

Determinism is the job's business: a job must carry everything it needs (scenario text,
configuration, seed) and build its own state (a ``SimRing`` holds MuJoCo objects that cannot
be pickled), so the same job gives the same result in any process.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from typing import Any, Callable, Iterator, Sequence


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


@contextlib.contextmanager
def executor(workers: int | None = 1, dask: str | Any | None = None) -> Iterator[Executor]:
    """An executor for :func:`run_jobs`, shut down on exit.

    ``dask``: a scheduler address (``"tcp://…:8786"``) or a ``dask.distributed.Client``
    (used as is, not closed); it wins over ``workers``. Otherwise ``workers`` ≤ 1 runs in
    this process and ``workers`` > 1 starts a local process pool (None: one per CPU).
    """
    if dask is not None:
        try:
            from dask.distributed import Client
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise RuntimeError("--dask needs the optional extra: pip install 'irring[dask]'") \
                from exc
        own = not isinstance(dask, Client)
        client = Client(dask) if own else dask
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
    pool = ProcessPoolExecutor(max_workers=n,
                               mp_context=multiprocessing.get_context(_start_method()))
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def run_jobs(fn: Callable[[Any], Any], jobs: Sequence[Any], ex: Executor | None = None, *,
             progress: Callable[[Any], None] | None = None) -> list[Any]:
    """``[fn(job) for job in jobs]`` on ``ex`` (default: in this process), in job order.

    ``fn`` must be a module-level function and the jobs picklable for a process pool or
    Dask. ``progress(result)`` is called as each job finishes (in completion order). The
    first job that raises makes this raise, after cancelling the jobs not yet started.
    """
    if ex is None or isinstance(ex, SerialExecutor):  # one at a time, so progress moves
        results = []
        for job in jobs:
            results.append(fn(job))
            if progress is not None:
                progress(results[-1])
        return results
    futures = [ex.submit(fn, job) for job in jobs]
    index = {f: i for i, f in enumerate(futures)}
    results: list[Any] = [None] * len(futures)
    try:
        for f in as_completed(futures):
            results[index[f]] = f.result()
            if progress is not None:
                progress(results[index[f]])
    except BaseException:
        for f in futures:
            f.cancel()
        raise
    return results
