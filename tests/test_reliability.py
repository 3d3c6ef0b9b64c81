"""Regression tests of issue 17 (reliability): every bad input found by the probe ends in
a typed :class:`~habitsim.errors.HabitsimError` (``error: …``, exit 2, a message of
bounded length), and a command that writes several files leaves all of them or none."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from habitsim.cli import main
from habitsim.errors import HabitsimError, OutputPathError
from habitsim.fileio import atomic_write_text, check_writable, output_transaction


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.gaits import generate

    p = tmp_path_factory.mktemp("motion") / "walk.npz"
    generate("dog", "walk", seed=0, duration_s=0.5).save(p)
    return p


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Exit code and stderr of ``habitsim ARGV`` run in this process."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    return code, err


def files_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ------------------------------------------------------------------ outputs as transactions


def test_check_writable_file_where_a_folder_should_be(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputPathError, match="file where a folder should be"):
        check_writable(tmp_path / "f" / "sub" / "r.json", "--report")
    with pytest.raises(OutputPathError, match="is a folder"):
        check_writable(tmp_path, "--out")
    assert files_under(tmp_path) == ["f"]


def test_atomic_write_into_a_file_is_typed(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputPathError, match="file where a folder should be"):
        atomic_write_text(tmp_path / "f" / "r.json", "{}")


@pytest.mark.skipif(os.geteuid() == 0, reason="the super-user writes into read-only folders")
def test_read_only_folder_is_typed(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(OutputPathError):
            check_writable(ro / "r.json")
        with pytest.raises(OutputPathError):
            atomic_write_text(ro / "r.json", "{}")
    finally:
        ro.chmod(0o755)


def test_read_only_folder_is_typed_even_for_root(tmp_path: Path, monkeypatch) -> None:
    """What a read-only folder (or file system) answers, simulated: EACCES on create."""
    import tempfile

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(OutputPathError, match="Permission denied"):
        check_writable(tmp_path / "r.json", "--report")
    with pytest.raises(OutputPathError, match="Permission denied"):
        atomic_write_text(tmp_path / "r.json", "{}")
    assert files_under(tmp_path) == []


def test_transaction_all_or_none(tmp_path: Path) -> None:
    a, b = tmp_path / "a.txt", tmp_path / "sub" / "b.txt"
    with pytest.raises(RuntimeError):
        with output_transaction({"a": a, "b": b}):
            atomic_write_text(a, "1")
            raise RuntimeError("work failed after the first write")
    assert files_under(tmp_path) == []
    a.write_text("old")
    with output_transaction({"a": a, "b": b}):
        atomic_write_text(a, "new")
        atomic_write_text(b, "new")
        assert a.read_text() == "old"  # nothing moves before the end of the block
    assert a.read_text() == b.read_text() == "new"
    assert files_under(tmp_path) == ["a.txt", "sub", "sub/b.txt"]


def test_transaction_rolls_back_a_failed_commit(tmp_path: Path, monkeypatch) -> None:
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old")
    real_replace = os.replace

    def failing_replace(src, dst):
        if str(dst) == str(b):
            raise PermissionError(13, "Permission denied")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OutputPathError, match="b.txt"):
        with output_transaction({"a": a, "b": b}):
            atomic_write_text(a, "new")
            atomic_write_text(b, "new")
    assert a.read_text() == "old"
    assert files_under(tmp_path) == ["a.txt"]


def test_transaction_refuses_one_path_twice(tmp_path: Path) -> None:
    with pytest.raises(OutputPathError, match="same file"):
        with output_transaction({"--out": tmp_path / "x", "--report": tmp_path / "." / "x"}):
            pass


@pytest.mark.slow
@pytest.mark.parametrize(
    "extra",
    [["--report", "{blocker}/r.json"], ["--qpos", "{blocker}/q.npz"]],
    ids=["report", "qpos"],
)
def test_refine_unwritable_second_output_leaves_nothing(
    tmp_path: Path, motion_file: Path, capsys, extra: list[str]
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    out = tmp_path / "ok.npz"
    extra = [e.format(blocker=blocker) for e in extra]
    code, err = run_cli(["refine", motion_file, "--out", out, *extra], capsys)
    assert code == 2 and err.startswith("error: ") and "file where a folder" in err
    assert files_under(tmp_path) == ["blocker"]


@pytest.mark.parametrize(
    "extra",
    [["--report", "{blocker}/r.json"], ["--video", "{blocker}/v.gif"]],
    ids=["report", "video"],
)
def test_track_unwritable_second_output_leaves_nothing(
    tmp_path: Path, motion_file: Path, capsys, extra: list[str]
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    extra = [e.format(blocker=blocker) for e in extra]
    code, err = run_cli(["track", motion_file, "--out", tmp_path / "sim.npz", *extra], capsys)
    assert code == 2 and err.startswith("error: "), err
    assert files_under(tmp_path) == ["blocker"]


def test_transfer_unwritable_bvh_leaves_nothing(tmp_path: Path, motion_file: Path, capsys) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    code, err = run_cli(
        [
            "transfer",
            motion_file,
            "--to",
            "cat",
            "--method",
            "direct",
            "--out",
            tmp_path / "ok.npz",
            "--bvh",
            blocker / "x.bvh",
        ],
        capsys,
    )
    assert code == 2 and "file where a folder" in err
    assert files_under(tmp_path) == ["blocker"]


def test_transfer_writes_both_outputs(tmp_path: Path, motion_file: Path, capsys) -> None:
    code, _ = run_cli(
        [
            "transfer",
            motion_file,
            "--to",
            "cat",
            "--method",
            "direct",
            "--out",
            tmp_path / "ok.npz",
            "--bvh",
            tmp_path / "x.bvh",
        ],
        capsys,
    )
    assert code == 0
    assert files_under(tmp_path) == ["ok.npz", "x.bvh"]


# ------------------------------------------------------------------ BVH reader

from habitsim.bvh import MAX_DEPTH, parse_bvh, read_bvh  # noqa: E402
from habitsim.errors import BVHParseError, MotionFileError  # noqa: E402

EXAMPLE_BVH = Path(__file__).parents[1] / "habitsim" / "examples" / "dog_walk.bvh"


def small_bvh(offset: str = "0 0 1", frame_time: str = "0.0333333", root: str = "0 0 0") -> str:
    return (
        "HIERARCHY\nROOT hips\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition "
        f"Zrotation Xrotation Yrotation\n  JOINT spine\n  {{\n    OFFSET {offset}\n"
        "    CHANNELS 3 Zrotation Xrotation Yrotation\n    End Site\n    {\n      OFFSET 0 0 1\n"
        f"    }}\n  }}\n}}\nMOTION\nFrames: 2\nFrame Time: {frame_time}\n"
        f"{root} 0 0 0 0 0 0\n0 0 0 0 0 0 0 0 0\n"
    )


def test_small_bvh_reads() -> None:
    assert parse_bvh(small_bvh()).num_frames == 2


@pytest.mark.parametrize("ft", ["1e-320", "0", "-0.1", "1e-9", "3600", "1e300"])
def test_bvh_frame_time_out_of_range(ft: str) -> None:
    with pytest.raises(BVHParseError, match=r"frame time .*1 to 1000 Hz"):
        parse_bvh(small_bvh(frame_time=ft))


def test_bvh_all_zero_offsets() -> None:
    text = small_bvh(offset="0 0 0").replace("OFFSET 0 0 1", "OFFSET 0 0 0")
    with pytest.raises(BVHParseError, match="OFFSET is zero"):
        parse_bvh(text)


@pytest.mark.parametrize("where", ["offset", "root"])
def test_bvh_absurd_values(where: str) -> None:
    text = small_bvh(offset="0 0 1e300") if where == "offset" else small_bvh(root="1e300 0 0")
    with pytest.raises(BVHParseError, match=r"valid: \|value\| <= 1e\+07"):
        parse_bvh(text)


def test_bvh_deep_nesting_is_bounded() -> None:
    depth = 1000
    head = "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 1\nCHANNELS 0\n"
    body = "".join(f"JOINT j{k}\n{{\nOFFSET 0 0 1\nCHANNELS 1 Xrotation\n" for k in range(1, depth))
    text = head + body + "}\n" * depth + "MOTION\nFrames: 1\nFrame Time: 0.1\n" + "0 " * (depth - 1)
    with pytest.raises(BVHParseError, match=f"at most {MAX_DEPTH}"):
        parse_bvh(text)


def test_bvh_huge_token_is_not_echoed(tmp_path: Path) -> None:
    token = "x" * 5_000_000
    for text in (
        small_bvh().replace("OFFSET 0 0 1", f"OFFSET 0 0 {token}", 1),
        small_bvh().replace("Frames: 2", f"Frames: {token}"),
        small_bvh().replace("0 0 0 0 0 0 0 0 0\n", f"0 0 0 0 0 0 0 0 {token}\n0 0 0 0 0 0 0 0 0\n"),
    ):
        with pytest.raises(BVHParseError) as ei:
            parse_bvh(text)
        assert len(str(ei.value)) < 300


def test_bvh_without_motion_fails_before_reading_it_whole(tmp_path: Path) -> None:
    import tracemalloc

    p = tmp_path / "big.bvh"
    with p.open("w") as fh:
        fh.write("HIERARCHY\nROOT hips\n{\n  OFFSET 0 0 0\n")
        line = "  OFFSET 1 2 3 " + "4 " * 40 + "\n"
        for _ in range(50_000_000 // len(line)):
            fh.write(line)
    tracemalloc.start()
    try:
        with pytest.raises(BVHParseError, match=":5: "):
            read_bvh(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 300 * 2**20  # the 50 MB file is never held (let alone tokenised) whole


def test_bvh_long_hierarchy_without_motion(tmp_path: Path) -> None:
    p = tmp_path / "long.bvh"
    joint = "JOINT j{k}\n{{\nOFFSET 0 0 1\nCHANNELS 1 Xrotation\n}}\n"
    joints = "".join(joint.format(k=k) for k in range(40_000))
    p.write_text("HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 0\n" + joints)
    with pytest.raises(BVHParseError, match="joints|no MOTION"):
        read_bvh(p)


def test_bvh_example_still_imports() -> None:
    from habitsim.bvh_mapping import import_bvh
    from habitsim.species import load_species

    motion, _ = import_bvh(EXAMPLE_BVH, load_species("dog"))
    assert motion.num_frames > 10


def test_bvh_cli_error_is_exit_2(tmp_path: Path, capsys) -> None:
    p = tmp_path / "bad.bvh"
    p.write_text(small_bvh(frame_time="1e-320"))
    code, err = run_cli(
        [
            "transfer",
            p,
            "--from",
            "dog",
            "--to",
            "cat",
            "--method",
            "direct",
            "--out",
            tmp_path / "o.npz",
        ],
        capsys,
    )
    assert code == 2 and err.startswith("error: ") and "frame time" in err
    assert files_under(tmp_path) == ["bad.bvh"]


# ------------------------------------------------------------------ .npz motion reader


def _motion_arrays() -> dict[str, np.ndarray]:
    from habitsim.gaits import generate

    m = generate("dog", "walk", seed=0, duration_s=0.3)
    with np.load(_save(m)) as z:
        return {k: z[k] for k in z.files}


def _save(m) -> Path:
    import tempfile

    p = Path(tempfile.mkdtemp()) / "m.npz"
    m.save(p)
    return p


@pytest.fixture(scope="module")
def arrays() -> dict[str, np.ndarray]:
    return _motion_arrays()


def write_npz(tmp_path: Path, arrays: dict[str, np.ndarray], **changes) -> Path:
    d = {**arrays, **changes}
    d = {k: v for k, v in d.items() if v is not None}
    p = tmp_path / "m.npz"
    with p.open("wb") as fh:
        np.savez(fh, **d)
    return p


NPZ_CASES = {
    "format_version_str": dict(format_version=np.array("1")),
    "format_version_array": dict(format_version=np.array([1, 1])),
    "format_version_nan": dict(format_version=np.array(np.nan)),
    "joint_names_0d": dict(joint_names=np.array("pelvis")),
    "joint_names_numbers": dict(joint_names=np.arange(27)),
    "fps_array": dict(fps=np.array([30.0, 30.0])),
    "fps_str": dict(fps=np.array("30")),
    "fps_huge": dict(fps=np.array(1e300)),
    "fps_tiny": dict(fps=np.array(1e-300)),
    "species_array": dict(species=np.array(["dog", "cat"])),
    "species_number": dict(species=np.array(3)),
    "rotations_str": dict(rotations=np.array([["a"]])),
    "root_str": dict(root_positions=np.array(["x", "y", "z"])),
    "contacts_str": dict(contacts=np.array([["a"] * 4])),
    "metadata_list": dict(metadata_json=np.array("[1, 2]")),
    "metadata_deep": dict(metadata_json=np.array("[" * 100_000 + "]" * 100_000)),
    "metadata_deep_object": dict(metadata_json=np.array('{"a":' + "[" * 200 + "]" * 200 + "}")),
    "metadata_bytes": dict(metadata_json=np.array(b"{}")),
}


@pytest.mark.parametrize("case", sorted(NPZ_CASES))
def test_npz_bad_fields_are_typed(tmp_path: Path, arrays, case: str) -> None:
    from habitsim.motion import load_motion

    p = write_npz(tmp_path, arrays, **NPZ_CASES[case])
    with pytest.raises(HabitsimError) as ei:
        load_motion(p)
    assert len(str(ei.value)) < 400


def test_npz_root_far_away(tmp_path: Path, arrays) -> None:
    from habitsim.errors import InvalidMotionError
    from habitsim.motion import load_motion

    root = arrays["root_positions"].copy()
    root[0, 0] = 1e300
    with pytest.raises(InvalidMotionError, match="root_positions reach"):
        load_motion(write_npz(tmp_path, arrays, root_positions=root))


def test_npy_under_npz_name(tmp_path: Path) -> None:
    from habitsim.motion import load_motion

    p = tmp_path / "m.npz"
    with p.open("wb") as fh:
        np.save(fh, np.zeros(3))
    with pytest.raises(MotionFileError, match="single .npy array"):
        load_motion(p)


def test_non_npz_refused_in_our_words(tmp_path: Path, arrays) -> None:
    from habitsim.motion import load_motion

    p = tmp_path / "m.npz"
    np.savez(p, **arrays, extra=np.array([object()], dtype=object))
    with pytest.raises(MotionFileError) as ei:
        load_motion(p)
    assert "allow_pickle" not in str(ei.value) and "never loads" in str(ei.value)
    p.write_text("hello")
    with pytest.raises(MotionFileError, match="not a zip"):
        load_motion(p)


def test_npz_zip_bomb_is_refused_from_the_headers(tmp_path: Path, arrays) -> None:
    import tracemalloc

    from habitsim.motion import load_motion

    big = np.zeros((40_000, 27, 4, 8))  # 276 MB of zeros, compresses to < 1 MB
    p = tmp_path / "bomb.npz"
    np.savez_compressed(p, **{**arrays, "rotations": big})
    del big
    assert p.stat().st_size < 2 * 2**20
    tracemalloc.start()
    try:
        with pytest.raises(MotionFileError, match="decompress"):
            load_motion(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 * 2**20


@pytest.mark.parametrize(
    "kw",
    [
        dict(fps=1e300),
        dict(fps=1e-300),
        dict(fps="30"),
        dict(fps=np.array([30.0])),
        dict(root=1e300),
        dict(root="x"),
    ],
)
def test_motion_absurd_but_finite(kw) -> None:
    from habitsim.motion import Motion
    from habitsim.skeleton import get_skeleton

    root, rot = get_skeleton("dog").standing_pose()
    rp = np.repeat(root[None], 3, axis=0)
    if "root" in kw:
        rp = np.full((3, 3), kw["root"], dtype=object if isinstance(kw["root"], str) else float)
    with pytest.raises(HabitsimError):
        Motion("dog", kw.get("fps", 30.0), rp, np.repeat(rot[None], 3, axis=0))


# ------------------------------------------------------------------ species, manifest, run state


def _species_toml(tmp_path: Path, old: str, new: str, top: str = "") -> Path:
    """The dog's species file with ``old`` replaced by ``new`` (every time) and ``top``
    put first (top-level keys)."""
    from habitsim.species import load_species

    text = load_species("dog").path.read_text(encoding="utf-8")
    assert old in text
    p = tmp_path / "dog.toml"
    p.write_text(top + "\n" + text.replace(old, new), encoding="utf-8")
    return p


@pytest.mark.parametrize(
    "old, new, top, match",
    [
        ("[posture]", "[xposture]", "posture = 5", "posture must be a table"),
        ("[gaits.", "[xgaits.", 'gaits = "x"', "gaits must be a table"),
        ("[segments]", "[xsegments]", "segments = [1, 2]", "segments must be a table"),
        ("mass_kg = ", "mass_kg = 1e300 # ", "", "within"),
        ("mass_kg = ", "mass_kg = 100000000000000000000 # ", "", "within"),
    ],
    ids=["posture_int", "gaits_str", "segments_list", "mass_huge", "mass_bigint"],
)
def test_species_toml_wrong_types(tmp_path: Path, old: str, new: str, top: str, match: str):
    from habitsim.errors import SpeciesFileError
    from habitsim.species import load_species_file

    with pytest.raises(SpeciesFileError, match=match):
        load_species_file(_species_toml(tmp_path, old, new, top))


def test_species_cli_bad_file_exit_2(tmp_path: Path, capsys) -> None:
    from habitsim.species import load_species_file

    p = _species_toml(tmp_path, "[posture]", "[xposture]", "posture = 5")
    with pytest.raises(HabitsimError):
        load_species_file(p)


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.dataset import build_dataset

    out = tmp_path_factory.mktemp("data")
    build_dataset(
        out, clips_per_species=1, seed=0, species=["cat", "dog"], workers=1, progress=False
    )
    return out


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


EVAL_ARGS = [
    "--methods",
    "direct",
    "--refine",
    "none",
    "--workers",
    "1",
    "--report-pairs",
    "0",
    "--no-videos",
    "--no-report",
    "--no-progress",
    "--max-clips",
    "1",
    "--split",
    "train",
    "--no-track",
    "--no-dynamic",
    "--targets",
    "all",
]


@pytest.fixture(scope="module")
def eval_run(small_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("eval") / "run"
    assert main(["eval", "--data", str(small_dataset), "--out", str(out), *EVAL_ARGS]) == 0
    return out


@pytest.mark.parametrize(
    "tamper",
    [
        "run_list",
        "run_config_str",
        "run_deep",
        "row_list",
        "row_no_key",
        "row_wrong_key",
        "row_deep",
    ],
)
def test_eval_resume_tampered_state(
    tmp_path: Path, small_dataset: Path, eval_run: Path, capsys, tamper: str
) -> None:
    import json
    import shutil

    out = tmp_path / "run"
    shutil.copytree(eval_run, out)
    run, rows = out / "run.json", sorted((out / "rows").glob("*.json"))
    assert rows
    deep = "[" * 100_000 + "]" * 100_000
    if tamper == "run_list":
        run.write_text("[1, 2]")
    elif tamper == "run_config_str":
        run.write_text(json.dumps({"config": "x"}))
    elif tamper == "run_deep":
        run.write_text(deep)
    elif tamper == "row_list":
        rows[0].write_text("[1]")
    elif tamper == "row_no_key":
        rows[0].write_text(json.dumps({"status": "ok"}))
    elif tamper == "row_wrong_key":
        rows[0].write_text(json.dumps({"key": 5, "status": "ok"}))
    elif tamper == "row_deep":
        rows[0].write_text(deep)
    code, err = run_cli(
        ["eval", "--data", small_dataset, "--out", out, *EVAL_ARGS, "--resume"], capsys
    )
    assert code == 2 and err.startswith("error: ") and len(err) < 600, err


# ------------------------------------------------------------------ CLI argument bounds


@pytest.mark.parametrize(
    "argv, match",
    [
        (["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--seed", str(2**64)], "--seed"),
        (["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--seed", "-1"], "--seed"),
        (
            ["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--temperature", "0"],
            "--temperature",
        ),
        (
            ["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--temperature", "-1"],
            "--temperature",
        ),
        (
            ["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--temperature", "nan"],
            "--temperature",
        ),
        (["track", "{m}", "--settle", "1e9"], "--settle"),
        (["track", "{m}", "--control-hz", "inf"], "--control-hz"),
        (["data", "synth", "--out", "{t}/d", "--fps", "100000"], "fps"),
        (["data", "synth", "--out", "{t}/d", "--fps", "0.001"], "fps"),
        (["data", "synth", "--out", "{t}/d", "--seed", str(2**64)], "--seed"),
        (["eval", "--data", "{t}", "--out", "{t}/e", "--workers", "100000"], "--workers"),
    ],
)
def test_cli_argument_bounds(tmp_path: Path, motion_file: Path, capsys, argv, match) -> None:
    argv = [a.format(m=motion_file, t=tmp_path) for a in argv]
    code, err = run_cli(argv, capsys)
    assert code == 2 and err.startswith("error: ") and match in err, err
    assert "valid" in err
    assert files_under(tmp_path) == []


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


def test_npz_corrupt_array_header(tmp_path: Path, arrays) -> None:
    """A member whose .npy header dict is cut short (numpy raises tokenize.TokenError)."""
    import io
    import zipfile

    from habitsim.motion import load_motion

    p = tmp_path / "m.npz"
    with zipfile.ZipFile(p, "w") as zf:
        for k, v in arrays.items():
            buf = io.BytesIO()
            np.save(buf, v)
            raw = buf.getvalue()
            if k == "fps":  # the header dict left open: {'descr': '<f8', ... (no '}')
                raw = raw.replace(b"}", b" ", 1)
            zf.writestr(f"{k}.npy", raw)
    with pytest.raises(MotionFileError, match="not a readable"):
        load_motion(p)


@pytest.mark.parametrize("command", ["synth", "eval"])
def test_output_folder_under_a_file(tmp_path: Path, small_dataset: Path, capsys, command) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    if command == "synth":
        argv = [
            "data",
            "synth",
            "--out",
            blocker / "d",
            "--species",
            "cat",
            "--clips-per-species",
            "1",
            "--workers",
            "1",
            "--no-progress",
        ]
    else:
        argv = ["eval", "--data", small_dataset, "--out", blocker / "e", *EVAL_ARGS]
    code, err = run_cli(argv, capsys)
    assert code == 2 and err.startswith("error: ") and "file where a folder" in err, err
    assert files_under(tmp_path) == ["blocker"]


# ------------------------------------------------------------------ same seed, same bytes

import json  # noqa: E402
import re  # noqa: E402

#: Keys of wall-clock measurements in JSON reports and tables (never in array files).
_TIMING_KEY = re.compile(
    r"(wall|cpu|solve|build|mean|max)_time|^time_|realtime_factor|median_ms$|^cpu_total_s$"
)


def _without_timing(v, drop: tuple[str, ...] = ()):
    if isinstance(v, dict):
        return {
            k: _without_timing(x, drop)
            for k, x in v.items()
            if not _TIMING_KEY.search(str(k)) and k not in drop
        }
    if isinstance(v, list):
        return [_without_timing(x, drop) for x in v]
    return v


def _same_bytes(a: Path, b: Path) -> None:
    assert a.read_bytes() == b.read_bytes(), f"{a.name}: same seed, different bytes"


def _same_report(a: Path, b: Path, drop: tuple[str, ...] = ()) -> None:
    """Same JSON but for timing keys (and the keys ``drop``, e.g. the output folder)."""
    ra, rb = (_without_timing(json.loads(p.read_text()), drop) for p in (a, b))
    assert ra == rb, f"{a.name}: same seed, different report (timing keys removed)"


def _twice(tmp_path: Path, capsys, argv: list) -> tuple[Path, Path]:
    """Run ``habitsim ARGV`` in folders run1/ and run2/ ({d} = the folder)."""
    outs = []
    for k in (1, 2):
        d = tmp_path / f"run{k}"
        d.mkdir()
        code, err = run_cli([str(a).format(d=d) for a in argv], capsys)
        assert code == 0, err
        outs.append(d)
    return outs[0], outs[1]


def test_same_seed_synth_is_byte_identical(tmp_path: Path, capsys) -> None:
    a, b = _twice(
        tmp_path,
        capsys,
        [
            "data",
            "synth",
            "--out",
            "{d}/data",
            "--species",
            "cat,dog",
            "--clips-per-species",
            "1",
            "--workers",
            "1",
            "--no-progress",
        ],
    )
    files = files_under(a / "data")
    assert files == files_under(b / "data") and any(f.endswith(".npz") for f in files)
    for f in files:
        if (a / "data" / f).is_file():
            _same_bytes(a / "data" / f, b / "data" / f)


@pytest.mark.parametrize("method", ["direct", "habit"])
def test_same_seed_transfer_is_byte_identical(
    tmp_path: Path, motion_file: Path, capsys, method: str
) -> None:
    argv = ["transfer", motion_file, "--to", "cat", "--method", method, "--seed", "3"]
    a, b = _twice(tmp_path, capsys, [*argv, "--out", "{d}/o.npz", "--bvh", "{d}/o.bvh"])
    _same_bytes(a / "o.npz", b / "o.npz")
    _same_bytes(a / "o.bvh", b / "o.bvh")


@pytest.mark.slow
def test_same_seed_refine_is_byte_identical(tmp_path: Path, motion_file: Path, capsys) -> None:
    a, b = _twice(
        tmp_path,
        capsys,
        [
            "refine",
            motion_file,
            "--max-iter",
            "20",
            "--out",
            "{d}/r.npz",
            "--qpos",
            "{d}/q.npz",
            "--report",
            "{d}/r.json",
        ],
    )
    _same_bytes(a / "r.npz", b / "r.npz")  # no solve time in the motion's metadata
    _same_bytes(a / "q.npz", b / "q.npz")
    _same_report(a / "r.json", b / "r.json")


@pytest.mark.slow
def test_same_seed_track_is_byte_identical(tmp_path: Path, motion_file: Path, capsys) -> None:
    a, b = _twice(
        tmp_path, capsys, ["track", motion_file, "--out", "{d}/s.npz", "--report", "{d}/s.json"]
    )
    _same_bytes(a / "s.npz", b / "s.npz")
    _same_report(a / "s.json", b / "s.json")


def test_same_seed_eval_tables_are_identical(
    tmp_path: Path, small_dataset: Path, eval_run: Path, capsys
) -> None:
    import csv

    from habitsim.evaluation.runner import VOLATILE_COLUMNS

    again = tmp_path / "run"
    code, err = run_cli(["eval", "--data", small_dataset, "--out", again, *EVAL_ARGS], capsys)
    assert code == 0, err
    assert files_under(eval_run) == files_under(again)
    arrays = [f for f in files_under(again) if f.endswith(".npz")]
    assert arrays
    for f in [*arrays, "summary.csv"]:
        _same_bytes(eval_run / f, again / f)

    def rows(p: Path) -> list[dict]:
        with p.open(newline="", encoding="utf-8") as fh:
            return [
                {k: v for k, v in r.items() if k not in VOLATILE_COLUMNS}
                for r in csv.DictReader(fh)
            ]

    assert rows(eval_run / "rows.csv") == rows(again / "rows.csv")
    for f in ["summary.json", *(f for f in files_under(again) if f.startswith("rows/"))]:
        _same_report(eval_run / f, again / f, drop=("out",))


# ------------------------------------------------------------------ every writer: typed errors

#: The two unwritable destinations of each writer's regression test: a file where a folder
#: should be, and a read-only folder (skipped for the super-user, who writes there anyway).
UNWRITABLE = [
    "file",
    pytest.param(
        "read_only",
        marks=pytest.mark.skipif(os.geteuid() == 0, reason="the super-user writes anywhere"),
    ),
]


@pytest.fixture
def unwritable(tmp_path: Path, request):
    """A folder path nothing can be written under (``request.param``: "file" or
    "read_only"); the read-only folder is made writable again at the end."""
    kind = request.param
    if kind == "file":
        blocker = tmp_path / "blocker"
        blocker.write_text("a file where a folder should be")
        yield blocker / "sub"
        return
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        yield ro / "sub"
    finally:
        ro.chmod(0o755)


def _typed_output_error(exc: BaseException) -> None:
    assert isinstance(exc, OutputPathError), repr(exc)
    assert len(str(exc)) < 600


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_save_checkpoint_unwritable(unwritable: Path) -> None:
    from habitsim.models import shipped_checkpoint
    from habitsim.models.checkpoint import export_checkpoint, load_checkpoint, save_checkpoint

    src = shipped_checkpoint()
    ck = load_checkpoint(src)
    with pytest.raises(OutputPathError) as ei:
        save_checkpoint(unwritable / "ck", ck.model, ck.config, {"fps": 30.0})
    _typed_output_error(ei.value)
    with pytest.raises(OutputPathError) as ei:
        export_checkpoint(src, unwritable / "shipped")
    _typed_output_error(ei.value)
    assert not unwritable.exists()


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_train_checked_before_training(unwritable: Path, small_dataset: Path, capsys) -> None:
    code, err = run_cli(
        ["train", "--data", small_dataset, "--out", unwritable / "ck", "--config", "small"],
        capsys,
    )
    assert code == 2 and err.startswith("error: ") and "--out" in err, err
    assert not unwritable.exists()


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_evaluator_unwritable(unwritable: Path, small_dataset: Path) -> None:
    from habitsim.evaluation.evaluator import load_evaluator, save_evaluator, train_evaluator

    calls = []
    with pytest.raises(OutputPathError) as ei:  # refused before training
        train_evaluator(small_dataset, unwritable / "e", progress=False, log=calls.append)
    _typed_output_error(ei.value)
    assert calls == []
    ev = load_evaluator()
    with pytest.raises(OutputPathError) as ei:
        save_evaluator(
            ev.model,
            unwritable / "e",
            accuracy={},
            data_dir=small_dataset,
            seed=0,
            clips_per_species=1,
            wall_time_s=0.0,
            final_loss=0.0,
        )
    _typed_output_error(ei.value)
    assert not unwritable.exists()


@pytest.mark.parametrize("where", ["report_files", "report.html", "summary.csv"])
def test_eval_outputs_checked_before_the_run(
    tmp_path: Path, small_dataset: Path, capsys, where: str
) -> None:
    """A folder where a table should be, or a file where report_files/ should be."""
    out = tmp_path / "run"
    out.mkdir()
    if where == "report_files":
        (out / where).write_text("x")
    else:
        (out / where).mkdir()
    args = [a for a in EVAL_ARGS if a != "--no-report"]
    code, err = run_cli(["eval", "--data", small_dataset, "--out", out, *args], capsys)
    assert code == 2 and err.startswith("error: ") and where in err, err
    assert not list((out / "rows").glob("*.json"))  # no pair ran


def test_write_report_unwritable(tmp_path: Path, eval_run: Path) -> None:
    import shutil

    from habitsim.evaluation.report import write_report

    for case in ("file", "folder_inside"):
        out = tmp_path / case
        shutil.copytree(eval_run, out)
        shutil.rmtree(out / "report_files", ignore_errors=True)
        if case == "file":
            (out / "report_files").write_text("x")
        else:  # an old figure that is a folder cannot be cleared
            (out / "report_files" / "01_old.png").mkdir(parents=True)
        with pytest.raises(OutputPathError) as ei:
            write_report(out)
        _typed_output_error(ei.value)
        assert not (out / "report.html").exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="the super-user writes into read-only folders")
def test_write_report_read_only(tmp_path: Path, eval_run: Path) -> None:
    import shutil

    from habitsim.evaluation.report import write_report

    out = tmp_path / "run"
    shutil.copytree(eval_run, out)
    (out / "report_files").chmod(0o555)
    try:
        with pytest.raises(OutputPathError):
            write_report(out)
    finally:
        (out / "report_files").chmod(0o755)


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_demo_checked_before_work(unwritable: Path, tmp_path: Path, capsys) -> None:
    code, err = run_cli(["demo", "--out", unwritable / "demo", "--no-progress"], capsys)
    assert code == 2 and err.startswith("error: "), err
    assert not unwritable.exists()


@pytest.mark.parametrize("blocked", ["pipeline", "report_files", "report.md"])
def test_demo_pipeline_outputs_checked_before_the_data_set(
    tmp_path: Path, capsys, blocked: str
) -> None:
    out = tmp_path / "demo"
    out.mkdir()
    if blocked == "report.md":
        (out / blocked).mkdir()
    else:
        (out / blocked).write_text("x")
    code, err = run_cli(["demo", "--out", out, "--no-progress"], capsys)
    assert code == 2 and err.startswith("error: ") and blocked in err, err
    assert files_under(out) == [blocked]  # the data set was not built


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_synth_into_unwritable_folder(unwritable: Path, capsys) -> None:
    argv = ["data", "synth", "--species", "cat", "--clips-per-species", "1", "--workers", "1"]
    code, err = run_cli([*argv, "--no-progress", "--out", unwritable / "d"], capsys)
    assert code == 2 and err.startswith("error: "), err
    assert not unwritable.exists()


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


def test_make_dirs_read_only_even_for_root(tmp_path: Path, monkeypatch) -> None:
    from habitsim.fileio import make_dirs

    def denied(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "mkdir", denied)
    with pytest.raises(OutputPathError, match="Permission denied"):
        make_dirs(tmp_path / "x" / "y", "checkpoint folder")


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
@pytest.mark.parametrize("command", ["import-bvh", "export-bvh"])
def test_bvh_commands_checked_before_work(
    unwritable: Path, motion_file: Path, capsys, command: str
) -> None:
    if command == "import-bvh":
        argv = ["data", "import-bvh", EXAMPLE_BVH, "--species", "dog"]
        argv += ["--out", unwritable / "m.npz"]
    else:
        argv = ["data", "export-bvh", motion_file, "--out", unwritable / "m.bvh"]
    code, err = run_cli(argv, capsys)
    assert code == 2 and err.startswith("error: ") and "--out" in err, err
    assert not unwritable.exists()


@pytest.mark.parametrize("flag", ["--out", "--report", "--video"])
def test_retarget_outputs_checked_together(
    tmp_path: Path, motion_file: Path, capsys, flag: str
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    paths = {
        "--out": tmp_path / "q.npz",
        "--report": tmp_path / "r.json",
        "--video": tmp_path / "v.gif",
    }
    paths[flag] = blocker / paths[flag].name
    argv = ["retarget", motion_file, "--robot", tmp_path / "missing.xml", "--feet", "a,b,c,d"]
    argv += ["--track", *(x for k, p in paths.items() for x in (k, p))]
    code, err = run_cli(argv, capsys)
    assert code == 2 and "file where a folder" in err and flag in err, err
    assert files_under(tmp_path) == ["blocker"]


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_write_golden_unwritable(unwritable: Path) -> None:
    from habitsim.testing import write_golden

    with pytest.raises(OutputPathError) as ei:
        write_golden(unwritable / "g.json", {"x": 1.0})
    _typed_output_error(ei.value)


# ------------------------------------------------------------------ absurd but valid-shaped inputs


def _absurd(species: str, frames: int, fps: float, root_shift=(0.0, 0.0, 0.0), flip=False):
    from habitsim.motion import Motion
    from habitsim.skeleton import get_skeleton

    root, rot = get_skeleton(species).standing_pose()
    rp = np.repeat(root[None], frames, axis=0) + np.asarray(root_shift, float)
    q = np.repeat(rot[None], frames, axis=0)
    if flip:
        q[::2] *= -1.0
    return Motion(species, fps, rp, q)


@pytest.mark.slow
def test_refine_far_root_summary_prints(tmp_path: Path, capsys) -> None:
    """A camel 75 km from the origin (3 frames at 240 fps): the report's verdict holds
    missing figures, which the summary printed with a TypeError."""
    src = tmp_path / "camel.npz"
    _absurd("camel", 3, 240.0, (-0.8e5, 0.0, 0.0), flip=True).save(src)
    code = main(["refine", str(src), "--out", str(tmp_path / "r.npz"), "--max-iter", "3"])
    captured = capsys.readouterr()
    assert code in (0, 1, 2), captured.err
    assert code != 2 or captured.err.startswith("error: ")


def test_refine_summary_missing_figures() -> None:
    from habitsim.cli.refine_cmd import _summary

    rep = {
        "species": "camel",
        "frames": 3,
        "stage": "A",
        "status": "Solve_Succeeded",
        "iterations": 3,
        "solve_time_s": None,
        "windows": [{}],
        "max_constraint_violation": None,
        "checks": {"stance_drift_max_mm": None, "penetration_max_mm": float("nan")},
        "cost": {"track": None},
        "metrics_before": {"skate_mm": None, "jerk": 1.0},
        "metrics_after": {"skate_mm": 2.0, "jerk": float("nan")},
        "verdict": {
            "before": {"skate_mm": None, "jerk": 1.0, "penetration_mm": None},
            "after": {"skate_mm": None, "jerk": None, "penetration_mm": 0.0},
            "ok": True,
            "worse": [],
        },
        "residual_mg": {"mean": None, "max": 1.0},
    }
    text = _summary(rep)
    assert "skate_mm n/a → n/a" in text and "n/a" in text


def test_eval_tables_when_no_pair_has_features(tmp_path: Path, eval_run: Path) -> None:
    """Every pair failed (an absurd clip): the tables are still written, features
    (0, 0), instead of a ValueError from reshape."""
    from habitsim.evaluation.runner import load_rows, write_tables

    rows = [{k: v for k, v in r.items() if k != "features"} for r in load_rows(eval_run)]
    for r in rows:
        r.update(status="error", note="InvalidMotionError: x")
    write_tables(tmp_path, rows)
    with np.load(tmp_path / "features.npz") as z:
        assert z["features"].shape == (0, 0) and z["keys"].shape == (0,)


def test_track_balance_far_below_the_floor(tmp_path: Path, capsys) -> None:
    """A cat 100 km under the floor held by the balance controller: the stance QP's
    least-squares fallback met a matrix singular in floating point (LinAlgError)."""
    from habitsim.motion import Motion
    from habitsim.skeleton import get_skeleton

    root, rot = get_skeleton("cat").standing_pose()
    rp = np.repeat(root[None], 7, axis=0)
    rp[:, 2] = -1e5
    q = np.zeros((7, rot.shape[0], 4))
    q[..., 0] = 1.0
    contacts = np.array(
        [[0, 0, 1, 1], [1, 1, 1, 1], [1, 0, 0, 0], [1, 0, 1, 0], [0, 0, 1, 1], [0, 0, 1, 1]]
        + [[0, 0, 0, 1]],
        dtype=bool,
    )
    src = tmp_path / "cat.npz"
    Motion("cat", 30.0, rp, q, contacts, {"action": "trot"}).save(src)
    argv = ["track", src, "--controller", "balance", "--out", tmp_path / "o.npz"]
    code, err = run_cli([*argv, "--settle", "0.3", "--control-hz", "1", "--assist", "root"], capsys)
    assert code in (0, 1) or (code == 2 and err.startswith("error: ")), err
