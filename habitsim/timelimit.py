"""A call stopped after a time limit: an entry-point transfer method (someone else's
code run inside ``habitsim eval``) that hangs fails its row instead of holding the run.

:func:`call_with_time_limit` runs a function and raises
:class:`~habitsim.errors.TimeLimitError` ("… exceeded N s") when it runs longer:

* in a process's main thread (a local pool's worker, ``--workers 1``), an interval timer
  (``SIGALRM``) interrupts the call where it is, even in ``time.sleep`` or a busy Python
  loop, and the call's ``finally`` blocks run; a call stuck inside compiled code is
  interrupted when it returns to Python;
* in another thread (a Dask worker's task thread, where no signal can be set), the call
  runs in a daemon thread of its own that is given up after the limit: the row fails
  on time, and the abandoned call runs on in the background until its process ends.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from typing import Any, TypeVar

from .errors import ArgumentRangeError, TimeLimitError

__all__ = ["call_with_time_limit"]

T = TypeVar("T")


class _Expired(BaseException):
    """Raised into the call by the timer (a ``BaseException``, so that the call's own
    ``except Exception`` does not swallow it)."""


def call_with_time_limit(fn: Callable[[], T], seconds: float | None, what: str) -> T:
    """``fn()``, stopped after ``seconds``.

    Args:
        fn: the call (no arguments: bind them with a lambda or ``functools.partial``).
        seconds: the time limit [s] (None: no limit).
        what: the call's name in the message (``method 'x'``).

    Raises:
        TimeLimitError: ``"{what} exceeded {seconds} s"``.
        ArgumentRangeError: ``seconds`` not a positive number.
        Whatever ``fn`` raises.
    """
    if seconds is None:
        return fn()
    if isinstance(seconds, bool) or not isinstance(seconds, int | float) or not seconds > 0:
        raise ArgumentRangeError(f"time limit {seconds!r}; valid: a positive number of seconds")
    message = f"{what} exceeded {seconds:g} s"
    in_main = threading.current_thread() is threading.main_thread()
    if in_main and hasattr(signal, "setitimer") and signal.getitimer(signal.ITIMER_REAL)[0] == 0:
        return _with_timer(fn, float(seconds), message)
    return _in_thread(fn, float(seconds), message)


def _with_timer(fn: Callable[[], T], seconds: float, message: str) -> T:
    def expire(signum: int, frame: Any) -> None:
        raise _Expired

    previous = signal.signal(signal.SIGALRM, expire)
    try:
        signal.setitimer(signal.ITIMER_REAL, seconds)
        try:
            return fn()
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
    except _Expired:
        raise TimeLimitError(message) from None
    finally:
        signal.signal(signal.SIGALRM, previous)


def _in_thread(fn: Callable[[], T], seconds: float, message: str) -> T:
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - handed to the caller's thread
            box["error"] = e

    worker = threading.Thread(target=run, name="habitsim-time-limited", daemon=True)
    worker.start()
    worker.join(seconds)
    if worker.is_alive():
        raise TimeLimitError(message)
    if "error" in box:
        raise box["error"]
    return box["value"]
