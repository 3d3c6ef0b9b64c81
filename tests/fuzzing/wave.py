"""Fuzzing families of the newer inputs: text prompts to text-to-motion, species made
from a clip, ``habitsim score`` folders, entry-point methods inside ``habitsim eval``,
export onto a user's rig, and in-place loop options.

Each family has a generator (``make_*``: the workspace and a seeded
:class:`random.Random` → the input) and a runner (``run_*``: the input read the way a
user's would be). The command-line families return an argv that the campaign's own
command-line runner (exit codes 0, 1 or 2 with ``error: …``) executes.
"""

from __future__ import annotations

import math
import os
import random
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np

#: Hostile prompts of text-to-motion (a few are built at random below).
PROMPTS: list[str] = [
    "",
    " ",
    "\t\n\r ",
    "\u200b\u200b",  # zero-width spaces
    "a dog trots to the left",
    "a cat walks slowly",
    "a unicorn gallops across the sky",  # an unknown species
    "a dog does a backflip and juggles",  # an unknown action
    "كلب يمشي إلى اليسار",  # right to left
    "\u202eyad a skaw god a",  # a right-to-left override
    "🐕🐕🐕 trots 🐾",
    "a\x00dog\x00walks",
    "\ud800 a lone surrogate",
    "\udfff",
    "\x1b[31mred\x07\x08\x7f",
    "a dog " * 85,  # just past 512 characters
    "x" * 1_000_000,  # 1 MB
    "é" * 511,
    "\U0010ffff" * 100,
]
#: Species names of the requests and of new species.
NAMES: list[str] = [
    "dog",
    "cat",
    "Dog",
    "unicorn",
    "",
    " ",
    "../cat",
    "a/b",
    "a\\b",
    "..",
    ".",
    "狗",
    "dog\x00",
    "x" * 10_000,
    "fz_dog",
    "fz-dog",
    "1dog",
    "con",
]

#: The shipped fox (a glTF rig, a clip to make a species from).
_FOX = Path(__file__).parents[2] / "habitsim" / "examples" / "Fox.glb"


def _prompt(rnd: random.Random) -> str:
    if rnd.random() < 0.7:
        return rnd.choice(PROMPTS)
    alphabet = [chr(rnd.randrange(0x110000)) for _ in range(20)] + list("a dog trots ")
    return "".join(rnd.choice(alphabet) for _ in range(rnd.randrange(1, 600)))


# ---------------------------------------------------------------------- text to motion


def t2m_checkpoint(ws: Any) -> Path:
    """A tiny text-to-motion checkpoint trained on the workspace's data set with the
    bundled sentence model (made once, in the campaign's process, a few seconds)."""
    ck = ws.root / "t2m" / "ck"
    if ck.is_dir():
        return ck
    from habitsim.captions.store import caption_dataset
    from habitsim.dataset import build_dataset
    from habitsim.models.t2m import text_to_motion
    from habitsim.models.t2m_data import build_code_set
    from habitsim.models.t2m_train import t2m_preset, train_codegpt

    data = ws.root / "t2m" / "data"
    build_dataset(data, clips_per_species=11, species=["dog", "cat"], workers=1, progress=False)
    caption_dataset(data, seed=0)
    build_code_set(data, ws.root / "t2m" / "codes")
    cfg = t2m_preset("tiny").replace(
        **{"train.steps": 2, "train.checkpoint_every": 2, "train.val_every": 2}
    )
    train_codegpt(ws.root / "t2m" / "codes", ck, cfg, log=lambda s: None)
    text_to_motion("a dog walks", "dog", 2.0, checkpoint=ck)  # the text model loaded here
    return ck


def make_t2m(ws: Any, rnd: random.Random) -> dict[str, Any]:
    # the other arguments mostly valid, so that most prompts reach the text model
    hostile = rnd.random() < 0.3
    seconds = [0.0, -1.0, math.nan, math.inf, 1e9, 0.01, 60.0] if hostile else [2.0, 1.0, 4.0]
    return {
        "text": _prompt(rnd),
        "species": rnd.choice(NAMES[:8] + ["fox", "horse"] if hostile else ["dog", "cat", "fox"]),
        "seconds": rnd.choice(seconds),
        "seed": rnd.choice([0, 1, -1, 2**40] if hostile else [0, 1, 7]),
        "guidance": rnd.choice([1.0, 3.0, 0.0, -1.0, math.nan] if hostile else [1.0, 3.0]),
        "cli": rnd.random() < 0.3,
    }


def run_t2m(ws: Any, case: Any) -> None:
    d = case.data
    ck = t2m_checkpoint(ws)
    if d["cli"]:
        from .campaign import Case, _run_cli

        argv = ["t2m", "generate", d["text"], "--species", d["species"], "--checkpoint", str(ck)]
        argv += ["--seconds", str(d["seconds"]), "--seed", str(d["seed"])]
        argv += ["--guidance", str(d["guidance"]), "--out", str(ws.path(".npz"))]
        _run_cli(ws, Case("cli", argv))
        return
    from habitsim.models.t2m import text_to_motion

    text_to_motion(
        d["text"],
        d["species"],
        d["seconds"],
        seed=d["seed"],
        guidance=d["guidance"],
        checkpoint=ck,
    )


# ---------------------------------------------------------------------- species from a clip


def _rig_text(ws: Any) -> str:
    """The dog walk on a foreign rig (cm, other names, helper joints), 1 s."""
    cached = getattr(ws, "_wave_rig", None)
    if cached is None:
        import sys

        sys.path.insert(0, str(Path(__file__).parents[1]))
        from foreign_rig import _foreign_rig  # type: ignore[import-not-found]

        from habitsim.gaits import generate

        cached = _foreign_rig(generate("dog", "walk", seed=3, duration_s=1.0)).to_text()
        ws._wave_rig = cached
    return cached


def _clip(ws: Any, rnd: random.Random) -> Path:
    """A reference clip: the foreign rig, too short, without legs, empty, with NaN."""
    from .campaign import _TINY_BVH, _bvh_text

    text = _rig_text(ws)
    head, _, motion = text.partition("MOTION\n")
    lines = motion.splitlines()
    kind = rnd.choice(["rig", "rig", "short", "one", "nolegs", "empty", "nan", "mutated", "glb"])
    if kind == "short":
        text = head + "MOTION\nFrames: 3\n" + "\n".join(lines[1:5]) + "\n"
    elif kind == "one":
        text = head + "MOTION\nFrames: 1\n" + "\n".join(lines[1:3]) + "\n"
    elif kind == "nolegs":
        text = _TINY_BVH
    elif kind == "empty":
        text = ""
    elif kind == "nan":
        rows = lines[2:]
        i = rnd.randrange(len(rows))
        vals = rows[i].split()
        vals[rnd.randrange(len(vals))] = rnd.choice(["nan", "inf", "1e308"])
        rows[i] = " ".join(vals)
        text = head + "MOTION\n" + "\n".join(lines[:2] + rows) + "\n"
    elif kind == "mutated":
        text = _bvh_text(ws, rnd)
    elif kind == "glb":
        p = ws.path(".glb")
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(
            (Path(__file__).parents[2] / "habitsim" / "examples" / "Fox.glb").read_bytes()
        )
        return p
    p = ws.path(".bvh")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    return p


def make_fromclip(ws: Any, rnd: random.Random) -> list[str]:
    catalog = ws.path("_catalog")
    name = f"fz_dog{rnd.randrange(10**6)}" if rnd.random() < 0.4 else rnd.choice(NAMES)
    argv = ["species", "from-clip", str(_clip(ws, rnd)), "--name", name]
    argv += ["--catalog", str(rnd.choice([catalog, catalog, ws.blocker / "c"]))]
    if rnd.random() < 0.3:
        argv += ["--mass", rnd.choice(["20", "0", "-5", "nan", "1e9", "x"])]
    if rnd.random() < 0.2:
        argv += ["--like", rnd.choice(["dog", "cat", "unicorn", "", "fz_dog"])]
    if rnd.random() < 0.2:
        argv += ["--posture", rnd.choice(["digitigrade", "plantigrade", "flying", ""])]
    return argv


# ---------------------------------------------------------------------- habitsim score


def _score_folder(ws: Any, rnd: random.Random) -> Path:
    """A folder of motion files as ``habitsim score`` reads them, made hostile: wrong
    names, empty files, another species' files, mixed formats, links out, a folder
    named like a file."""
    folder = ws.path("_score")
    folder.mkdir(parents=True)
    clip = next((ws.dataset / "val").rglob("*.npz"), ws.motion_file)
    for i in range(rnd.randint(0, 3)):
        kind = rnd.choice(
            ["npz", "cat_npz", "empty_npz", "empty_bvh", "bvh", "glb", "link", "dir", "txt", "bad"]
        )
        name = rnd.choice(["a", "b", "..x", "名", " ", "x" * 200, "clip"]) + str(i)
        if kind == "npz":
            (folder / f"{name}.npz").write_bytes(ws.motion_file.read_bytes())
        elif kind == "cat_npz":
            (folder / f"{name}.npz").write_bytes(clip.read_bytes())
        elif kind == "empty_npz":
            (folder / f"{name}.npz").write_bytes(b"")
        elif kind == "empty_bvh":
            (folder / f"{name}.bvh").write_bytes(b"")
        elif kind == "bvh":
            (folder / f"{name}.bvh").write_text(_rig_text(ws), encoding="utf-8")
        elif kind == "glb":
            (folder / f"{name}.glb").write_bytes(_FOX.read_bytes())
        elif kind == "link":
            target = rnd.choice(["/etc/hostname", str(ws.motion_file), "/nonexistent"])
            (folder / f"{name}.npz").symlink_to(target)
        elif kind == "dir":
            (folder / f"{name}.npz").mkdir(exist_ok=True)
        elif kind == "txt":
            (folder / f"{name}.txt").write_text("not a motion")
        else:
            (folder / f"{name}.bvh").write_bytes(os.urandom(rnd.randrange(1, 200)))
    return folder


def make_score(ws: Any, rnd: random.Random) -> list[str]:
    argv = ["score", str(_score_folder(ws, rnd)), "--no-evaluator", "--no-dynamic"]
    if rnd.random() < 0.5:
        argv += ["--species", rnd.choice(["dog", "cat", "unicorn", "", "fox"])]
    if rnd.random() < 0.3:
        argv += ["--contacts", rnd.choice(["labels", "geometry", "auto"])]
    if rnd.random() < 0.2:
        argv.append("--follow-symlinks")
    if rnd.random() < 0.3:
        argv += ["--out", str(rnd.choice([ws.path("_o"), ws.blocker / "o"]))]
    return argv


# ---------------------------------------------------------------------- entry-point methods


def _m_raises(source: Any, target: str, **kw: Any) -> Any:
    raise RuntimeError("a method's own bug")


def _m_none(source: Any, target: str, **kw: Any) -> Any:
    return None


def _m_array(source: Any, target: str, **kw: Any) -> Any:
    return np.zeros((source.num_frames, 3))


def _m_nan(source: Any, target: str, **kw: Any) -> Any:
    from habitsim.transfer_methods import direct_transfer

    out = direct_transfer(source, target, **kw)
    out.rotations[:] = np.nan
    return out


def _m_other_species(source: Any, target: str, **kw: Any) -> Any:
    return source


def _m_short(source: Any, target: str, **kw: Any) -> Any:
    from habitsim.transfer_methods import direct_transfer

    out = direct_transfer(source, target, **kw)
    out.root_positions = out.root_positions[:1]
    return out


def _m_hangs(source: Any, target: str, **kw: Any) -> Any:
    while True:
        time.sleep(0.01)


def _m_spins(source: Any, target: str, **kw: Any) -> Any:
    x = 0
    while True:
        x += 1


def _m_kills(source: Any, target: str, **kw: Any) -> Any:
    os.kill(os.getpid(), signal.SIGKILL)


def _m_exits(source: Any, target: str, **kw: Any) -> Any:
    raise SystemExit(3)


#: Hostile methods, registered as plugins would be (name → function).
HOSTILE_METHODS = {
    "fz_raises": _m_raises,
    "fz_none": _m_none,
    "fz_array": _m_array,
    "fz_nan": _m_nan,
    "fz_other_species": _m_other_species,
    "fz_short": _m_short,
    "fz_hangs": _m_hangs,
    "fz_spins": _m_spins,
    "fz_kills": _m_kills,
    "fz_exits": _m_exits,
}


def register_methods() -> None:
    """Register :data:`HOSTILE_METHODS` (in the campaign's process: forked runs inherit them)."""
    from habitsim.transfer_methods import method_names, register_method

    for name, fn in HOSTILE_METHODS.items():
        if name not in method_names():
            register_method(name, fn, "fuzzing: a hostile method", kind="external")


def _outputs_folder(ws: Any, rnd: random.Random) -> Path:
    """A folder of another method's outputs (``DIR/<target>/<clip_id>.npz``), hostile."""
    folder = ws.path("_outputs")
    clip_ids = [p.stem for p in (ws.dataset / "train").rglob("*.npz")]
    for target in rnd.sample(["cat", "dog", "unicorn", "...", "Cat"], 2):
        d = folder / target
        d.mkdir(parents=True, exist_ok=True)
        for cid in clip_ids + ["stray"]:
            kind = rnd.choice(["ok", "empty", "other", "dir", "link", "bvh", "missing"])
            p = d / f"{cid}.npz"
            if kind == "ok":
                p.write_bytes(ws.motion_file.read_bytes())
            elif kind == "empty":
                p.write_bytes(b"")
            elif kind == "other":
                p.write_bytes(os.urandom(64))
            elif kind == "dir":
                p.mkdir()
            elif kind == "link":
                p.symlink_to("/etc/hostname")
            elif kind == "bvh":
                (d / f"{cid}.bvh").write_text(_rig_text(ws), encoding="utf-8")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def make_methods(ws: Any, rnd: random.Random) -> list[str]:
    out = ws.path("_eval")
    argv = ["eval", "--data", str(ws.dataset), "--out", str(out), "--refine", "none"]
    argv += ["--no-track", "--no-dynamic", "--no-report", "--no-videos", "--no-progress"]
    argv += ["--report-pairs", "0", "--split", "train", "--max-clips", "1"]
    argv += ["--targets", "all"]  # the workspace's data set: cat and dog
    if rnd.random() < 0.8:
        argv += ["--methods", ",".join(rnd.sample(sorted(HOSTILE_METHODS), rnd.randint(1, 2)))]
    else:
        argv += ["--methods", "direct"]
        argv += ["--method", f"fz_dir={_outputs_folder(ws, rnd)}"]
    argv += ["--method-timeout", rnd.choice(["1", "1", "1", "0.5", "0", "nan"])]
    # a method that kills its process kills an in-process (--workers 1) run with it
    killer = "fz_kills" in argv[argv.index("--methods") + 1]
    argv += ["--workers", "2" if killer else rnd.choice(["1", "1", "2"])]
    argv += ["--retries", rnd.choice(["0", "1", "1", "2", "-1"])]
    return argv


# ---------------------------------------------------------------------- export onto a rig


def make_rig(ws: Any, rnd: random.Random) -> list[str]:
    """``data export-bvh MOTION --rig RIG``, with rigs that cannot take the motion."""
    from .campaign import _TINY_BVH, _bvh_text, _npz_file

    kind = rnd.choice(["rig", "tiny", "mutated", "empty", "glb", "short", "missing"])
    if kind == "glb":
        rig = ws.path(".glb")
        rig.parent.mkdir(parents=True, exist_ok=True)
        rig.write_bytes(_FOX.read_bytes())
    else:
        rig = ws.path(".bvh")
        rig.parent.mkdir(parents=True, exist_ok=True)
        text = {
            "rig": _rig_text(ws),
            "tiny": _TINY_BVH,
            "empty": "",
            "short": _rig_text(ws).partition("MOTION")[0],
        }.get(kind)
        if kind == "mutated":
            text = _bvh_text(ws, rnd)
        if kind != "missing":
            rig.write_text(text or "", encoding="utf-8", errors="surrogatepass")
    motion = rnd.choice(
        [
            str(ws.motion_file),
            str(ws.motion_file),
            str(next((ws.dataset / "val").rglob("*.npz"), ws.motion_file)),  # a cat
            str(_npz_file(ws, rnd)),
        ]
    )
    out = rnd.choice([ws.path(".bvh"), ws.path(".bvh"), ws.blocker / "x.bvh", ws.path(".glb")])
    argv = ["data", "export-bvh", motion, "--rig", str(rig), "--out", str(out)]
    if rnd.random() < 0.3:
        argv += ["--units", rnd.choice(["cm", "m", "mm", "in"])]
    if rnd.random() < 0.3:
        argv += ["--up", rnd.choice(["y", "z", "-x"])]
    return argv


# ---------------------------------------------------------------------- loops


def make_loop(ws: Any, rnd: random.Random) -> list[str]:
    """In-place loop options of ``data import-bvh`` and ``transfer``."""
    loops = ["1", "2", "3", "0", "-1", "1000", "1e9", "nan", "x", "2.5"]
    seconds = ["1", "3", "0", "-1", "nan", "inf", "1e9", "3600", "0.001", "x"]
    if rnd.random() < 0.5:
        clip = _clip(ws, rnd)
        argv = ["data", "import-bvh", str(clip), "--species", "dog"]
        argv += ["--out", str(ws.path(".npz"))]
    else:
        argv = ["transfer", str(ws.motion_file), "--to", "cat", "--method", "direct"]
        argv += ["--out", str(ws.path(".npz"))]
    if rnd.random() < 0.6:
        argv += ["--loop", rnd.choice(loops)]
    if rnd.random() < 0.6:
        argv += ["--seconds", rnd.choice(seconds)]
    if rnd.random() < 0.2:
        argv += ["--start", rnd.choice(["0", "0.5", "-1", "99"])]
    if rnd.random() < 0.2:
        argv += ["--end", rnd.choice(["0.5", "0", "99", "nan"])]
    return argv
