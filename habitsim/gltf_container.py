"""The glTF 2.0 container read within bounds: the GLB chunks, the JSON document, its
buffers and accessors (:mod:`habitsim.gltf` builds joints and animations on it).

pygltflib holds the document (its dataclasses), but its loaders parse the JSON without
bounds and read any buffer URI, ``../../etc/passwd`` or ``/etc/hostname`` included. So
the file is read here: the GLB header and chunks are checked against the file's size,
the JSON goes through :func:`habitsim.jsonfile.loads_json`, every field the reader uses
is type-checked on the raw JSON (indices in range, counts, offsets and lengths
non-negative, strides and component types valid, vectors of the right length and
finite) before pygltflib sees it, and a buffer's URI is either a ``data:`` URI or a
relative path that stays inside the glTF file's folder (no absolute path, no ``..``, no
symbolic link out of it). Every accessor is bounds-checked against the bytes its buffer
holds before a view is made. Failures are :class:`~habitsim.errors.GLTFError` naming the
file and the field, never quoting the content of a file read or refused.
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
import math
import re
import struct
import urllib.parse
import warnings
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any, NoReturn

import numpy as np
import pygltflib

from .errors import GLTFError, brief, brief_path
from .jsonfile import DocumentLimits, loads_json, read_bounded

__all__ = ["GLTFReadOptions", "GLTFFile"]


@dataclass(frozen=True)
class GLTFReadOptions:
    """Limits of a glTF / GLB read (docs/formats.md says why).

    Attributes:
        max_file_bytes: largest ``.glb`` / ``.gltf`` file and largest external buffer
            [bytes] (512 MiB).
        max_json_bytes: largest JSON document [bytes] (32 MiB; a rig's is a few hundred
            kB).
        max_nodes: most nodes in the document.
        max_other_objects: most entries of the arrays the reader does not use (meshes,
            materials, images, …), which pygltflib decodes at ~1 ms each.
        max_samples: most frames × sampled nodes of one read (the clip resampled at
            ``fps``: 1,000,000 is e.g. a 60-joint rig for 9 minutes at 30 Hz, ~300 MB of
            arrays); also the most values of an accessor without a buffer view.
    """

    max_file_bytes: int = 512 << 20
    max_json_bytes: int = 32 << 20
    max_nodes: int = 100_000
    max_samples: int = 1_000_000
    max_other_objects: int = 5_000


_DTYPES: dict[int, np.dtype] = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}
_NORM_DIV = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: GLB header and chunk types (glTF 2.0 spec, "GLB File Format Specification").
_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942
_MAX_STRIDE = 252
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


# ---------------------------------------------------------------------- raw JSON checks


def _shown(v: Any) -> str:
    """A field's value for a message: a number as it is, anything else by its type only
    (a message never quotes the file's text)."""
    if isinstance(v, int | float) and not isinstance(v, bool):
        return brief(v, 40)
    return f"a {type(v).__name__}"


class _Checker:
    """Type checks of the raw glTF JSON, raising :class:`GLTFError` with the field's
    JSON path."""

    def __init__(self, source: str, doc: dict[str, Any], max_nodes: int):
        self.source = source
        self.doc = doc
        self.counts: dict[str, int] = {}
        for key in ("buffers", "bufferViews", "accessors", "nodes", "skins", "animations"):
            v = doc.get(key)
            if v is None:
                doc.pop(key, None)
                self.counts[key] = 0
                continue
            if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
                self.fail(key, "must be a list of objects")
            self.counts[key] = len(v)
        if self.counts["nodes"] > max_nodes:
            self.fail("nodes", f"{self.counts['nodes']} nodes; valid: at most {max_nodes}")

    def fail(self, where: str, msg: str) -> NoReturn:
        raise GLTFError(f"{self.source}: {where} {msg}")

    def int_(
        self,
        obj: dict[str, Any],
        key: str,
        where: str,
        lo: int = 0,
        hi: int | None = None,
        required: bool = False,
    ) -> None:
        v = obj.get(key)
        if v is None:
            obj.pop(key, None)
            if required:
                self.fail(f"{where}.{key}", "is missing; valid: an integer")
            return
        if isinstance(v, bool) or not isinstance(v, int) or v < lo or (hi is not None and v > hi):
            rng = f"{lo} to {hi}" if hi is not None else f"≥ {lo}"
            self.fail(f"{where}.{key}", f"is {_shown(v)}; valid: an integer {rng}")

    def index(self, obj: dict[str, Any], key: str, where: str, of: str, required: bool) -> None:
        n = self.counts[of]
        if n == 0 and obj.get(key) is not None:
            self.fail(f"{where}.{key}", f"is {_shown(obj[key])}; the file has no {of}")
        self.int_(obj, key, where, 0, n - 1, required)

    def str_(self, obj: dict[str, Any], key: str, where: str, required: bool = False) -> None:
        v = obj.get(key)
        if v is None:
            obj.pop(key, None)
            if required:
                self.fail(f"{where}.{key}", "is missing; valid: a string")
        elif not isinstance(v, str):
            self.fail(f"{where}.{key}", f"is {type(v).__name__}; valid: a string")

    def numbers(self, obj: dict[str, Any], key: str, where: str, n: int) -> None:
        v = obj.get(key)
        if v is None:
            obj.pop(key, None)
            return
        ok = isinstance(v, list) and len(v) == n
        ok = ok and all(
            isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in v
        )
        if not ok:
            self.fail(f"{where}.{key}", f"valid: a list of {n} finite numbers")

    def check(self) -> None:
        d = self.doc
        for i, b in enumerate(d.get("buffers", [])):
            self.str_(b, "uri", f"buffers[{i}]")
            self.int_(b, "byteLength", f"buffers[{i}]", 0, required=True)
        for i, v in enumerate(d.get("bufferViews", [])):
            w = f"bufferViews[{i}]"
            self.index(v, "buffer", w, "buffers", True)
            self.int_(v, "byteOffset", w, 0)
            self.int_(v, "byteLength", w, 1, required=True)
            self.int_(v, "byteStride", w, 1, _MAX_STRIDE)
        for i, a in enumerate(d.get("accessors", [])):
            w = f"accessors[{i}]"
            self.index(a, "bufferView", w, "bufferViews", False)
            self.int_(a, "byteOffset", w, 0)
            self.int_(a, "count", w, 1, required=True)
            self.int_(a, "componentType", w, 0, required=True)
            if a["componentType"] not in _DTYPES:
                self.fail(f"{w}.componentType", f"is {a['componentType']}; valid: {list(_DTYPES)}")
            self.str_(a, "type", w, required=True)
            if a["type"] not in _NCOMP:
                self.fail(f"{w}.type", f"is not one of {', '.join(_NCOMP)}")
            if a.get("normalized") is not None and not isinstance(a["normalized"], bool):
                self.fail(f"{w}.normalized", "valid: true or false")
        for i, n in enumerate(d.get("nodes", [])):
            w = f"nodes[{i}]"
            self.str_(n, "name", w)
            kids = n.get("children")
            if kids is not None:
                if not isinstance(kids, list):
                    self.fail(f"{w}.children", "valid: a list of node indices")
                for k in range(len(kids)):
                    self.index({"c": kids[k]}, "c", f"{w}.children[{k}]", "nodes", True)
            for key, size in (("matrix", 16), ("translation", 3), ("rotation", 4), ("scale", 3)):
                self.numbers(n, key, w, size)
        for i, s in enumerate(d.get("skins", [])):
            w = f"skins[{i}]"
            joints = s.get("joints")
            if not isinstance(joints, list) or not joints:
                self.fail(f"{w}.joints", "valid: a non-empty list of node indices")
            for k in range(len(joints)):
                self.index({"j": joints[k]}, "j", f"{w}.joints[{k}]", "nodes", True)
        for i, a in enumerate(d.get("animations", [])):
            self._animation(a, f"animations[{i}]")

    def _animation(self, a: dict[str, Any], w: str) -> None:
        self.str_(a, "name", w)
        samplers, channels = a.get("samplers"), a.get("channels")
        if not isinstance(samplers, list) or not all(isinstance(s, dict) for s in samplers):
            self.fail(f"{w}.samplers", "valid: a list of objects")
        if not isinstance(channels, list) or not all(isinstance(c, dict) for c in channels):
            self.fail(f"{w}.channels", "valid: a list of objects")
        for k, s in enumerate(samplers):
            self.index(s, "input", f"{w}.samplers[{k}]", "accessors", True)
            self.index(s, "output", f"{w}.samplers[{k}]", "accessors", True)
            self.str_(s, "interpolation", f"{w}.samplers[{k}]")
        for k, c in enumerate(channels):
            cw = f"{w}.channels[{k}]"
            self.int_(c, "sampler", cw, 0, len(samplers) - 1, required=True)
            t = c.get("target")
            if not isinstance(t, dict):
                self.fail(f"{cw}.target", "valid: an object with node and path")
            self.index(t, "node", f"{cw}.target", "nodes", False)
            self.str_(t, "path", f"{cw}.target", required=True)


# ---------------------------------------------------------------------- the file

#: The arrays :class:`_Checker` checks; built straight into pygltflib's dataclasses
#: (their generic decoder costs ~1 ms an object: a 20,000-node file took half a minute).
_CHECKED = ("buffers", "bufferViews", "accessors", "nodes", "skins", "animations")


def _make(cls: type, d: dict[str, Any]) -> Any:
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in d.items() if k in names})


def _fill_checked(doc: pygltflib.GLTF2, raw: dict[str, Any]) -> None:
    """Set the checked arrays of ``doc`` from the raw (checked) JSON."""
    g = pygltflib
    doc.buffers = [_make(g.Buffer, d) for d in raw.get("buffers", [])]
    doc.bufferViews = [_make(g.BufferView, d) for d in raw.get("bufferViews", [])]
    doc.accessors = [_make(g.Accessor, d) for d in raw.get("accessors", [])]
    doc.nodes = [_make(g.Node, d) for d in raw.get("nodes", [])]
    doc.skins = [_make(g.Skin, d) for d in raw.get("skins", [])]
    anims = []
    for a in raw.get("animations", []):
        channels = [
            _make(g.AnimationChannel, {**c, "target": _make(g.AnimationChannelTarget, c["target"])})
            for c in a["channels"]
        ]
        samplers = [_make(g.AnimationSampler, s) for s in a["samplers"]]
        anims.append(_make(g.Animation, {**a, "channels": channels, "samplers": samplers}))
    doc.animations = anims


class GLTFFile:
    """A glTF / GLB file read within :class:`GLTFReadOptions`: the pygltflib document
    (``doc``, every field the reader uses type-checked) and its buffers on demand.

    Raises:
        GLTFError: missing, unreadable, too large, a corrupt GLB container, JSON out of
            bounds, a field of the wrong type or out of range.
    """

    def __init__(self, path: str | Path, options: GLTFReadOptions | None = None):
        self.options = opt = options or GLTFReadOptions()
        p = Path(path)
        self.path = p
        self.source = str(p)
        if not p.exists():
            raise GLTFError(f"{brief_path(p)}: no such glTF file")
        data = read_bounded(p, "glTF file", GLTFError, opt.max_file_bytes)
        self._blob: bytes | None = None
        if data[:4] == _GLB_MAGIC:
            text = self._glb(data)
            kind = "GLB"
        else:
            text, kind = data, "glTF JSON"
        raw = loads_json(
            text,
            f"{brief_path(p)}: not a readable {kind} file",
            error=GLTFError,
            options=DocumentLimits(max_bytes=opt.max_json_bytes),
        )
        if not isinstance(raw, dict):
            raise GLTFError(f"{brief_path(p)}: the {kind} document is not a JSON object")
        _Checker(self.source, raw, opt.max_nodes).check()
        others = sum(len(v) for k, v in raw.items() if k not in _CHECKED and isinstance(v, list))
        if others > opt.max_other_objects:
            raise GLTFError(
                f"{brief_path(p)}: {others} meshes, materials and other objects; valid: at most "
                f"{opt.max_other_objects} (GLTFReadOptions.max_other_objects)"
            )
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                doc = pygltflib.GLTF2.from_dict(
                    {k: v for k, v in raw.items() if k not in _CHECKED}, infer_missing=True
                )
                _fill_checked(doc, raw)
        except Exception as e:  # noqa: BLE001 - the library raises many kinds on bad input
            raise GLTFError(
                f"{brief_path(p)}: not a readable {kind} document ({type(e).__name__} in a "
                "field habitsim does not read)"
            ) from None
        if self._blob is not None:
            doc.set_binary_blob(self._blob)
        self.doc = doc
        self._buffers: dict[int, bytes] = {}

    def _glb(self, data: bytes) -> bytes:
        """The JSON chunk of a GLB file (the BIN chunk is kept in ``_blob``)."""
        view = memoryview(data)
        if len(data) < 20:
            raise self.error("not a readable GLB file (shorter than its header)")
        _, version, length = struct.unpack_from("<4sII", data, 0)
        if version != 2:
            raise self.error(f"not a readable GLB file (GLB version {version}; valid: 2)")
        if length > len(data):
            raise self.error("not a readable GLB file (truncated: its header declares more bytes)")
        pos, chunks = 12, list[tuple[int, memoryview]]()
        while pos + 8 <= length:
            n, kind = struct.unpack_from("<II", data, pos)
            if pos + 8 + n > length:
                raise self.error(
                    f"not a readable GLB file (chunk {len(chunks)} runs past the end of the file)"
                )
            chunks.append((kind, view[pos + 8 : pos + 8 + n]))
            pos += 8 + n
        if not chunks or chunks[0][0] != _CHUNK_JSON:
            raise self.error("not a readable GLB file (its first chunk is not JSON)")
        if len(chunks) > 1 and chunks[1][0] == _CHUNK_BIN:
            self._blob = bytes(chunks[1][1])
        return bytes(chunks[0][1])

    def error(self, msg: str) -> GLTFError:
        return GLTFError(f"{brief_path(self.source)}: {msg}")

    def buffer(self, i: int) -> bytes:
        """The bytes of buffer ``i`` (at least its ``byteLength``)."""
        if i in self._buffers:
            return self._buffers[i]
        if not 0 <= i < len(self.doc.buffers):
            raise self.error(f"buffer {i} does not exist ({len(self.doc.buffers)} buffers)")
        buf = self.doc.buffers[i]
        need = int(buf.byteLength)
        uri = buf.uri
        if uri is None:
            blob = self._blob
            if blob is None or i != 0:
                raise self.error(
                    f"buffers[{i}] has no uri and is not the BIN chunk of a GLB file; valid: "
                    "a data: URI or a file beside the .gltf"
                )
            data = blob
        elif uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if not head.endswith(";base64"):
                raise self.error(f"buffers[{i}].uri: a data URI must be base64-encoded")
            try:
                data = base64.b64decode(payload, validate=True)
            except (binascii.Error, ValueError):
                raise self.error(f"buffers[{i}].uri: not valid base64 data") from None
        else:
            data = self._external(i, uri, need)
        if len(data) < need:
            raise self.error(f"buffers[{i}] is shorter than its byteLength {need} (truncated?)")
        self._buffers[i] = data
        return data

    def _external(self, i: int, uri: str, need: int) -> bytes:
        """The first ``need`` bytes of the file a relative buffer URI names, refused when it
        leaves the glTF file's folder."""
        where = f"buffers[{i}].uri"
        rel = urllib.parse.unquote(uri)
        pp = PurePosixPath(rel)
        if (
            _SCHEME.match(rel)
            or pp.is_absolute()
            or rel.startswith("\\")
            or ".." in pp.parts
            or "\x00" in rel
            or "\\" in rel
        ):
            raise self.error(
                f"{where}: refused; valid: a data: URI or a relative path inside the glTF "
                "file's folder (no absolute path, no '..')"
            )
        if need > self.options.max_file_bytes:
            raise self.error(
                f"buffers[{i}].byteLength {need}; valid: at most {self.options.max_file_bytes}"
            )
        try:
            folder = self.path.parent.resolve()
            target = (self.path.parent / rel).resolve()
            if not target.is_relative_to(folder):
                raise self.error(
                    f"{where}: refused (a link out of the glTF file's folder); valid: a file "
                    "inside it"
                )
            if not target.is_file():
                raise self.error(f"{where}: no such file beside the glTF file")
            with target.open("rb") as fh:
                return fh.read(need)
        except GLTFError:
            raise
        except (OSError, ValueError, RuntimeError) as e:  # RuntimeError: a symlink loop
            reason = getattr(e, "strerror", None) or type(e).__name__
            raise self.error(f"{where}: cannot read ({reason})") from None

    def accessor(self, idx: int | None, what: str) -> np.ndarray:
        """(count, components) float64 values of an accessor (normalized ints scaled)."""
        acc_list = self.doc.accessors
        if idx is None or not 0 <= idx < len(acc_list):
            raise self.error(f"{what}: accessor {idx} does not exist ({len(acc_list)} accessors)")
        acc = acc_list[idx]
        if acc.sparse is not None:
            raise self.error(
                f"{what}: accessor {idx} is sparse; sparse accessors are not supported"
            )
        dtype = _DTYPES[acc.componentType]
        ncomp = _NCOMP[acc.type]
        count = int(acc.count)
        if acc.bufferView is None:
            if count * ncomp > self.options.max_samples:
                raise self.error(
                    f"{what}: accessor {idx} without a buffer view asks for {count} values; "
                    f"valid: at most {self.options.max_samples}"
                )
            return np.zeros((count, ncomp))
        view = self.doc.bufferViews[acc.bufferView]
        data = self.buffer(view.buffer)
        elem = dtype.itemsize * ncomp
        stride = view.byteStride or elem
        if stride < elem:
            raise self.error(
                f"{what}: bufferView {acc.bufferView} has byteStride {stride}, shorter than one "
                f"element of accessor {idx} ({elem} bytes)"
            )
        v_start = int(view.byteOffset or 0)
        v_end = v_start + int(view.byteLength)
        start = v_start + int(acc.byteOffset or 0)
        need = start + (count - 1) * stride + elem
        if v_end > len(data) or need > v_end:
            raise self.error(
                f"{what}: accessor {idx} needs bytes up to {need} of buffer {view.buffer}, "
                f"past the end of its bufferView or buffer (truncated or corrupt buffer?)"
            )
        arr = np.ndarray(
            (count, ncomp), dtype=dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize)
        ).astype(np.float64)
        if acc.normalized and acc.componentType in _NORM_DIV:
            arr = np.maximum(arr / _NORM_DIV[acc.componentType], -1.0)
        if not np.all(np.isfinite(arr)):
            raise self.error(f"{what}: accessor {idx} holds non-finite values")
        return arr

    def data_uri_buffers(self) -> None:
        """Replace every external buffer's URI by a data URI of the bytes read through
        :meth:`buffer` (so a writer never reads a file URI itself)."""
        for i, buf in enumerate(self.doc.buffers):
            if buf.uri is not None and not buf.uri.startswith("data:"):
                data = self.buffer(i)[: int(buf.byteLength)]
                buf.uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode(
                    "ascii"
                )
