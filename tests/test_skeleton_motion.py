"""Skeleton FK (hand-computed chain, numpy vs torch), standing poses, Motion and npz I/O."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import habitsim
from habitsim import rotations as R
from habitsim.errors import (
    HabitsimError,
    InvalidMotionError,
    MotionFileError,
    UnknownSpeciesError,
)
from habitsim.models.kinematics import fk_torch
from habitsim.motion import FEATURE_DIM, Motion, load_motion
from habitsim.skeleton import FOOT_JOINTS, JOINT_NAMES, PARENTS, Skeleton, fk, get_skeleton


def _chain() -> Skeleton:
    # root -> a (1 m along +x) -> b (0.5 m along -z): computable on paper.
    offsets = np.array([[0, 0, 0], [1.0, 0, 0], [0, 0, -0.5]])
    return Skeleton("dog", ("root", "a", "b"), (-1, 0, 1), offsets)


def test_fk_hand_computed_chain() -> None:
    sk = _chain()
    q = np.stack([R.rot_z(np.pi / 2), R.rot_y(np.pi / 2), R.quat_identity()])
    pos = fk(sk, np.array([1.0, 2.0, 3.0]), q)
    # a = root + Rz(90)[1,0,0] = (1, 3, 3); b = a + Rz(90)Ry(90)[0,0,-0.5]
    # Ry(90)(0,0,-0.5) = (-0.5,0,0); Rz(90)(-0.5,0,0) = (0,-0.5,0)
    np.testing.assert_allclose(pos, [[1, 2, 3], [1, 3, 3], [1, 2.5, 3]], atol=1e-12)


def test_topology() -> None:
    assert len(JOINT_NAMES) >= 21
    assert JOINT_NAMES[0] == "pelvis" and PARENTS[0] == -1
    assert all(p < i for i, p in enumerate(PARENTS) if i > 0)  # parents precede children
    assert sum(n.startswith("spine") for n in JOINT_NAMES) >= 3
    assert sum(n.startswith("tail") for n in JOINT_NAMES) >= 2
    assert FOOT_JOINTS == ("lf_toe", "rf_toe", "lh_toe", "rh_toe")
    for leg in ("lf", "rf", "lh", "rh"):
        assert sum(n.startswith(leg + "_") for n in JOINT_NAMES) == 5


@pytest.mark.parametrize("species", habitsim.species_names())
def test_numpy_and_torch_fk_agree(species: str) -> None:
    sk = get_skeleton(species)
    rng = np.random.default_rng(0)
    q = R.quat_normalize(rng.normal(size=(7, sk.num_joints, 4)))
    root = rng.normal(size=(7, 3))
    p_np = fk(sk, root, q)
    p_t = fk_torch(sk, torch.tensor(root), torch.tensor(q)).numpy()
    assert np.abs(p_np - p_t).max() < 1e-6
    # float32 torch too, within 1e-6 of the float64 result relative to body size
    p32 = fk_torch(
        sk, torch.tensor(root, dtype=torch.float32), torch.tensor(q, dtype=torch.float32)
    )
    assert np.abs(p32.numpy() - p_np).max() < 1e-5 * max(1.0, np.abs(p_np).max())


@pytest.mark.parametrize("species", habitsim.species_names())
def test_standing_pose_feet_on_ground(species: str) -> None:
    sk = get_skeleton(species)
    root, q = sk.standing_pose()
    pos = sk.fk(root, q)
    toes = pos[sk.foot_indices]
    np.testing.assert_allclose(toes[:, 2], 0.0, atol=1e-9)
    sp = habitsim.load_species(species)
    hip = pos[sk.index("lh_hip")]
    assert hip[2] == pytest.approx(sp.hip_height, rel=1e-9)
    # bone lengths equal the species' segment lengths
    assert sk.bone_lengths[sk.index("lh_knee")] == pytest.approx(sp.segments["hind_upper"])
    assert sk.bone_lengths[sk.index("lf_toe")] == pytest.approx(sp.segments["fore_foot"])
    # left side is +y, head is ahead of the tail
    assert pos[sk.index("lf_toe"), 1] > 0 > pos[sk.index("rf_toe"), 1]
    assert pos[sk.index("snout"), 0] > pos[sk.index("tail3"), 0]


def _walk_like(species: str = "dog", t: int = 12) -> Motion:
    sk = get_skeleton(species)
    root, q = sk.standing_pose()
    roots = root[None] + np.arange(t)[:, None] * np.array([0.02, 0.0, 0.0])
    quats = np.repeat(q[None], t, axis=0)
    knee = sk.index("lh_knee")
    quats[:, knee] = R.quat_mul(quats[:, knee], R.rot_y(0.3 * np.sin(np.arange(t) / 3)))
    contacts = np.ones((t, 4), bool)
    return Motion(species, 30.0, roots, quats, contacts, {"action": "walk", "seed": 3})


def test_npz_round_trip(tmp_path) -> None:
    m = _walk_like()
    path = m.save(tmp_path / "clip.npz")
    m2 = load_motion(path)
    assert m2.species == "dog" and m2.fps == 30.0 and m2.metadata == {"action": "walk", "seed": 3}
    np.testing.assert_array_equal(m2.contacts, m.contacts)
    assert np.abs(m2.global_positions() - m.global_positions()).max() < 1e-12
    assert [p.name for p in tmp_path.iterdir()] == ["clip.npz"]  # no temp files left


def test_features_round_trip() -> None:
    m = _walk_like()
    f = m.features()
    assert f.shape == (m.num_frames, FEATURE_DIM) and f.dtype == np.float32
    # velocity part of frame 1 is the finite difference of the positions times fps
    x = m.global_positions()
    j = len(JOINT_NAMES)
    np.testing.assert_allclose(f[1, j * 4 :].reshape(j, 3), (x[1] - x[0]) * 30.0, atol=1e-5)
    back = Motion.from_features(f, "dog", 30.0, root_start=m.root_positions[0])
    assert np.abs(back.global_positions() - x).max() < 1e-5


def test_bad_motions_raise_typed_errors() -> None:
    m = _walk_like()
    with pytest.raises(UnknownSpeciesError, match="known: .*dog"):
        Motion("hores", 30, m.root_positions, m.rotations)
    bad = m.rotations.copy()
    bad[3, 4, 0] = np.nan
    with pytest.raises(InvalidMotionError, match="NaN"):
        Motion("dog", 30, m.root_positions, bad)
    with pytest.raises(InvalidMotionError, match="shape"):
        Motion("dog", 30, m.root_positions, m.rotations[:, :10])
    with pytest.raises(InvalidMotionError, match="fps"):
        Motion("dog", 0, m.root_positions, m.rotations)
    with pytest.raises(InvalidMotionError, match="unit"):
        Motion("dog", 30, m.root_positions, m.rotations * 2)
    with pytest.raises(InvalidMotionError, match="contacts"):
        Motion("dog", 30, m.root_positions, m.rotations, np.ones((3, 4), bool))
    assert issubclass(InvalidMotionError, HabitsimError)


def test_bad_motion_files(tmp_path) -> None:
    with pytest.raises(MotionFileError, match="no such"):
        load_motion(tmp_path / "missing.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(MotionFileError, match="readable"):
        load_motion(junk)
    partial = tmp_path / "partial.npz"
    np.savez(partial, species=np.array("dog"))
    with pytest.raises(MotionFileError, match="missing keys"):
        load_motion(partial)
    with pytest.raises(MotionFileError, match=".npz"):
        _walk_like().save(tmp_path / "clip.txt")


def test_failed_save_leaves_nothing(tmp_path, monkeypatch) -> None:
    m = _walk_like()

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(OSError):
        m.save(tmp_path / "clip.npz")
    assert list(tmp_path.iterdir()) == []


def test_public_api_resolves() -> None:
    for name in habitsim.__all__:
        assert hasattr(habitsim, name), name


def test_mirrored_motion_is_the_reflected_motion():
    from habitsim.gaits import generate
    from habitsim.motion import mirror_permutation

    m = generate("dog", "turn_left", seed=2, duration_s=1.5).with_contacts()
    r = m.mirrored()
    perm = mirror_permutation()
    assert JOINT_NAMES[perm[JOINT_NAMES.index("lf_elbow")]] == "rf_elbow"
    assert JOINT_NAMES[perm[JOINT_NAMES.index("spine2")]] == "spine2"
    expect = m.global_positions()[:, perm] * np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(r.global_positions(), expect, atol=1e-9)
    np.testing.assert_array_equal(r.contacts, m.contacts[:, [1, 0, 3, 2]])
    assert r.metadata["action"] == "turn_right" and m.metadata["action"] == "turn_left"
    # a reflection twice is the identity
    np.testing.assert_allclose(r.mirrored().rotations, m.rotations, atol=1e-12)
