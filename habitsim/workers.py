"""Worker processes that never outlive the run that started them.

The local process pools of ``habitsim eval`` and ``habitsim data synth`` start their
workers with :func:`init_worker`, which ties each worker's life to its parent in two
ways:

* on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)``: the kernel kills the worker the moment
  its parent dies, whatever killed the parent (SIGKILL included);
* everywhere, a daemon thread that polls the parent pid and exits the worker when the
  worker has been re-parented (its parent died), the fallback where ``prctl`` is missing.

So a killed run leaves no CPU-holding orphans and no late writes into its output folder.
The parent stops its pool with :func:`stop_pool` when it is interrupted (Ctrl-C, or
SIGTERM, which the command line turns into the same ``KeyboardInterrupt``): queued tasks
are cancelled and running workers terminated instead of waited for.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import ctypes
import os
import signal
import sys
import threading
import time

__all__ = ["init_worker", "stop_pool", "WATCHDOG_INTERVAL_S"]

#: How often the fallback watchdog checks that the parent is alive [s].
WATCHDOG_INTERVAL_S = 0.5
_PR_SET_PDEATHSIG = 1


def init_worker(parent_pid: int) -> None:
    """Pool initializer: make this worker die with ``parent_pid`` (see the module doc).

    Args:
        parent_pid: ``os.getpid()`` of the process that creates the pool.
    """
    # a forked worker inherits the parent's Python SIGTERM handler (the command line's
    # "stop like Ctrl-C"); a worker must simply end on SIGTERM
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)
    threading.Thread(
        target=_watch_parent, args=(parent_pid,), name="habitsim-parent-watchdog", daemon=True
    ).start()


def _watch_parent(parent_pid: int) -> None:
    while True:
        time.sleep(WATCHDOG_INTERVAL_S)
        if os.getppid() != parent_pid:
            os._exit(1)


def stop_pool(pool: cf.ProcessPoolExecutor, timeout_s: float = 5.0) -> None:
    """Stop a pool at once: cancel queued tasks, terminate running workers, wait for them
    (at most ``timeout_s`` before they are killed)."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        with contextlib.suppress(Exception):
            p.terminate()
    deadline = time.monotonic() + timeout_s
    for p in procs:
        with contextlib.suppress(Exception):
            p.join(max(0.0, deadline - time.monotonic()))
            if p.is_alive():
                p.kill()
                p.join(1.0)
    # Not ``shutdown(wait=True)``: its join has no timeout, and the pool's manager thread
    # can be stuck on a future lock an interrupt left held (see ``habitsim.cli.run``).
    manager = getattr(pool, "_executor_manager_thread", None)
    if manager is not None:
        manager.join(max(0.0, deadline - time.monotonic()) + 1.0)
