"""The identity import of a file written by :func:`habitsim.bvh.write_bvh` (joint names
and hierarchy identical to the habitsim skeleton): rotations and root translation copied."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..bvh import BVHData
from ..motion import Motion
from ..rotations import quat_fix_continuity
from ..skeleton import JOINT_NAMES, PARENTS, get_skeleton
from ..species import Species
from .chains import _IDX
from .result import JointMapping, MappingNote


def _habitsim_order(bvh: BVHData) -> list[int] | None:
    """Source indices of the habitsim joints (JOINT_NAMES order) if the file is habitsim's."""
    keep = [j for j in range(bvh.num_joints) if not bvh.is_end_site[j]]
    by_name = {bvh.names[j]: j for j in keep}
    if len(keep) != len(JOINT_NAMES) or set(by_name) != set(JOINT_NAMES):
        return None
    for n, p in zip(JOINT_NAMES, PARENTS, strict=True):
        sp = bvh.parents[by_name[n]]
        if (p < 0) != (sp < 0) or (p >= 0 and bvh.names[sp] != JOINT_NAMES[p]):
            return None
    return [by_name[n] for n in JOINT_NAMES]


def is_habitsim_bvh(bvh: BVHData) -> bool:
    """True if the file's joints (End Sites aside) are exactly habitsim's, same hierarchy."""
    return _habitsim_order(bvh) is not None


def identity_root_scale(bvh: BVHData, species: Species) -> float:
    """The factor the identity import applies to a habitsim file's root translation: 1
    when its offsets are the species' skeleton's, else the hind-leg length ratio."""
    keep = _habitsim_order(bvh)
    assert keep is not None
    off = bvh.offsets[keep]
    if np.allclose(off[1:], get_skeleton(species).offsets[1:], atol=1e-6):
        return 1.0
    src_leg = sum(float(np.linalg.norm(off[_IDX[n]])) for n in ("lh_knee", "lh_hock", "lh_toe"))
    return species.hind_leg_length / src_leg if src_leg > 0 else 1.0


def _identity_import(bvh: BVHData, species: Species) -> tuple[Motion, JointMapping]:
    keep = _habitsim_order(bvh)
    assert keep is not None
    q = quat_fix_continuity(bvh.local_rotations()[:, keep], axis=0)
    root = bvh.root_translation()
    skel = get_skeleton(species)
    notes = ["habitsim-exported file: rotations and root translation copied"]
    codes = [MappingNote.COPIED]
    scale = identity_root_scale(bvh, species)
    if not np.allclose(bvh.offsets[keep][1:], skel.offsets[1:], atol=1e-6):
        codes.append(MappingNote.ROOT_SCALED)
        notes.append(
            f"bone offsets differ from the {species.name} skeleton: root translation scaled "
            f"by the hind-leg length ratio {scale:.4g}"
        )
    joints: dict[str, str | None] = {n: n for n in JOINT_NAMES}
    codes.append(MappingNote.OWN_TOE_STANCE)
    notes.append("stance labels detected on the file's own toes (habitsim contact rule)")
    mapping = JointMapping(joints, "identity", None, scale, notes, note_codes=codes)
    meta = {"source": "bvh", "bvh_file": Path(bvh.source).name, "mapping": mapping.to_dict()}
    m = Motion(species.name, bvh.fps, root * scale, q, metadata=meta)
    from ..contacts import detect_contacts

    m = Motion(m.species, m.fps, m.root_positions, m.rotations, detect_contacts(m), meta)
    return m, mapping
