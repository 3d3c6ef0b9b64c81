"""Helper-laden and stylised rigs in the automatic mapping: control chains (IK, pole,
target, twist, MCH/ORG) used only where they are the legs that animate, fore/hind and
head/tail from the clip's geometry, and the up axis from where the feet are."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from foreign_rig import (
    BLENDER_EXPECTED,
    PET_EXPECTED,
    _foreign_rig,
    blender_rig,
    pet_rig,
)

import habitsim
from habitsim.bvh_mapping import (
    MappingNote,
    MappingOptions,
    find_up,
    import_bvh,
    is_control_name,
    is_helper_name,
    is_never_limb_name,
    name_cues,
)
from habitsim.errors import SkeletonMappingError


@pytest.fixture(scope="module")
def walk():
    return habitsim.generate("dog", "walk", seed=3, duration_s=3.0)


@pytest.fixture(scope="module")
def reference(walk):
    """The walk through a plain foreign rig: what any rig of the same motion imports as."""
    motion, _ = import_bvh(_foreign_rig(walk), "dog")
    return motion.global_positions()


def _check_mapping(mapping, expected):
    wrong = {k: (mapping.joints[k], v) for k, v in expected.items() if mapping.joints[k] != v}
    assert not wrong, wrong


def _check_positions(motion, walk, reference):
    pos = motion.global_positions()
    # the plain rig's import, joint by joint (the feet's stance points differ a little)
    np.testing.assert_allclose(pos, reference, atol=0.02)
    # and near the original motion (the import plants the feet and scales the root)
    err = np.linalg.norm(pos - walk.global_positions(), axis=-1)
    leg = walk.species_info.hind_leg_length
    assert np.median(err) < 0.1 * leg and err.max() < 0.25 * leg


def test_control_and_never_limb_names():
    for n in ("L_legIK_2", "MCH-shin_ik.L", "thigh_twist_01_l", "LeftLegIKTarget", "CTRL_torso"):
        assert is_control_name(n) and is_helper_name(n) and not is_never_limb_name(n), n
    for n in ("Dog_LeftTail001", "Bip01_L_Toe0Nub", "Bip01_Footsteps", "L_Armor01"):
        assert is_never_limb_name(n) and not is_control_name(n), n
    for n in ("DEF-thigh.L", "L_Leg_A_1", "b_LeftLegUpper", "RightAnkle"):
        assert not is_helper_name(n), n
    # Blender's layer prefixes are no part of a bone's name
    assert name_cues("DEF-thigh.L") == ("l", "thigh")
    assert name_cues("MCH-shin_ik.R") == ("r", "shinik")


def test_pet_rig_maps_its_animated_ik_legs(walk, reference):
    """The pet's hind legs are its ``legIK`` chains (the deforming copy is static, the
    display copy floats); fore/hind from the head's end although the names say "leg"
    for both pairs and the hierarchy (rooted at the chest) says the opposite; the head
    named "tail" and the tail named "head" are found by geometry; y up, cm."""
    motion, mapping = import_bvh(pet_rig(walk), "dog")
    _check_mapping(mapping, PET_EXPECTED)
    assert (mapping.frame.units, mapping.frame.up, mapping.frame.forward) == ("cm", "+y", "+z")
    codes = mapping.note_codes
    assert codes.count(MappingNote.CONTROL_LEG) == 2
    assert MappingNote.FORE_FROM_HEAD in codes
    assert MappingNote.HEAD_TAIL_FROM_GEOMETRY in codes
    assert MappingNote.UP_FROM_FEET in codes and MappingNote.UP_UNSURE not in codes
    assert any("L_leg_1 does not animate" in n for n in mapping.notes)
    _check_positions(motion, walk, reference)


def test_pet_rig_without_deforming_legs(walk, reference):
    """The IK chains are the only hind legs there are: they are used."""
    motion, mapping = import_bvh(pet_rig(walk, deforming=False, floating=False), "dog")
    _check_mapping(mapping, PET_EXPECTED)
    _check_positions(motion, walk, reference)


def test_a_static_chain_never_beats_an_animated_one(walk):
    """With every chain counted as static (the knob at an unreachable share), the
    deforming copy's name wins: it is the animation that gives the IK chain the leg."""
    _, mapping = import_bvh(pet_rig(walk), "dog", options=MappingOptions(animated_share=10.0))
    assert mapping.joints["lh_hip"] == "L_leg_1" and mapping.joints["rh_toe"] == "R_leg_4"


def test_the_chain_whose_tip_reaches_the_ground_wins(walk):
    """The lifted display copy animates like the IK legs and comes first in the file; it
    loses because its tip never reaches the ground, unless any height counts as ground."""
    _, mapping = import_bvh(pet_rig(walk), "dog")
    assert mapping.joints["lh_hip"] == "L_legIK_1"
    _, loose = import_bvh(pet_rig(walk), "dog", options=MappingOptions(ground_share=10.0))
    assert loose.joints["lh_hip"] == "L_legIKshow_1"


def test_blender_rig_maps_deforming_chains(walk, reference):
    """DEF chains over their animated MCH IK copies and static ORG copies, twist segments
    in series spanned, IK targets and poles left out; z up, metres, forward -y."""
    motion, mapping = import_bvh(blender_rig(walk), "dog")
    _check_mapping(mapping, BLENDER_EXPECTED)
    assert not any(v and "twist" in v for v in mapping.joints.values())
    assert (mapping.frame.units, mapping.frame.up, mapping.frame.forward) == ("m", "+z", "-y")
    assert MappingNote.CONTROL_LEG not in mapping.note_codes
    assert min(mapping.confidence.values()) >= 0.67 and mapping.warnings == []
    _check_positions(motion, walk, reference)


def _stance(feet_xy, lift, foot_z=0.0):
    """One frame: four feet at ``feet_xy`` (x, y) on z = ``foot_z``, their leg roots
    ``lift`` above them, and a pelvis above the hind roots."""
    feet = np.array([[x, y, foot_z] for x, y in feet_xy])
    roots = feet + [0.0, 0.0, lift]
    pelvis = roots[2:].mean(axis=0)
    return np.concatenate([feet, roots, pelvis[None]])[None]  # (1, 9, 3)


FEET, ROOTS, PELVIS = [0, 1, 2, 3], [4, 5, 6, 7], 8


def test_up_axis_of_a_long_low_body():
    """Short legs under a long body: the direction from the feet to the pelvis leans
    more backward than up, the feet on one plane still say z."""
    pose = _stance([(0.6, 0.1), (0.6, -0.1), (-0.6, 0.1), (-0.6, -0.1)], lift=0.2)
    clip = np.repeat(pose, 10, axis=0)
    names_axis = "-x"  # what the pelvis-over-feet direction says
    v = (pose[0, PELVIS] - pose[0, FEET].mean(axis=0)).round(3)
    assert abs(v[0]) > abs(v[2])
    ev = find_up(clip, pose, FEET, ROOTS, 0.2, names_axis)
    assert ev.axis == "+z" and not ev.unsure and ev.source == "feet"
    assert "up +z from the feet" in ev.describe()


def test_weak_up_evidence_is_unsure_and_uses_the_rest_pose():
    """A clip lying on the ground (roots barely above feet bunched together) is weak
    evidence: the mapping says it is unsure, and a standing rest pose breaks the tie."""
    lying = _stance([(0.02, 0.02), (0.02, -0.02), (-0.02, 0.02), (-0.02, -0.02)], lift=0.03)
    clip = np.repeat(lying, 10, axis=0)
    standing = _stance([(0.5, 0.1), (0.5, -0.1), (-0.5, 0.1), (-0.5, -0.1)], lift=0.45)
    ev = find_up(clip, standing, FEET, ROOTS, 0.5, None)
    assert ev.unsure and ev.axis == "+z" and ev.source == "rest pose"
    assert "unsure" in ev.describe()
    # a rest pose that is no standing pose gives no evidence
    ev = find_up(clip, lying, FEET, ROOTS, 0.5, "+z")
    assert ev.unsure and ev.rest_axis is None and ev.source == "names"


def test_given_up_axis_is_not_noted(walk):
    _, mapping = import_bvh(pet_rig(walk), "dog", up="y")
    assert mapping.frame.up == "+y"
    assert MappingNote.UP_FROM_FEET not in mapping.note_codes


@pytest.mark.parametrize("in_place", [False, True])
def test_without_a_skull_the_travel_tells_fore_from_hind(walk, in_place):
    """A head with no jaw or ears, names with no fore/hind cue and a hierarchy rooted at
    the chest: the stance feet's sweep (the same in a travelling clip and an in-place
    loop) says which end goes first. Backward, it says the opposite."""
    motion, mapping = import_bvh(pet_rig(walk, skull=False, in_place=in_place), "dog")
    _check_mapping(mapping, {k: v for k, v in PET_EXPECTED.items() if k != "head"})
    assert MappingNote.FORE_FROM_TRAVEL in mapping.note_codes
    assert MappingNote.FORE_FROM_HEAD not in mapping.note_codes
    backward = pet_rig(walk, skull=False, in_place=in_place)
    backward = dataclasses.replace(backward, frames=backward.frames[::-1].copy())
    _, mapping = import_bvh(backward, "dog")
    assert mapping.joints["lf_shoulder"] == "L_legIK_1"  # swapped: the clip runs backward
    # with the skull back, the head's end decides, and the travel is noted as disagreeing
    backward = pet_rig(walk, in_place=in_place)
    backward = dataclasses.replace(backward, frames=backward.frames[::-1].copy())
    _, mapping = import_bvh(backward, "dog")
    _check_mapping(mapping, PET_EXPECTED)
    assert MappingNote.TRAVEL_DISAGREES in mapping.note_codes


def test_long_low_pet_gets_its_up_axis(walk):
    """A body stretched long and low on short legs (y up): from the feet to the pelvis
    the direction leans backward more than up, and the feet on one ground still say +y;
    legs, fore/hind, head and tail as in the plain pet."""
    rig = pet_rig(walk, shape=(1.6, 0.4))
    motion, mapping = import_bvh(rig, "dog")
    assert mapping.frame.up == "+y" and MappingNote.UP_FROM_FEET in mapping.note_codes
    hips = rig.fk()[:, rig.index("Pet_Hip")]
    tips = [f"{S}_{leg}_4" for S in "LR" for leg in ("Leg_A", "legIK")]
    feet = rig.fk()[:, [rig.index(n) for n in tips]].mean(axis=1)
    lean = np.abs((hips - feet).mean(axis=0))
    assert lean[2] > lean[1]  # the pelvis sits farther behind the feet than above them
    j = mapping.joints
    for s, S in (("l", "L"), ("r", "R")):
        assert j[f"{s}f_toe"] == f"{S}_Leg_A_4" and j[f"{s}h_toe"] == f"{S}_legIK_4"
        assert all(j[f"{s}f_{g}"].startswith(f"{S}_Leg_A_") for g in ("elbow", "wrist"))
        assert all(j[f"{s}h_{g}"] == f"{S}_legIK_{k}" for k, g in ((1, "hip"), (2, "knee")))
    assert j["lf_shoulder"][-1] == j["rf_shoulder"][-1]  # one girdle split for both sides
    assert (j["neck"], j["tail1"]) == ("Pet_Tail_F_1", "Pet_Head_B_1")


def test_inspection_tags_control_bones(walk):
    from habitsim.bvh_mapping import describe_hierarchy

    rig = pet_rig(walk)
    _, mapping = import_bvh(rig, "dog")
    lines = describe_hierarchy(rig, mapping).splitlines()
    line = {ln.split()[0]: ln for ln in lines if not ln.strip().endswith("[end]")}
    assert "[control]" in line["L_legIK_1"] and "-> lh_hip" in line["L_legIK_1"]
    assert "[control]" in line["L_legIK_pole"] and "->" not in line["L_legIK_pole"]
    assert "-> neck" in line["Pet_Tail_F_1"]  # named "tail", mapped by where it is
    assert "[" not in line["L_leg_1"]


def test_a_leg_no_chain_animates_is_an_error(walk):
    """Hind legs driven by IK targets that were never baked: every hind chain of the rig
    keeps one pose while the fore legs walk. The import stops and says why."""
    rig = pet_rig(walk, floating=False)
    frozen = rig.frames.copy()
    for j, name in enumerate(rig.names):
        if "legIK_" in name and not name.endswith(("pole", "target")) and not rig.is_end_site[j]:
            cols = slice(rig.channel_start[j], rig.channel_start[j] + 6)
            frozen[:, cols] = frozen[0, cols]
    rig = dataclasses.replace(rig, frames=frozen)
    with pytest.raises(SkeletonMappingError, match="no chain of this rig animates 2 of its legs"):
        import_bvh(rig, "dog")
