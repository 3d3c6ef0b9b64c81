"""A foreign rig written from a synthetic dog walk whose stance is known: other joint names,
6-channel joints, centimetres, z up, an extra root, and the helpers a motion-capture rig
carries."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from habitsim.bvh import BVHData, bvh_text, parse_bvh

RENAME = {
    "pelvis": "Hips_jnt",
    "spine1": "SpineA",
    "spine2": "SpineB",
    "spine3": "Chest",
    "neck": "NeckA",
    "head": "Skull",
    "snout": "Nose",
    "tail1": "TailBase",
    "tail2": "TailMid",
    "tail3": "TailTip",
}
for _s, _S in (("l", "L"), ("r", "R")):
    RENAME.update(
        {
            f"{_s}f_scapula": f"{_S}_Collar",
            f"{_s}f_shoulder": f"{_S}_UpperArm",
            f"{_s}f_elbow": f"{_S}_LowerArm",
            f"{_s}f_wrist": f"{_S}_Paw",
            f"{_s}f_toe": f"{_S}_Digits",
            f"{_s}h_ilium": f"{_S}_Ilium",
            f"{_s}h_hip": f"{_S}_Thigh",
            f"{_s}h_knee": f"{_S}_Shin",
            f"{_s}h_hock": f"{_S}_Hock",
            f"{_s}h_toe": f"{_S}_Toes",
        }
    )


CM = 100.0


#: The same rig with its legs named by leg codes and numbers only, as robot rigs name them.
CODED = {
    **{k: v for k, v in RENAME.items() if k[1:3] not in ("f_", "h_")},
    **{
        f"{s}{g}_{seg}": f"{g.upper()}{s.upper()}_{k}"
        for s in "lr"
        for g, segs in (
            ("f", ("scapula", "shoulder", "elbow", "wrist", "toe")),
            ("h", ("ilium", "hip", "knee", "hock", "toe")),
        )
        for k, seg in enumerate(segs)
    },
}


def _foreign_rig(  # noqa: N803 - the unit factor
    motion, CM: float = CM, rename=RENAME, anonymous: bool = False, nub=(0.05, 0.0, -0.25)
) -> BVHData:
    """The motion as a foreign rig: other names, 6 channels, cm, z up, helpers
    (``anonymous``: every joint, helpers included, named ``J000`` … in file order;
    ``nub``: where the toe nub points from the toe [m])."""
    h = parse_bvh(bvh_text(motion))
    starts = h.channel_start
    f = h.num_frames
    nodes: list[dict] = []  # name, parent name, offset (cm), values (F, 6) or None

    def add(name, parent, offset, values=None):
        nodes.append(
            {"name": name, "parent": parent, "offset": np.asarray(offset, float), "values": values}
        )

    add("Rig_Root", None, [0, 0, 0], np.zeros((f, 6)))
    add("Rig_Footsteps", "Rig_Root", [0, 0, 0], np.zeros((f, 6)))
    for j, name in enumerate(h.names):
        if h.is_end_site[j]:
            parent = h.names[h.parents[j]]
            if parent.endswith("_toe"):  # a toe nub pointing into the ground instead
                add(
                    rename[parent] + "_Nub",
                    rename[parent],
                    np.asarray(nub) * CM,
                    np.zeros((f, 6)),
                )
            else:
                add(rename[parent] + "_End", rename[parent], h.offsets[j] * CM)
            continue
        ch = h.channels[j]
        vals = np.zeros((f, 6))
        cols = {c: starts[j] + k for k, c in enumerate(ch)}
        for k, c in enumerate(("Xposition", "Yposition", "Zposition")):
            vals[:, k] = h.frames[:, cols[c]] * CM if c in cols else h.offsets[j, k] * CM
        for k, c in enumerate(("Zrotation", "Xrotation", "Yrotation")):
            vals[:, 3 + k] = h.frames[:, cols[c]]
        parent = "Rig_Root" if h.parents[j] < 0 else rename[h.names[h.parents[j]]]
        add(rename[name], parent, h.offsets[j] * CM, vals)
        u = CM / 100.0  # helper sizes below are in cm
        if name == "pelvis":  # a sided helper chain longer than a leg
            prev = "Hips_jnt"
            for k in range(1, 6):
                add(f"L_TailHelper0{k}", prev, [-15.0 * u, 3.0 * u, 0.0], np.zeros((f, 6)))
                prev = f"L_TailHelper0{k}"
            add(prev + "_End", prev, [-15.0 * u, 0.0, 0.0])
        if name.endswith("f_shoulder"):
            side = name[0].upper()
            add(f"{side}_Armor01", rename[name], [0.0, 5.0 * u, 5.0 * u], np.zeros((f, 6)))
            add(f"{side}_Armor01_End", f"{side}_Armor01", [0.0, 5.0 * u, 0.0])

    kids: dict[str | None, list[dict]] = {}
    for n in nodes:
        kids.setdefault(n["parent"], []).append(n)
    lines, columns = ["HIERARCHY"], []

    def emit(n, depth):
        pad = "  " * depth
        if n["values"] is None:
            lines.append(f"{pad}End Site")
            lines.append(f"{pad}{{")
            lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in n["offset"]))
            lines.append(f"{pad}}}")
            return
        lines.append(f"{pad}{'ROOT' if n['parent'] is None else 'JOINT'} {n['name']}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in n["offset"]))
        lines.append(
            f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
        )
        columns.append(n["values"])
        for c in kids.get(n["name"], []):
            emit(c, depth + 1)
        lines.append(f"{pad}}}")

    emit(kids[None][0], 0)
    data = np.concatenate(columns, axis=1)
    if anonymous:
        count = iter(range(len(lines)))
        lines = [
            re.sub(r"^(\s*(?:ROOT|JOINT)) .*$", lambda m: f"{m.group(1)} J{next(count):03d}", ln)
            for ln in lines
        ]
    lines += ["MOTION", f"Frames: {f}", f"Frame Time: {1.0 / motion.fps:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in data]
    return parse_bvh("\n".join(lines) + "\n", source="foreign_rig.bvh")


#: File axes of habitsim's forward, left and up in a y-up rig (forward +z, left +x, up +y,
#: as the Labrador's capture) and in a Blender-like z-up rig (forward -y, left +x, up +z).
Y_UP = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]).T
BLENDER_Z_UP = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T


def _posed_rig(
    motion, nodes, axes, unit: float, source: str, in_place: bool = False, shape=(1.0, 1.0)
) -> BVHData:
    """A rig of any hierarchy posed by a habitsim motion, every joint with 6 channels.

    ``nodes``: ``(name, parent, follow, mode)`` in file order, parents first. ``follow``
    is a habitsim joint whose world frame the joint takes, a pair ``(a, b)`` of joints
    whose midpoint it sits at (with ``a``'s frame), or None (the world origin). ``mode``:
    ``"anim"`` follows every frame, ``"static"`` keeps its frame-0 pose relative to its
    parent, ``"point"`` follows the position only (an IK target), ``("lift", d)`` follows
    raised by ``d`` metres (a display copy off the ground). A node named ``"End"`` is an
    End Site whose ``follow`` is its offset in metres along the parent's habitsim axes.
    ``axes``: (3, 3) matrix taking habitsim (forward, left, up) vectors to file axes;
    ``unit``: metres per file unit; ``in_place``: the pelvis's travel over the ground
    taken out (a game loop's root motion stripped); ``shape``: every position stretched
    by these factors along habitsim's forward and up (a stylised body: ``(1.6, 0.4)`` is
    long and low on short legs; the joints' translation channels take it).
    """
    from habitsim.rotations import matrix_to_quat, quat_to_euler
    from habitsim.skeleton import JOINT_NAMES, fk

    pos_h, rot_h = fk(motion.skeleton, motion.root_positions, motion.rotations, True)
    if in_place:
        travel = motion.root_positions - motion.root_positions[0]
        travel[:, 2] = 0.0
        pos_h = pos_h - travel[:, None]
    pos_h = pos_h * np.array([shape[0], 1.0, shape[1]])
    idx = {n: i for i, n in enumerate(JOINT_NAMES)}
    f = motion.num_frames
    frame: dict[str, tuple[np.ndarray, np.ndarray]] = {}  # name -> (G (F,3,3), P (F,3)) file
    local: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    ends: list[tuple[str, str, np.ndarray]] = []
    for name, parent, follow, mode in nodes:
        if name == "End":
            ends.append((name, parent, axes @ np.asarray(follow, float) / unit))
            continue
        if follow is None:
            g, p = np.broadcast_to(np.eye(3), (f, 3, 3)).copy(), np.zeros((f, 3))
        else:
            a, b = (follow, follow) if isinstance(follow, str) else follow
            g = axes @ rot_h[:, idx[a]] @ axes.T
            p = 0.5 * (pos_h[:, idx[a]] + pos_h[:, idx[b]]) @ axes.T / unit
        if mode == "point":
            g = np.broadcast_to(np.eye(3), (f, 3, 3)).copy()
        if isinstance(mode, tuple) and mode[0] == "lift":
            p = p + axes @ np.array([0.0, 0.0, mode[1]]) / unit
        if parent is None:
            gl, tl = g, p
        else:
            gp, pp = frame[parent]
            gl = np.swapaxes(gp, -1, -2) @ g
            tl = np.einsum("fba,fb->fa", gp, p - pp)
        if mode == "static":
            gl = np.broadcast_to(gl[0], gl.shape).copy()
            tl = np.broadcast_to(tl[0], tl.shape).copy()
            g = gl if parent is None else frame[parent][0] @ gl
            p = (
                tl
                if parent is None
                else frame[parent][1] + np.einsum("fab,fb->fa", frame[parent][0], tl)
            )
        frame[name], local[name] = (g, p), (gl, tl)

    kids: dict[str | None, list[str]] = {}
    for name, parent, _, _ in nodes:
        if name != "End":
            kids.setdefault(parent, []).append(name)
    end_of = {parent: off for _, parent, off in ends}
    lines, columns = ["HIERARCHY"], []

    def emit(name: str, depth: int) -> None:
        pad = "  " * depth
        gl, tl = local[name]
        lines.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in tl[0]))
        lines.append(
            f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
        )
        eul = np.degrees(quat_to_euler(matrix_to_quat(gl), "ZXY"))
        columns.append(np.concatenate([tl, eul], axis=1))
        for c in kids.get(name, []):
            emit(c, depth + 1)
        if name in end_of:
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET " + " ".join(f"{v:.6f}" for v in end_of[name]))
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    emit(kids[None][0], 0)
    data = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {f}", f"Frame Time: {1.0 / motion.fps:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in data]
    return parse_bvh("\n".join(lines) + "\n", source=source)


_TOE_TIP = (0.03, 0.0, 0.0)


def pet_rig(
    motion,
    deforming: bool = True,
    floating: bool = True,
    skull: bool = True,
    in_place: bool = False,
    shape=(1.0, 1.0),
) -> BVHData:
    """A stylised pet's rig (y up, cm): the rig roots at the chest, so the hind legs hang
    deeper than the fore legs; both leg pairs are named ``*Leg*`` (no fore/hind cue); the
    animated hind legs are ``L_legIK_1…4``, beside a static deforming copy ``L_leg_1…4``
    (``deforming``), an animated display copy lifted off the ground ``L_legIKshow_1…4``
    (``floating``), a static pole and an animated IK target; the fore legs carry twist
    bones; the head chain is named ``Pet_Tail_F_*`` and carries ears and a jaw, and the
    tail is named ``Pet_Head_B_*``. Without ``skull`` the head has no jaw and no ears;
    ``in_place`` strips the root's travel; ``shape`` stretches the body (see
    :func:`_posed_rig`).

    :data:`PET_EXPECTED` is the mapping it should get.
    """
    nodes: list = [
        ("Pet_Root", None, None, "static"),
        ("Pet_Body", "Pet_Root", "spine3", "anim"),
        ("Pet_Back", "Pet_Body", "spine2", "anim"),
        ("Pet_Back1", "Pet_Back", "spine1", "anim"),
        ("Pet_Hip", "Pet_Back1", "pelvis", "anim"),
        ("Pet_Head_B_1", "Pet_Hip", "tail1", "anim"),
        ("Pet_Head_B_2", "Pet_Head_B_1", "tail2", "anim"),
        ("Pet_Head_B_3", "Pet_Head_B_2", "tail3", "anim"),
        ("End", "Pet_Head_B_3", (0.05, 0.0, 0.0), None),
        ("Pet_Tail_F_1", "Pet_Body", "neck", "anim"),
        ("Pet_Tail_F_2", "Pet_Tail_F_1", "head", "anim"),
        ("Pet_Tail_F_Nose", "Pet_Tail_F_2", "snout", "anim"),
        ("End", "Pet_Tail_F_Nose", (0.02, 0.0, 0.0), None),
    ]
    if skull:
        nodes += [
            ("Pet_Jaw", "Pet_Tail_F_2", ("head", "snout"), "anim"),
            ("End", "Pet_Jaw", (0.05, 0.0, -0.02), None),
        ]
    for s, S in (("l", "L"), ("r", "R")):
        if skull:
            nodes += [
                (f"Pet_Ear.{S}", "Pet_Tail_F_2", "head", "anim"),
                ("End", f"Pet_Ear.{S}", (0.0, 0.03 if s == "l" else -0.03, 0.06), None),
            ]
        segs = ("scapula", "shoulder", "elbow", "wrist", "toe")
        prev = "Pet_Body"
        for k, seg in enumerate(segs):
            nodes.append((f"{S}_Leg_A_{k}", prev, f"{s}f_{seg}", "anim"))
            prev = f"{S}_Leg_A_{k}"
        nodes.append(("End", prev, _TOE_TIP, None))
        nodes.append(
            (f"{S}_Leg_A_1_twist", f"{S}_Leg_A_1", (f"{s}f_shoulder", f"{s}f_elbow"), "anim")
        )
        copies = [("legIKshow", ("lift", 0.35))] if floating else []
        copies += [("legIK", "anim")]
        if deforming:
            copies.append(("leg", "static"))
        for stem, mode in copies:
            prev = "Pet_Hip"
            for k, seg in enumerate(("hip", "knee", "hock", "toe"), start=1):
                nodes.append((f"{S}_{stem}_{k}", prev, f"{s}h_{seg}", mode))
                prev = f"{S}_{stem}_{k}"
            nodes.append(("End", prev, _TOE_TIP, None))
        nodes += [
            (f"{S}_legIK_pole", "Pet_Hip", f"{s}h_knee", "static"),
            (f"{S}_legIK_target", "Pet_Root", f"{s}h_toe", "point"),
        ]
    return _posed_rig(motion, nodes, Y_UP, 0.01, "pet_rig.bvh", in_place, shape)


PET_EXPECTED = {
    "pelvis": "Pet_Hip",
    "spine3": "Pet_Body",
    "neck": "Pet_Tail_F_1",
    "head": "Pet_Tail_F_2",
    "tail1": "Pet_Head_B_1",
    **{
        f"{s}f_{seg}": f"{S}_Leg_A_{k}"
        for s, S in (("l", "L"), ("r", "R"))
        for k, seg in enumerate(("scapula", "shoulder", "elbow", "wrist", "toe"))
    },
    **{
        f"{s}h_{seg}": f"{S}_legIK_{k}"
        for s, S in (("l", "L"), ("r", "R"))
        for k, seg in enumerate(("hip", "knee", "hock", "toe"), start=1)
    },
}


def blender_rig(motion) -> BVHData:
    """A Blender-like rig (z up, metres, forward -y): deforming ``DEF-`` chains with twist
    segments in series, an animated ``MCH-…_ik`` copy of each hind leg, static ``ORG-``
    copies, IK targets and poles, a ``CTRL_`` root control. :data:`BLENDER_EXPECTED` is
    the mapping it should get."""
    nodes: list = [
        ("root", None, None, "static"),
        ("CTRL_torso", "root", "pelvis", "anim"),
        ("DEF-spine", "CTRL_torso", "pelvis", "anim"),
        ("DEF-spine.001", "DEF-spine", "spine1", "anim"),
        ("DEF-spine.002", "DEF-spine.001", "spine2", "anim"),
        ("DEF-spine.003", "DEF-spine.002", "spine3", "anim"),
        ("DEF-neck", "DEF-spine.003", "neck", "anim"),
        ("DEF-head", "DEF-neck", "head", "anim"),
        ("End", "DEF-head", (0.12, 0.0, 0.0), None),
        ("DEF-jaw", "DEF-head", ("head", "snout"), "anim"),
        ("End", "DEF-jaw", (0.05, 0.0, -0.02), None),
        ("DEF-tail.001", "DEF-spine", "tail1", "anim"),
        ("DEF-tail.002", "DEF-tail.001", "tail2", "anim"),
        ("DEF-tail.003", "DEF-tail.002", "tail3", "anim"),
        ("End", "DEF-tail.003", (0.05, 0.0, 0.0), None),
    ]
    for s, S in (("l", "L"), ("r", "R")):
        fore = (
            ("DEF-shoulder", f"{s}f_scapula"),
            ("DEF-upper_arm", f"{s}f_shoulder"),
            ("DEF-upper_arm_twist", (f"{s}f_shoulder", f"{s}f_elbow")),
            ("DEF-forearm", f"{s}f_elbow"),
            ("DEF-hand", f"{s}f_wrist"),
            ("DEF-fingers", f"{s}f_toe"),
        )
        prev = "DEF-spine.003"
        for stem, follow in fore:
            nodes.append((f"{stem}.{S}", prev, follow, "anim"))
            prev = f"{stem}.{S}"
        nodes.append(("End", prev, _TOE_TIP, None))
        hind = (
            ("thigh", f"{s}h_hip"),
            ("thigh_twist", (f"{s}h_hip", f"{s}h_knee")),
            ("shin", f"{s}h_knee"),
            ("foot", f"{s}h_hock"),
            ("toe", f"{s}h_toe"),
        )
        for layer, parent, mode, suffix in (
            ("DEF", "DEF-spine", "anim", ""),
            ("ORG", "CTRL_torso", "static", ""),
            ("MCH", "CTRL_torso", "anim", "_ik"),
        ):
            prev = parent
            for stem, follow in hind:
                if layer != "DEF" and "twist" in stem:
                    continue
                nodes.append((f"{layer}-{stem}{suffix}.{S}", prev, follow, mode))
                prev = f"{layer}-{stem}{suffix}.{S}"
            nodes.append(("End", prev, _TOE_TIP, None))
        nodes += [
            (f"foot_ik.{S}", "root", f"{s}h_hock", "point"),
            (f"thigh_ik_target.{S}", "root", f"{s}h_knee", "static"),
            (f"hand_ik.{S}", "root", f"{s}f_wrist", "point"),
        ]
    return _posed_rig(motion, nodes, BLENDER_Z_UP, 1.0, "blender_rig.bvh")


BLENDER_EXPECTED = {
    "pelvis": "DEF-spine",
    "spine1": "DEF-spine.001",
    "spine3": "DEF-spine.003",
    "neck": "DEF-neck",
    "head": "DEF-head",
    "tail1": "DEF-tail.001",
    **{
        f"{s}f_{seg}": f"{stem}.{S}"
        for s, S in (("l", "L"), ("r", "R"))
        for seg, stem in (
            ("scapula", "DEF-shoulder"),
            ("shoulder", "DEF-upper_arm"),
            ("elbow", "DEF-forearm"),
            ("wrist", "DEF-hand"),
            ("toe", "DEF-fingers"),
        )
    },
    **{
        f"{s}h_{seg}": f"DEF-{stem}.{S}"
        for s, S in (("l", "L"), ("r", "R"))
        for seg, stem in (("hip", "thigh"), ("knee", "shin"), ("hock", "foot"), ("toe", "toe"))
    },
}


def user_dog(folder: Path, name: str = "mydog", seed: int = 3, scale: float = 1.0) -> Path:
    """A user species ``name`` made by ``species from-clip`` from a synthetic dog walk
    written as a foreign rig (its lengths times ``scale``) into ``folder``; returns its
    user catalog ``folder / "catalog"`` (point ``$HABITSIM_SPECIES_PATH`` at it)."""
    import habitsim
    from habitsim.fromclip.make import species_from_clip
    from habitsim.source import SourceOptions

    walk = habitsim.generate("dog", "walk", seed=seed, duration_s=2.0)
    rig = folder / f"{name}_walk.bvh"
    rig.write_text(_foreign_rig(walk, CM=CM * scale).to_text(), encoding="utf-8")
    catalog = folder / "catalog"
    species_from_clip(rig, name, catalog=catalog, source=SourceOptions(units="cm"))
    return catalog
