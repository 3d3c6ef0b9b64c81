"""The transfer methods, behind one registry.

A transfer method re-expresses a motion on another species' skeleton: a function
``fn(motion, target, *, seed, **options) -> Motion``. :data:`METHODS` is the one registry
of them: :func:`habitsim.transfer` (``method=``), ``habitsim transfer --method``, the
pipeline (:func:`habitsim.pipeline.run_clip`), the evaluation (``habitsim eval
--methods``) and ``habitsim bench real`` all take their names from it.

=====================  =========  ===========================================================
name                   kind       what it does
=====================  =========  ===========================================================
``habit``              learned    VQ-VAE (EMA + code reset), decoder gets z_c and g_c
``habit_ema``          learned    the same trained with an EMA codebook, no code reset
``no_habit``           learned    VQ-VAE whose decoder gets neither z_c nor g_c
``habit_only``         learned    decoder gets the habit latent z_c only
``text_only``          learned    decoder gets the text embedding g_c only
``direct``             baseline   local rotations copied, root scaled by h_target / h_source;
                                  the source's stance labels and metadata kept as they are
``direct_relabelled``  baseline   the same motion; stance labels and metadata as the learned
                                  methods make them
``ground_truth``       reference  the paired synthetic target motion (generated clips only)
=====================  =========  ===========================================================

The two ``direct`` entries move the body identically and differ in what travels with it:

* ``direct`` keeps the source's contact labels frame for frame, exactly as they are, and
  all of the source's metadata (plus ``method``, ``source_species``, ``species``); a
  source without labels gives a motion without labels (the pipeline's transfer stage then
  labels it, :func:`habitsim.stance.schedule.transfer_contacts`). It is the baseline the
  benchmarks (``habitsim eval``, ``habitsim bench real``) report.
* ``direct_relabelled`` labels the output with
  :func:`habitsim.stance.schedule.transfer_contacts`, as the learned methods do (the
  source's schedule carried over in normalised time and cleaned of single-frame runs;
  without source labels, contacts detected on the output's resting feet or the duty-factor
  guess) and writes ``metadata["transfer"]`` in the learned methods' format (``from``,
  ``to``, ``hip_height_ratio``, how the labels were found); of the source's metadata it
  keeps ``action``, ``gait``, ``pair_key`` and ``seed``.

A learned method is named here, not imported: its function lives in
:mod:`habitsim.models.transfer` and is loaded on its first call (:class:`LazyFunction`),
so ``import habitsim``, the command line's parser and the baselines never import torch.
A learned method needs a trained checkpoint of its ``variant``; without one it raises
:class:`~habitsim.models.errors.MethodNotAvailableError`, a :class:`MethodUnavailable`.

:func:`habitsim.transfer` calls a method as ``fn(motion, target, seed=…, checkpoint=…,
temperature=…, plant=…)``, the pipeline as ``fn(motion, target, seed=…)``; a method takes
``**options`` for the options it has no use for. A method that cannot serve a pair raises
:class:`MethodUnavailable`; the benchmarks record that in the row instead of failing.
New methods register with :func:`register_method` or its decorator form
:meth:`MethodRegistry.add`. For the process-pool and Dask executors a method travels to
the workers by name: register module-level functions (or ``functools.partial`` of them).

**The source clip's id.** A caller that knows which clip the source is (the evaluation:
the data set's clip id, the clip file's stem) passes it as ``clip_id``; a method receives
it when its function takes a ``clip_id`` keyword (or ``**options``), so one that looks up
its own precomputed outputs can find them. Methods written without it keep working.

**Plugins.** A pip-installed package registers methods under the entry-point group
:data:`ENTRY_POINT_GROUP` (``habitsim.methods``), one entry per method, its name the
method's name and its value the function::

    [project.entry-points."habitsim.methods"]
    my_method = "my_package.transfer:my_method"

They join the registry on its first lookup (:meth:`MethodRegistry.load_entry_points`),
as :class:`LazyFunction` entries of kind ``external``: the package is imported only when
the method is first called. Every process finds them by itself, so they also run on the
process-pool and Dask workers. An entry whose name is invalid or already taken is left
out with a :class:`MethodPluginWarning`.
"""

from __future__ import annotations

import importlib
import inspect
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from importlib import metadata as importlib_metadata
from typing import Any, Literal, get_args

from .errors import HabitsimError, MethodUnavailable, UnknownMethodError
from .motion import Motion
from .species import load_species
from .stance.policy import ConformPolicy
from .stance.schedule import transfer_contacts

__all__ = [
    "ENTRY_POINT_GROUP",
    "METHODS",
    "MethodPluginWarning",
    "LazyFunction",
    "MethodKind",
    "MethodRegistrationError",
    "MethodRegistry",
    "MethodUnavailable",
    "TransferFn",
    "TransferMethod",
    "UnknownMethodError",
    "direct_relabelled_transfer",
    "direct_transfer",
    "get_method",
    "ground_truth_transfer",
    "method_names",
    "register_method",
    "run_method",
]

#: ``fn(motion, target, *, seed, **options) -> Motion``: a transfer method's function.
TransferFn = Callable[..., Motion]
#: ``learned`` (a trained network), ``baseline`` (no network), ``reference`` (the
#: ground truth a benchmark compares against) or ``external`` (another system's: a
#: plugin's function, a folder of its outputs).
MethodKind = Literal["learned", "baseline", "reference", "external"]
#: The entry-point group under which installed packages register transfer methods.
ENTRY_POINT_GROUP = "habitsim.methods"


class MethodRegistrationError(HabitsimError, ValueError):
    """A method that cannot be registered: a bad name or kind, a function that is not
    callable, or a name already taken."""


class MethodPluginWarning(UserWarning):
    """An entry point of the ``habitsim.methods`` group that was left out (an invalid
    method name or one already registered); the message names the entry and why."""


def accepts_keyword(fn: Callable[..., Any], name: str) -> bool:
    """True when ``fn`` takes the keyword argument ``name`` (by name or ``**kwargs``);
    False when its signature cannot be read."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return False
    return any(
        p.kind == p.VAR_KEYWORD
        or (p.name == name and p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD))
        for p in params
    )


@dataclass(frozen=True)
class LazyFunction:
    """A transfer function named by its module, imported on its first call.

    Attributes:
        module: the module that defines it (``habitsim.models.transfer``).
        attribute: the function's name in that module, or of a factory returning it.
        factory_args: ``None``: ``attribute`` is the function; else ``attribute`` is a
            factory called with these arguments to make it.
    """

    module: str
    attribute: str
    factory_args: tuple[str, ...] | None = None

    def load(self) -> TransferFn:
        """The function (imports :attr:`module`; a dotted :attr:`attribute` is followed)."""
        obj: Any = importlib.import_module(self.module)
        for part in self.attribute.split("."):
            obj = getattr(obj, part)
        return obj if self.factory_args is None else obj(*self.factory_args)


@dataclass(frozen=True)
class TransferMethod:
    """A registered transfer method.

    Attributes:
        name: registry name (``method=`` of :func:`habitsim.transfer`, ``--method``,
            ``--methods``).
        description: one line for listings and reports.
        fn: the function, or where to load it from on first call (:class:`LazyFunction`).
        kind: ``learned``, ``baseline``, ``reference`` or ``external``
            (:data:`MethodKind`).
        variant: the model variant whose trained checkpoint it needs (None: no network).
    """

    name: str
    description: str
    fn: TransferFn | LazyFunction
    kind: MethodKind = "baseline"
    variant: str | None = None

    @property
    def learned(self) -> bool:
        """It runs a trained network (and imports torch when called)."""
        return self.kind == "learned"

    @property
    def needs_checkpoint(self) -> bool:
        """It needs a trained checkpoint of :attr:`variant`."""
        return self.variant is not None

    def load(self) -> TransferFn:
        """The method's function (a lazy one is imported now)."""
        return self.fn.load() if isinstance(self.fn, LazyFunction) else self.fn

    def __call__(
        self,
        motion: Motion,
        target: str,
        *,
        seed: int | None = 0,
        clip_id: str | None = None,
        **options: Any,
    ) -> Motion:
        """``fn(motion, target, seed=seed, **options)``, plus ``clip_id=clip_id`` when it
        is given and the function takes it (no checks: see :func:`run_method`)."""
        fn = self.load()
        if clip_id is not None and accepts_keyword(fn, "clip_id"):
            options["clip_id"] = clip_id
        return fn(motion, target, seed=seed, **options)


class MethodRegistry(Mapping[str, TransferMethod]):
    """Transfer methods by name, in registration order.

    Looking up an unknown name raises :class:`UnknownMethodError` listing the registered
    ones (a ``KeyError``, so ``in`` and ``.get`` work as for a dict). The methods of
    installed plugins (entry-point group :data:`ENTRY_POINT_GROUP`) join on the first
    lookup, listing or count.
    """

    def __init__(self, entry_point_group: str | None = None) -> None:
        self._methods: dict[str, TransferMethod] = {}
        self._group = entry_point_group
        self._plugins_loaded = entry_point_group is None

    def _plugins(self) -> None:
        if not self._plugins_loaded:
            self.load_entry_points()

    def __getitem__(self, name: str) -> TransferMethod:
        self._plugins()
        try:
            return self._methods[name]
        except (KeyError, TypeError):
            valid = ", ".join(self._methods)
            raise UnknownMethodError(f"unknown transfer method {name!r}; valid: {valid}") from None

    def __iter__(self) -> Iterator[str]:
        self._plugins()
        return iter(self._methods)

    def __len__(self) -> int:
        self._plugins()
        return len(self._methods)

    def load_entry_points(self) -> list[TransferMethod]:
        """Register the methods installed packages declare under the registry's
        entry-point group (done once by the first lookup; call it again after installing
        a package in a running process). An entry already registered under its name by
        an earlier call is kept as it is.

        Returns:
            The methods registered by this call.
        """
        self._plugins_loaded = True
        if self._group is None:
            return []
        added = []
        for ep in importlib_metadata.entry_points(group=self._group):
            fn = LazyFunction(ep.module, ep.attr) if ep.attr else None
            known = self._methods.get(ep.name)
            if known is not None and known.fn == fn:
                continue  # found by an earlier call
            dist = getattr(ep.dist, "name", None) or "an installed package"
            try:
                if fn is None:
                    raise MethodRegistrationError(
                        f"method {ep.name!r}: the entry point names a module, not its "
                        "function ('package.module:function')"
                    )
                m = self.register(ep.name, fn, f"from {dist} ({ep.value})", kind="external")
            except MethodRegistrationError as e:
                warnings.warn(
                    f"{self._group} entry point {ep.name} = {ep.value!r} of {dist} left out: {e}",
                    MethodPluginWarning,
                    stacklevel=2,
                )
                continue
            added.append(m)
        return added

    def register(
        self,
        name: str,
        fn: TransferFn | LazyFunction,
        description: str = "",
        *,
        kind: MethodKind = "baseline",
        variant: str | None = None,
        overwrite: bool = False,
    ) -> TransferMethod:
        """Add a method.

        Args:
            name: a lower-case identifier (``my_method``).
            fn: ``fn(motion, target, *, seed, **options) -> Motion``, or a
                :class:`LazyFunction` naming it.
            description: one line for listings.
            kind: ``learned``, ``baseline``, ``reference`` or ``external``.
            variant: the model variant whose checkpoint it needs (None: no network).
            overwrite: replace a method of the same name.

        Returns:
            The registered :class:`TransferMethod`.

        Raises:
            MethodRegistrationError: a bad name or kind, ``fn`` not callable, or the name
                taken (unless ``overwrite``).
        """
        if (
            not isinstance(name, str)
            or not name
            or not name.replace("_", "").isalnum()
            or name != name.lower()
        ):
            raise MethodRegistrationError(f"method names are lower-case identifiers, got {name!r}")
        if kind not in get_args(MethodKind):
            raise MethodRegistrationError(
                f"method {name!r}: unknown kind {kind!r}; valid: {', '.join(get_args(MethodKind))}"
            )
        if not isinstance(fn, LazyFunction) and not callable(fn):
            raise MethodRegistrationError(f"method {name!r}: fn must be callable")
        if name in self._methods and not overwrite:
            raise MethodRegistrationError(f"method {name!r} is already registered")
        m = TransferMethod(name, description, fn, kind, variant)
        self._methods[name] = m
        return m

    def add(
        self,
        name: str,
        *,
        description: str,
        kind: MethodKind = "baseline",
        variant: str | None = None,
    ) -> Callable[[TransferFn], TransferFn]:
        """:meth:`register` as a decorator of the method's function (which it returns)."""

        def decorate(fn: TransferFn) -> TransferFn:
            self.register(name, fn, description, kind=kind, variant=variant)
            return fn

        return decorate


#: The one registry of transfer methods (with the plugins of :data:`ENTRY_POINT_GROUP`).
METHODS = MethodRegistry(ENTRY_POINT_GROUP)
#: Add a transfer method to :data:`METHODS` (:meth:`MethodRegistry.register`).
register_method = METHODS.register


def get_method(name: str) -> TransferMethod:
    """The registered method called ``name``.

    Raises:
        UnknownMethodError: listing the registered methods.
    """
    return METHODS[name]


def method_names() -> list[str]:
    """Every registered method name, in registration order."""
    return list(METHODS)


def run_method(
    method: str | TransferMethod,
    source: Motion,
    target: str,
    *,
    seed: int | None = 0,
    clip_id: str | None = None,
    **options: Any,
) -> Motion:
    """Apply a method and check its output is on the target species' skeleton.

    Args:
        method: a registered name or a :class:`TransferMethod`.
        source: the source motion.
        target: target species.
        seed: the method's seed.
        clip_id: the source clip's id (a data set's clip id, a file's stem), passed to
            a method whose function takes ``clip_id`` (None: not passed).
        **options: passed on to the method (:func:`habitsim.transfer` passes
            ``checkpoint``, ``temperature`` and ``plant``).

    Raises:
        UnknownMethodError: an unknown name (lists the registered ones).
        MethodUnavailable: the method cannot serve this pair.
        HabitsimError: the method returned a motion of another species.
    """
    m = METHODS[method] if isinstance(method, str) else method
    out = m(source, target, seed=seed, clip_id=clip_id, **options)
    if not isinstance(out, Motion):
        raise HabitsimError(f"method {m.name!r} returned {type(out).__name__}, not a Motion")
    if out.species != load_species(target).name:
        raise HabitsimError(
            f"method {m.name!r} returned a {out.species!r} motion for target {target!r}"
        )
    return out


# ---------------------------------------------------------------------------- entries

#: The learned methods' model variants (:data:`habitsim.models.config.VARIANTS`) and
#: their descriptions.
_LEARNED = {
    "habit": "VQ-VAE (EMA + code reset) with habit latent z_c and text embedding g_c",
    "habit_ema": "VQ-VAE (EMA, no code reset) with z_c and g_c",
    "no_habit": "VQ-VAE without z_c and g_c (reconstruction model)",
    "habit_only": "VQ-VAE with the habit latent z_c only",
    "text_only": "VQ-VAE with the text embedding g_c only",
}
#: The module defining the learned methods' functions (imports torch).
_LEARNING_MODULE = "habitsim.models.transfer"

for _variant, _description in _LEARNED.items():
    register_method(
        _variant,
        LazyFunction(_LEARNING_MODULE, "network_method", (_variant,)),
        _description,
        kind="learned",
        variant=_variant,
    )


@METHODS.add(
    "direct",
    description="local rotations copied, root scaled by the hip-height ratio; "
    "the source's stance labels and metadata kept",
)
def direct_transfer(source: Motion, target: str, *, seed: int | None = 0, **_: Any) -> Motion:
    """Copy local rotations onto the target skeleton; scale the root by h_t / h_s.

    The source's contact labels are kept frame for frame: the timing is copied, so they
    are the transferred motion's intended stance phases (refinement pins the feet to the
    ground during them, even where the target's feet now hover).

    Args:
        source: the source motion.
        target: target species.
        seed: unused (deterministic).

    Returns:
        The motion on ``target``'s skeleton at the source's frame rate, with the source's
        labels (None when it has none) and metadata.
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


@METHODS.add(
    "direct_relabelled",
    description="local rotations copied, root scaled by the hip-height ratio; "
    "stance labels found as for the learned methods",
)
def direct_relabelled_transfer(
    source: Motion,
    target: str,
    *,
    seed: int | None = 0,
    policy: ConformPolicy | None = None,
    **_: Any,
) -> Motion:
    """The ``direct`` motion labelled as the learned methods label theirs.

    The source's local rotations on the target skeleton, the root path scaled by the
    hip-height ratio h_target / h_source; stance labels by
    :func:`habitsim.stance.schedule.transfer_contacts` (the source's, frame for frame,
    when it has them) and ``metadata["transfer"]`` as the learned methods write it.

    Args:
        source: the source motion.
        target: target species.
        seed: unused (deterministic).
        policy: the footfall-schedule knobs (None: the defaults of
            :class:`~habitsim.stance.policy.ConformPolicy`).
    """
    del seed
    tgt = load_species(target).name
    ratio = load_species(tgt).hip_height / load_species(source.species).hip_height
    info = {
        "method": "direct_relabelled",
        "from": source.species,
        "to": tgt,
        "hip_height_ratio": round(ratio, 4),
    }
    meta = {k: v for k, v in source.metadata.items() if k in ("action", "gait", "pair_key", "seed")}
    out = Motion(tgt, source.fps, source.root_positions * ratio, source.rotations.copy())
    labels, how = transfer_contacts(out, source, policy=policy)
    meta["transfer"] = {**info, "contacts": how}
    return Motion(out.species, out.fps, out.root_positions, out.rotations, labels.array, meta)


@METHODS.add(
    "ground_truth",
    description="paired synthetic target motion, generate(target, like=source)",
    kind="reference",
)
def ground_truth_transfer(source: Motion, target: str, *, seed: int | None = 0, **_: Any) -> Motion:
    """The paired synthetic target motion ``generate(target, like=source)``: the same
    action with the same dimensionless draws (Froude number, turn rate, start phase,
    heading, frame count) performed by the target in its own habits.

    Raises:
        MethodUnavailable: the source was not made by the generator, or the target has
            no such action.
    """
    from .errors import GaitError
    from .gaits import generate

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
