"""One CPU thread inside the computations whose results must not depend on the machine.

A sum computed by several threads adds its terms in another order than one thread does,
so a matrix product, a convolution or a sparse factorisation gives results that differ in
the last bits with the thread count. Refinement and tracking amplify such a difference
(an IPOPT solve ends after another iteration, a foot touches down one step later), so a
transfer made on a 2-core laptop, in a pool worker and on a 64-core server would give
three different tables. :func:`one_thread` limits, for the block it guards:

* the BLAS and OpenMP thread pools loaded in the process (numpy's and scipy's OpenBLAS,
  CasADi's own OpenBLAS that IPOPT's MUMPS calls, torch's OpenMP), through
  `threadpoolctl <https://github.com/joblib/threadpoolctl>`_, and
* torch's intra-op threads, when torch is loaded,

and restores them after. It guards the network's inference in a transfer, the IPOPT
solves of refinement and the evaluator's inference. MuJoCo's stepping runs on one thread
and needs no guard. A pool limits libraries already loaded when the block starts, so a
solver is guarded where it is called (its libraries loaded when it was built), not where
it is built.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator

from threadpoolctl import OpenBLASController, register, threadpool_limits

__all__ = ["one_thread"]


class _CasadiOpenBLAS(OpenBLASController):
    """CasADi's wheels ship OpenBLAS under a name threadpoolctl does not know."""

    filename_prefixes = ("libcasadi-tp-openblas",)


register(_CasadiOpenBLAS)


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """Run the block on one CPU thread (BLAS, OpenMP and torch), restored afterwards.

    Same inputs ⇒ bitwise-identical results whatever the machine's core count, the
    caller's thread settings (``OMP_NUM_THREADS``, ``torch.set_num_threads``) or the
    process the block runs in. Nested blocks are fine.
    """
    torch = sys.modules.get("torch")
    threads = torch.get_num_threads() if torch is not None else None
    with threadpool_limits(limits=1):
        if torch is not None:
            torch.set_num_threads(1)
        try:
            yield
        finally:
            if torch is not None and threads is not None:
                torch.set_num_threads(threads)
