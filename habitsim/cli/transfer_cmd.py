"""``habitsim transfer``: transfer a motion file (.npz, .bvh, .glb, .gltf) to another species."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from .conventions import add_source_options, source_options

if TYPE_CHECKING:
    from ..models.habit_fit import HabitFitOptions


def _description() -> str:
    """The command's description, with every registered method."""
    from ..transfer_methods import METHODS

    return (
        "Re-express a motion (.npz, or .bvh/.glb/.gltf imported with --from) on another "
        "species' skeleton. "
        "Held-out target species borrow the habit latent of the nearest training species "
        "in text-embedding space; the choice is printed. Methods: "
        + "; ".join(f"{m.name}: {m.description}" for m in METHODS.values())
    )


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``transfer`` command."""
    p = sub.add_parser(
        "transfer",
        help="transfer a motion to another species, keeping the target's habits",
        description=_description(),
    )
    p.add_argument(
        "source",
        type=Path,
        nargs="?",
        metavar="SRC",
        help="source motion (.npz) or motion capture (.bvh, .glb, .gltf)",
    )
    p.add_argument("--to", metavar="SPECIES", help="target species")
    p.add_argument(
        "--from",
        "--species",
        dest="from_species",
        metavar="SPECIES",
        help="source species (required for .bvh/.glb/.gltf: the skeleton to import onto; "
        "for .npz it relabels the motion)",
    )
    add_source_options(p, of="the source")
    p.add_argument("--out", type=Path, metavar="OUT.npz", help="output motion file")
    p.add_argument(
        "--action",
        metavar="ACTION",
        help="the source's action (walk, trot, …) when its file does not say (a .bvh): "
        "it gives the stance labels of the result the target's duty factor where its feet slide",
    )
    p.add_argument(
        "--bvh",
        type=Path,
        metavar="OUT.bvh",
        help="also write the result as BVH (with a glTF --rig also .glb / .gltf)",
    )
    from .bvh_cmd import add_rig_options

    add_rig_options(p, prefix="rig-")  # --bvh onto the user's rig (--rig, --rig-map, …)
    p.add_argument(
        "--method", default="habit", help="transfer method (default: habit; see --list-methods)"
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the habit latent (default 0)")
    p.add_argument(
        "--checkpoint",
        type=Path,
        metavar="DIR",
        help="checkpoint folder (default: the shipped one)",
    )
    p.add_argument(
        "--temperature", type=float, default=1.0, help="prior sampling temperature (default 1)"
    )
    p.add_argument(
        "--habit-from",
        type=Path,
        nargs="+",
        metavar="REF.npz",
        help="reference clip(s) of the target species: the habit latent is fitted to them "
        "(K clips: one latent fitted on all) instead of drawn from the target's prior",
    )
    p.add_argument(
        "--habit-steps",
        type=int,
        default=200,
        metavar="N",
        help="Adam steps of fitting the habit latent to the --habit-from clips (default 200; "
        "0: the habit encoder's mean)",
    )
    p.add_argument("--list-methods", action="store_true", help="list the transfer methods and exit")
    p.set_defaults(func=_transfer)


def _transfer(ns: argparse.Namespace) -> int:
    from ..errors import MotionFileError
    from ..transfer_methods import METHODS

    if ns.list_methods:
        for m in METHODS.values():
            where = "no network"
            if m.variant is not None:
                from ..models.transfer import resolve_checkpoint

                try:
                    where = f"checkpoint {resolve_checkpoint(m.variant)}"
                except Exception:  # noqa: BLE001 - listing only
                    where = "no checkpoint (train one with --variant)"
            print(f"{m.name:17s} {m.description} [{where}]")
        return 0
    missing = [f for f, v in (("SRC", ns.source), ("--to", ns.to), ("--out", ns.out)) if v is None]
    if missing:
        raise MotionFileError(f"habitsim transfer needs {', '.join(missing)}")
    METHODS[ns.method]  # UnknownMethodError listing the registered ones
    if ns.out.suffix != ".npz":
        raise MotionFileError(f"--out must end in .npz, got {ns.out.name!r}")
    kinds = (".bvh", ".glb", ".gltf") if ns.rig is not None else (".bvh",)
    if ns.bvh is not None and ns.bvh.suffix.lower() not in kinds:
        raise MotionFileError(f"--bvh must end in {' or '.join(kinds)}, got {ns.bvh.name!r}")
    bad = [r.name for r in ns.habit_from or () if r.suffix != ".npz"]
    if bad:
        raise MotionFileError(
            f"--habit-from takes .npz motions of the target species, got {bad[0]!r}"
        )
    if ns.rig is not None and ns.bvh is None:
        raise MotionFileError("--rig needs --bvh OUT.bvh (the file written on the rig)")
    from ..fileio import output_transaction

    # both destinations checked before the transfer; written together or not at all
    with output_transaction({"--out": ns.out, "--bvh": ns.bvh}):
        return _transfer_outputs(ns)


def _transfer_outputs(ns: argparse.Namespace) -> int:
    from ..errors import MotionFileError
    from ..models.transfer import transfer
    from ..source import load_clip
    from ..species import load_species
    from ..stance.report import TransferRecord

    target = load_species(ns.to).name
    suffix = ns.source.suffix.lower()
    species = ns.from_species if suffix != ".npz" else None
    clip = load_clip(ns.source, source_options(ns, species))
    if clip.mapping is not None:
        print(clip.mapping)
    if clip.cut:
        print(f"source span: {clip.kept()}")
    if clip.looped():
        print(f"source {clip.looped()}")
    motion = clip.motion
    from ..bvh_mapping.report import in_place_note

    if (note := in_place_note(motion.metadata)) is not None:
        print(note)
    if ns.action is not None:
        from ..gaits import ACTIONS

        if ns.action not in ACTIONS:
            raise MotionFileError(f"unknown --action {ns.action!r}; valid: {', '.join(ACTIONS)}")
        motion.metadata["action"] = ns.action
    out = transfer(
        motion,
        to=target,
        method=ns.method,
        source=ns.from_species if suffix == ".npz" else None,
        seed=ns.seed,
        checkpoint=ns.checkpoint,
        temperature=ns.temperature,
        habit_from=ns.habit_from,
        habit_options=_habit_options(ns.habit_steps),
    )
    rec = TransferRecord.from_metadata(out.metadata)
    if rec is not None and rec.retrieval is not None:
        print(rec.retrieval.explanation)
    if rec is not None and rec.levelled is not None:
        lv = rec.levelled
        dz = lv.fore_minus_hind_per_leg
        print(
            f"trunk pitched {lv.pitch_deg:+.1f}° before planting: the decoded fore stance "
            f"toes stood {abs(dz):.3f} leg lengths {'below' if dz < 0 else 'above'} the hind ones"
        )
    habit = None if rec is None else dict(rec.entries).get("habit_from")
    if habit is not None:
        print(
            f"habit latent {habit['method']} from {habit['k']} clip(s) "
            f"({', '.join(habit['clips'])}): reconstruction error {habit['fit_loss_start']:.4f} "
            f"-> {habit['fit_loss']:.4f}"
        )
    how = None if rec is None else rec.contacts
    if how is not None and how.method == "duty":
        print(
            f"stance labels of {', '.join(how.detail('feet_by_duty'))} from the {target}'s "
            f"{how.detail('gait')} duty factor {how.detail('duty_factor')} "
            "(those feet never rest in the output)"
        )
    out.save(ns.out)
    msg = (
        f"transferred {ns.source.name} ({motion.species}, {motion.num_frames} frames at "
        f"{motion.fps:g} fps) to {target} with {ns.method} -> {ns.out}"
    )
    if ns.bvh is not None:
        from ..bvh import write_bvh
        from .bvh_cmd import write_on_rig

        if ns.rig is not None:
            msg += f", {ns.bvh} on {write_on_rig(out, ns.bvh, ns)}"
        else:
            write_bvh(out, ns.bvh)
            msg += f", {ns.bvh}"
    print(msg)
    return 0


def _habit_options(steps: int) -> HabitFitOptions:
    """``--habit-steps``: the fit's steps (0: the habit encoder's mean, no fit)."""
    from ..models.habit_fit import HabitFitOptions

    return HabitFitOptions(steps=steps) if steps > 0 else HabitFitOptions(method="encoder")
