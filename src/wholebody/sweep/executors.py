"""Where independent jobs run: one interface, ``map(function, jobs)`` yielding ``(index, result)``
in completion order, serially, on a local process pool or on Ray.

``function`` must be a module-level function (pickled by reference) and each job picklable; an
exception raised by ``function`` is raised by ``map``. Use an executor as a context manager: on an
exception (Ctrl-C included) the pending jobs are cancelled and the pool's processes stopped.
Workers run single-threaded numerics (:data:`SINGLE_THREAD_ENV`): one run per core.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import socket
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, Callable, Iterable, Iterator

log = logging.getLogger(__name__)

#: environment of the worker processes: one BLAS/OpenMP thread each (one run per core)
SINGLE_THREAD_ENV = {name: "1" for name in (
    "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS")}

CLUSTER_HINT = "pip install 'wholebody[cluster]'"


class Executor:
    """Runs ``function(job)`` for every job; ``map`` yields ``(index in jobs, result)`` as each
    completes."""

    name = "executor"

    def map(self, function: Callable[[Any], Any], jobs: Iterable[Any]
            ) -> Iterator[tuple[int, Any]]:
        raise NotImplementedError

    def close(self, cancel: bool = False) -> None:
        """Release the workers; ``cancel``: drop the pending jobs and stop the running ones."""

    def describe(self) -> str:
        return self.name

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(cancel=exc_type is not None)


class SerialExecutor(Executor):
    """Every job in this process, one after the other (in job order)."""

    name = "serial"

    def map(self, function, jobs):
        for i, job in enumerate(jobs):
            yield i, function(job)


def _worker_init() -> None:
    """Pool workers ignore Ctrl-C: the parent stops them (and writes what is done)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def _environment(overrides: dict[str, str]):
    """``os.environ`` updated while the pool starts processes (a spawned worker inherits it, and
    BLAS reads it when it loads, before any initializer could set it); restored after."""
    saved = {k: os.environ.get(k) for k in overrides}
    os.environ.update(overrides)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


class LocalPoolExecutor(Executor):
    """A :class:`~concurrent.futures.ProcessPoolExecutor` of ``workers`` processes (default: one
    per core) started with ``context`` (``spawn`` or ``forkserver``), with ``env`` set in them."""

    name = "local pool"

    def __init__(self, workers: int | None = None, context: str = "spawn",
                 env: dict[str, str] | None = None):
        if workers is not None and int(workers) < 1:
            raise ValueError(f"--workers: expected a whole number >= 1, got {workers}")
        if context not in ("spawn", "forkserver"):
            raise ValueError(f"context: expected 'spawn' or 'forkserver', got '{context}'")
        self.workers = int(workers) if workers is not None else (os.cpu_count() or 1)
        self.context = context
        self.env = dict(SINGLE_THREAD_ENV if env is None else env)
        self._pool: ProcessPoolExecutor | None = None

    def describe(self) -> str:
        return f"local pool, {self.workers} worker{'s' * (self.workers != 1)}"

    def _get_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(self.workers,
                                             mp_context=multiprocessing.get_context(self.context),
                                             initializer=_worker_init)
        return self._pool

    def map(self, function, jobs):
        jobs = list(jobs)
        if not jobs:
            return
        pool = self._get_pool()
        with _environment(self.env):  # processes start on submission
            futures = {pool.submit(function, job): i for i, job in enumerate(jobs)}
        pending = set(futures)  # left to close(cancel=True) if the caller stops early
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in sorted(done, key=futures.get):
                yield futures[future], future.result()

    def close(self, cancel: bool = False) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if not cancel:
            pool.shutdown(wait=True)
            return
        # the running jobs are stopped, not awaited: the pool then sees its workers gone, fails
        # the pending futures (BrokenProcessPool) and cleans up (cancelling them here instead
        # trips Python 3.11's pool on its way down)
        processes = list((getattr(pool, "_processes", None) or {}).values())
        for process in processes:
            if process.is_alive():
                process.terminate()
        for process in processes:
            process.join(timeout=5.0)
        pool.shutdown(wait=True, cancel_futures=not processes)
        log.debug("local pool: %d worker(s) stopped", len(processes))


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """ConnectionError naming ``--ray ADDRESS`` if a ``host:port`` address does not accept a TCP
    connection (Ray itself would retry for minutes, deaf to Ctrl-C); other forms (``local``,
    ``auto``, ``ray://...``) are left to Ray."""
    host, sep, port = address.rpartition(":")
    if not sep or not host or "/" in address or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as exc:
        raise ConnectionError(f"--ray {address}: no Ray head node answers there "
                              f"({exc.strerror or exc}); start one with `ray start --head`"
                              ) from None


def _apply(function, job):
    """``function(job)``: the task Ray runs (``function`` travels pickled by reference)."""
    return function(job)


class RayExecutor(Executor):
    """Jobs as Ray tasks (one CPU each) on the cluster at ``address`` (``ray start --head``'s
    address, or ``"auto"``), or on a new local instance with ``"local"`` (``num_cpus`` of this
    machine, default all). Ray is imported here; without it, ImportError saying how to install it.
    An instance this executor started is shut down by :meth:`close`; one that was already
    initialised in this process is used as it is and left running."""

    name = "ray"

    def __init__(self, address: str = "local", num_cpus: int | None = None,
                 env: dict[str, str] | None = None):
        try:
            import ray
        except ImportError:
            raise ImportError(f"--ray {address}: Ray is not installed; {CLUSTER_HINT}"
                              ) from None
        self._ray = ray
        self.address = address
        self._owned = not ray.is_initialized()
        if self._owned:
            options = {"runtime_env": {"env_vars": dict(SINGLE_THREAD_ENV if env is None
                                                        else env)},
                       "include_dashboard": False, "logging_level": logging.WARNING}
            if address == "local" and num_cpus is not None:
                options["num_cpus"] = int(num_cpus)
            _check_reachable(address)
            try:
                ray.init(address=address, **options)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise ConnectionError(f"--ray {address}: cannot connect to a Ray cluster ({exc})"
                                      ) from None
        cpus = int(ray.cluster_resources().get("CPU", 0))
        self._description = f"ray at {address}, {cpus} CPU{'s' * (cpus != 1)}"

    def describe(self) -> str:
        return self._description

    def map(self, function, jobs):
        ray = self._ray
        remote = ray.remote(num_cpus=1, max_retries=0)(_apply)  # also for builtins
        refs = {remote.remote(function, job): i for i, job in enumerate(jobs)}
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    yield refs[ref], ray.get(ref)
        finally:
            for ref in pending:
                ray.cancel(ref, force=True)

    def close(self, cancel: bool = False) -> None:
        if self._owned and self._ray.is_initialized():
            self._ray.shutdown()
        self._owned = False


def add_executor_options(parser) -> None:
    """``--workers N | --ray ADDRESS | --serial`` on an argparse parser (``sweep``, ``report``),
    read back by :func:`make_executor`."""
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="processes of the local pool (default: one per core)")
    where.add_argument("--ray", metavar="ADDRESS",
                       help="run on the Ray cluster at ADDRESS (`ray start --head` prints it; "
                            "'auto'), or 'local' for a new local instance")
    where.add_argument("--serial", action="store_true", help="every run in this process")


def make_executor(serial: bool = False, workers: int | None = None,
                  ray: str | None = None) -> Executor:
    """The executor of the CLI options: ``--serial``, ``--ray ADDRESS``, else a local pool of
    ``--workers`` (default one per core; ValueError below 1)."""
    if workers is not None and workers < 1:
        raise ValueError(f"--workers: expected a whole number >= 1, got {workers}")
    if serial:
        return SerialExecutor()
    if ray is not None:
        return RayExecutor(ray)
    return LocalPoolExecutor(workers)


def ordered(executor: Executor, function: Callable[[Any], Any], jobs: Iterable[Any],
            progress: Callable[[int, Any], None] | None = None) -> list:
    """``function(job)`` for every job on ``executor``, results in job order; ``progress(index,
    result)`` is called as each completes."""
    jobs = list(jobs)
    results: list = [None] * len(jobs)
    for i, result in executor.map(function, jobs):
        results[i] = result
        if progress is not None:
            progress(i, result)
    return results


def scenario_executor(workers: int) -> Executor:
    """The executor of a scenario's ``workers`` parameter: 1 serial (in this process), N > 1 a
    local pool of N processes, 0 one process per core."""
    workers = int(workers)
    if workers == 1:
        return SerialExecutor()
    return LocalPoolExecutor(None if workers == 0 else workers)
