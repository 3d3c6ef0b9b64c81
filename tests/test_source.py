"""Reading a clip file the one way every command does (habitsim.source): .npz and motion
capture, the span kept, and the errors for options that do not apply."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from helpers import EXAMPLE_BVH, run_cli

from habitsim.bvh import read_bvh
from habitsim.errors import ArgumentRangeError, MotionFileError, UnknownSpeciesError
from habitsim.motion import load_motion
from habitsim.source import SourceOptions, Span, cut_source, load_clip


@pytest.fixture(scope="module")
def walk_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.gaits import generate

    p = tmp_path_factory.mktemp("walk") / "walk.npz"
    generate("dog", "walk", seed=0, duration_s=2.0).save(p)
    return p


def test_npz_span_keeps_the_frames_of_its_seconds(walk_file: Path) -> None:
    whole = load_motion(walk_file)
    clip = load_clip(walk_file, SourceOptions(span=Span(0.5, 1.5)))
    first = int(round(0.5 * whole.fps))
    stop = int(round(1.5 * whole.fps))
    assert clip.mapping is None
    assert clip.first_frame == first and clip.cut
    assert clip.motion.num_frames == stop - first
    np.testing.assert_array_equal(clip.motion.root_positions, whole.root_positions[first:stop])
    assert "of the file's" in clip.kept()
    assert not load_clip(walk_file).cut and load_clip(walk_file).kept() == ""


def test_bvh_span_is_cut_before_the_import() -> None:
    whole = load_clip(EXAMPLE_BVH, SourceOptions(species="dog"))
    part = load_clip(EXAMPLE_BVH, SourceOptions(species="dog", span=Span(start_s=1.0)))
    fps = read_bvh(EXAMPLE_BVH).fps
    assert part.first_frame == int(round(fps)) and part.source_frames == whole.motion.num_frames
    assert part.motion.num_frames == whole.motion.num_frames - part.first_frame
    # the same source joints, one second later: the imported trunk path follows the file's
    assert part.mapping is not None and part.mapping.mapped() == whole.mapping.mapped()
    np.testing.assert_allclose(
        part.motion.root_positions[:, 2],
        whole.motion.root_positions[part.first_frame :, 2],
        atol=0.02,
    )


def test_cut_source_keeps_every_channel_of_the_span() -> None:
    bvh = read_bvh(EXAMPLE_BVH)
    cut, first = cut_source(bvh, Span(end_s=1.0))
    assert first == 0 and cut.num_frames == int(round(bvh.fps))
    np.testing.assert_array_equal(cut.frames, bvh.frames[: cut.num_frames])
    assert cut_source(bvh, Span()) == (bvh, 0)


@pytest.mark.parametrize(
    ("span", "words"),
    [
        (Span(start_s=1e4), "keeps 0 frame"),
        (Span(0.0, 0.01), "at least two frames"),
    ],
)
def test_a_span_outside_the_clip_is_refused(walk_file: Path, span: Span, words: str) -> None:
    with pytest.raises(ArgumentRangeError, match=words):
        load_clip(walk_file, SourceOptions(span=span))


@pytest.mark.parametrize(
    ("start", "end", "words"),
    [(-1.0, None, "--start must be"), (None, float("nan"), "--end must be"), (2.0, 1.0, "after")],
)
def test_a_malformed_span_is_refused(start, end, words: str) -> None:
    with pytest.raises(ArgumentRangeError, match=words):
        Span(start, end)


def test_import_options_on_a_habitsim_motion_are_refused(walk_file: Path) -> None:
    with pytest.raises(MotionFileError, match=r"--map, --up apply to motion capture"):
        load_clip(walk_file, SourceOptions(joint_map={"pelvis": "x"}, up="y"))


def test_motion_capture_needs_a_known_species(tmp_path: Path) -> None:
    with pytest.raises(MotionFileError, match="needs a species"):
        load_clip(EXAMPLE_BVH)
    with pytest.raises(UnknownSpeciesError):
        load_clip(EXAMPLE_BVH, SourceOptions(species="unicorn"))
    odd = tmp_path / "clip.fbx"
    odd.write_bytes(b"")
    with pytest.raises(MotionFileError, match=r"valid: \.npz, \.bvh, \.glb, \.gltf"):
        load_clip(odd)


def test_import_bvh_command_writes_only_the_span(tmp_path: Path, capsys) -> None:
    out = tmp_path / "part.npz"
    code, err = run_cli(
        [
            "data",
            "import-bvh",
            EXAMPLE_BVH,
            "--species",
            "dog",
            "--out",
            out,
            "--start",
            "1",
            "--end",
            "2.5",
        ],
        capsys,
    )
    assert code == 0, err
    m = load_motion(out)
    assert m.num_frames == int(round(2.5 * m.fps)) - int(round(1.0 * m.fps))


def test_span_with_a_folder_import_is_refused(tmp_path: Path, capsys) -> None:
    code, err = run_cli(
        [
            "data",
            "import-bvh",
            "--dir",
            tmp_path,
            "--species",
            "dog",
            "--out",
            tmp_path / "o",
            "--start",
            "1",
        ],
        capsys,
    )
    assert code == 2 and "--start apply to one file" in err
