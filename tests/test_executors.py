"""A worker process that dies under a task (SIGKILL, as the out-of-memory killer sends)
is retried and reported, never a raw ``BrokenProcessPool`` / ``KilledWorker``; a method
that hangs is stopped by the per-call time limit."""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import pytest

from habitsim.errors import ArgumentRangeError, TimeLimitError
from habitsim.evaluation.executors import (
    ExecutorError,
    ExecutorOptions,
    LocalExecutor,
    TaskLost,
)
from habitsim.timelimit import call_with_time_limit


def _square_or_die(task: tuple[int, str, str]) -> int:
    """``x * x``; ``once``: SIGKILL this process the first time (a marker file remembers
    it), ``always``: every time."""
    x, mode, marker = task
    if mode == "always" or (mode == "once" and not os.path.exists(marker)):
        if mode == "once":
            Path(marker).write_text("died")
        os.kill(os.getpid(), signal.SIGKILL)
    return x * x


def _tasks(tmp_path: Path, killer: str) -> list[tuple[int, str, str]]:
    return [(x, killer if x == 3 else "", str(tmp_path / "marker")) for x in range(6)]


def test_a_worker_killed_once_is_retried_and_the_results_match(tmp_path: Path) -> None:
    notes: list[str] = []
    ex = LocalExecutor(2, ExecutorOptions(retries=1, log=notes.append))
    try:
        got = dict(ex.map_unordered(_square_or_die, _tasks(tmp_path, "once")))
    finally:
        ex.close()
    assert (tmp_path / "marker").is_file()  # the task did kill its worker once
    assert {t[0]: r for t, r in got.items()} == {x: x * x for x in range(6)}
    assert any("worker process died" in n for n in notes), notes


def test_a_task_that_always_kills_its_worker_is_given_up(tmp_path: Path) -> None:
    notes: list[str] = []
    ex = LocalExecutor(2, ExecutorOptions(retries=1, log=notes.append))
    try:
        got = {t[0]: r for t, r in ex.map_unordered(_square_or_die, _tasks(tmp_path, "always"))}
    finally:
        ex.close()
    lost = got.pop(3)
    assert isinstance(lost, TaskLost)
    assert "worker process died" in lost.note and "out of memory" in lost.note
    assert lost.attempts == 2  # the first run and one retry, alone
    assert got == {x: x * x for x in range(6) if x != 3}  # the others are not charged
    assert any("giving it up" in n for n in notes), notes


def test_no_retries_gives_a_killer_up_at_once(tmp_path: Path) -> None:
    ex = LocalExecutor(2, ExecutorOptions(retries=0))
    try:
        got = {t[0]: r for t, r in ex.map_unordered(_square_or_die, _tasks(tmp_path, "always"))}
    finally:
        ex.close()
    assert isinstance(got[3], TaskLost) and got[3].attempts == 1
    assert all(got[x] == x * x for x in range(6) if x != 3)


def test_executor_options_are_checked() -> None:
    with pytest.raises(ExecutorError, match="valid: 0 to 100"):
        ExecutorOptions(retries=-1)
    with pytest.raises(ExecutorError, match="whole number"):
        ExecutorOptions(retries=1.5)  # type: ignore[arg-type]


def _hang() -> None:
    while True:
        pass


def test_a_call_past_its_time_limit_is_stopped() -> None:
    t0 = time.monotonic()
    with pytest.raises(TimeLimitError, match=r"method 'x' exceeded 0.2 s"):
        call_with_time_limit(_hang, 0.2, "method 'x'")
    assert time.monotonic() - t0 < 5
    assert call_with_time_limit(lambda: 7, 5.0, "f") == 7
    assert call_with_time_limit(lambda: 7, None, "f") == 7
    with pytest.raises(ZeroDivisionError):
        call_with_time_limit(lambda: 1 / 0, 5.0, "f")
    with pytest.raises(ArgumentRangeError, match="positive number"):
        call_with_time_limit(lambda: 7, 0.0, "f")
    # outside the main thread (a Dask worker's task thread): the call is given up
    import threading

    box: list[BaseException] = []

    def other() -> None:
        try:
            call_with_time_limit(lambda: time.sleep(30), 0.2, "method 'y'")
        except TimeLimitError as e:
            box.append(e)

    th = threading.Thread(target=other)
    th.start()
    th.join(10)
    assert box and "method 'y' exceeded 0.2 s" in str(box[0])


distributed = pytest.importorskip("distributed")


@pytest.mark.slow
def test_dask_killed_worker_is_a_lost_task_not_a_traceback(tmp_path: Path) -> None:
    """A local Dask cluster: a task that kills its worker every time yields a
    :class:`TaskLost` (the scheduler's ``KilledWorker``), the others their results."""
    import cloudpickle

    from habitsim.evaluation.executors import DaskExecutor

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    notes: list[str] = []
    ex = DaskExecutor(workers=2, options=ExecutorOptions(retries=1, log=notes.append))
    try:
        got = {t[0]: r for t, r in ex.map_unordered(_square_or_die, _tasks(tmp_path, "always"))}
    finally:
        ex.close()
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert isinstance(got[3], TaskLost) and "died every time" in got[3].note
    assert all(got[x] == x * x for x in range(6) if x != 3)
    assert notes
