"""A foreign rig written from a synthetic dog walk whose stance is known: other joint names,
6-channel joints, centimetres, z up, an extra root, and the helpers a motion-capture rig
carries."""

from __future__ import annotations

import re

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
