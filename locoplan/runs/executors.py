"""Where runs execute: in this process, on a local process pool, or on a Dask cluster.

An executor has one job: ``imap_unordered(fn, items)`` yields ``(index, fn(items[index]))`` as each
finishes, in whatever order they finish. The functions it runs (``runs.spec.execute``,
``execute_e_min``) depend only on their argument, so a result is the same on any executor and however
the work is split; the caller puts results back in order and commits each as it arrives.

Adding an executor is one class here and one line in :data:`EXECUTORS`.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import socket
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, Callable, Iterator, Protocol
from urllib.parse import urlsplit

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
    threads' locks. Each worker imports locoplan and loads the compiled kernels (``locoplan.sim.native``)
    once (benchmarks/bench_batch.py measures that start), then keeps its calculators across runs.
    The pool is made lazily, so an executor that is never given work starts no process."""

    name = "process"

    def __init__(self, workers: int | None = None) -> None:
        asked = int(workers or os.cpu_count() or 1)
        if asked < 1:
            raise InputError(Problem("", "workers", f"must be >= 1 (got {workers})"))
        # the runs are CPU-bound: more processes than cores only add memory (each holds its calculators)
        self.workers = min(asked, usable_cores())
        self.asked = asked
        self._pool = None

    def _get_pool(self, n_items: int):
        if self._pool is None:
            # concurrent.futures starts a process per submitted task up to this count, so a short batch
            # starts no more processes than it has tasks
            self._pool = ProcessPoolExecutor(self.workers,
                                             mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_worker_start, initargs=(os.getpid(),))
        return self._pool

    def imap_unordered(self, fn, items):
        if not items:
            return
        pool = self._get_pool(len(items))
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


def usable_cores() -> int:
    """The cores this process may run on (its affinity mask, else the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _worker_start(parent_pid: int) -> None:
    """In each worker process: end with the parent. A worker blocked on its task queue never learns that
    the parent was killed (kill -9 runs no clean-up), so it would live on, reparented; on Linux the kernel
    sends it SIGKILL when the parent dies, elsewhere a thread checks the parent every second."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:  # the parent died before the signal was asked for
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(1.0)
            if os.getppid() != parent_pid:
                os._exit(1)
    threading.Thread(target=watch, name="locoplan-parent-watch", daemon=True).start()


def probe_scheduler(address: str, timeout_s: float = 3.0) -> None:
    """Before a Dask client connects (which can wait minutes on a server that accepts and never answers):
    connect with a short timeout and read what the server says first. A Dask scheduler sends its handshake
    at once; a closed port, a silent server or an HTTP server is named, exit 2."""
    text = str(address)
    url = urlsplit(text if "://" in text else f"tcp://{text}")
    if url.scheme not in ("tcp", "tls"):
        raise InputError(Problem("", "scheduler", f"expected tcp://HOST:PORT or tls://HOST:PORT, got {text!r}"))
    try:
        host, port = url.hostname, url.port
    except ValueError:
        host, port = None, None
    if not host or not port:
        raise InputError(Problem("", "scheduler", f"expected tcp://HOST:PORT (a port number, e.g. 8786), got {text!r}"))
    if url.scheme == "tls":
        return  # the TLS handshake comes first; the client's own timeout covers it
    try:
        sock = socket.create_connection((host, port), timeout=timeout_s)
    except socket.timeout:
        raise InputError(Problem("", "scheduler", f"no answer from {host}:{port} within {timeout_s:g} s (a firewall, "
                                 "or no such host?): start the scheduler (dask scheduler) or check the address")) from None
    except OSError as exc:
        raise InputError(Problem("", "scheduler", f"cannot reach the Dask scheduler at {host}:{port}: "
                                 f"{exc.strerror or exc} (is it running? start it with: dask scheduler)")) from None
    try:
        sock.settimeout(timeout_s)
        try:
            first = sock.recv(64)
        except socket.timeout:
            first = None
        if first is None:
            # nothing said: an HTTP server waits for a request, so ask it what it is
            try:
                sock.sendall(b"GET / HTTP/1.0\r\n\r\n")
                reply = sock.recv(64)
            except OSError:
                reply = b""
            what = "an HTTP server" if reply.startswith(b"HTTP/") else "a server that says nothing"
            raise InputError(Problem("", "scheduler", f"{host}:{port} is {what}, not a Dask scheduler (a scheduler "
                                     f"greets at once; nothing came within {timeout_s:g} s): check the port (the "
                                     "scheduler's is 8786 by default; 8787 is its dashboard)"))
        if first.startswith(b"HTTP/") or first[:1] == b"<":
            raise InputError(Problem("", "scheduler", f"{host}:{port} is an HTTP server, not a Dask scheduler: check "
                                     "the port (the scheduler's is 8786 by default; 8787 is its dashboard)"))
        if not first:
            raise InputError(Problem("", "scheduler", f"{host}:{port} closed the connection at once: not a Dask "
                                     "scheduler, or one refusing clients"))
    finally:
        sock.close()


class DaskExecutor:
    """A Dask distributed cluster: ``scheduler`` is its address (``tcp://HOST:PORT``) or a
    ``distributed.Client``. Needs the ``dask`` extra (``pip install 'locoplan[dask]'``). Every worker
    needs locoplan installed (the same version: each record names the versions that computed it);
    route and consist travel inside the tasks, so the workers need no copy of the input files."""

    name = "dask"

    def __init__(self, scheduler: Any, timeout_s: float = 10.0) -> None:
        if isinstance(scheduler, str):
            probe_scheduler(scheduler)  # seconds, where a client could wait minutes
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
        if self._own and not self.client.scheduler_info()["workers"]:
            try:  # a cluster whose workers are still starting: give them a moment, never forever
                self.client.wait_for_workers(1, timeout=timeout_s)
            except (TimeoutError, OSError, ValueError):
                self.client.close()
                raise InputError(Problem("", "scheduler", f"the Dask scheduler at {scheduler} has no workers (none "
                                         f"joined within {timeout_s:g} s): start some (dask worker {scheduler})")) from None
        self.workers = max(1, sum(w.get("nthreads", 1) for w in self.client.scheduler_info()["workers"].values()))

    def imap_unordered(self, fn, items):
        from distributed import as_completed as finished  # the optional dependency, imported when used

        if not items:
            return
        # pure=False: every task runs (Dask would otherwise deduplicate equal arguments by their hash)
        futures = self.client.map(fn, items, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        try:
            for fut in finished(futures):
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
