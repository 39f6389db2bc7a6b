"""Where runs execute: in this process, on a local process pool, or on a Dask cluster.

An executor has one job: ``imap_unordered(fn, items)`` yields ``(index, fn(items[index]))`` as each
finishes, in whatever order they finish. The functions it runs (``runs.spec.execute``,
``execute_e_min``) depend only on their argument, so a result is the same on any executor and however
the work is split; the caller puts results back in order and commits each as it arrives.

Adding an executor is one class here and one line in :data:`EXECUTORS`.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Iterator, Protocol

from ..errors import InputError, Problem


class Executor(Protocol):
    workers: int
    name: str

    def imap_unordered(self, fn: Callable[[Any], Any], items: list) -> Iterator[tuple[int, Any]]: ...

    def close(self) -> None: ...


class SerialExecutor:
    """Every run in this process, one after the other (what a single command does)."""

    name = "serial"

    def __init__(self) -> None:
        self.workers = 1

    def imap_unordered(self, fn, items):
        for i, item in enumerate(items):
            yield i, fn(item)

    def close(self) -> None:
        pass


class ProcessExecutor:
    """A local pool of ``workers`` processes (default: the core count).

    Processes are *spawned*, not forked: a fork would copy the parent's open result store and its
    threads' locks. Each worker imports locoplan and loads the compiled kernels (``locoplan.native``)
    once (benchmarks/bench_batch.py measures that start), then keeps its calculators across runs.
    The pool is made lazily, so an executor that is never given work starts no process."""

    name = "process"

    def __init__(self, workers: int | None = None) -> None:
        self.workers = int(workers or os.cpu_count() or 1)
        if self.workers < 1:
            raise InputError(Problem("", "workers", f"must be >= 1 (got {workers})"))
        self._pool = None

    def _get_pool(self):
        if self._pool is None:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            self._pool = ProcessPoolExecutor(self.workers, mp_context=multiprocessing.get_context("spawn"))
        return self._pool

    def imap_unordered(self, fn, items):
        from concurrent.futures import as_completed

        if not items:
            return
        pool = self._get_pool()
        futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
        try:
            for fut in as_completed(futures):
                yield futures[fut], fut.result()
        finally:
            for fut in futures:
                fut.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class DaskExecutor:
    """A Dask distributed cluster: ``scheduler`` is its address (``tcp://HOST:PORT``) or a
    ``distributed.Client``. Needs the ``dask`` extra (``pip install 'locoplan[dask]'``). Every worker
    needs locoplan installed (the same version: each record names the versions that computed it);
    route and consist travel inside the tasks, so the workers need no copy of the input files."""

    name = "dask"

    def __init__(self, scheduler: Any, timeout_s: float = 30.0) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise InputError(Problem("", "scheduler", "a Dask cluster needs the 'distributed' package: "
                                     "pip install 'locoplan[dask]'")) from None
        if isinstance(scheduler, Client):
            self.client, self._own = scheduler, False
        else:
            try:
                self.client, self._own = Client(str(scheduler), timeout=timeout_s), True
            except (OSError, TimeoutError, ValueError) as exc:
                raise InputError(Problem("", "scheduler", f"cannot reach the Dask scheduler at {scheduler}: {exc}")) from None
        self.workers = max(1, sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values()))

    def imap_unordered(self, fn, items):
        from distributed import as_completed

        if not items:
            return
        # pure=False: every task runs (Dask would otherwise deduplicate equal arguments by their hash)
        futures = self.client.map(fn, items, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for fut in as_completed(futures):
                yield index[fut.key], fut.result()
        finally:
            self.client.cancel(futures)

    def close(self) -> None:
        if self._own:
            self.client.close()


EXECUTORS: dict[str, Callable[..., Executor]] = {
    "serial": SerialExecutor,
    "process": ProcessExecutor,
    "dask": DaskExecutor,
}


def make_executor(workers: int | None = None, scheduler: Any = None) -> Executor:
    """The executor a command asks for: a Dask cluster if ``scheduler`` is given, else in this process
    for one worker, else a process pool of ``workers`` (None: the core count)."""
    if scheduler is not None:
        return EXECUTORS["dask"](scheduler)
    if workers is not None and workers < 1:
        raise InputError(Problem("", "workers", f"must be >= 1 (got {workers})"))
    if workers == 1:
        return EXECUTORS["serial"]()
    return EXECUTORS["process"](workers)
