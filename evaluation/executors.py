"""Executors: where the benchmark's independent tasks run.

The runner hands an executor a picklable function and a list of picklable tasks and
consumes ``(task, result)`` pairs *as they finish* (so each finished row is written at
once and a killed run loses at most the tasks in flight). Scheduling is delegated, never
home-made:

* :class:`LocalExecutor` — the standard library's ``ProcessPoolExecutor`` (``workers``
  processes; ``workers=1`` runs in-process, handy for debugging and profiling).
* :class:`DaskExecutor` — a Dask ``distributed`` cluster (``pip install
  'habitsim[cluster]'``), via ``Client.submit`` and ``as_completed``. Every worker needs
  the same habitsim installation and access to the data set and output folders (a
  shared file system), because tasks carry file paths, not arrays.

Workers die with the run either way: the local pool through
:func:`habitsim.workers.init_worker`; the worker processes of a local Dask cluster
(``--executor dask`` without ``--scheduler``) exit when their parent's pipe closes, so a
SIGKILL'd run leaves none behind, and an interrupted one (Ctrl-C, SIGTERM) kills them at
once instead of waiting for the tasks in flight. Workers of a remote scheduler are not
the run's to stop.

Starting a Dask cluster by hand (one scheduler, any number of workers, any machines)::

    dask scheduler --host HEAD --port 8786                 # on the head node
    dask worker tcp://HEAD:8786 --nworkers 2 --nthreads 1  # on each worker machine
    habitsim eval --data DIR --methods direct --out OUT --executor dask --scheduler tcp://HEAD:8786

``HEAD`` is the head node's address on the cluster's private network, never ``0.0.0.0``
on a machine reachable from outside: Dask's protocol has no authentication and runs the
pickled tasks it receives, so an open scheduler runs anyone's code.

(``dask-scheduler`` / ``dask-worker`` are the older names of the same commands;
``python -m distributed.cli.dask_scheduler`` works everywhere.) Use ``--nthreads 1``:
each task already keeps a core busy (MuJoCo, numpy), and threads inside one worker
process would contend for the GIL. Results do not depend on the executor or the
machine: every task is deterministic and independent of where and in which order it
runs, and its thread-count sensitive steps run on one thread (:mod:`habitsim.threads`).
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import os
import signal
from collections.abc import Callable, Iterator, Sequence
from typing import Any, Protocol

from habitsim.errors import HabitsimError, unknown_choice

__all__ = [
    "EXECUTORS",
    "ExecutorError",
    "Executor",
    "LocalExecutor",
    "DaskExecutor",
    "make_executor",
]

#: Names accepted by :func:`make_executor` (``--executor``).
EXECUTORS = ("local", "dask")


class ExecutorError(HabitsimError, RuntimeError):
    """An executor that cannot start (e.g. Dask not installed, scheduler unreachable)."""


class Executor(Protocol):
    """Runs independent tasks, yielding results as they complete."""

    name: str

    def map_unordered(
        self, fn: Callable[[Any], Any], tasks: Sequence[Any]
    ) -> Iterator[tuple[Any, Any]]:
        """Yield ``(task, fn(task))`` in completion order; exceptions propagate."""
        ...

    def close(self) -> None:
        """Release workers / connections."""
        ...


def _init_worker(parent_pid: int | None = None) -> None:
    if parent_pid is not None:  # die with the run that started the pool
        from habitsim.workers import init_worker

        init_worker(parent_pid)
    # One busy core per worker process: no thread oversubscription from torch/BLAS.
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover
        pass


class LocalExecutor:
    """A local process pool (``workers`` processes; 1 = in this process).

    Args:
        workers: number of processes (default: the CPU count).
    """

    name = "local"

    def __init__(self, workers: int | None = None):
        n = workers if workers is not None else (os.cpu_count() or 1)
        if not isinstance(n, int) or n < 1:
            raise ExecutorError(f"workers must be a positive integer, got {workers!r}")
        self.workers = n
        self._pool: cf.ProcessPoolExecutor | None = None

    def map_unordered(
        self, fn: Callable[[Any], Any], tasks: Sequence[Any]
    ) -> Iterator[tuple[Any, Any]]:
        if self.workers == 1:
            for t in tasks:
                yield t, fn(t)
            return
        if self._pool is None:
            self._pool = cf.ProcessPoolExecutor(
                self.workers, initializer=_init_worker, initargs=(os.getpid(),)
            )
        futs: dict[cf.Future, Any] = {}
        try:
            # an interrupt while the tasks are submitted stops the pool as well
            for t in tasks:
                futs[self._pool.submit(fn, t)] = t
            for f in cf.as_completed(futs):
                yield futs[f], f.result()
        except BaseException:
            # interrupted (Ctrl-C / SIGTERM) or a task failed: stop the workers now rather
            # than wait for the pairs in flight
            from habitsim.workers import stop_pool

            pool, self._pool = self._pool, None
            stop_pool(pool)
            raise
        finally:
            for f in futs:
                f.cancel()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


class DaskExecutor:
    """Tasks on a Dask distributed cluster.

    Args:
        scheduler: scheduler address (``tcp://host:8786``); ``None`` starts a local
            cluster in this process (``workers`` processes, one thread each).
        workers: processes of the local cluster when ``scheduler`` is None.
        timeout_s: how long to wait for the scheduler [s].

    Raises:
        ExecutorError: dask/distributed missing, or the scheduler is unreachable.
    """

    name = "dask"

    def __init__(
        self, scheduler: str | None = None, workers: int | None = None, timeout_s: float = 30.0
    ):
        try:
            from distributed import Client, LocalCluster
        except ImportError as e:
            raise ExecutorError(
                "the dask executor needs dask[distributed]: pip install 'habitsim[cluster]'"
            ) from e
        self._cluster = None
        self._killed = False
        try:
            if scheduler is None:
                self._cluster = LocalCluster(
                    n_workers=workers or (os.cpu_count() or 1),
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                )
                self.client = Client(self._cluster, timeout=timeout_s)
            else:
                self.client = Client(scheduler, timeout=timeout_s)
        except (OSError, TimeoutError) as e:
            raise ExecutorError(f"cannot reach the Dask scheduler {scheduler!r}: {e}") from e
        self.scheduler = scheduler

    def map_unordered(
        self, fn: Callable[[Any], Any], tasks: Sequence[Any]
    ) -> Iterator[tuple[Any, Any]]:
        from distributed import as_completed

        if not tasks:
            return
        futs = [self.client.submit(fn, t, pure=False) for t in tasks]
        index = {f.key: i for i, f in enumerate(futs)}
        try:
            for f in as_completed(futs):
                yield tasks[index[f.key]], f.result()
        except BaseException:
            # interrupted (Ctrl-C / SIGTERM) or a task failed: the worker processes of our
            # own cluster stop now, not after the nanny's grace period with a task still
            # writing its traces
            self._kill_local_workers()
            self._killed = True
            raise
        finally:
            for f in futs:
                f.cancel()

    def _kill_local_workers(self) -> None:
        """SIGKILL the worker processes of the local cluster (none with a scheduler: the
        workers of a remote cluster are not ours to stop)."""
        if self._cluster is None:
            return
        for nanny in list(getattr(self._cluster, "workers", {}).values()):
            pid = getattr(nanny, "pid", None)
            if isinstance(pid, int) and pid > 0 and pid != os.getpid():
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)

    def close(self) -> None:
        # after an interruption the workers are already gone: closing must not fail on it
        quiet = contextlib.suppress(Exception) if self._killed else contextlib.nullcontext()
        with quiet:
            self.client.close()
            if self._cluster is not None:
                self._cluster.close(timeout=10)


def make_executor(
    kind: str = "local", *, workers: int | None = None, scheduler: str | None = None
) -> LocalExecutor | DaskExecutor:
    """An executor by name (``local`` or ``dask``).

    Raises:
        ExecutorError: an unknown name, or a scheduler address given to ``local``.
    """
    if kind not in EXECUTORS:
        raise ExecutorError(unknown_choice("executor", kind, EXECUTORS))
    if kind == "local":
        if scheduler:
            raise ExecutorError("--scheduler is only used with --executor dask")
        return LocalExecutor(workers)
    return DaskExecutor(scheduler, workers)
