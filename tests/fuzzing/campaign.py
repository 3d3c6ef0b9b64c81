"""The fuzzing campaign over habitsim's readers and command line (a developer tool,
not part of the installed package): ``make fuzz`` runs it (``FUZZ_N`` inputs, default
10,000), as does ``python -m fuzzing`` from ``tests/`` (:mod:`fuzzing.__main__`).

Each input is made by mutating a valid one (the shipped example BVH, a generated motion
file, the dog's species file, a small data set's manifest, a well-formed command line)
with a seeded :class:`random.Random`: tokens replaced by hostile values (``1e-320``,
``nan``, ``1e300``, a 100,000-character word, …), lines dropped, doubled or cut, joints
nested a thousand deep, arrays swapped for ones of another dtype or shape, zip archives
truncated or corrupted, JSON values replaced. Every input is then read the way a user's
file would be, and its outcome counted:

* ``ok`` — read (or the command ran) without an error;
* ``typed`` — refused with a :class:`~habitsim.errors.HabitsimError` (for the command
  line: ``error: …`` and exit code 2, or an argparse usage error);
* ``raw`` — any other exception: a bug, shown with its input and traceback;
* ``hang`` — still running after the per-input time limit (:class:`FuzzLimits`), killed;
* ``memory`` — a ``MemoryError`` under the per-input memory limit (4 × the input's size
  + :attr:`FuzzLimits.memory_mb`, as the readers promise in docs/formats.md; an
  address-space limit, not applied to the command-line targets, whose libraries reserve
  address space they never use: their peak memory is reported instead).

Each input runs in a forked child process with those limits (``FuzzLimits.isolate``), so
a hang or a memory blow-up is counted, not suffered; the child's peak memory above the
campaign's own is reported per target.

Families: BVH text, BVH imports, ``.npz`` motions (arrays swapped, zips cut), species
TOML, data-set manifests, command lines, heavy commands on absurd motions, and the
structure-aware ones of :mod:`fuzzing.families`: glTF documents (indices, counts, offsets,
strides, component types, nulls, negative numbers, huge key times, node cycles and long
chains, buffer URIs with ``..`` or absolute paths, cut or flipped containers), JSON and
TOML documents out of bounds (deep, recursive tables, big integers) for every JSON/TOML
reader, and motion metadata of the wrong types.

The same generators drive the hypothesis tests of ``tests/test_fuzz.py`` (there with a
small, bounded number of examples); this module runs the long campaign.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import random
import re
import resource
import select
import shutil
import signal
import sys
import tempfile
import time
import traceback
import warnings
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.errors import HabitsimError

from . import families, wave

__all__ = [
    "TARGETS",
    "Case",
    "Workspace",
    "CampaignResult",
    "FuzzLimits",
    "OUTCOMES",
    "make_case",
    "run_case",
    "campaign",
    "print_campaign",
]

#: Inputs of each kind, in the proportions of a campaign.
TARGETS: dict[str, float] = {
    "bvh": 0.20,
    "bvh_import": 0.06,
    "npz": 0.17,
    "species": 0.10,
    "manifest": 0.07,
    "cli": 0.06,
    "heavy": 0.02,
    "gltf": 0.16,
    "docs": 0.10,
    "npz_meta": 0.06,
    # the newer inputs (fuzzing.wave)
    "t2m": 0.03,
    "fromclip": 0.02,
    "score": 0.02,
    "methods": 0.01,
    "rig": 0.02,
    "loop": 0.02,
}
#: The families of :mod:`fuzzing.wave` run as command lines (the rest call the library).
_WAVE_ARGV = {
    "fromclip": wave.make_fromclip,
    "score": wave.make_score,
    "methods": wave.make_methods,
    "rig": wave.make_rig,
    "loop": wave.make_loop,
}
#: How an input can end (the columns of the table).
OUTCOMES = ("ok", "typed", "raw", "hang", "memory")


@dataclass(frozen=True)
class FuzzLimits:
    """Per-input limits of a campaign.

    Attributes:
        time_s: wall time after which an input counts as ``hang`` [s] (the heavy
            commands' small budgets take a few seconds).
        memory_mb: memory an input may take beyond 4 × its size [MB] (docs/formats.md).
        isolate: run each input in a forked child (False: in this process, without the
            limits; what the hypothesis tests do).
    """

    time_s: float = 120.0
    memory_mb: float = 300.0
    isolate: bool = True


#: Hostile number-like tokens.
NUMBERS = [
    "0",
    "-0",
    "1",
    "-1",
    "0.0333333",
    "1e-320",
    "5e-324",
    "1e-300",
    "1e300",
    "-1e300",
    "1e308",
    "1e309",
    "nan",
    "-nan",
    "inf",
    "-inf",
    "NaN",
    "1e7",
    "1e8",
    "123456789012345678901",
    "0x10",
    "1_000",
    "1e",
    "--1",
    "+1",
    "3.",
    ".5",
    "1e-9",
    "100000",
    "0.001",
    "2e9",
]
#: Hostile words and structure tokens of a BVH file.
WORDS = [
    "",
    "{",
    "}",
    "ROOT",
    "JOINT",
    "End",
    "Site",
    "OFFSET",
    "CHANNELS",
    "MOTION",
    "HIERARCHY",
    "Frames:",
    "Frame",
    "Time:",
    "Xrotation",
    "Yposition",
    "Wrotation",
    "\x00",
    "\u2028",
    "é",
    "x" * 100_000,
    "9" * 5000,
]
#: Hostile TOML values.
TOML_VALUES = [
    "5",
    "-1",
    "0",
    '"x"',
    '""',
    "[]",
    "[1]",
    "[1, 2, 3]",
    '["a", "b"]',
    "[[1, 2], [3]]",
    "{ a = 1 }",
    "{}",
    "1e300",
    "-1e300",
    "inf",
    "nan",
    "true",
    "100000000000000000000",
    "9223372036854775807",
    "[1e300, 1e301]",
    "[-1, 1]",
    "[1, -1]",
    "0.5",
    "1979-05-27",
    '"' + "x" * 10_000 + '"',
]
#: Hostile JSON values.
JSON_VALUES: list[Any] = [
    None,
    True,
    False,
    0,
    -1,
    1.5,
    1e300,
    -1e300,
    float("nan"),
    "x",
    "",
    "x" * 10_000,
    [],
    [1],
    {},
    {"a": 1},
    2**70,
    "../up.npz",
    "/abs.npz",
    "a\x00b.npz",
]


@dataclass
class Case:
    """One fuzzed input: which reader it is for and what to feed it."""

    target: str
    data: Any
    note: str = ""


class Workspace:
    """Valid starting points and a scratch folder for the generated files.

    Building it generates one short motion and a two-species, one-clip data set (a few
    seconds); call :meth:`close` (or use it as a context manager) to remove the folder.
    """

    def __init__(self, root: str | Path | None = None):
        from habitsim.dataset import build_dataset
        from habitsim.gaits import generate
        from habitsim.species import load_species

        self._own = root is None
        self.root = Path(tempfile.mkdtemp(prefix="habitsim-fuzz-") if root is None else root)
        self.root.mkdir(parents=True, exist_ok=True)
        example = resources.files("habitsim.examples") / "dog_walk.bvh"
        lines = example.read_text(encoding="utf-8").splitlines()
        m = lines.index("MOTION")
        # the example's hierarchy with 4 of its frames
        self.bvh_seeds = [
            "\n".join(lines[: m + 1] + ["Frames: 4"] + lines[m + 2 : m + 7]) + "\n",
            _TINY_BVH,
        ]
        motion = generate("dog", "walk", seed=0, duration_s=0.2)
        p = self.root / "seed.npz"
        motion.save(p)
        with np.load(p) as z:
            self.npz_seed = {k: z[k] for k in z.files}
        self.motion_file = p
        toml = load_species("dog").path
        assert toml is not None  # a catalog species is read from its file
        self.toml_seed = toml.read_text(encoding="utf-8")
        data = self.root / "dataset"
        build_dataset(
            data, clips_per_species=1, seed=0, species=["cat", "dog"], workers=1, progress=False
        )
        self.dataset = data
        self.manifest_seed = json.loads((data / "manifest.json").read_text(encoding="utf-8"))
        self.gltf_doc, self.gltf_blob = families.gltf_seed()
        families.preload()  # imported here, not under a child's memory limit
        wave.register_methods()  # the hostile entry-point methods, inherited by every run
        self.blocker = self.root / "blocker"
        self.blocker.write_text("a file where a folder should be")
        self._n = 0

    def path(self, suffix: str) -> Path:
        """A fresh file path in the scratch folder."""
        self._n += 1
        return self.root / "cases" / f"c{self._n}_{os.getpid()}{suffix}"  # forked runs too

    def close(self) -> None:
        if self._own:
            shutil.rmtree(self.root, ignore_errors=True)

    def __enter__(self) -> Workspace:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


_TINY_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 10 5
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 0 5
      }
    }
  }
  JOINT LeftLeg
  {
    OFFSET 5 -10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -10 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.033333
0 40 0 0 0 0 0 0 0 0 0 0 0 0 0
1 40 0 5 0 0 0 0 0 0 0 0 0 0 0
"""


# ---------------------------------------------------------------------- text mutations


def _mutate_lines(text: str, rnd: random.Random, tokens: list[str], extra_lines: list[str]) -> str:
    """1–3 random edits of a text: a token replaced, a line dropped / doubled / inserted,
    the text cut or random characters spliced in."""
    lines = text.split("\n")
    for _ in range(rnd.randint(1, 3)):
        op = rnd.randrange(7)
        k = rnd.randrange(len(lines)) if lines else 0
        if op == 0 and lines:  # replace one token of a line
            toks = lines[k].split(" ")
            toks[rnd.randrange(len(toks))] = rnd.choice(tokens)
            lines[k] = " ".join(toks)
        elif op == 1 and lines:
            del lines[k]
        elif op == 2 and lines:
            lines[k:k] = [lines[k]] * rnd.choice([1, 2, 50])
        elif op == 3:
            lines.insert(k, rnd.choice(extra_lines))
        elif op == 4:
            cut = "\n".join(lines)[: rnd.randrange(len("\n".join(lines)) + 1)]
            lines = cut.split("\n")
        elif op == 5 and lines:
            noise = "".join(rnd.choice("{} \t\r\x00\u2028#=.-e09aZ\"'[],") for _ in range(8))
            pos = rnd.randrange(len(lines[k]) + 1)
            lines[k] = lines[k][:pos] + noise + lines[k][pos:]
        elif op == 6 and lines:  # many edits of the same kind: every number of a line
            lines[k] = " ".join(rnd.choice(tokens) if _isnum(t) else t for t in lines[k].split(" "))
    return "\n".join(lines)


def _isnum(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _bvh_text(ws: Workspace, rnd: random.Random) -> str:
    text = rnd.choice(ws.bvh_seeds)
    r = rnd.random()
    if r < 0.08:  # deep nesting
        depth = rnd.choice([50, 199, 201, 1000, 3000])
        nest = "".join(f"JOINT n{d}\n{{\nOFFSET 0 0 1\nCHANNELS 0\n" for d in range(depth))
        i = text.index("End Site")
        return text[:i] + nest + "}\n" * depth + text[i:]
    if r < 0.16:  # every OFFSET scaled
        f = rnd.choice([0.0, 1e-300, 1e-30, 1e300, -1.0, 1e6, 1e8])
        out = []
        for line in text.split("\n"):
            parts = line.split()
            if parts[:1] == ["OFFSET"] and len(parts) == 4:
                line = "OFFSET " + " ".join(repr(float(v) * f) for v in parts[1:])
            out.append(line)
        return "\n".join(out)
    if r < 0.24:  # Frame Time
        ft = rnd.choice(NUMBERS + WORDS[:4])
        return "\n".join(
            f"Frame Time: {ft}" if ln.startswith("Frame Time") else ln for ln in text.split("\n")
        )
    if r < 0.30:  # joints renamed: the mapping works from the hierarchy alone
        for name in {
            ln.split()[1]
            for ln in text.split("\n")
            if ln.strip().split()[:1] in (["JOINT"], ["ROOT"]) and len(ln.split()) > 1
        }:
            text = text.replace(f" {name}\n", f" j{rnd.randrange(10**6)}\n")
        return text
    return _mutate_lines(
        text,
        rnd,
        NUMBERS + WORDS,
        [
            "{",
            "}",
            "End Site",
            "MOTION",
            "Frames: 3",
            "Frame Time: 0.1",
            "ROOT r",
            "JOINT j",
            "OFFSET 1 2 3",
            "CHANNELS 3 Xrotation Yrotation Zrotation",
            "CHANNELS 7",
            "",
            "0 " * 15,
            "1e300 " * 15,
        ],
    )


# ---------------------------------------------------------------------- arrays


def _hostile_array(rnd: random.Random) -> np.ndarray:
    kind = rnd.randrange(9)
    if kind == 0:
        return np.array(rnd.choice([1, 0, -1, 2**62, 30, 1.0, np.nan, np.inf, 1e300, 1e-300]))
    if kind == 1:
        return np.array(rnd.choice(["1", "dog", "", "x" * 10_000, "[]", "{}", "pelvis"]))
    if kind == 2:
        return np.array(rnd.choice([True, False]))
    if kind == 3:
        shape = tuple(rnd.choice([0, 1, 2, 3, 4, 27]) for _ in range(rnd.randrange(4)))
        return np.full(shape, rnd.choice([0.0, 1.0, np.nan, 1e300, -1e300, 0.5]))
    if kind == 4:
        return np.array(["a", "b", "c"])
    if kind == 5:
        return np.zeros(rnd.choice([(3,), (2, 2)]), dtype=rnd.choice(["c16", "u1", "i8", "f2"]))
    if kind == 6:
        return np.array([{"a": 1}, None], dtype=object)  # pickled by np.savez
    if kind == 7:
        return np.array(b"bytes")
    return np.array("[" * rnd.choice([10, 10_000]) + "]" * 10)


def _npz_file(ws: Workspace, rnd: random.Random) -> Path:
    arrays = dict(ws.npz_seed)
    for _ in range(rnd.randint(1, 3)):
        key = rnd.choice([*arrays, "contacts", "extra"])
        op = rnd.randrange(5)
        if op == 0:
            arrays.pop(key, None)
        elif op in (1, 2):
            arrays[key] = _hostile_array(rnd)
        elif (
            op == 3
            and key in ("root_positions", "rotations")
            and key in arrays
            and arrays[key].dtype.kind == "f"
            and arrays[key].size
        ):
            a = np.array(arrays[key], dtype=float)
            a.flat[rnd.randrange(a.size)] = rnd.choice([np.nan, 1e300, -1e300, 0.0, 1e6])
            if rnd.random() < 0.3:
                with np.errstate(all="ignore"):
                    a = a * rnd.choice([0.0, 1e300, 1e-300, -1.0])
            arrays[key] = a
        elif op == 4:
            arrays["fps"] = np.array(rnd.choice([1e300, 1e-300, 0.001, 1e5, -30.0, 30, 1, 1000]))
    p = ws.path(".npz")
    p.parent.mkdir(parents=True, exist_ok=True)
    with p.open("wb") as fh:
        (np.savez_compressed if rnd.random() < 0.5 else np.savez)(fh, **arrays)
    r = rnd.random()
    if r < 0.10:  # cut short
        raw = p.read_bytes()
        p.write_bytes(raw[: rnd.randrange(len(raw))])
    elif r < 0.20:  # bytes flipped
        flipped = bytearray(p.read_bytes())
        for _ in range(rnd.randint(1, 20)):
            flipped[rnd.randrange(len(flipped))] = rnd.randrange(256)
        p.write_bytes(bytes(flipped))
    elif r < 0.24:
        with p.open("wb") as fh:
            np.save(fh, np.zeros(3))
    elif r < 0.27:
        p.write_bytes(bytes(rnd.randrange(256) for _ in range(rnd.randrange(200))))
    elif r < 0.30:  # a zip bomb: a few MB of zeros that decompress to far more
        with p.open("wb") as fh:
            np.savez_compressed(fh, **{**arrays, "rotations": np.zeros((80_000, 27, 4, 2))})
    return p


# ---------------------------------------------------------------------- TOML, JSON


def _species_text(ws: Workspace, rnd: random.Random) -> str:
    text = ws.toml_seed
    if rnd.random() < 0.15:  # a table replaced by a value, written at the top
        table = rnd.choice(
            [
                "posture",
                "segments",
                "girths",
                "joint_limits",
                "gaits",
                "habits",
                "gaits.walk",
                "gaits.walk.footfall",
            ]
        )
        text = text.replace(f"[{table}]", f"[x{table}]").replace(f"[{table}.", f"[x{table}.")
        return f"{table.split('.')[0]} = {rnd.choice(TOML_VALUES)}\n{text}"
    lines = text.split("\n")
    for _ in range(rnd.randint(1, 3)):
        k = rnd.randrange(len(lines))
        if "=" in lines[k] and rnd.random() < 0.7:
            key = lines[k].split("=", 1)[0]
            lines[k] = f"{key}= {rnd.choice(TOML_VALUES)}"
        else:
            lines = _mutate_lines(
                "\n".join(lines), rnd, TOML_VALUES, ["[gaits.trot]", "[x]", "name = 5", "a = ["]
            ).split("\n")
    return "\n".join(lines)


def _json_paths(obj: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if len(prefix) > 6:
        return out
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _json_paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj[:3]):
            out += _json_paths(v, (*prefix, i))
    return out


def _manifest(ws: Workspace, rnd: random.Random) -> dict[str, Any]:
    m = json.loads(json.dumps(ws.manifest_seed))
    for _ in range(rnd.randint(1, 3)):
        path = rnd.choice(_json_paths(m)[1:])
        parent = m
        for k in path[:-1]:
            parent = parent[k]
        if rnd.random() < 0.2 and isinstance(parent, dict):
            parent.pop(path[-1], None)
            continue
        v = rnd.choice(JSON_VALUES)
        if rnd.random() < 0.05:
            v = _DEEP  # written as 100,000 nested lists (see _run_manifest)
        with contextlib.suppress(IndexError, KeyError, TypeError):
            parent[path[-1]] = v
    return m


_DEEP = "\x00deep\x00"


# ---------------------------------------------------------------------- command line


def _cli_argv(ws: Workspace, rnd: random.Random) -> list[str]:
    seeds = ["0", "1", "-1", str(2**32 - 1), str(2**32), str(2**64), "abc", "1e3"]
    temps = ["1", "0.5", "0", "-1", "nan", "inf", "1e-9", "11", "x"]
    fpss = ["30", "0", "-5", "100000", "0.001", "nan", "1000", "1"]
    species = ["dog", "cat", "horse", "unicorn", "", "x" * 1000, "Dog"]

    def motion_in() -> str:
        r = rnd.random()
        if r < 0.5:
            return str(ws.motion_file)
        if r < 0.8:
            return str(_npz_file(ws, rnd))
        return rnd.choice([str(ws.root / "missing.npz"), str(ws.root), str(ws.blocker)])

    def bvh_in() -> str:
        if rnd.random() < 0.2:
            return rnd.choice([str(ws.root / "missing.bvh"), str(ws.blocker)])
        p = ws.path(".bvh")
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(
            rnd.choice(ws.bvh_seeds) if rnd.random() < 0.3 else _bvh_text(ws, rnd),
            encoding="utf-8",
            errors="surrogatepass",
        )
        return str(p)

    def out(suffix: str) -> str:
        r = rnd.random()
        if r < 0.7:
            return str(ws.path(suffix))
        if r < 0.85:
            return str(ws.blocker / f"x{suffix}")
        return rnd.choice([str(ws.root), str(ws.path(".txt"))])

    c = rnd.randrange(7)
    if c == 0:
        argv = [
            "transfer",
            motion_in(),
            "--to",
            rnd.choice(species),
            "--out",
            out(".npz"),
            "--method",
            rnd.choice(["direct_relabelled", "direct_relabelled", "nope"]),
            "--seed",
            rnd.choice(seeds),
            "--temperature",
            rnd.choice(temps),
        ]
        if rnd.random() < 0.4:
            argv += ["--bvh", out(".bvh")]
    elif c == 1:
        argv = [
            "data",
            "export-bvh",
            motion_in(),
            "--out",
            out(".bvh"),
            "--order",
            rnd.choice(["ZXY", "XYZ", "abc", "", "XXY"]),
        ]
    elif c == 2:
        argv = [
            "data",
            "import-bvh",
            bvh_in(),
            "--species",
            rnd.choice(species),
            "--out",
            out(".npz"),
        ]
        if rnd.random() < 0.5:
            argv += ["--fps", rnd.choice(fpss)]
    elif c == 3:
        argv = ["data", "inspect-bvh", bvh_in(), "--species", rnd.choice(species)]
    elif c == 4:
        argv = ["motion", "stats", motion_in()]
    elif c == 5:
        argv = ["species", "show", rnd.choice(species)]
    else:  # argument bounds of the heavy commands (refused before any work)
        argv = rnd.choice(
            [
                ["track", motion_in(), "--settle", rnd.choice(["1e9", "-1", "nan", "61"])],
                ["track", motion_in(), "--control-hz", rnd.choice(["0", "-1", "inf", "1e6"])],
                [
                    "data",
                    "synth",
                    "--out",
                    out(""),
                    "--fps",
                    rnd.choice(["100000", "0.001", "nan"]),
                ],
                ["data", "synth", "--out", out(""), "--seed", rnd.choice(["-1", str(2**64)])],
                [
                    "eval",
                    "--data",
                    str(ws.dataset),
                    "--out",
                    out(""),
                    "--workers",
                    rnd.choice(["0", "100000"]),
                ],
                [
                    "refine",
                    motion_in(),
                    "--out",
                    out(".npz"),
                    "--report",
                    str(ws.blocker / "r.json"),
                ],
            ]
        )
    return argv


# ---------------------------------------------------------------------- heavy commands

#: Longest clip of the heavy commands' inputs [s] (so a campaign stays fast).
HEAVY_MAX_SECONDS = 1.0


def _absurd_motion(rnd: random.Random, species: str | None = None, min_frames: int = 1):
    """A valid-shaped motion with absurd but accepted values: fps at the ends of its
    range, one to a few dozen frames, roots far away, under the floor, in the sky or
    teleporting, random or flipped joint rotations, odd contact labels and actions."""
    from habitsim.motion import FPS_RANGE, MAX_ABS_POSITION_M, Motion
    from habitsim.skeleton import get_skeleton
    from habitsim.species import species_names

    sp = species or rnd.choice(species_names())
    root0, rot0 = get_skeleton(sp).standing_pose()
    fps = rnd.choice([FPS_RANGE[0], 1.5, 7.3, 30.0, 30.0, 240.0, 999.9, FPS_RANGE[1]])
    frames = rnd.choice([1, 1, 2, 3, 4, 7, 15, 30])
    frames = max(min_frames, min(frames, int(HEAVY_MAX_SECONDS * fps)))
    root = np.repeat(root0[None], frames, axis=0).astype(float)
    big = MAX_ABS_POSITION_M
    kind = rnd.choice(["stand", "far", "under", "sky", "teleport", "ramp", "tiny"])
    if kind == "far":
        root[:, rnd.randrange(2)] += rnd.choice([-1, 1]) * rnd.uniform(0.5, 1.0) * big
    elif kind == "under":
        root[:, 2] = -rnd.choice([0.01, 1.0, 100.0, big])
    elif kind == "sky":
        root[:, 2] = rnd.choice([10.0, 1e3, big])
    elif kind == "teleport":
        root[1::2, rnd.randrange(3)] += rnd.choice([1.0, 1e3, 0.9 * big])
    elif kind == "ramp":
        root[:, 0] += np.linspace(0.0, rnd.choice([1.0, 100.0, 0.9 * big]), frames)
    elif kind == "tiny":
        root *= 1e-9
    nprng = np.random.default_rng(rnd.getrandbits(32))
    rot = np.repeat(rot0[None], frames, axis=0).astype(float)
    rkind = rnd.choice(["pose", "noise", "random", "flip", "identity", "frozen_random"])
    if rkind == "noise":
        rot = rot + nprng.normal(0.0, 0.2, rot.shape)
    elif rkind == "random":
        rot = nprng.normal(size=rot.shape)
    elif rkind == "flip":
        rot[::2] *= -1.0
    elif rkind == "identity":
        rot[:] = (1.0, 0.0, 0.0, 0.0)
    elif rkind == "frozen_random":
        rot[:] = nprng.normal(size=rot.shape[1:])
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    contacts = rnd.choice([None, np.ones((frames, 4), bool), np.zeros((frames, 4), bool), "random"])
    if isinstance(contacts, str):
        contacts = nprng.random((frames, 4)) < 0.5
    meta: dict[str, Any] = {}
    if rnd.random() < 0.6:
        meta["action"] = rnd.choice(["walk", "trot", "jump", "sit", "rotary_gallop", "nope", ""])
    note = f"{sp} {frames} frames at {fps:g} fps, root {kind}, rotations {rkind}"
    return Motion(sp, fps, root, rot, contacts, meta), note


def _heavy_argv(ws: Workspace, rnd: random.Random) -> tuple[list[str], str]:
    """A heavy command (transfer, refine, track, eval) on an absurd motion, with small
    budgets: short clips, a few IPOPT iterations, one pair."""
    from habitsim.species import species_names

    command = rnd.choices(["transfer", "refine", "track", "eval", "light"], [4, 3, 3, 1, 1])[0]
    if command == "eval":
        return _heavy_eval(ws, rnd)
    # refinement needs 3 frames: mostly give it those, sometimes fewer
    motion, note = _absurd_motion(
        rnd, min_frames=3 if command == "refine" and rnd.random() < 0.8 else 1
    )
    src = ws.path(".npz")
    src.parent.mkdir(parents=True, exist_ok=True)
    motion.save(src)
    out = ws.path(".npz")
    if command == "transfer":
        argv = ["transfer", str(src), "--to", rnd.choice(species_names()), "--out", str(out)]
        argv += ["--method", rnd.choice(["direct_relabelled", "direct_relabelled", "habit"])]
        argv += ["--seed", str(rnd.choice([0, 1, 2**32 - 1]))]
        if rnd.random() < 0.3:
            argv += ["--temperature", rnd.choice(["0.001", "1", "10"])]
        if rnd.random() < 0.3:
            argv += ["--bvh", str(ws.path(".bvh"))]
    elif command == "refine":
        argv = ["refine", str(src), "--out", str(out), "--max-iter", rnd.choice(["1", "3", "5"])]
        if rnd.random() < 0.6:  # the shortest windows and overlaps, sometimes too short
            window = rnd.choice(["8", "8", "9", "10", "16", "100000", "5"])
            argv += ["--window", window, "--overlap", rnd.choice(["4", "4", "5", "3"])]
        for flag, p in (("--detect-contacts", 0.3), ("--fallback", 0.6), ("--no-metrics", 0.5)):
            if rnd.random() < p:
                argv.append(flag)
        if rnd.random() < 0.1 and motion.num_frames <= 8:
            argv.append("--dynamics")
        if rnd.random() < 0.3:
            argv += ["--report", str(ws.path(".json")), "--qpos", str(ws.path(".npz"))]
    elif command == "track":
        controller = rnd.choice(["servo", "pd", "servo+stance", "balance", "mpc"])
        argv = ["track", str(src), "--controller", controller, "--out", str(out)]
        if rnd.random() < 0.5:
            argv += ["--settle", rnd.choice(["0", "0.002", "0.3"])]
        if rnd.random() < 0.4:
            hz = ["1", "7.5", "50", "10000"] if controller != "mpc" else ["1", "50", "250"]
            argv += ["--control-hz", rnd.choice(hz)]
        if rnd.random() < 0.3:
            argv.append("--assist")
            argv.append("root")
        if rnd.random() < 0.2:
            argv.append("--no-stop")
        if rnd.random() < 0.3:
            argv += ["--report", str(ws.path(".json"))]
    else:  # the light readers of the same files
        argv = rnd.choice(
            [
                ["motion", "stats", str(src)],
                ["data", "export-bvh", str(src), "--out", str(ws.path(".bvh"))],
            ]
        )
    return argv, note


def _heavy_eval(ws: Workspace, rnd: random.Random) -> tuple[list[str], str]:
    """``habitsim eval`` of one pair on a copy of the small data set whose training clip
    is replaced by an absurd motion of the same species."""
    data = ws.path("")
    shutil.copytree(ws.dataset, data)
    clip = rnd.choice([c for c in ws.manifest_seed["clips"] if c["split"] == "train"])
    motion, note = _absurd_motion(rnd, clip["species"])
    motion.metadata["action"] = clip["action"]
    (data / clip["path"]).unlink()
    motion.save(data / clip["path"])
    argv = ["eval", "--data", str(data), "--out", str(ws.path("")), "--workers", "1"]
    argv += ["--methods", rnd.choice(["direct", "habit"]), "--max-clips", "1"]
    argv += ["--split", "train", "--sources", clip["species"], "--report-pairs"]
    argv += [rnd.choice(["0", "1"]), "--no-videos", "--no-progress", "--no-dynamic"]
    argv += ["--refine", rnd.choice(["none", "none", "kinematic"])]
    argv += rnd.choice([["--no-track"], ["--no-track"], ["--controller", "servo"]])
    argv += ["--targets", rnd.choice(["all", clip["species"], "cat,dog"])]
    if rnd.random() < 0.5:
        argv.append("--no-report")
    return argv, f"eval of {note}"


# ---------------------------------------------------------------------- running


def make_case(target: str, ws: Workspace, rnd: random.Random) -> Case:
    """One fuzzed input for ``target`` (a key of :data:`TARGETS`)."""
    if target in ("bvh", "bvh_import"):
        return Case(target, _bvh_text(ws, rnd))
    if target == "npz":
        return Case(target, _npz_file(ws, rnd))
    if target == "species":
        return Case(target, _species_text(ws, rnd))
    if target == "manifest":
        return Case(target, (_manifest(ws, rnd), rnd.random() < 0.5))
    if target == "cli":
        return Case(target, _cli_argv(ws, rnd))
    if target == "heavy":
        argv, note = _heavy_argv(ws, rnd)
        return Case(target, argv, note)
    if target == "gltf":
        return Case(target, families.make_gltf(ws, rnd))
    if target == "docs":
        return Case(target, families.make_doc(ws, rnd))
    if target == "npz_meta":
        return Case(target, families.make_npz_meta(ws, rnd))
    if target == "t2m":
        return Case(target, wave.make_t2m(ws, rnd))
    if target in _WAVE_ARGV:
        return Case(target, _WAVE_ARGV[target](ws, rnd))
    raise HabitsimError(f"unknown fuzz target {target!r}; valid: {', '.join(TARGETS)}")


def _run_bvh(ws: Workspace, case: Case) -> None:
    from habitsim.bvh import parse_bvh

    parse_bvh(case.data, source="<fuzz>", strict=len(case.data) % 2 == 0)


def _run_bvh_import(ws: Workspace, case: Case) -> None:
    from habitsim.bvh_mapping import import_bvh

    p = ws.path(".bvh")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(case.data.encode("utf-8", errors="surrogatepass"))
    import_bvh(p, "dog", plant=len(case.data) % 3 == 0)


def _run_npz(ws: Workspace, case: Case) -> None:
    from habitsim.motion import load_motion

    m = load_motion(case.data)
    m.features()


def _run_species(ws: Workspace, case: Case) -> None:
    from habitsim.species import load_species_file

    p = ws.path(".toml")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(case.data.encode("utf-8", errors="surrogatepass"))
    load_species_file(p)


def _run_manifest(ws: Workspace, case: Case) -> None:
    from habitsim.dataset import load_manifest

    manifest, check_files = case.data
    d = ws.path("")
    d.mkdir(parents=True)
    text = json.dumps(manifest).replace(json.dumps(_DEEP), "[" * 100_000 + "]" * 100_000)
    (d / "manifest.json").write_text(text, encoding="utf-8")
    if check_files:  # the clip files next to the manifest
        for f in ws.dataset.iterdir():
            if f.is_dir():
                shutil.copytree(f, d / f.name)
    load_manifest(d, check_files=check_files)


def _run_cli(ws: Workspace, case: Case) -> None:
    from habitsim.cli import main as cli_main

    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = cli_main(case.data)
    except SystemExit as e:  # argparse: "usage: … error: …", exit code 2
        if e.code == 2:
            raise _Typed("usage error") from None
        raise
    if code == 2:
        lines = err.getvalue().splitlines()  # (warnings may come first)
        if not any(x.startswith("error: ") for x in lines) and "usage" not in err.getvalue():
            raise RuntimeError(f"exit code 2 without 'error:' ({err.getvalue()[:200]!r})")
        raise _Typed(err.getvalue())
    if code not in (0, 1):
        raise RuntimeError(f"exit code {code}")
    if case.data[0] == "eval":  # a pair's raw exception is kept in its row, not raised
        out_dir = Path(case.data[case.data.index("--out") + 1])
        for row in sorted((out_dir / "rows").glob("*.json")):
            note = str(json.loads(row.read_text(encoding="utf-8")).get("note", ""))
            # a hostile method's own exception (fuzzing.wave) is its bug, not habitsim's
            if _RAW_NOTE.search(note) and "(wave.py:" not in note:
                raise RuntimeError(f"raw exception in the pair {row.stem}: {note[:300]}")


#: The note of an eval row whose pair ended in a raw exception ("… (file.py:123)").
_RAW_NOTE = re.compile(r"\(\w+\.py:\d+\)$")


class _Typed(HabitsimError):
    """The command line refused the input the proper way (counted as ``typed``)."""


_RUNNERS: dict[str, Callable[[Workspace, Case], None]] = {
    "bvh": _run_bvh,
    "bvh_import": _run_bvh_import,
    "npz": _run_npz,
    "species": _run_species,
    "manifest": _run_manifest,
    "cli": _run_cli,
    "heavy": _run_cli,
    "gltf": families.run_gltf,
    "docs": families.run_doc,
    "npz_meta": families.run_npz_meta,
    "t2m": wave.run_t2m,
    **dict.fromkeys(_WAVE_ARGV, _run_cli),
}


def run_case(ws: Workspace, case: Case) -> tuple[str, BaseException | None]:
    """Run one input in this process; ``("ok" | "typed" | "raw" | "memory", the exception
    or None)``."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with np.errstate(all="ignore"):
                _RUNNERS[case.target](ws, case)
    except HabitsimError as e:
        return "typed", e
    except MemoryError as e:
        return "memory", e
    except Exception as e:  # noqa: BLE001 - what the campaign is looking for
        return "raw", e
    return "ok", None


#: Targets run without the address-space limit: the heavy commands' libraries (IPOPT,
#: BLAS thread pools, torch) reserve address space they never touch, and fail or spin
#: under it; their peak memory is still measured and reported.
_NO_AS_LIMIT = ("cli", "heavy", *_WAVE_ARGV)


class ChildFailure(Exception):
    """A raw exception, hang or crash of a forked input, as the parent sees it:
    ``kind`` is the child's exception type (or ``hang`` / ``crash``)."""

    def __init__(self, outcome: str, kind: str, message: str, tb: str = ""):
        super().__init__(message)
        self.outcome, self.kind, self.tb = outcome, kind, tb


def _input_bytes(case: Case) -> int:
    """The size of an input [bytes]: its file's, or its text's."""
    d = case.data
    if isinstance(d, tuple):
        d = next((x for x in d if isinstance(x, Path)), None)
    if isinstance(d, Path):
        with contextlib.suppress(OSError):
            return d.stat().st_size
        return 0
    return len(d) if isinstance(d, str) else 0


def _status_kb(field: str) -> int:
    """A field of /proc/self/status [KiB] (0 where there is none)."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def run_isolated(
    ws: Workspace, case: Case, limits: FuzzLimits
) -> tuple[str, BaseException | None, float]:
    """Run one input in a forked child under ``limits``: (outcome, the exception or None,
    the child's peak memory above this process's [MB])."""
    budget = int(4 * _input_bytes(case) + limits.memory_mb * 2**20)
    vm = _status_kb("VmSize") * 1024
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: run, report as JSON, leave without any clean-up
        os.close(r)
        code = 0
        try:
            if case.target not in _NO_AS_LIMIT:
                resource.setrlimit(resource.RLIMIT_AS, (vm + budget, resource.RLIM_INFINITY))
            base = _status_kb("VmRSS")
            outcome, exc = run_case(ws, case)
            grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024
            tb = "" if exc is None else "".join(traceback.format_exception(exc)[-4:])
            kind = "" if exc is None else type(exc).__name__
            msg = "" if exc is None else str(exc)[:500]
            data = json.dumps(
                {"outcome": outcome, "kind": kind, "message": msg, "tb": tb, "mb": grown}
            )
            with os.fdopen(w, "wb") as fh:
                fh.write(data.encode())
        except BaseException:  # noqa: BLE001 - the child must never return to the caller
            code = 3
        os._exit(code)
    os.close(w)
    chunks, deadline, hung = [], time.monotonic() + limits.time_s, False
    with os.fdopen(r, "rb") as fh:
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fh], [], [], left)[0]:
                hung = True
                os.kill(pid, signal.SIGKILL)
                break
            chunk = os.read(fh.fileno(), 1 << 16)
            if not chunk:
                break
            chunks.append(chunk)
    _, status = os.waitpid(pid, 0)
    peak = float("nan")  # unknown unless the child reports it
    if hung:
        return (
            "hang",
            ChildFailure("hang", "hang", f"still running after {limits.time_s:g} s"),
            peak,
        )
    try:
        res = json.loads(b"".join(chunks))
    except ValueError:
        sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
        return (
            "raw",
            ChildFailure("raw", "crash", f"the child died (signal {sig}, status {status})"),
            peak,
        )
    peak = max(0.0, float(res.get("mb", 0.0)))
    if res["outcome"] == "ok":
        return "ok", None, peak
    return (
        res["outcome"],
        ChildFailure(res["outcome"], res["kind"], res["message"], res["tb"]),
        peak,
    )


@dataclass
class CampaignResult:
    """Counts of a campaign: ``counts[target][outcome]`` and the first raw failures."""

    counts: dict[str, Counter]
    raw: list[tuple[Case, BaseException, str]]
    seconds: float
    peak_mb: dict[str, float] | None = None

    @property
    def total(self) -> Counter:
        t: Counter = Counter()
        for c in self.counts.values():
            t.update(c)
        return t

    def table(self) -> str:
        peak = self.peak_mb or {}
        head = f"{'target':12s} {'inputs':>7s} " + " ".join(f"{o:>7s}" for o in OUTCOMES)
        lines = [head + f" {'peak MB':>8s}"]
        for name, c in [*self.counts.items(), ("total", self.total)]:
            top = max(peak.values(), default=0.0) if name == "total" else peak.get(name, 0.0)
            row = f"{name:12s} {sum(c.values()):7d} " + " ".join(f"{c[o]:7d}" for o in OUTCOMES)
            lines.append(row + f" {top:8.0f}")
        return "\n".join(lines)


def campaign(
    n: int,
    seed: int = 0,
    targets: list[str] | None = None,
    keep: int = 5,
    progress: bool = False,
    workspace: Workspace | None = None,
    limits: FuzzLimits | None = None,
) -> CampaignResult:
    """Run ``n`` fuzzed inputs (targets drawn in the proportions of :data:`TARGETS`), each
    under ``limits`` (None: :class:`FuzzLimits` defaults)."""
    lim = limits or FuzzLimits()
    names = targets or list(TARGETS)
    bad = [t for t in names if t not in TARGETS]
    if bad:
        raise HabitsimError(f"unknown fuzz targets {bad}; valid: {', '.join(TARGETS)}")
    weights = [TARGETS[t] for t in names]
    rnd = random.Random(seed)
    counts: dict[str, Counter] = {t: Counter() for t in names}
    peak: dict[str, float] = dict.fromkeys(names, 0.0)
    raw: list[tuple[Case, BaseException, str]] = []
    t0 = time.perf_counter()
    ws = workspace or Workspace()
    if "t2m" in names:  # trained and its text model loaded here, once
        wave.t2m_checkpoint(ws)
    try:
        for i in range(n):
            target = rnd.choices(names, weights)[0]
            case = make_case(target, ws, random.Random(rnd.getrandbits(64)))
            if lim.isolate:
                outcome, exc, mb = run_isolated(ws, case, lim)
                peak[target] = max(peak[target], mb)
            else:
                outcome, exc = run_case(ws, case)
            counts[target][outcome] += 1
            if outcome in ("raw", "hang", "memory") and len(raw) < keep:
                assert exc is not None  # a failed run returns its exception
                tb = (
                    exc.tb
                    if isinstance(exc, ChildFailure)
                    else "".join(traceback.format_exception(exc)[-4:])
                )
                raw.append((case, exc, tb))
            if progress and (i + 1) % 500 == 0:
                failed = {o: sum(c[o] for c in counts.values()) for o in OUTCOMES[2:]}
                print(
                    f"  {i + 1}/{n} inputs, "
                    + ", ".join(f"{v} {o}" for o, v in failed.items())
                    + f", {time.perf_counter() - t0:.0f} s",
                    file=sys.stderr,
                    flush=True,
                )
            if (i + 1) % 200 == 0:  # keep the scratch folder small
                shutil.rmtree(ws.root / "cases", ignore_errors=True)
    finally:
        if workspace is None:
            ws.close()
    return CampaignResult(counts, raw, time.perf_counter() - t0, peak if lim.isolate else None)


def _describe(case: Case) -> str:
    d = case.data
    if isinstance(d, str | Path):
        text = str(d)
    else:
        text = json.dumps(d, default=str)
    text = text if len(text) <= 300 else text[:300] + f"… ({len(text)} characters)"
    return f"{text} ({case.note})" if case.note else text


#: Legend of :meth:`CampaignResult.table`.
LEGEND = (
    "inputs: fuzzed inputs of that target; ok: read (or the command ran) without an error; "
    "typed: refused with a HabitsimError (error: ..., exit code 2, or a usage error); "
    "raw: any other exception, a bug (shown below the table with its input); "
    "hang: still running at the time limit; memory: a MemoryError under the memory limit "
    "(4 x the input's size + the budget); peak MB: the largest memory one input took "
    "beyond the campaign's own."
)


def print_campaign(res: CampaignResult, n: int, seed: int) -> None:
    """Print a campaign's counts by outcome and their legend, then its first raw
    exceptions."""
    from habitsim.cli.conventions import format_legend

    print(f"fuzz: {n} inputs, seed {seed}, {res.seconds:.0f} s")
    print(res.table())
    print(format_legend(LEGEND))
    for case, exc, tb in res.raw:
        if isinstance(exc, ChildFailure):
            outcome, kind = exc.outcome, exc.kind
        else:
            outcome = "memory" if isinstance(exc, MemoryError) else "raw"
            kind = type(exc).__name__
        print(f"\n{outcome} {kind} on a {case.target} input: {_describe(case)}\n{exc}\n{tb}")
