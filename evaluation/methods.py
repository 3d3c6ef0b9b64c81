"""Transfer methods the benchmark runner compares, behind one registry.

A method is a function ``fn(source: Motion, target: str, *, seed: int) -> Motion``
returning the source's motion on the target species' skeleton. It raises
:class:`MethodUnavailable` when it cannot serve a pair (e.g. no ground truth for an
action the target does not have); the runner records that in the row instead of failing.

Built in:

* ``direct``: the source's local joint rotations copied onto the target skeleton
  (same topology), root path scaled by the hip-height ratio h_target / h_source, same
  frame rate. The source's contact labels are kept: the timing is copied frame for
  frame, so they are the transferred motion's intended stance phases (refinement pins
  the feet to the ground during them, even where the target's feet now hover).
* ``ground_truth``: the paired synthetic target motion,
  ``habitsim.gaits.generate(target, like=source)`` — the same action with the same
  dimensionless draws (Froude number, turn rate, start phase, heading, frame count)
  performed by the target in its own habits. Only for clips made by the generator.

The learned methods of :mod:`habitsim.models` (``habit``, ``habit_ema``, ``no_habit``,
``habit_only``, ``text_only``: :func:`habitsim.models.available_methods`) are registered
on the first look-up of a method, and run :func:`habitsim.models.transfer`.

For the process-pool and Dask executors, the function of a method travels to the
workers by reference: register module-level functions (or ``functools.partial`` of
them), not lambdas or closures.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

from habitsim.errors import HabitsimError, UnknownMethodError, unknown_choice
from habitsim.motion import Motion
from habitsim.species import load_species

__all__ = [
    "Method",
    "MethodUnavailable",
    "UnknownMethodError",
    "direct_transfer",
    "ground_truth_transfer",
    "register_method",
    "get_method",
    "method_names",
    "run_method",
]

TransferFn = Callable[..., Motion]


class MethodUnavailable(HabitsimError):
    """A method that cannot produce this (clip, target) pair; the reason is the message."""


@dataclass(frozen=True)
class Method:
    """A registered transfer method.

    Attributes:
        name: registry name (``--methods``).
        fn: ``fn(source, target, *, seed) -> Motion``.
        description: one line for the report.
        kind: ``baseline``, ``reference`` (ground truth) or ``learned``.
    """

    name: str
    fn: TransferFn
    description: str
    kind: str = "baseline"


_REGISTRY: dict[str, Method] = {}
_discovered = False


def register_method(
    name: str,
    fn: TransferFn,
    description: str = "",
    *,
    kind: str = "baseline",
    overwrite: bool = False,
) -> Method:
    """Add a method to the registry.

    Raises:
        HabitsimError: a bad name, or a name already taken (unless ``overwrite``).
    """
    if not name or not name.replace("_", "").isalnum() or name != name.lower():
        raise HabitsimError(f"method names are lower-case identifiers, got {name!r}")
    if not callable(fn):
        raise HabitsimError(f"method {name!r}: fn must be callable")
    if name in _REGISTRY and not overwrite:
        raise HabitsimError(f"method {name!r} is already registered")
    m = Method(name, fn, description, kind)
    _REGISTRY[name] = m
    return m


def _learned_transfer(source: Motion, target: str, *, seed: int, method: str) -> Motion:
    from habitsim.models import MethodNotAvailableError
    from habitsim.models.transfer import transfer

    try:
        return transfer(source, to=target, method=method, seed=seed)
    except MethodNotAvailableError as e:  # a variant without a trained checkpoint
        raise MethodUnavailable(str(e)) from None


def _discover() -> None:
    """Register the learned methods of :mod:`habitsim.models` (first use: imports torch)."""
    global _discovered
    if _discovered:
        return
    _discovered = True
    from habitsim.models import available_methods

    for name in available_methods():
        if name not in _REGISTRY:
            register_method(
                name,
                functools.partial(_learned_transfer, method=name),
                f"habitsim.models.transfer(method={name!r})",
                kind="learned",
            )


def get_method(name: str) -> Method:
    """The registered method called ``name``.

    Raises:
        UnknownMethodError: listing the registered methods.
    """
    _discover()
    if name not in _REGISTRY:
        raise UnknownMethodError(unknown_choice("method", name, _REGISTRY))
    return _REGISTRY[name]


def method_names() -> list[str]:
    """Every registered method name (built-in first, then in registration order)."""
    _discover()
    return list(_REGISTRY)


def run_method(method: str | Method, source: Motion, target: str, *, seed: int = 0) -> Motion:
    """Apply a method and check its output is on the target species' skeleton.

    Raises:
        MethodUnavailable: the method cannot serve this pair.
        HabitsimError: the method returned a motion of another species.
    """
    m = get_method(method) if isinstance(method, str) else method
    out = m.fn(source, target, seed=seed)
    if not isinstance(out, Motion):
        raise HabitsimError(f"method {m.name!r} returned {type(out).__name__}, not a Motion")
    if out.species != load_species(target).name:
        raise HabitsimError(
            f"method {m.name!r} returned a {out.species!r} motion for target {target!r}"
        )
    return out


# ---------------------------------------------------------------------------- built-ins


def direct_transfer(source: Motion, target: str, *, seed: int = 0) -> Motion:
    """Copy local rotations onto the target skeleton; scale the root by h_t / h_s.

    Args:
        source: the source motion.
        target: target species.
        seed: unused (deterministic).
    """
    del seed
    tgt = load_species(target)
    k = tgt.hip_height / source.species_info.hip_height
    meta = dict(source.metadata)
    meta.update(method="direct", source_species=source.species, species=tgt.name)
    labels = None if source.contacts is None else source.contacts.copy()
    if labels is not None:  # the stance labels are the source's, frame for frame
        meta["transfer"] = {"method": "direct", "contacts": {"method": "source"}}
    return Motion(
        tgt.name, source.fps, source.root_positions * k, source.rotations.copy(), labels, meta
    )


def ground_truth_transfer(source: Motion, target: str, *, seed: int = 0) -> Motion:
    """The paired synthetic target motion ``generate(target, like=source)``.

    Raises:
        MethodUnavailable: the source was not made by the generator, or the target has
            no such action.
    """
    from habitsim.errors import GaitError
    from habitsim.gaits import generate

    del seed
    meta = source.metadata or {}
    if meta.get("generator") != "habitsim.gaits":
        raise MethodUnavailable("no paired ground truth: the source is not a synthetic clip")
    try:
        out = generate(target, like=source)
    except GaitError as e:
        raise MethodUnavailable(f"no paired ground truth: {e}") from None
    out.metadata = {
        **out.metadata,
        "method": "ground_truth",
        "source_species": source.species,
        "transfer": {"method": "ground_truth", "contacts": {"method": "planned"}},
    }
    return out


register_method(
    "direct",
    direct_transfer,
    "local rotations copied, root scaled by the hip-height ratio",
    kind="baseline",
)
register_method(
    "ground_truth",
    ground_truth_transfer,
    "paired synthetic target motion, generate(target, like=source)",
    kind="reference",
)
