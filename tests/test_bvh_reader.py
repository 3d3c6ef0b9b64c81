"""The BVH reader's bounds (habitsim.bvh): absurd values, deep nesting, huge tokens and files
without motion end in a typed error of bounded length."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import EXAMPLE_BVH, files_under, run_cli

from habitsim.bvh import MAX_DEPTH, parse_bvh, read_bvh
from habitsim.errors import BVHParseError


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
