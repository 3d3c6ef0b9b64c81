"""The synthetic data set builder: layout, manifest, determinism, pairing, resume, errors."""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import files_under

from habitsim import DatasetError, UnknownSpeciesError, load_species
from habitsim.cli import main
from habitsim.dataset import (
    MANIFEST_NAME,
    SPLITS,
    STATS_COLUMNS,
    DatasetBuild,
    build_dataset,
    clip_seed,
    clip_split,
    iter_clips,
    load_manifest,
    plan_clips,
)
from habitsim.errors import OutputPathError
from habitsim.gaits import ACTIONS, LOCOMOTION_ACTIONS, available_actions
from habitsim.motion import load_motion

SPECIES = ["tiger", "cat", "horse"]  # tiger is held out (cousin: cat)
CLIPS = 4
SEED = 3
Built = tuple[Path, DatasetBuild]


def build(out: Path, **kw) -> DatasetBuild:
    args = dict(clips_per_species=CLIPS, seed=SEED, species=SPECIES, workers=1, progress=False)
    args.update(kw)
    return build_dataset(out, **args)


def arrays(root: Path) -> dict[str, dict[str, np.ndarray]]:
    """Every clip file's arrays, keyed by path relative to the data set folder."""
    out = {}
    for f in sorted(root.glob("*/*/*.npz")):
        with np.load(f, allow_pickle=False) as z:
            out[f.relative_to(root).as_posix()] = {k: z[k] for k in z.files}
    return out


def assert_same_arrays(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for path in a:
        assert a[path].keys() == b[path].keys(), path
        for k in a[path]:
            np.testing.assert_array_equal(a[path][k], b[path][k], err_msg=f"{path}:{k}")


def manifest_clips(root: Path) -> list[dict]:
    return json.loads((root / MANIFEST_NAME).read_text())["clips"]


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Built:
    out = tmp_path_factory.mktemp("ds") / "data"
    return out, build(out)


# ---------------------------------------------------------------------------- layout


def test_layout_and_manifest_fields(built: Built) -> None:
    root, b = built
    assert b.generated == len(SPECIES) * CLIPS and b.reused == 0
    for name in (MANIFEST_NAME, "stats.csv", "stats.md"):
        assert (root / name).is_file()
    data = json.loads((root / MANIFEST_NAME).read_text())
    for key in (
        "format_version",
        "generator_version",
        "seed",
        "clips_per_species",
        "species",
        "clips",
        "fps",
    ):
        assert key in data
    assert data["seed"] == SEED and data["clips_per_species"] == CLIPS
    assert [s["name"] for s in data["species"]] == sorted(SPECIES)
    assert len(data["clips"]) == len(SPECIES) * CLIPS
    pattern = re.compile(r"^(train|val|test)/([a-z]+)/\2_([a-z_]+)_(\d{4})\.npz$")
    files = {p.relative_to(root).as_posix() for p in root.glob("*/*/*.npz")}
    assert files == {c["path"] for c in data["clips"]}
    for c in data["clips"]:
        for key in (
            "path",
            "split",
            "species",
            "held_out",
            "action",
            "gait",
            "speed_mps",
            "froude",
            "duty_factor",
            "turn_rate",
            "duration_s",
            "frames",
            "seed",
            "pair_key",
        ):
            assert key in c, key
        m = pattern.match(c["path"])
        assert m, c["path"]
        assert (m.group(1), m.group(2), m.group(3), int(m.group(4))) == (
            c["split"],
            c["species"],
            c["action"],
            c["index"],
        )
        assert c["held_out"] == load_species(c["species"]).held_out
        assert all(v is None or math.isfinite(v) for v in c["measured"].values())


def test_held_out_species_only_in_test(built: Built) -> None:
    man = load_manifest(built[0])
    assert {c.split for c in man.select(species="tiger")} == {"test"}
    assert all(not c.held_out for c in man.select(split="train"))
    assert all(c.split == "test" for c in man.clips if c.held_out)
    assert man.select(split="train")  # training species do reach train


def test_actions_spread_over_available(built: Built) -> None:
    man = load_manifest(built[0])
    for sp in SPECIES:
        acts = available_actions(sp)
        got = [c.action for c in sorted(man.select(species=sp), key=lambda c: c.index)]
        assert got == [acts[i % len(acts)] for i in range(CLIPS)]


def test_every_clip_loads_and_matches_entry(built: Built) -> None:
    root, _ = built
    n = 0
    for entry, m in iter_clips(root):
        n += 1
        assert m.species == entry.species
        assert m.num_frames == entry.frames
        assert m.metadata["action"] == entry.action and m.metadata["seed"] == entry.seed
        assert m.metadata["pair_key"] == entry.pair_key
        assert load_motion(root / entry.path).num_frames == entry.frames
    assert n == len(SPECIES) * CLIPS
    assert len(list(iter_clips(root, split="test", species="tiger"))) == CLIPS


def test_stats_files(built: Built) -> None:
    root, b = built
    with open(root / "stats.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0].keys()) == STATS_COLUMNS
    groups = {(c.species, c.action) for c in b.manifest.clips}
    assert {(r["species"], r["action"]) for r in rows} == groups
    assert sum(int(r["clips"]) for r in rows) == len(b.manifest.clips)
    walk = next(r for r in rows if r["species"] == "cat" and r["action"] == "walk")
    assert float(walk["froude"]) == pytest.approx(float(walk["froude_target"]), rel=0.1)
    assert "| species |" in (root / "stats.md").read_text()


# ---------------------------------------------------------------------------- pairing


def test_paired_clips_share_action_and_dimensionless_draws(built: Built) -> None:
    root, _ = built
    man = load_manifest(root)
    pairs = man.pairs("cat", "tiger") + man.pairs("cat", "horse")
    assert len(pairs) >= 6
    for a, b in pairs:
        assert a.action == b.action and a.seed == b.seed and a.pair_key == b.pair_key
        ma, mb = load_motion(root / a.path), load_motion(root / b.path)
        assert ma.metadata["params"] == mb.metadata["params"]
        if a.action in LOCOMOTION_ACTIONS:
            band_a = load_species(a.species).gaits[a.gait].froude
            band_b = load_species(b.species).gaits[b.gait].froude
            ua = (a.froude - band_a[0]) / (band_a[1] - band_a[0])
            ub = (b.froude - band_b[0]) / (band_b[1] - band_b[0])
            assert ua == pytest.approx(ub, abs=1e-9)
            assert a.turn_rate_nd == pytest.approx(b.turn_rate_nd, abs=1e-9)
            assert a.duration_s == pytest.approx(b.duration_s)
    assert any(a.action == "turn_left" and a.turn_rate_nd > 0 for a, _ in pairs)


def test_seeds_and_splits_are_species_independent() -> None:
    jobs = plan_clips(["cat", "horse", "tiger"], 25, 7, 30.0)
    by_key: dict[tuple[str, int], set[tuple[int, str]]] = {}
    for j in jobs:
        assert j.seed == clip_seed(7, j.action, j.pair_index)
        if not j.held_out:
            by_key.setdefault((j.action, j.pair_index), set()).add((j.seed, j.split))
    assert all(len(v) == 1 for v in by_key.values())  # same seed and split in every species
    assert clip_seed(7, "walk", 0) != clip_seed(8, "walk", 0) != clip_seed(7, "trot", 0)
    assert plan_clips(["cat"], 25, 7, 30.0) == [j for j in jobs if j.species == "cat"]


def test_split_rule_ratio() -> None:
    for action in ACTIONS:
        splits = [clip_split(action, k, held_out=False) for k in range(20)]
        assert [splits.count(s) for s in SPLITS] == [16, 2, 2]
        assert clip_split(action, 3, held_out=True) == "test"


# ---------------------------------------------------------------------------- determinism


@pytest.mark.slow
def test_same_seed_identical_across_builds_and_workers(built: Built, tmp_path: Path) -> None:
    root, _ = built
    b2 = build(tmp_path / "w2", workers=2)
    assert b2.workers == 2
    assert_same_arrays(arrays(root), arrays(tmp_path / "w2"))
    assert manifest_clips(root) == manifest_clips(tmp_path / "w2")
    # Another species list: the shared species' clips are the same.
    build(tmp_path / "cat", species=["cat"])
    a = {k: v for k, v in arrays(root).items() if "/cat/" in k}
    assert_same_arrays(a, arrays(tmp_path / "cat"))


def test_different_seed_differs(built: Built, tmp_path: Path) -> None:
    root, _ = built
    build(tmp_path / "s", seed=SEED + 1)
    a, b = arrays(root), arrays(tmp_path / "s")
    assert a.keys() == b.keys()
    for path in a:
        assert (
            not np.array_equal(a[path]["rotations"], b[path]["rotations"])
            or a[path]["rotations"].shape != b[path]["rotations"].shape
        )


# ---------------------------------------------------------------------------- resume


def test_resume_skips_existing_clips(tmp_path: Path) -> None:
    out = tmp_path / "d"
    build(out, clips_per_species=2)
    mtimes = {p: p.stat().st_mtime_ns for p in out.glob("*/*/*.npz")}
    before = manifest_clips(out)
    again = build(out, clips_per_species=2)
    assert (again.generated, again.reused) == (0, len(mtimes))
    assert {p: p.stat().st_mtime_ns for p in out.glob("*/*/*.npz")} == mtimes
    assert manifest_clips(out) == before
    fresh = build(out, clips_per_species=2, resume=False)
    assert fresh.generated == len(mtimes)


def test_interrupted_build_resumes_to_same_result(built: Built, tmp_path: Path) -> None:
    root, _ = built
    out = tmp_path / "d"
    build(out)
    (out / MANIFEST_NAME).unlink()
    victim = next(iter(sorted(out.glob("train/*/*.npz"))))
    victim.unlink()
    with pytest.raises(DatasetError, match="no manifest"):
        load_manifest(out)
    b = build(out)
    assert (b.generated, b.reused) == (1, len(SPECIES) * CLIPS - 1)
    assert_same_arrays(arrays(root), arrays(out))
    assert manifest_clips(out) == manifest_clips(root)


def test_resume_replaces_corrupt_clip_and_removes_stale(tmp_path: Path) -> None:
    out = tmp_path / "d"
    build(out, clips_per_species=3)
    clip = out / "train/cat/cat_walk_0000.npz"
    clip.write_bytes(b"not a zip")
    (out / MANIFEST_NAME).unlink()
    b = build(out, clips_per_species=2)  # fewer clips: the third of each species is stale
    assert b.generated == 1 and b.removed == len(SPECIES)
    assert len(list(out.glob("*/*/*.npz"))) == 2 * len(SPECIES)
    load_motion(clip)
    assert len(load_manifest(out).clips) == 2 * len(SPECIES)


def test_clip_failure_names_the_clip_and_writes_no_manifest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import habitsim.dataset.clips as ds  # where a clip is generated

    def boom(*a, **k):
        raise RuntimeError("generator exploded")

    monkeypatch.setattr(ds, "generate", boom)
    with pytest.raises(DatasetError, match=r"clip \w+/cat/cat_walk_0000\.npz.*generator exploded"):
        build(tmp_path / "d", species=["cat"])
    assert not (tmp_path / "d" / MANIFEST_NAME).exists()


# ---------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"clips_per_species": 0}, "clips_per_species"),
        ({"clips_per_species": -2}, "clips_per_species"),
        ({"clips_per_species": 1.5}, "clips_per_species"),
        ({"clips_per_species": True}, "clips_per_species"),
        ({"chains_per_species": -1}, "chains_per_species"),
        ({"seed": -1}, "seed"),
        ({"workers": 0}, "workers"),
        ({"fps": 0.0}, "fps"),
        ({"fps": float("nan")}, "fps"),
        ({"species": []}, "no species"),
        ({"species": ["cat", "cat"]}, "more than once"),
    ],
)
def test_bad_arguments(tmp_path: Path, kw: dict, match: str) -> None:
    with pytest.raises(DatasetError, match=match):
        build(tmp_path / "d", **kw)
    assert not (tmp_path / "d").exists()


def test_unknown_species(tmp_path: Path) -> None:
    with pytest.raises(UnknownSpeciesError, match="unicorn.*known: bear"):
        build(tmp_path / "d", species=["cat", "unicorn"])
    assert not (tmp_path / "d").exists()


def test_out_dir_is_a_file(tmp_path: Path) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(DatasetError, match="not a directory"):
        build(f)


def test_other_configuration_needs_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "d"
    build(out, clips_per_species=1)
    for kw in ({"seed": SEED + 1}, {"seed": SEED + 1, "resume": False}, {"fps": 25.0}):
        with pytest.raises(DatasetError, match="another configuration"):
            build(out, clips_per_species=1, **kw)
        assert load_manifest(out).seed == SEED  # untouched
    b = build(out, clips_per_species=1, seed=SEED + 1, overwrite=True)
    assert b.generated == len(SPECIES) and load_manifest(out).seed == SEED + 1


def test_overwrite_refuses_foreign_manifest(tmp_path: Path) -> None:
    (tmp_path / MANIFEST_NAME).write_text('{"name": "some web app"}')
    with pytest.raises(DatasetError):
        build(tmp_path, overwrite=True)
    with pytest.raises(DatasetError, match="not a habitsim"):
        build(tmp_path)
    assert (tmp_path / MANIFEST_NAME).read_text() == '{"name": "some web app"}'


def test_load_manifest_validation(built: Built, tmp_path: Path) -> None:
    root, _ = built
    with pytest.raises(DatasetError, match="no such data set"):
        load_manifest(tmp_path / "missing")
    data = json.loads((root / MANIFEST_NAME).read_text())

    def tampered(edit) -> Path:
        d = json.loads(json.dumps(data))
        edit(d)
        out = tmp_path / f"t{len(list(tmp_path.iterdir()))}"
        out.mkdir()
        (out / MANIFEST_NAME).write_text(json.dumps(d))
        return out

    held = next(i for i, c in enumerate(data["clips"]) if c["held_out"])
    cases = [
        (lambda d: d["clips"][held].update(split="train"), "only be in 'test'"),
        (lambda d: d["clips"][0].update(path="../x.npz"), "relative .npz path"),
        (lambda d: d["clips"][0].update(split="dev"), "unknown split"),
        (lambda d: d["clips"][0].pop("seed"), "lacks seed"),
        (lambda d: d["clips"][0].update(frames="many"), "'frames' must be int"),
        (lambda d: d.update(format_version=99), "format_version"),
        (lambda d: d.update(kind="other"), "not a habitsim"),
    ]
    for edit, match in cases:
        with pytest.raises(DatasetError, match=match):
            load_manifest(tampered(edit), check_files=False)
    with pytest.raises(DatasetError, match="missing"):
        load_manifest(tampered(lambda d: None))  # manifest without its clip files
    man = load_manifest(root)
    with pytest.raises(DatasetError, match="unknown split"):
        man.select(split="dev")
    with pytest.raises(DatasetError, match="not in the data set"):
        man.select(species="dog")


# ---------------------------------------------------------------------------- CLI


def test_cli_synth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli"
    code = main(
        [
            "data",
            "synth",
            "--out",
            str(out),
            "--clips-per-species",
            "2",
            "--seed",
            "1",
            "--species",
            "cat, wolf",
            "--workers",
            "1",
            "--no-progress",
        ]
    )
    assert code == 0
    man = load_manifest(out)
    assert man.species_names == ["cat", "wolf"] and len(man.clips) == 4 and man.seed == 1
    text = capsys.readouterr().out
    assert "4 clips of 2 species" in text and "phase err" in text and "wolf*" in text


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--clips-per-species", "0"], "clips_per_species"),
        (["--species", "cat,unicorn"], "unknown species 'unicorn'"),
        (["--workers", "0"], "workers"),
    ],
)
def test_cli_synth_bad_call(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], match: str
) -> None:
    out = tmp_path / "cli"
    code = main(["data", "synth", "--out", str(out), "--no-progress", *extra])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and match in err
    assert not (out / MANIFEST_NAME).exists()


def test_cli_synth_other_seed_keeps_existing_manifest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cli"
    args = [
        "data",
        "synth",
        "--out",
        str(out),
        "--clips-per-species",
        "1",
        "--species",
        "cat",
        "--workers",
        "1",
        "--no-progress",
    ]
    assert main(args) == 0
    before = (out / MANIFEST_NAME).read_text()
    assert main([*args, "--seed", "9"]) == 2
    assert "error:" in capsys.readouterr().err
    assert (out / MANIFEST_NAME).read_text() == before
    assert main([*args, "--seed", "9", "--overwrite"]) == 0
    assert load_manifest(out).seed == 9


@pytest.mark.parametrize("value", ['"fast"', "[1]", '{"a": 1}', "true"])
def test_manifest_non_numeric_measured(tmp_path: Path, small_dataset: Path, value: str) -> None:
    import json
    import shutil

    from habitsim.dataset import load_manifest
    from habitsim.errors import DatasetError

    d = tmp_path / "d"
    shutil.copytree(small_dataset, d)
    m = json.loads((d / "manifest.json").read_text())
    key = next(iter(m["clips"][0]["measured"]))
    m["clips"][0]["measured"][key] = json.loads(value)
    (d / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match="measured"):
        load_manifest(d)


@pytest.mark.parametrize("path", ["a\x00b.npz", "x" * 300 + ".npz", "/abs.npz", "../up.npz"])
def test_manifest_bad_clip_path(tmp_path: Path, small_dataset: Path, path: str) -> None:
    import json
    import shutil

    from habitsim.dataset import load_manifest
    from habitsim.errors import DatasetError

    d = tmp_path / "d"
    shutil.copytree(small_dataset, d)
    m = json.loads((d / "manifest.json").read_text())
    m["clips"][0]["path"] = path
    (d / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(DatasetError, match="clip path"):
        load_manifest(d)


def test_build_dataset_fps_bounds(tmp_path: Path) -> None:
    from habitsim.dataset import build_dataset
    from habitsim.errors import DatasetError

    for fps in (100000.0, 0.001):
        with pytest.raises(DatasetError, match="valid"):
            build_dataset(
                tmp_path / "d",
                clips_per_species=1,
                fps=fps,
                species=["cat"],
                workers=1,
                progress=False,
            )


def test_synth_into_existing_read_only_folder_even_for_root(tmp_path: Path, monkeypatch) -> None:
    """An existing data set folder that refuses new files (EACCES on create, as a
    read-only folder or file system answers) is refused before any clip is made."""
    import tempfile

    from habitsim.dataset import build_dataset

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    (tmp_path / "d").mkdir()
    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(OutputPathError, match="Permission denied"):
        build_dataset(tmp_path / "d", clips_per_species=1, species=["cat"], workers=1)
    assert files_under(tmp_path) == ["d"]


def test_build_leaves_files_habitsim_did_not_write(tmp_path: Path) -> None:
    """A folder with someone's files is refused; --overwrite writes beside them and removes
    only the earlier build's files."""
    from habitsim.errors import OutputFolderError

    out = tmp_path / "ds"
    (out / "train" / "cat").mkdir(parents=True)
    theirs = out / "train" / "cat" / "cat_walk_0000.npz"  # a name of the clip layout
    theirs.write_text("not habitsim's")
    kw = dict(clips_per_species=1, species=["dog"], workers=1, progress=False)
    with pytest.raises(OutputFolderError):
        build_dataset(out, **kw)
    build_dataset(out, overwrite=True, **kw)
    build_dataset(out, overwrite=True, seed=1, **kw)
    assert theirs.read_text() == "not habitsim's"
    assert load_manifest(out).seed == 1


# ---------------------------------------------------------------------------- chains


def test_chained_clips_follow_the_others(tmp_path: Path) -> None:
    out = tmp_path / "d"
    b = build(out, species=["cat"], clips_per_species=2, chains_per_species=2)
    chains = [c for c in b.manifest.clips if c.action == "chain"]
    assert [c.index for c in chains] == [2, 3]
    assert len({c.pair_key for c in chains}) == 2 and all("cat" in c.pair_key for c in chains)
    assert json.loads((out / MANIFEST_NAME).read_text())["chains_per_species"] == 2
    assert load_manifest(out).chains_per_species == 2
    for c in chains:
        m = load_motion(out / c.path)
        steps = m.metadata["chain"]["segments"]
        assert 2 <= len(steps) <= 5 and c.gait == m.metadata["gait"]
        assert c.measured["skate_mm"] is not None and c.measured["penetration_mm"] < 0.5
    # the single-action clips are those of a build without chains
    plain = plan_clips(["cat"], 2, SEED, 30.0)
    assert [j.path for j in plain] == [c.path for c in b.manifest.clips[:2]]


def test_no_chains_by_default(built: Built) -> None:
    root, b = built
    assert all(c.action != "chain" for c in b.manifest.clips)
    assert "chains_per_species" not in json.loads((root / MANIFEST_NAME).read_text())


@pytest.mark.parametrize(
    "text",
    [
        '{"kind": "habitsim.dataset", "seed": ' + "9" * 5000 + "}",  # a raw ValueError before
        "[" * 100_000 + "]" * 100_000,
    ],
)
def test_manifest_out_of_bounds_is_typed(tmp_path: Path, text: str) -> None:
    (tmp_path / "manifest.json").write_text(text)
    with pytest.raises(DatasetError):
        load_manifest(tmp_path)
