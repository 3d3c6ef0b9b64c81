"""The benchmarks behind ``habitsim bench ...`` (installed as ``habitsim.evaluation.bench``).

One module per benchmark; each takes a frozen options dataclass and returns typed
results (rows, summaries, the targets each run meets or MISSES). The command line
(:mod:`habitsim.cli`) parses the options, calls these functions and prints.

* :mod:`~.data` — the synthetic data set build and forward-kinematics throughput.
* :mod:`~.sim` — raw ``mj_step`` rate against tracking rate, survival of synthetic walks.
* :mod:`~.refine` — refinement solve times, scaling, IPOPT success rate.
* :mod:`~.balance` — unassisted tracking with the torque controllers, QP / MPC timing.
* :mod:`~.train` — training throughput and transfer latency of the learning core.
* :mod:`~.model` — what a checkpoint's transfers look like against the learning targets.
* :mod:`~.real` — real motion capture through the whole pipeline; its printed report in
  :mod:`~.real_report`.
* :mod:`~.targets` — a benchmark target and its verdict (``met``, ``MISSED``, ``n/a``).

Submodules are imported on use; this package imports nothing.
"""
