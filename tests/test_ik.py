"""Leg IK: targets reached within 1 mm, honest errors when out of reach, typed errors."""

from __future__ import annotations

import numpy as np
import pytest

from habitsim.errors import IKError
from habitsim.ik import LEGS, foot_inclination, leg_fk, leg_geometry, leg_ik, pose_from_targets
from habitsim.motion import Motion
from habitsim.rotations import rot_z
from habitsim.skeleton import fk, get_skeleton
from habitsim.species import load_species

SPECIES = ("dog", "horse", "cat", "elephant", "rabbit", "giraffe")


def _random_leg_angles(rng: np.random.Generator, geo, t: int) -> list[np.ndarray]:
    """Angles around the standing pose with the middle joint bent its natural way."""
    abd = rng.uniform(-0.25, 0.25, t)
    gflex = geo.girdle_flex0 + rng.uniform(-0.2, 0.2, t)
    up = rng.uniform(-0.6, 0.6, t)
    low = geo.bend * rng.uniform(0.15, 1.4, t)  # never straight: the solution is unique
    foot = rng.uniform(-0.8, 0.8, t)
    return [abd, gflex, up, low, foot]


@pytest.mark.parametrize("species", SPECIES)
@pytest.mark.parametrize("leg", LEGS)
def test_ik_reaches_fk_targets_within_1mm(species: str, leg: str) -> None:
    rng = np.random.default_rng(7)
    geo = leg_geometry(species, leg)
    t = 400
    root = rng.normal(0, 0.3, (t, 3))
    prot = rot_z(rng.uniform(-np.pi, np.pi, t))
    abd, gflex, up, low, foot = _random_leg_angles(rng, geo, t)
    target = leg_fk(species, leg, root, prot, abd, gflex, up, low, foot)
    # the solver's domain: toe below the shoulder / hip (a leg, not an arm raised overhead)
    zero = np.zeros(t)
    shoulder = leg_fk(species, leg, root, prot, zero, gflex, zero, zero, zero)
    shoulder_z = shoulder[:, 2] + geo.upper + geo.lower + geo.foot
    keep = target[:, 2] < shoulder_z - 0.25 * (geo.upper + geo.lower)
    assert keep.sum() > 100
    root, prot, target = root[keep], prot[keep], target[keep]
    abd, gflex, up, low, foot = (a[keep] for a in (abd, gflex, up, low, foot))
    incl = foot_inclination(prot, abd, gflex, up, low, foot)
    res = leg_ik(species, leg, root, prot, target, gflex, incl)
    assert res.reach_error.max() < 1e-3
    # the solution is a real pose: its own FK lands on the target
    toe = leg_fk(
        species,
        leg,
        root,
        prot,
        res.abduction,
        res.girdle_flex,
        res.upper_flex,
        res.lower_flex,
        res.foot_flex,
    )
    np.testing.assert_allclose(toe, target, atol=1e-3)
    np.testing.assert_allclose(res.toe, toe, atol=1e-9)


@pytest.mark.parametrize("leg", LEGS)
def test_compliant_foot_takes_up_reach_within_its_band(leg: str) -> None:
    """A toe too far (or too close) for the nominal foot angle is reached by turning the foot."""
    rng = np.random.default_rng(3)
    geo = leg_geometry("horse", leg)
    t = 300
    root = np.zeros((t, 3))
    prot = np.eye(3)
    reach = geo.upper + geo.lower
    # toes spread fore and aft of the leg at heights from folded to nearly stretched
    ang = rng.uniform(-0.7, 0.7, t)
    dist = rng.uniform(0.55, 1.0, t) * (reach + geo.foot)
    zero = np.zeros(t)
    girdle = np.full(t, geo.girdle_flex0)
    shoulder = leg_fk("horse", leg, root, prot, zero, girdle, zero, zero, zero)
    shoulder = shoulder + np.array([0.0, 0.0, geo.upper + geo.lower + geo.foot])
    target = shoulder + np.stack([dist * np.sin(ang), zero, -dist * np.cos(ang)], -1)
    band = (0.7 * reach, 0.9 * reach)
    plain = leg_ik("horse", leg, root, prot, target)
    res = leg_ik("horse", leg, root, prot, target, distal_band=band, max_inclination_change=np.pi)
    d_plain = np.linalg.norm(plain.distal_target - plain.proximal, axis=-1)
    d = np.linalg.norm(res.distal_target - res.proximal, axis=-1)
    # where some foot angle puts the wrist / hock in the band, the compliant solution does
    toe_d = np.linalg.norm(target - res.proximal, axis=-1)
    feasible = (toe_d - geo.foot <= band[1] - 1e-6) & (toe_d + geo.foot >= band[0] + 1e-6)
    outside = (d_plain > band[1] + 1e-6) | (d_plain < band[0] - 1e-6)
    assert (feasible & outside).sum() > 30
    inside = feasible & outside
    assert np.all(d[inside] <= band[1] + 1e-6) and np.all(d[inside] >= band[0] - 1e-6)
    assert res.reach_error[inside].max() < 1e-6
    # frames already in the band keep the nominal foot angle (the same solution)
    keep = ~outside

    def total(r):  # the foot segment's angle in the leg plane
        return r.foot_flex[keep] + r.lower_flex[keep] + r.upper_flex[keep]

    np.testing.assert_allclose(total(res), total(plain), atol=1e-9)
    # the turn is bounded
    small = leg_ik("horse", leg, root, prot, target, distal_band=band, max_inclination_change=0.05)
    turn = np.abs(
        (small.upper_flex + small.lower_flex + small.foot_flex)
        - (plain.upper_flex + plain.lower_flex + plain.foot_flex)
    )
    assert np.all(np.minimum(turn, 2 * np.pi - turn) <= 0.05 + 1e-9)


def test_ik_unreachable_target_is_clamped_and_reported() -> None:
    geo = leg_geometry("dog", "LH")
    root = np.zeros((1, 3))
    far = np.array([[0.0, 0.0, -3.0 * (geo.upper + geo.lower + geo.foot)]])
    res = leg_ik("dog", "LH", root, np.eye(3), far)
    assert np.all(np.isfinite(res.upper_flex))
    # the leg is stretched toward the target: the error is the missing length
    assert res.reach_error[0] > geo.upper + geo.lower
    assert res.reach_ratio[0] > 1.0


def test_pose_from_targets_matches_full_skeleton_fk() -> None:
    """Solved rotations, put through the skeleton's FK, put the toes on the targets."""
    sp = load_species("dog")
    skel = get_skeleton(sp)
    root, quats = skel.standing_pose()
    t = 30
    roots = np.repeat(root[None], t, 0)
    rots = np.repeat(quats[None], t, 0)
    pos = fk(skel, roots, rots)
    toes = pos[:, skel.foot_indices].copy()
    rng = np.random.default_rng(3)
    toes[..., :2] += rng.uniform(-0.04, 0.04, (t, 4, 2))  # step the feet about
    toes[..., 2] += rng.uniform(0.0, 0.05, (t, 4))
    sol = pose_from_targets(sp, roots, rots, toes)
    assert sol.reach_error.max() < 1e-3
    got = fk(skel, roots, sol.rotations)[:, skel.foot_indices]
    np.testing.assert_allclose(got, toes, atol=1e-3)
    Motion(species="dog", fps=30.0, root_positions=roots, rotations=sol.rotations)  # valid motion


@pytest.mark.parametrize("limit", [False, True])
def test_pose_from_targets_solves_every_leg_as_leg_ik_does(limit: bool) -> None:
    """The four legs solved together are, value for value, :func:`leg_ik` of each leg on
    its trunk frame, with per-leg girdle flexion and foot inclination, an abduction range,
    and targets out of reach and tucked up; the rotations are each leg's quaternions, the
    toes its solved toes, and the caller's rotations are not touched."""
    from habitsim.ik import _abduction_range, axial_frames

    sp = load_species("horse")
    skel = get_skeleton(sp)
    root, quats = skel.standing_pose()
    t = 24
    rng = np.random.default_rng(5)
    roots = np.repeat(root[None], t, 0) + rng.normal(0.0, 0.02, (t, 3))
    rots = np.repeat(quats[None], t, 0)
    rots[:, 0] = rot_z(rng.uniform(-0.3, 0.3, t))
    before = rots.copy()
    toes = fk(skel, roots, rots)[:, skel.foot_indices] + rng.normal(0.0, 0.08, (t, 4, 3))
    toes[3:6, 0, 2] += 0.9  # a fore paw tucked up to the shoulder: abduction runs out
    toes[8:10, 3, 2] -= 1.5  # a hind toe far out of reach
    gflex = rng.normal(0.0, 0.2, (t, 4))
    incl = rng.normal(0.0, 0.2, (t, 4))
    sol = pose_from_targets(sp, roots, rots, toes, gflex, incl, limit_abduction=limit)
    np.testing.assert_array_equal(rots, before)
    frames = axial_frames(sp, roots, rots)
    for k, leg in enumerate(LEGS):
        one = leg_ik(
            sp,
            leg,
            frames.girdle_root[:, k],
            frames.parent_rotation[:, k],
            toes[:, k],
            gflex[:, k],
            incl[:, k],
            abduction_range=_abduction_range(sp, leg) if limit else None,
        )
        for name in ("abduction", "upper_flex", "lower_flex", "foot_flex", "toe", "reach_error"):
            np.testing.assert_array_equal(getattr(sol.legs[k], name), getattr(one, name))
        np.testing.assert_array_equal(sol.toes[:, k], one.toe)
        np.testing.assert_array_equal(sol.reach_error[:, k], one.reach_error)
        joints = leg_geometry(sp, leg).joints
        got = np.stack([sol.rotations[:, skel.index(j)] for j in joints[:4]], axis=1)
        np.testing.assert_array_equal(got, one.quaternions())
    assert sol.reach_error[8:10, 3].min() > 0.5  # honest about the unreachable toe
    with pytest.raises(IKError, match="girdle_flex must have shape"):
        pose_from_targets(sp, roots, rots, toes, gflex[:, :3])
    with pytest.raises(IKError, match="foot_inclination contains NaN"):
        pose_from_targets(sp, roots, rots, toes, gflex, np.full((t, 4), np.nan))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"target": np.full((2, 3), np.nan)},
        {"target": np.zeros((2, 2))},
        {"girdle_root": np.zeros((5, 3))},
        {"foot_inclination": np.array([np.inf, 0.0])},
    ],
)
def test_ik_bad_inputs_raise(kwargs: dict) -> None:
    args = {
        "girdle_root": np.zeros((2, 3)),
        "parent_rotation": np.eye(3),
        "target": np.zeros((2, 3)) - [0, 0, 0.3],
    }
    args.update(kwargs)
    with pytest.raises(IKError):
        leg_ik("dog", "LF", **args)


def test_ik_unknown_leg() -> None:
    with pytest.raises(IKError, match="LF"):
        leg_ik("dog", "XX", np.zeros(3), np.eye(3), np.array([0.0, 0.0, -0.3]))
