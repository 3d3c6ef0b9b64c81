"""``habitsim species list``, ``habitsim species show``: browse the species catalog (the
built-in one and the user catalogs of ``$HABITSIM_SPECIES_PATH``);
``habitsim species from-clip``: make a user species from one motion-capture clip."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..species import POSTURES, Species, all_species, load_species
from .conventions import add_source_options, source_options

_COLUMNS = (
    "name",
    "common name",
    "mass kg",
    "hip m",
    "leg m",
    "posture",
    "gaits",
    "held out / cousin",
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``list`` and ``show`` to the ``species`` command group."""
    p = sub.add_parser(
        "list",
        help="list every species in the catalog",
        description="List every species in the catalog with its main numbers.",
    )
    p.add_argument("--json", action="store_true", help="print a JSON list of species summaries")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser(
        "show",
        help="print all numbers of one species",
        description="Print one species' numbers, gaits, habits and description.",
    )
    p.add_argument("name", help="species name (see 'habitsim species list')")
    p.add_argument("--json", action="store_true", help="print the species as a JSON object")
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser(
        "from-clip",
        help="make a user species from one motion-capture clip",
        description=(
            "Measure the animal a BVH/glTF clip shows (segment lengths, standing posture, "
            "hip and shoulder heights), write its species file into a user catalog folder "
            "with its MuJoCo models, and check that the model stands (docs/species.md)."
        ),
    )
    p.add_argument("clip", type=Path, metavar="REF", help="the clip: .bvh, .glb or .gltf")
    p.add_argument("--name", required=True, help="the new species' name (lower-case identifier)")
    p.add_argument(
        "--mass",
        type=float,
        default=None,
        metavar="KG",
        help="body mass in kg (default: the catalog's allometric rule, docs/species.md)",
    )
    p.add_argument(
        "--posture",
        choices=POSTURES,
        default=None,
        help="posture class (default: classified from the leg angles)",
    )
    p.add_argument(
        "--like",
        default=None,
        metavar="SPECIES",
        help="built-in training species to borrow girths, joint limits, gaits and habits "
        "from (default: the nearest of the same posture)",
    )
    p.add_argument(
        "--description",
        default=None,
        metavar="TEXT",
        help="plain-language habit description, 15 words or more (default: the borrowed "
        "species' description, with the measured size)",
    )
    p.add_argument(
        "--catalog",
        type=Path,
        default=None,
        metavar="DIR",
        help="user catalog folder to write into (default: the first folder of "
        "$HABITSIM_SPECIES_PATH)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a user species of that name in the catalog folder",
    )
    p.add_argument("--json", action="store_true", help="print the report as a JSON object")
    add_source_options(p, of="the clip", loop=False)
    p.set_defaults(func=_cmd_from_clip)


# ------------------------------------------------------------------ list


def _held_out_text(sp: Species) -> str:
    parts = [] if sp.user_catalog is None else [f"user ({sp.user_catalog})"]
    if sp.held_out:
        parts.append(f"held out (cousin {sp.cousin})")
    if sp.outlier:
        parts.append("outlier")
    return ", ".join(parts) or "-"


def _list_rows(species: list[Species]) -> list[tuple[str, ...]]:
    return [
        (
            sp.name,
            sp.common_name,
            f"{sp.mass_kg:g}",
            f"{sp.hip_height:.2f}",
            f"{sp.leg_length:.2f}",
            sp.posture,
            ",".join(sorted(sp.gaits)),
            _held_out_text(sp),
        )
        for sp in species
    ]


def format_table(rows: Sequence[tuple[str, ...]], header: tuple[str, ...] = _COLUMNS) -> str:
    """Left-aligned text columns (numbers right-aligned), two spaces apart."""
    numeric = {2, 3, 4}
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]

    def line(r: tuple[str, ...]) -> str:
        pairs = enumerate(zip(r, widths, strict=True))
        cells = [c.rjust(w) if i in numeric else c.ljust(w) for i, (c, w) in pairs]
        return "  ".join(cells).rstrip()

    return "\n".join([line(header), "  ".join("-" * w for w in widths), *map(line, rows)])


def _cmd_list(ns: argparse.Namespace) -> int:
    species = all_species(include_user=True)
    if ns.json:
        print(json.dumps([sp.summary() for sp in species], indent=2))
    else:
        print(format_table(_list_rows(species)))
    return 0


# ------------------------------------------------------------------ show


def species_details(sp: Species) -> dict[str, Any]:
    """Every number of a species in file units (degrees for angles), JSON-ready."""
    deg = math.degrees
    h = sp.habits
    return {
        **sp.summary(),
        "taxonomy": sp.taxonomy,
        "fore_leg_length_m": round(sp.fore_leg_length, 4),
        "shoulder_height_m": round(sp.shoulder_height, 4),
        "trunk_pitch_deg": round(deg(sp.trunk_pitch), 2),
        "segments_m": dict(sp.segments),
        "girths_m": dict(sp.girths),
        "inclinations_deg": {k: round(deg(v), 3) for k, v in sp.inclinations.items()},
        "neck_elevation_deg": round(deg(sp.neck_elevation), 3),
        "head_pitch_deg": round(deg(sp.head_pitch), 3),
        "tail_carriage_deg": round(deg(sp.tail_carriage), 3),
        "joint_limits_deg": {
            k: [round(deg(lo), 3), round(deg(hi), 3)] for k, (lo, hi) in sp.joint_limits.items()
        },
        "gait_habits": {
            g: {
                "footfall": {f: gh.footfall[f] for f in ("LH", "LF", "RH", "RF")},
                "duty_factor": list(gh.duty_factor),
                "froude": list(gh.froude),
            }
            for g, gh in sp.gaits.items()
        },
        "habits": h.table(),
        "description": sp.description,
        "sources": list(sp.sources),
        "user_catalog": str(sp.user_catalog) if sp.user_catalog else None,
        "path": str(sp.path) if sp.path else None,
    }


def _wrap(text: str, width: int = 88, indent: str = "  ") -> str:
    lines, cur = [], indent
    for word in text.split():
        if len(cur) + len(word) + 1 > width and cur.strip():
            lines.append(cur.rstrip())
            cur = indent
        cur += word + " "
    if cur.strip():
        lines.append(cur.rstrip())
    return "\n".join(lines)


def _cmd_show(ns: argparse.Namespace) -> int:
    sp = load_species(ns.name)  # UnknownSpeciesError -> "error: ..." and exit 2 in cli.main
    d = species_details(sp)
    if ns.json:
        print(json.dumps(d, indent=2))
        return 0
    out = [
        f"{sp.name}: {sp.common_name} ({sp.taxonomy})",
        f"  mass {sp.mass_kg:g} kg, posture {sp.posture}, {_held_out_text(sp)}",
        f"  hip height {sp.hip_height:.3f} m, shoulder height {sp.shoulder_height:.3f} m, "
        f"trunk pitch {d['trunk_pitch_deg']:+.1f} deg",
        f"  hind leg {sp.hind_leg_length:.3f} m, fore leg {sp.fore_leg_length:.3f} m",
        "",
        "description:",
        _wrap(sp.description),
        "",
        "segments [m]:",
        _wrap(", ".join(f"{k} {v:g}" for k, v in sp.segments.items())),
        "girths [m]:",
        _wrap(", ".join(f"{k} {v:g}" for k, v in sp.girths.items())),
        "posture [deg from vertical, + = distal end ahead]:",
        _wrap(", ".join(f"{k} {v:+.1f}" for k, v in d["inclinations_deg"].items())),
        f"  neck {d['neck_elevation_deg']:+.1f}, head {d['head_pitch_deg']:+.1f}, "
        f"tail {d['tail_carriage_deg']:+.1f}",
        "joint limits [deg]:",
        _wrap(", ".join(f"{k} [{lo:g}, {hi:g}]" for k, (lo, hi) in d["joint_limits_deg"].items())),
        "",
    ]
    rows = [
        (
            g,
            " ".join(f"{f}={gh.footfall[f]:.2f}" for f in ("LH", "LF", "RH", "RF")),
            f"{gh.duty_factor[0]:.2f}-{gh.duty_factor[1]:.2f}",
            f"{gh.froude[0]:.2f}-{gh.froude[1]:.2f}",
        )
        for g, gh in sp.gaits.items()
    ]
    out.append(format_table(rows, header=("gait", "footfall (LH = 0)", "duty factor", "froude")))
    hb = d["habits"]
    out += [
        "",
        "habits:",
        _wrap(", ".join(f"{k} {v:g}" for k, v in hb.items())),
        "sources:",
        *[f"  - {s}" for s in sp.sources],
    ]
    print("\n".join(out))
    return 0


# ------------------------------------------------------------------ from-clip


def _cmd_from_clip(ns: argparse.Namespace) -> int:
    from ..fromclip.make import species_from_clip

    r = species_from_clip(
        ns.clip,
        ns.name,
        catalog=ns.catalog,
        mass_kg=ns.mass,
        posture=ns.posture,
        like=ns.like,
        description=ns.description,
        source=source_options(ns),
        replace=ns.overwrite,
    )
    sp, d, m = r.species, r.draft, r.measure
    measured = {k: round(v, 4) for k, v in m.measured.items()}
    report: dict[str, Any] = {
        "name": sp.name,
        "file": str(r.file),
        "models": str(r.models),
        "seconds": round(r.seconds, 2),
        "mapping": m.mapping.frame.describe() if m.mapping.frame else m.mapping.method,
        "measured_m": measured,
        "estimated": list(d.estimated),
        "hip_height_m": {"clip": round(m.hip_height, 4), "species": round(sp.hip_height, 4)},
        "shoulder_height_m": {
            "clip": round(m.shoulder_height, 4),
            "species": round(sp.shoulder_height, 4),
        },
        "posture": sp.posture,
        "posture_from": d.posture_from,
        "mass_kg": sp.mass_kg,
        "mass_from": d.mass_from,
        "cousin": d.cousin,
        "limits_widened": list(d.widened),
        "stand": r.stand.describe(),
    }
    if ns.json:
        print(json.dumps(report, indent=2))
        return 0
    how = "given" if d.posture_from == "given" else f"legs nearest the {d.posture_from}'s"
    lines = [
        f"{sp.name}: written {r.file} and {r.models}/ in {r.seconds:.1f} s",
        f"  clip {m.source}: {m.frames} frames at {m.fps:g} Hz; {report['mapping']}",
        "  measured [m]: " + ", ".join(f"{k} {v:g}" for k, v in measured.items()),
        "  from " + d.cousin + ": " + (", ".join(d.estimated) or "no segment"),
        f"  hip height {m.hip_height:.3f} m on the clip, {sp.hip_height:.3f} m standing; "
        f"shoulder {m.shoulder_height:.3f} / {sp.shoulder_height:.3f} m",
        f"  posture {sp.posture} ({how}), mass {sp.mass_kg:g} kg ({d.mass_from}), "
        f"borrows from {d.cousin}",
        "  stands on home: " + r.stand.describe(),
        f"  use it: HABITSIM_SPECIES_PATH={r.file.parent} habitsim species show {sp.name}",
    ]
    if d.widened:
        lines.insert(5, "  joint limits widened to hold the standing pose: " + ", ".join(d.widened))
    print("\n".join(lines))
    return 0
