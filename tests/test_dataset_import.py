"""``habitsim data import-bvh --dir``: a data set from a folder of motion-capture files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from habitsim.bvh import write_bvh
from habitsim.cli import main
from habitsim.dataset import iter_clips, load_manifest
from habitsim.dataset_import import IMPORT_KIND, import_folder, read_labels
from habitsim.errors import (
    BVHParseError,
    DatasetError,
    InputPathError,
    OutputBusyError,
    OutputFolderError,
)
from habitsim.gaits import generate


@pytest.fixture(scope="module")
def mocap(tmp_path_factory):
    """A folder of BVH files the project writes itself (one in a sub-folder)."""
    root = tmp_path_factory.mktemp("mocap")
    (root / "more").mkdir()
    for name, action, seed in (("Walk 01", "walk", 1), ("trot_02", "trot", 2)):
        write_bvh(generate("dog", action, seed=seed, duration_s=1.5), root / f"{name}.bvh")
    write_bvh(generate("dog", "walk", seed=3, duration_s=1.0, fps=60.0), root / "more/w3.bvh")
    (root / "notes.txt").write_text("not a motion file\n")
    return root


@pytest.mark.slow
def test_a_folder_becomes_a_data_set(mocap, tmp_path):
    labels = tmp_path / "labels.csv"
    labels.write_text("file,action,split\nWalk 01.bvh,walk,\ntrot_02.bvh,trot,val\n")
    out = tmp_path / "ds"
    build = import_folder(mocap, out, "dog", labels=labels)
    man = load_manifest(out)
    assert json.loads((out / "manifest.json").read_text())["kind"] == IMPORT_KIND
    assert [c.path for c in man.clips] == [
        "train/dog/walk_01.npz",
        "train/dog/w3.npz",
        "val/dog/trot_02.npz",
    ]  # files in sorted path order
    assert [c.action for c in man.clips] == ["walk", "unlabelled", "trot"]
    assert man.fps == 30.0 and build.skipped == []
    clips = list(iter_clips(man))
    for entry, m in clips:
        assert m.fps == 30.0 and m.num_frames == entry.frames
        assert m.contacts is not None and m.contacts.any()  # stance found on the source's feet
        assert m.metadata["pair_key"] == entry.pair_key
        assert 0.0 < entry.duty_factor < 1.0 and entry.speed_mps > 0.0
    # the 60 fps file was resampled to the data set's rate
    assert clips[1][1].num_frames == 31
    # a trained-on split of one species' clips loads as training windows
    from habitsim.models.data import load_clip_set

    cs = load_clip_set(out, "train")
    assert len(cs.clips) == 2 and cs.species == ["dog"]


def test_bad_inputs_are_refused_and_nothing_is_left(mocap, tmp_path):
    out = tmp_path / "ds"
    with pytest.raises(DatasetError, match="no such folder"):
        import_folder(tmp_path / "nope", out, "dog")
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DatasetError, match="no motion file"):
        import_folder(empty, out, "dog")
    with pytest.raises(DatasetError, match="not in"):
        import_folder(mocap, out, "dog", labels={"missing.bvh": {"action": "walk"}})
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "a.bvh").write_bytes((mocap / "trot_02.bvh").read_bytes())
    (bad / "b.bvh").write_text("HIERARCHY\nROOT x {\n")
    with pytest.raises(BVHParseError, match=r"^b\.bvh: "):
        import_folder(bad, out, "dog")
    assert not (out / "manifest.json").exists() and not list(out.rglob("*.npz"))
    build = import_folder(bad, out, "dog", skip_bad=True)
    assert [f for f, _ in build.skipped] == ["b.bvh"] and len(build.manifest.clips) == 1
    with pytest.raises(OutputFolderError, match="--overwrite"):
        import_folder(bad, out, "dog", skip_bad=True)
    # an overwrite replaces the clips the old data set had
    import_folder(mocap, out, "dog", overwrite=True)
    assert sorted(p.name for p in out.rglob("*.npz")) == ["trot_02.npz", "w3.npz", "walk_01.npz"]
    with pytest.raises(DatasetError, match="held-out"):
        import_folder(
            mocap,
            tmp_path / "t",
            "tiger",
            labels={"trot_02.bvh": {"action": "trot", "split": "train"}},
        )


@pytest.mark.parametrize(
    "text, match",
    [
        ("name,action\nx.bvh,walk\n", "columns file,action"),
        ("file,action,split\nx.bvh,walk,dev\n", "unknown split"),
        ("file,action\nx.bvh,\n", "empty file or action"),
        ("file,action\nx.bvh,walk\nx.bvh,trot\n", "named twice"),
    ],
)
def test_bad_label_files_are_named(tmp_path, text, match):
    p = tmp_path / "l.csv"
    p.write_text(text)
    with pytest.raises(DatasetError, match=match):
        read_labels(p)


@pytest.mark.slow
def test_the_command_line(mocap, tmp_path, capsys):
    out = tmp_path / "ds"
    assert (
        main(["data", "import-bvh", "--dir", str(mocap), "--species", "dog", "--out", str(out)])
        == 0
    )
    text = capsys.readouterr().out
    assert "data set" in text and "3 clips of dog" in text and "more/w3.bvh" in text
    assert (
        main(
            [
                "data",
                "import-bvh",
                str(mocap / "trot_02.bvh"),
                "--dir",
                str(mocap),
                "--species",
                "dog",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "not both" in capsys.readouterr().err
    assert np.isfinite(load_manifest(out).clips[0].froude)


def test_files_and_links_habitsim_did_not_write_are_left_alone(mocap, tmp_path):
    """A folder holding no data set keeps its files; a link out of --out is not written
    through; --overwrite removes only what habitsim wrote."""
    out = tmp_path / "ds"
    (out / "train" / "dog").mkdir(parents=True)
    theirs = out / "train" / "dog" / "theirs.npz"
    theirs.write_text("not habitsim's")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.npz").write_text("outside")
    (out / "val").symlink_to(outside, target_is_directory=True)
    labels = {"trot_02.bvh": {"action": "trot", "split": "val"}}
    with pytest.raises(OutputFolderError):  # without --overwrite
        import_folder(mocap, out, "dog", labels=labels)
    with pytest.raises(OutputFolderError):  # val/ leads out of --out
        import_folder(mocap, out, "dog", labels=labels, overwrite=True)
    assert sorted(p.name for p in outside.iterdir()) == ["keep.npz"]
    (out / "val").unlink()
    import_folder(mocap, out, "dog", labels=labels, overwrite=True)
    import_folder(mocap, out, "dog", overwrite=True)  # replaces its own data set
    assert theirs.read_text() == "not habitsim's"
    assert sorted(p.name for p in out.rglob("*.npz")) == [
        "theirs.npz",
        "trot_02.npz",
        "w3.npz",
        "walk_01.npz",
    ]
    assert not (out / "val").exists()  # the replaced data set's val/ clip is gone


def test_links_out_of_the_source_folder_are_refused(mocap, tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    (src / "a.bvh").write_bytes((mocap / "trot_02.bvh").read_bytes())
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x:0:0:SECRET-LINE\n")
    (src / "b.bvh").symlink_to(secret)
    with pytest.raises(InputPathError) as e:
        import_folder(src, tmp_path / "out", "dog")
    assert "SECRET" not in str(e.value) and not (tmp_path / "out").exists()
    # followed when asked; the parse error names the file, not what it holds
    with pytest.raises(BVHParseError) as e:
        import_folder(src, tmp_path / "out", "dog", follow_symlinks=True)
    assert str(e.value).startswith("b.bvh:") and "SECRET" not in str(e.value)


def test_a_second_import_into_one_folder_is_refused(mocap, tmp_path):
    from helpers import hold

    out = tmp_path / "ds"
    with hold(out) as proc:
        with pytest.raises(OutputBusyError, match=str(proc.pid)):
            import_folder(mocap, out, "dog", overwrite=True)
    build = import_folder(mocap, out, "dog")  # the killed holder's lock is taken over
    assert len(build.manifest.clips) == 3
