"""Structure-aware mutation families of the fuzzing campaign: glTF documents and
buffers, JSON and TOML documents out of bounds, motion metadata of the wrong types.

Each family has a generator (``make_*``: a seeded :class:`random.Random` → the input)
and a runner (``run_*``: read the input the way a user's file is read); the campaign
(:mod:`fuzzing.campaign`) counts how each run ends.
"""

from __future__ import annotations

import contextlib
import copy
import json
import random
import re
import struct
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

#: Hostile values for a glTF field (an index, count, offset, stride, type, vector).
GLTF_VALUES: list[Any] = [
    None,
    -1,
    -8,
    0,
    1,
    3,
    7,
    255,
    2**31,
    2**64,
    "BIG",  # an integer of 5,000 digits (written into the JSON text)
    1.5,
    float("nan"),
    "x",
    "",
    [],
    {},
    True,
    [1.0, 0.0],
    [1e308] * 16,
    list(range(17)),
    5130,
    "MAT4",
    "SCALAR",
]
#: The fields the mutations aim at, by array of the document.
GLTF_FIELDS: dict[str, list[str]] = {
    "buffers": ["byteLength", "uri"],
    "bufferViews": ["buffer", "byteOffset", "byteLength", "byteStride"],
    "accessors": ["bufferView", "byteOffset", "componentType", "count", "type", "normalized"],
    "nodes": ["children", "matrix", "translation", "rotation", "scale", "name"],
    "skins": ["joints", "skeleton"],
}
#: Buffer URIs that must never be read.
HOSTILE_URIS = [
    "../../../../etc/passwd",
    "/etc/hostname",
    "file:///etc/hostname",
    "%2e%2e/%2e%2e/etc/hostname",
    "sub/../../x.bin",
    "C:\\Windows\\win.ini",
    "data:application/octet-stream;base64,@@@",
    "data:text/plain,abc",
    "link.bin",  # a symbolic link out of the folder
    "missing.bin",
    "",
]
_BIG_INT = "9" * 5000


def preload() -> None:
    """Import what the runners use (torch among them) in the campaign's own process, so
    a forked child's memory limit counts the input's work, not the libraries' loading."""
    import habitsim.bvh_mapping
    import habitsim.captions.store
    import habitsim.cli
    import habitsim.dataset
    import habitsim.evaluation.evaluator
    import habitsim.evaluation.tables
    import habitsim.gltf
    import habitsim.models.checkpoint  # noqa: F401


def gltf_seed() -> tuple[dict[str, Any], bytes]:
    """The shipped Fox's JSON document and BIN chunk."""
    raw = (resources.files("habitsim.examples") / "Fox.glb").read_bytes()
    n_json = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20 : 20 + n_json])
    n_bin = struct.unpack_from("<I", raw, 20 + n_json)[0]
    blob = raw[28 + n_json : 28 + n_json + n_bin]
    return doc, blob


_DEEP = re.compile(r'"DEEP:(\\d+):([lo])"')


def _deep(n: int, kind: str) -> str:
    """A marker :func:`_dump` writes as ``n`` nested lists or objects (built as text:
    the encoder itself would recurse)."""
    return f"DEEP:{n}:{kind}"


def _dump(doc: Any) -> bytes:
    text = json.dumps(doc).replace('"BIG"', _BIG_INT)
    text = _DEEP.sub(
        lambda m: (
            "[" * int(m[1]) + "0" + "]" * int(m[1])
            if m[2] == "l"
            else '{"a":' * int(m[1]) + "0" + "}" * int(m[1])
        ),
        text,
    )
    return text.encode()


def write_glb(path: Path, doc: dict[str, Any], blob: bytes) -> None:
    js = _dump(doc)
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(blob), b"BIN\0")
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body) + len(blob)) + body + blob)


def _time_accessors(doc: dict[str, Any]) -> list[int]:
    """The key-time accessors of the document that earlier mutations left readable."""
    accs, views = doc.get("accessors") or [], doc.get("bufferViews") or []
    out = set()
    for a in doc.get("animations") or []:
        for s in a.get("samplers") or []:
            i = s.get("input") if isinstance(s, dict) else None
            if type(i) is int and 0 <= i < len(accs):
                acc = accs[i]
                v, n = acc.get("bufferView"), acc.get("count")
                if type(v) is int and 0 <= v < len(views) and type(n) is int and n > 0:
                    if all(type(x.get("byteOffset", 0)) is int for x in (acc, views[v])):
                        out.add(i)
    return sorted(out)


def make_gltf(ws: Any, rnd: random.Random) -> tuple[Path, Any, float]:
    """A mutated Fox (GLB or .gltf + buffer file), the animation asked and the fps."""
    doc = copy.deepcopy(ws.gltf_doc)
    blob = bytearray(ws.gltf_blob)
    as_gltf = rnd.random() < 0.3
    folder = ws.path("")
    folder.mkdir(parents=True)
    for _ in range(rnd.randint(1, 3)):
        # (a mutation that meets an earlier one's wreckage is skipped)
        with contextlib.suppress(TypeError, AttributeError, KeyError, IndexError, ValueError):
            op = rnd.randrange(8)
            if op <= 2:  # a field of an entry set to a hostile value
                array = rnd.choice(list(GLTF_FIELDS))
                if doc.get(array):
                    entry = rnd.choice(doc[array])
                    entry[rnd.choice(GLTF_FIELDS[array])] = rnd.choice(GLTF_VALUES)
            elif op == 3 and doc.get("animations"):  # an animation's sampler or channel
                a = rnd.choice(doc["animations"])
                if rnd.random() < 0.5 and a["samplers"]:
                    s = rnd.choice(a["samplers"])
                    s[rnd.choice(["input", "output", "interpolation"])] = rnd.choice(GLTF_VALUES)
                elif a["channels"]:
                    c = rnd.choice(a["channels"])
                    if rnd.random() < 0.5:
                        c["sampler"] = rnd.choice(GLTF_VALUES)
                    else:
                        c["target"][rnd.choice(["node", "path"])] = rnd.choice(GLTF_VALUES)
            elif op == 4 and _time_accessors(doc):  # key times: huge, negative, non-finite
                acc = doc["accessors"][rnd.choice(_time_accessors(doc))]
                view = doc["bufferViews"][acc["bufferView"]]
                off = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
                k = rnd.randrange(acc["count"])
                v = rnd.choice([1e6, 1e9, 3e38, -1e6, float("nan"), float("inf"), 0.0])
                if 0 <= off + 4 * k <= len(blob) - 4:
                    struct.pack_into("<f", blob, off + 4 * k, v)
                acc.pop("max", None)
            elif op == 5 and all(isinstance(n, dict) for n in doc.get("nodes") or [None]):
                # node hierarchy: a cycle, a second parent, a long chain
                nodes = doc["nodes"]
                kind = rnd.randrange(3)
                if kind == 0:
                    i = rnd.randrange(len(nodes))
                    nodes[i].setdefault("children", []).append(i)
                elif kind == 1:
                    i, j = rnd.randrange(len(nodes)), rnd.randrange(len(nodes))
                    nodes[i].setdefault("children", []).append(j)
                else:
                    n0, length = len(nodes), rnd.choice([1000, 20_000])
                    nodes[-1].setdefault("children", []).append(n0)
                    for k in range(length):
                        nodes.append({"children": [n0 + k + 1]} if k + 1 < length else {})
                    doc["skins"][0]["joints"] = doc["skins"][0]["joints"] + list(
                        range(n0, n0 + length)
                    )
            elif op == 6:  # deep or big JSON somewhere
                doc["extras"] = rnd.choice([_deep(rnd.choice([70, 5000]), "l"), "BIG"])
            else:  # the container cut or flipped (after writing)
                doc["__cut__"] = rnd.choice(["cut", "flip"])
    cut = doc.pop("__cut__", None)
    if as_gltf:
        bin_name = "data.bin"
        (folder / bin_name).write_bytes(bytes(blob))
        (folder / "link.bin").symlink_to("/etc/hostname")
        if doc.get("buffers"):
            uri = rnd.choice([bin_name] * 3 + HOSTILE_URIS)
            doc["buffers"][0]["uri"] = uri
        path = folder / "rig.gltf"
        path.write_bytes(_dump(doc))
    else:
        path = folder / "rig.glb"
        write_glb(path, doc, bytes(blob))
    if cut is not None:
        raw = bytearray(path.read_bytes())
        if cut == "cut":
            raw = raw[: rnd.randrange(len(raw))]
        else:
            for _ in range(rnd.randint(1, 10)):
                raw[rnd.randrange(len(raw))] = rnd.randrange(256)
        path.write_bytes(bytes(raw))
    animation = rnd.choice([None, 0, 1, 2, "Walk", "Survey", -1, 99, "nope"])
    fps = rnd.choice([30.0, 30.0, 1e-3, 1e4, 240.0])
    return path, animation, fps


def run_gltf(ws: Any, case: Any) -> None:
    from habitsim.gltf import list_gltf_animations, read_gltf

    path, animation, fps = case.data
    list_gltf_animations(path)
    bvh = read_gltf(path, animation, fps)
    if len(path.name) % 5 == 0:  # sometimes imported all the way (rig.gltf)
        from habitsim.bvh_mapping import import_bvh

        import_bvh(bvh, "dog", plant=False)


# ---------------------------------------------------------------------- JSON / TOML


#: The JSON and TOML readers a document is fed to.
DOC_READERS = ["map_json", "map_toml", "manifest", "checkpoint", "evaluator", "captions", "rows"]
_MAP = {"extends": "auto", "units": "cm", "map": {"pelvis": "Hips", "lh_hip": None}}


def _hostile_json(rnd: random.Random) -> Any:
    kind = rnd.randrange(6)
    if kind == 0:
        return _deep(rnd.choice([10, 63, 64, 65, 1000, 100_000]), rnd.choice("lo"))
    if kind == 1:
        return "BIG"
    if kind == 2:
        return -(10 ** rnd.choice([19, 39, 40, 41, 300]))
    if kind == 3:
        return "x" * rnd.choice([10, 100_000])
    if kind == 4:
        return rnd.choice([None, True, 1.5, float("inf"), [], {}, "[[[[", '{"a":'])
    return {str(i): i for i in range(rnd.choice([1, 1000]))}


def _toml_text(rnd: random.Random) -> str:
    kind = rnd.randrange(5)
    n = rnd.choice([10, 64, 65, 999, 5000])
    if kind == 0:
        return "map = " + "[" * n + "]" * n + "\n"
    if kind == 1:
        return "map = " + "{a = " * n + "1" + "}" * n + "\n"
    if kind == 2:
        return "[" + ".".join(["map"] * n) + "]\npelvis = 'Hips'\n"
    if kind == 3:
        return f"[map]\npelvis = {rnd.choice(['9' * 5000, '9' * 50, '1e999', 'nan'])}\n"
    return "[map]\npelvis = 'Hips'\n" + rnd.choice(["a = [", "= 1", "[[map]]", "\x00"])


def _mutated_json(base: Any, rnd: random.Random) -> Any:
    doc = copy.deepcopy(base)
    if not isinstance(doc, dict) or rnd.random() < 0.1:
        return _hostile_json(rnd)
    for _ in range(rnd.randint(1, 2)):
        keys = list(doc)
        if keys and rnd.random() < 0.7:
            key = rnd.choice(keys)
            if isinstance(doc[key], dict) and doc[key] and rnd.random() < 0.5:
                sub = doc[key]
                sub[rnd.choice(list(sub))] = _hostile_json(rnd)
            else:
                doc[key] = _hostile_json(rnd)
        else:
            doc["extra"] = _hostile_json(rnd)
    return doc


def make_doc(ws: Any, rnd: random.Random) -> tuple[str, Path]:
    """A JSON or TOML document out of bounds, written where its reader looks for it."""
    reader = rnd.choice(DOC_READERS)
    folder = ws.path("")
    folder.mkdir(parents=True)
    if reader == "map_toml":
        path = folder / "map.toml"
        path.write_text(_toml_text(rnd), encoding="utf-8")
        return reader, path
    base = {
        "map_json": _MAP,
        "manifest": ws.manifest_seed,
        "checkpoint": {"format": "habitsim.models.checkpoint", "format_version": 1, "files": {}},
        "evaluator": {"kind": "habitsim.evaluator", "format_version": 1},
        "captions": {"kind": "habitsim.captions", "format": 1, "captions": []},
        "rows": {"key": "r", "status": "ok", "features": [1.0, 2.0]},
    }[reader]
    name = {
        "map_json": "map.json",
        "manifest": "manifest.json",
        "checkpoint": "config.json",
        "evaluator": "config.json",
        "captions": "captions.json",
        "rows": "rows/r.json",
    }[reader]
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(_dump(_mutated_json(base, rnd)))
    return reader, path


def run_doc(ws: Any, case: Any) -> None:
    reader, path = case.data
    if reader in ("map_json", "map_toml"):
        from habitsim.bvh_mapping import load_joint_map

        load_joint_map(path)
    elif reader == "manifest":
        from habitsim.dataset import load_manifest

        load_manifest(path.parent, check_files=False)
    elif reader == "checkpoint":
        from habitsim.models.checkpoint import load_checkpoint

        load_checkpoint(path.parent)
    elif reader == "evaluator":
        from habitsim.evaluation.evaluator import load_evaluator

        load_evaluator(path.parent)
    elif reader == "captions":
        from habitsim.captions.store import load_captions

        load_captions(path)
    else:
        from habitsim.evaluation.tables import load_rows

        load_rows(path.parent.parent)


# ---------------------------------------------------------------------- npz metadata


def make_npz_meta(ws: Any, rnd: random.Random) -> Path:
    """The seed motion with ``metadata_json`` fields of the wrong types, deep or big."""
    from habitsim.motion import METADATA_FIELD_KINDS

    arrays = dict(ws.npz_seed)
    meta = json.loads(str(arrays["metadata_json"][()]))
    for _ in range(rnd.randint(1, 3)):
        key = rnd.choice([*METADATA_FIELD_KINDS, "extra"])
        meta[key] = rnd.choice(
            [_hostile_json(rnd), "30", 30, 30.5, None, [30], {"a": 1}, "BIG", float("nan")]
        )
    arrays["metadata_json"] = np.array(_dump(meta).decode())
    p = ws.path(".npz")
    p.parent.mkdir(parents=True, exist_ok=True)
    with p.open("wb") as fh:
        np.savez_compressed(fh, **arrays)
    return p


def run_npz_meta(ws: Any, case: Any) -> None:
    from habitsim.motion import load_motion

    m = load_motion(case.data)
    m.mirrored().features()
