"""Import of foreign rigs: helper chains, per-leg confidence, source stance, planted feet.

The rigs are written here from a synthetic dog walk whose stance is known: the joints get
other names, 6-channel joints, centimetres, z up, an extra root, and rig helpers that a
motion-capture rig carries (a long sided tail helper, armour plates, toe nubs pointing into
the ground, a footstep tracker).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from foreign_rig import _foreign_rig

import habitsim
from habitsim.bvh_mapping import ImportReport, import_bvh
from habitsim.cli import main
from habitsim.stance.labels import stance_f1


@pytest.fixture(scope="module")
def walk():
    return habitsim.generate("dog", "walk", seed=3, duration_s=3.0)


@pytest.fixture(scope="module")
def rig(walk):
    return _foreign_rig(walk)


def test_source_stance_matches_the_known_footfalls(walk, rig):
    motion, _ = import_bvh(rig, "dog")
    imp = motion.metadata["import"]
    assert imp["contacts"]["method"] == "source foot path"
    assert ImportReport.from_metadata(motion.metadata).to_metadata() == imp  # type: ignore[union-attr]
    # the labels found on the foreign rig's own feet are the walk's own stance
    f1 = stance_f1(motion.contacts, walk.contacts)
    assert np.all(f1 >= 0.85), f1
    assert np.allclose(imp["contacts"]["duty"], motion.contacts.mean(axis=0), atol=1e-3)


def test_planted_feet_on_the_ground(rig):
    motion, _ = import_bvh(rig, "cat")  # another size: the legs are re-solved for the cat
    leg = motion.species_info.leg_length
    toes = motion.foot_positions()[..., 2]
    c = motion.contacts
    assert toes.min() >= -1e-6  # no toe under the ground
    assert np.all(np.abs(toes[c]) <= 0.01 * leg)  # stance toes within 1 % of leg length
    # stance feet stay put: horizontal slide within a stance run
    feet = motion.foot_positions()[..., :2]
    slide = np.linalg.norm(np.diff(feet, axis=0), axis=-1)[c[1:] & c[:-1]]
    assert slide.max() <= 0.005 * leg
    # the metric's contacts on the imported clip agree with the source's labels
    f1 = np.asarray(motion.metadata["import"]["contact_f1"])
    assert np.all(f1 >= 0.85), f1


def test_unplanted_import_hovers_or_sinks(rig):
    # The reason planting exists: bone directions alone put a cat's toes off the ground.
    motion, _ = import_bvh(rig, "cat", plant=False)
    leg = motion.species_info.leg_length
    toes = motion.foot_positions()[..., 2]
    assert np.abs(np.median(toes[motion.contacts])) > 0.01 * leg or toes.min() < -0.01 * leg


def test_cli_inspect_and_import_with_warning(rig, tmp_path, capsys):
    p = tmp_path / "rig.bvh"
    p.write_text(rig.to_text())
    assert main(["data", "inspect-bvh", str(p)]) == 0
    out = capsys.readouterr().out
    assert "L_TailHelper01  (15.3) [helper]" in out
    assert "L_Thigh" in out and "-> lh_hip" in out
    assert '"extends": "auto"' in out
    m = tmp_path / "m.json"
    m.write_text(
        json.dumps(
            {
                "extends": "auto",
                "map": {
                    "lh_hip": "L_TailHelper01",
                    "lh_knee": "L_TailHelper02",
                    "lh_hock": "L_TailHelper03",
                    "lh_toe": "L_TailHelper04",
                },
            }
        )
    )
    out_npz = tmp_path / "o.npz"
    rc = main(
        ["data", "import-bvh", str(p), "--species", "dog", "--out", str(out_npz), "--map", str(m)]
    )
    assert rc == 0 and out_npz.is_file()
    err = capsys.readouterr().err
    assert "warning: lh leg" in err
    back = habitsim.load_motion(out_npz)
    assert back.contacts is not None and back.metadata["import"]["warnings"]


def test_cli_inspect_takes_units_and_up(walk, tmp_path, capsys):
    """An inches file is read as centimetres unless told (nothing in a file tells them
    apart); inspect-bvh takes ``--units`` / ``--up`` as import-bvh does and sizes the rig
    as the import would."""
    p = tmp_path / "inch.bvh"
    p.write_text(_foreign_rig(walk, CM=100.0 / 2.54).to_text())
    assert main(["data", "inspect-bvh", str(p), "--units", "in", "--up", "z"]) == 0
    told = capsys.readouterr().out
    assert "units in (x0.0254 to m), up +z" in told
    _, mapping = import_bvh(p, "dog", units="in")
    assert f"root scale {mapping.root_scale:.4g}" in told
    assert main(["data", "inspect-bvh", str(p)]) == 0
    assert "units cm" in capsys.readouterr().out


def test_bench_real_import_options_reach_the_importer(rig, tmp_path):
    """``bench real --map / --units / --up`` are the importer's, for every clip."""
    from habitsim.evaluation.bench.real import read_clip

    clip = tmp_path / "rig.bvh"
    clip.write_text(rig.to_text())
    found = read_clip(clip, "dog").metadata["mapping"]
    assert (found["units"], found["up"]) == ("cm", "+z")
    told = read_clip(clip, "dog", units="in", up="z").metadata["mapping"]
    assert told["units"] == "in"
    m = tmp_path / "map.json"
    m.write_text(json.dumps({"extends": "auto", "map": {"tail3": None}}))
    assert read_clip(clip, "dog", joint_map=m).metadata["mapping"]["joints"].get("tail3") is None
    assert found["joints"]["tail3"] is not None
