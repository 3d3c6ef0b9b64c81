"""Explicit joint maps: joint-map files (JSON or TOML) and the check of a habitsim →
source mapping against a source skeleton."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..bvh import BVHData
from ..errors import SkeletonMappingError
from ..jsonfile import load_json, load_toml
from ..skeleton import JOINT_NAMES


def load_joint_map(path: str | Path) -> dict[str, Any]:
    """Read a joint-map file (JSON or TOML).

    JSON::

        {"extends": "auto", "units": "cm", "up": "y",
         "map": {"lh_hip": "b_LeftLegUpper", "lh_ilium": null}}

    TOML::

        extends = "auto"    # optional: start from the automatic mapping
        units = "cm"        # optional: m, cm, mm
        up = "y"            # optional: x, y, z with optional sign
        [map]
        pelvis = "Hips"
        lf_shoulder = "LeftArm"
        lh_ilium = ""       # unmapped (JSON: null)

    Without ``extends`` the file is the whole mapping (joints it does not name keep the
    species' standing pose); with ``extends = "auto"`` it overrides only the joints it
    names on top of the automatic mapping (:func:`auto_map`).

    Args:
        path: the ``.json`` or ``.toml`` file.

    Returns:
        ``{"map": {habitsim: source | None}, "units": str | None, "up": str | None,
        "extends": "auto" | None}``.

    Raises:
        SkeletonMappingError: unreadable file, an unknown suffix, a missing ``map`` table,
            non-string values, unknown keys or unknown habitsim joint names (the message
            lists the valid ones).
    """
    p = Path(path)
    kind = p.suffix.lower()
    if kind not in (".json", ".toml"):
        raise SkeletonMappingError(
            f"{p}: unknown joint-map file type {p.suffix!r}; valid: .json, .toml"
        )
    load = load_json if kind == ".json" else load_toml
    data = load(p, f"joint-map {kind[1:].upper()}", error=SkeletonMappingError)
    if not isinstance(data, dict):
        raise SkeletonMappingError(f"{p}: a joint map must be a table/object with a 'map' key")
    unknown = sorted(set(data) - {"map", "units", "up", "extends"})
    if unknown:
        raise SkeletonMappingError(
            f"{p}: unknown keys {unknown[:10]}; valid: map, units, up, extends"
        )
    m = data.get("map")
    if not isinstance(m, dict) or not m:
        raise SkeletonMappingError(
            f'{p}: needs a non-empty [map] table of habitsim_joint = "SourceJoint"'
        )
    out: dict[str, str | None] = {}
    for k, v in m.items():
        if v is not None and not isinstance(v, str):
            raise SkeletonMappingError(
                f"{p}: [map] {k} must be a source joint name (string), got {v!r:.60}"
            )
        out[k] = v or None
    bad = sorted(set(m) - set(JOINT_NAMES))
    if bad:
        raise SkeletonMappingError(
            f"{p}: unknown habitsim joints {bad[:10]}; valid: {', '.join(JOINT_NAMES)}"
        )
    for k in ("units", "up", "extends"):
        if k in data and not isinstance(data[k], str):
            raise SkeletonMappingError(f"{p}: {k} must be a string, got {data[k]!r:.60}")
    ext = data.get("extends")
    if ext is not None and ext != "auto":
        raise SkeletonMappingError(f"{p}: unknown extends {ext!r:.60}; valid: auto")
    return {"map": out, "units": data.get("units"), "up": data.get("up"), "extends": ext}


def validate_joint_map(
    joint_map: Mapping[str, str | None], bvh: BVHData, where: str = "joint map"
) -> dict[str, str | None]:
    """Check an explicit habitsim → source mapping against a BVH skeleton.

    Args:
        joint_map: habitsim joint name → source joint name (End Sites are named
            ``<parent>_End``).
        bvh: the source skeleton.
        where: name used in messages (e.g. the TOML path).

    Returns:
        Every habitsim joint → source name or None.

    Raises:
        SkeletonMappingError: unknown habitsim or source joint names (listing the valid
            ones), a source joint used twice, or no source joint for ``pelvis``.
    """
    bad = sorted(set(joint_map) - set(JOINT_NAMES))
    if bad:
        raise SkeletonMappingError(
            f"{where}: unknown habitsim joints {bad}; valid: {', '.join(JOINT_NAMES)}"
        )
    missing = sorted({v for v in joint_map.values() if v is not None and v not in bvh.names})
    if missing:
        names = ", ".join(bvh.names[:80]) + (" …" if len(bvh.names) > 80 else "")
        raise SkeletonMappingError(
            f"{where}: source joints {missing[:10]} are not in {bvh.source}; its joints: {names}"
        )
    seen: dict[str, str] = {}
    for k, v in joint_map.items():
        if v is None:
            continue
        if v in seen:
            raise SkeletonMappingError(
                f"{where}: source joint {v!r} is mapped to both {seen[v]} and {k}"
            )
        seen[v] = k
    if not joint_map.get("pelvis"):
        raise SkeletonMappingError(
            f'{where}: must map pelvis (the root) to a source joint, e.g. pelvis = "Hips"'
        )
    out: dict[str, str | None] = {n: None for n in JOINT_NAMES}
    out.update(joint_map)
    return out
