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

A worker process that dies under a task (the out-of-memory killer's SIGKILL, a crash in
a library) is replaced and the task run again, alone, up to
:attr:`ExecutorOptions.retries` times; a task that kills its worker every time yields a
:class:`TaskLost` (the runner makes it a failed row), never a raw ``BrokenProcessPool`` or
``KilledWorker``.

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
import ctypes
import multiprocessing as mp
import os
import signal
import sys
from collections.abc import Callable, Generator, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from habitsim.errors import HabitsimError, unknown_choice

__all__ = [
    "EXECUTORS",
    "ExecutorError",
    "ExecutorOptions",
    "TaskLost",
    "Executor",
    "LocalExecutor",
    "DaskExecutor",
    "make_executor",
]

#: Names accepted by :func:`make_executor` (``--executor``).
EXECUTORS = ("local", "dask")


class ExecutorError(HabitsimError, RuntimeError):
    """An executor that cannot start (e.g. Dask not installed, scheduler unreachable)."""


@dataclass(frozen=True)
class ExecutorOptions:
    """How an executor treats a worker process that dies under a task.

    Attributes:
        retries: how many times a task whose worker process died (killed by the
            out-of-memory killer, a crash in a library) is run again before it is given
            up as :class:`TaskLost`. A local pool runs each retry alone in a fresh
            worker, so a death is charged to the task that caused it, never to the tasks
            running beside it; a Dask cluster of the run's own gets this as the
            scheduler's ``allowed-failures`` (a remote scheduler keeps its own setting).
        log: where retries are noted (None: nowhere).
    """

    retries: int = 2
    log: Callable[[str], None] | None = None

    def __post_init__(self) -> None:
        if isinstance(self.retries, bool) or not isinstance(self.retries, int):
            raise ExecutorError(f"retries must be a whole number, got {self.retries!r}")
        if not 0 <= self.retries <= 100:
            raise ExecutorError(f"retries {self.retries}; valid: 0 to 100")

    def note(self, text: str) -> None:
        """Tell the run's console (when there is one)."""
        if self.log is not None:
            self.log(text)


@dataclass(frozen=True)
class TaskLost:
    """The result of a task whose worker process died every time it ran it.

    Attributes:
        note: what happened, for the task's row (``worker died … (out of memory?)``).
        attempts: how many times the task was run.
    """

    note: str
    attempts: int


class Executor(Protocol):
    """Runs independent tasks, yielding results as they complete."""

    name: str

    def map_unordered(
        self, fn: Callable[[Any], Any], tasks: Sequence[Any]
    ) -> Iterator[tuple[Any, Any]]:
        """Yield ``(task, fn(task))`` in completion order; a task whose worker died more
        often than :attr:`ExecutorOptions.retries` allows yields a :class:`TaskLost`
        instead; the task's own exceptions propagate."""
        ...

    def close(self) -> None:
        """Release workers / connections."""
        ...


#: In a local pool's worker: the run's shared array of task states (see ``_tracked``).
_task_states: Any = None


def _init_worker(parent_pid: int | None = None, states: Any = None) -> None:
    global _task_states
    _task_states = states
    if parent_pid is not None:  # die with the run that started the pool
        from habitsim.workers import init_worker

        init_worker(parent_pid)
    # One busy core per worker process: no thread oversubscription from torch/BLAS.
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    torch = sys.modules.get("torch")  # inherited from the parent (else the variables rule)
    if torch is not None:
        torch.set_num_threads(1)


def _tracked(fn: Callable[[Any], Any], index: int, task: Any) -> Any:
    """Run ``fn(task)`` in a pool worker, marking task ``index`` as started in the run's
    shared array (read by the parent when a worker dies: the tasks started and not
    finished are the ones that were running)."""
    if _task_states is not None:
        _task_states[index] = _STARTED
    return fn(task)


#: States of a task in a local pool's shared array.
_QUEUED, _STARTED = 0, 1


def _label(task: Any, index: int) -> str:
    """A task's name in a console note: its ``key`` when it has one."""
    key = getattr(task, "key", None)
    return str(key) if isinstance(key, str) else f"task {index + 1}"


def _death_note(attempts: int) -> str:
    return (
        f"the worker process died while running this task ({attempts} time"
        f"{'s' if attempts != 1 else ''}; killed, e.g. out of memory, or crashed)"
    )


class LocalExecutor:
    """A local process pool (``workers`` processes; 1 = in this process).

    A worker process that dies under a task (SIGKILL by the out-of-memory killer, a
    crash in a library) breaks the standard library's pool: the pool is rebuilt, the
    tasks that were queued go to it again, and the tasks that were running are run
    again alone, each in a fresh worker, up to :attr:`ExecutorOptions.retries` times;
    a task that kills its worker every time yields a :class:`TaskLost`. With
    ``workers=1`` the tasks run in this process, and a task that kills it ends the run.

    Args:
        workers: number of processes (default: the CPU count).
        options: retries of a task whose worker died (:class:`ExecutorOptions`).
    """

    name = "local"

    def __init__(self, workers: int | None = None, options: ExecutorOptions | None = None):
        n = workers if workers is not None else (os.cpu_count() or 1)
        if not isinstance(n, int) or n < 1:
            raise ExecutorError(f"workers must be a positive integer, got {workers!r}")
        self.workers = n
        self.options = options or ExecutorOptions()
        self._pool: cf.ProcessPoolExecutor | None = None
        self._pool_shape: tuple[int, int] = (0, 0)

    def map_unordered(
        self, fn: Callable[[Any], Any], tasks: Sequence[Any]
    ) -> Iterator[tuple[Any, Any]]:
        if self.workers == 1:
            for t in tasks:
                yield t, fn(t)
            return
        states = mp.RawArray(ctypes.c_int8, max(1, len(tasks)))
        deaths = [0] * len(tasks)
        queue = list(range(len(tasks)))
        stalls = 0  # rounds in a row in which workers died before running any task
        while queue:
            before = len(queue)
            lost = yield from self._round(fn, tasks, queue, self.workers, states)
            queue = [i for i in lost if states[i] != _STARTED]
            suspects = [i for i in lost if states[i] == _STARTED]
            stalls = stalls + 1 if not suspects and len(queue) == before else 0
            if stalls > self.options.retries:  # the workers die while starting: give up
                note = "the worker processes died before running this task (killed or crashed)"
                for i in queue:
                    yield tasks[i], TaskLost(note, 0)
                return
            if len(suspects) == 1:  # the one task running: its own death
                deaths[suspects[0]] += 1
            if lost:
                self.options.note(
                    f"a worker process died: {len(suspects)} task(s) it may have been "
                    f"running run again alone, {len(queue)} queued task(s) resubmitted"
                )
            for i in suspects:  # alone in a fresh worker: a death is this task's own
                while True:
                    if deaths[i] > self.options.retries:
                        yield tasks[i], TaskLost(_death_note(deaths[i]), deaths[i])
                        break
                    states[i] = _QUEUED
                    if not (yield from self._round(fn, tasks, [i], 1, states)):
                        break
                    deaths[i] += 1
                    left = self.options.retries + 1 - deaths[i]
                    self.options.note(
                        f"the worker process died running {_label(tasks[i], i)} alone "
                        f"({deaths[i]} time(s)); "
                        + (f"{left} more try(ies)" if left > 0 else "giving it up")
                    )

    def _round(
        self,
        fn: Callable[[Any], Any],
        tasks: Sequence[Any],
        indices: list[int],
        workers: int,
        states: Any,
    ) -> Generator[tuple[Any, Any], None, list[int]]:
        """Run ``indices`` on a pool of ``workers``, yielding their results; returns the
        indices left unfinished because a worker died (the pool is then discarded)."""
        if self._pool is None or self._pool_shape != (workers, id(states)):
            self._discard_pool()
            self._pool = cf.ProcessPoolExecutor(
                workers, initializer=_init_worker, initargs=(os.getpid(), states)
            )
            self._pool_shape = (workers, id(states))
        futs: dict[cf.Future, int] = {}
        lost: list[int] = []
        try:
            # an interrupt while the tasks are submitted stops the pool as well
            for n, i in enumerate(indices):
                try:
                    futs[self._pool.submit(_tracked, fn, i, tasks[i])] = i
                except cf.process.BrokenProcessPool:  # a worker died while submitting
                    lost.extend(indices[n:])
                    break
            for f in cf.as_completed(futs):
                try:
                    result = f.result()
                except cf.process.BrokenProcessPool:
                    lost.append(futs[f])
                    continue
                yield tasks[futs[f]], result
        except BaseException:
            # interrupted (Ctrl-C / SIGTERM) or a task failed: stop the workers now rather
            # than wait for the pairs in flight
            self._discard_pool()
            raise
        finally:
            for f in futs:
                f.cancel()
        if lost:
            self._discard_pool()
        return sorted(lost)

    def _discard_pool(self) -> None:
        from habitsim.workers import stop_pool

        pool, self._pool = self._pool, None
        if pool is not None:
            stop_pool(pool)

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
        options: retries of a task whose worker died (:class:`ExecutorOptions`): the
            local cluster's scheduler lets a task kill ``retries + 1`` workers before it
            gives it up, and gives each worker one task at a time so that a death is
            charged to the task that ran; a remote scheduler keeps its own settings
            (``distributed.scheduler.allowed-failures``; ``worker-saturation: 1.0``
            does the same there). A task given up yields a :class:`TaskLost`.

    Raises:
        ExecutorError: dask/distributed missing, or the scheduler is unreachable.
    """

    name = "dask"

    def __init__(
        self,
        scheduler: str | None = None,
        workers: int | None = None,
        timeout_s: float = 30.0,
        options: ExecutorOptions | None = None,
    ):
        self.options = options or ExecutorOptions()
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
                import dask

                # a death is charged to the tasks the worker was processing: one at a time
                # (saturation 1.0), so only the task that ran when it died
                settings = {
                    "distributed.scheduler.allowed-failures": self.options.retries,
                    "distributed.scheduler.worker-saturation": 1.0,
                }
                with dask.config.set(settings):
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
        from distributed import KilledWorker, as_completed

        if not tasks:
            return
        futs = [self.client.submit(fn, t, pure=False) for t in tasks]
        index = {f.key: i for i, f in enumerate(futs)}
        try:
            for f in as_completed(futs):
                i = index[f.key]
                try:
                    result = f.result()
                except KilledWorker:
                    # the scheduler gave the task up after it killed its workers
                    tries = self.options.retries + 1 if self._cluster is not None else None
                    note = (
                        "the Dask workers running this task died every time "
                        + (f"({tries} times" if tries else "(past the scheduler's allowed-failures")
                        + "; killed, e.g. out of memory, or crashed)"
                    )
                    self.options.note(f"{_label(tasks[i], i)}: {note}")
                    yield tasks[i], TaskLost(note, tries or 0)
                    continue
                yield tasks[i], result
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
    kind: str = "local",
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    options: ExecutorOptions | None = None,
) -> LocalExecutor | DaskExecutor:
    """An executor by name (``local`` or ``dask``), with ``options`` (retries of a task
    whose worker died; None: :class:`ExecutorOptions` defaults).

    Raises:
        ExecutorError: an unknown name, or a scheduler address given to ``local``.
    """
    if kind not in EXECUTORS:
        raise ExecutorError(unknown_choice("executor", kind, EXECUTORS))
    if kind == "local":
        if scheduler:
            raise ExecutorError("--scheduler is only used with --executor dask")
        return LocalExecutor(workers, options)
    return DaskExecutor(scheduler, workers, options=options)
