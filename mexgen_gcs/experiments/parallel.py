"""Where the runs execute: a local process pool (default) or a Dask distributed cluster.

No frames here. Both run the same task function, ``runner.run_one(spec) -> RunResult``, and
yield outcomes as runs finish (in completion order). Workers never touch the output
directory; the caller stores each result, so a cluster needs no shared file system.

- Local: ``concurrent.futures.ProcessPoolExecutor`` with the spawn start method, one process
  per core by default. BLAS/OpenMP are pinned to one thread in the workers (each run is one
  core's work, and results do not depend on a library's thread count; Dask's nanny pins its
  workers the same way). Workers ignore SIGINT (the parent owns shutdown) and exit when the
  parent process dies.
- Dask: ``dask.distributed.Client(address)``; ``client.map(run_one, specs)``. The workers need
  this package installed (``pip install 'mexgen-gcs[cluster]'`` on every node).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
import time
import traceback
from collections.abc import Generator, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

from mexgen_gcs.errors import ConfigError
from mexgen_gcs.experiments.runner import RunResult, RunSpec, run_one

_BLAS_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@dataclass(frozen=True, slots=True)
class RunFailure:
    """A run that raised: not stored, so the next invocation retries it."""

    spec: RunSpec
    error: str


Outcome = RunResult | RunFailure


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def execute(specs: Sequence[RunSpec], *, workers: int | None = None,
            scheduler: str | None = None, connect_timeout_s: float = 30.0
            ) -> Generator[Outcome, None, None]:
    """Run every spec; yield each outcome as it finishes. Closing the iterator early (or an
    exception in the consumer) cancels what has not started and stops the workers.
    ``connect_timeout_s``: how long to try to reach a Dask scheduler (ConfigError after)."""
    if not specs:
        return
    if scheduler:
        yield from _execute_dask(specs, scheduler, connect_timeout_s)
    else:
        yield from _execute_pool(specs, workers or default_workers())


# -- local process pool ----------------------------------------------------------------------

@contextlib.contextmanager
def _single_thread_blas() -> Iterator[None]:
    """Set the BLAS/OpenMP thread variables to 1 (unless set) while worker processes spawn;
    they read them when numpy loads. The parent's environment is restored afterwards."""
    saved = {k: os.environ.get(k) for k in _BLAS_THREAD_VARS}
    for k in _BLAS_THREAD_VARS:
        os.environ.setdefault(k, "1")
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _worker_init(parent_pid: int) -> None:
    """In each pool worker: leave Ctrl-C to the parent; exit if the parent dies."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def _execute_pool(specs: Sequence[RunSpec], workers: int) -> Iterator[Outcome]:
    n = max(1, min(workers, len(specs)))
    ctx = multiprocessing.get_context("spawn")
    with _single_thread_blas():
        pool = ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_worker_init,
                                   initargs=(os.getpid(),))
        # workers spawn as tasks are submitted (spawn context), so inside the pinned env
        futures: dict[Future[RunResult], RunSpec] = {pool.submit(run_one, s): s for s in specs}
    finished = False
    try:
        for fut in as_completed(futures):
            exc = fut.exception()
            if exc is not None:
                yield RunFailure(futures[fut], _describe(exc))
            else:
                yield fut.result()
        finished = True
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            # stop the runs in progress and those already queued to the workers now (they
            # would only be thrown away); shutdown forgets the processes, so take them first
            procs = list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in procs:
                with contextlib.suppress(Exception):
                    proc.terminate()


def _describe(exc: BaseException) -> str:
    return "".join(traceback.format_exception(exc)).strip()


# -- Dask distributed ------------------------------------------------------------------------

def _execute_dask(specs: Sequence[RunSpec], address: str,
                  connect_timeout_s: float) -> Iterator[Outcome]:
    try:
        from dask.distributed import Client
        from dask.distributed import as_completed as dask_as_completed
    except ImportError:
        raise ConfigError("--scheduler needs dask.distributed: install the cluster extra, "
                          "pip install 'mexgen-gcs[cluster]'") from None
    try:
        client = Client(address, timeout=f"{connect_timeout_s}s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConfigError(f"--scheduler {address}: cannot connect to a Dask scheduler there "
                          f"({exc})") from None
    futures: list[Any] = []
    try:
        futures = client.map(run_one, list(specs), pure=False)
        by_key = {f.key: s for f, s in zip(futures, specs, strict=True)}
        for fut in dask_as_completed(futures, loop=client.loop):
            spec = by_key[fut.key]
            if fut.status == "error":
                yield RunFailure(spec, _describe(fut.exception()))
            else:
                yield fut.result()
            fut.release()
    finally:
        with contextlib.suppress(Exception):
            client.cancel(futures)
        client.close()
