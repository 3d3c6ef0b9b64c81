"""Transfer (habitsim.transfer, habitsim.transfer_methods, habitsim.models.transfer): the
method registry, the footfall schedule a transfer keeps, and conforming a decoded motion
(speed, height and heading bounds, levelling, frame count)."""

from __future__ import annotations

import numpy as np
import pytest

from habitsim.contacts import (
    drop_short_runs,
    warp_contacts,
)
from habitsim.errors import HabitsimError, InvalidMotionError, UnknownSpeciesError
from habitsim.gaits import generate
from habitsim.models import (
    METHODS,
    available_methods,
    shipped_checkpoint,
    transfer,
)
from habitsim.models.errors import MethodNotAvailableError, UnknownMethodError
from habitsim.motion import Motion, resample_motion
from habitsim.stance.bounds import bound_heading, bound_height, bound_speed
from habitsim.stance.labels import stance_f1, stance_runs
from habitsim.stance.level import level_trunk
from habitsim.stance.policy import ConformPolicy
from habitsim.stance.report import TransferRecord
from habitsim.stance.schedule import ScheduleReason, transfer_contacts, walking_stance

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_transfer_labels_come_from_the_decoded_contacts_checked_against_the_source():
    src = generate("dog", "trot", seed=5, duration_s=2.0)
    out = Motion("horse", src.fps, src.root_positions * 2.0, src.rotations)
    labels, info = transfer_contacts(out, src, src.contacts)
    assert info["method"] == "decoded" and info["source_f1"] == [1.0] * 4
    np.testing.assert_array_equal(labels, src.contacts)
    # a decoded foot that disagrees with the source's footfalls takes the source's schedule
    bad = src.contacts.copy()
    bad[:, 2] = ~bad[:, 2]
    labels, info = transfer_contacts(out, src, bad)
    assert info["source_f1"][2] < ConformPolicy().min_source_agreement <= min(info["source_f1"][:2])
    assert info["feet_from_source"] == ["LH"]
    np.testing.assert_array_equal(labels, src.contacts)
    # a decoded foot that stands far longer than the source's (a high F1 all the same)
    # takes the source's schedule too
    long = src.contacts.copy()
    long[:, 0] |= np.roll(long[:, 0], 4) | np.roll(long[:, 0], 8)
    labels, info = transfer_contacts(out, src, long)
    assert info["duty"][0] - info["source_duty"][0] > ConformPolicy().max_duty_gap
    assert info["feet_from_source"] == ["LF"]
    np.testing.assert_array_equal(labels, src.contacts)
    # without decoded contacts (direct) the source's schedule is used as such
    labels, info = transfer_contacts(out, src)
    assert info["method"] == "source"
    np.testing.assert_array_equal(labels, src.contacts)


#: The default knobs of conforming a decoded motion.
POLICY = ConformPolicy()


@pytest.fixture(scope="module")
def trot():
    return generate("horse", "trot", seed=5, duration_s=3.0)


@pytest.fixture(scope="module")
def walk():
    return generate("dog", "walk", seed=2, duration_s=2.0)


def test_walking_stance_only_where_the_target_walks() -> None:
    """A cat at a walking Froude number gets no aerial phase; a trot, a faster clip and a
    jump keep their labels."""
    slow = generate("cat", "walk", seed=1, duration_s=3.0, froude=0.3, duty_factor=0.35)
    assert slow.contacts is not None and slow.contacts.mean(0).max() < POLICY.walk_min_duty
    labels, info = walking_stance(slow, slow.contacts, slow)
    labels = labels.array
    assert info is not None and info["froude"] <= info["walk_froude_max"] == 0.45
    assert labels.mean(0).min() >= POLICY.walk_min_duty
    assert (labels.sum(axis=1) >= POLICY.walk_min_feet).all()  # never fewer than two feet down
    assert (labels | ~slow.contacts).all()  # stance only grows
    assert info["duty_after"] == pytest.approx(labels.mean(0).round(3).tolist())
    # the same footfalls with no action known: decided by the Froude number alone
    bare = slow.slice(0)
    bare.metadata = {}
    np.testing.assert_array_equal(walking_stance(bare, slow.contacts, bare)[0], labels)
    # a trot is a trot
    trot = generate("cat", "trot", seed=1, duration_s=3.0, froude=0.6, duty_factor=0.4)
    kept, none = walking_stance(trot, trot.contacts, trot)
    assert none is None and (kept.array == trot.contacts).all()
    # faster than the cat walks, no action known: kept
    bare = trot.slice(0)
    bare.metadata = {}
    assert walking_stance(bare, trot.contacts, bare)[1] is None
    # a jump is not a cyclic gait
    jump = generate("cat", "jump", seed=1)
    assert walking_stance(jump, jump.contacts, jump)[1] is None


def test_transfer_keeps_the_source_footfalls(trot) -> None:
    assert trot.contacts is not None
    src = drop_short_runs(warp_contacts(trot.contacts, trot.num_frames))
    # direct_relabelled carries the source's schedule over
    out = transfer(trot, to="cat", method="direct_relabelled", seed=0)
    assert out.metadata["transfer"]["contacts"]["method"] == "source"
    np.testing.assert_array_equal(out.contacts, src)
    # the network's decoded contacts, checked foot by foot against the source's schedule
    # (before planting, which may step the legs faster: see the restep test)
    out = transfer(trot, to="cat", method="habit", seed=0, plant=False)
    how = out.metadata["transfer"]["contacts"]
    assert how["method"] == "decoded" and len(how["source_f1"]) == 4
    for k, foot in enumerate(("LF", "RF", "LH", "RH")):
        f1 = stance_f1(out.contacts[:, k : k + 1], src[:, k : k + 1])[0]
        if foot in how.get("feet_from_source", []):
            np.testing.assert_array_equal(out.contacts[:, k], src[:, k])
        else:  # kept: it agreed with the source's footfalls and stands as long
            assert f1 >= POLICY.min_source_agreement and how["source_f1"][k] == pytest.approx(
                f1, abs=1e-3
            )
            assert abs(out.contacts[:, k].mean() - src[:, k].mean()) <= POLICY.max_duty_gap


def _resting(m, labels) -> float:
    v = np.linalg.norm(np.diff(m.foot_positions(), axis=0), axis=-1) * m.fps
    on = labels[1:] & labels[:-1]
    return float((v[on] <= 0.1 * m.species_info.leg_length).mean())


def test_habit_transfer_plants_its_feet_on_its_labels(trot) -> None:
    planted = transfer(trot, to="elephant", method="habit", seed=0)
    raw = transfer(trot, to="elephant", method="habit", seed=0, plant=False)
    np.testing.assert_array_equal(planted.contacts, raw.contacts)  # same labels
    assert raw.metadata["transfer"]["planted"] is False
    report = planted.metadata["transfer"]["planted"]
    assert report["kept"] and len(report["stance_toe_height_per_leg"]) == 4
    assert report["max_reach_error_per_leg"] <= POLICY.plant_max_reach_per_leg
    c = planted.contacts
    assert _resting(planted, c) >= 0.95 > _resting(raw, c)
    z = planted.foot_positions()[..., 2][c] / planted.species_info.leg_length
    assert np.median(np.abs(z)) <= 0.01  # stance toes on the ground
    # swing feet are lifted: in the middle of each swing run the toe is near the
    # elephant's habitual swing height, not shuffling at the ground as decoded
    leg = planted.species_info.leg_length
    height = planted.species_info.habits.swing_height * leg
    mid_planted, mid_raw = [], []
    for f, runs in enumerate(stance_runs(~c)):
        for a, b in runs:
            if b - a >= 5 and a > 0 and b < len(c):  # whole swings between two stances
                mid_planted.append(planted.foot_positions()[(a + b) // 2, f, 2])
                mid_raw.append(raw.foot_positions()[(a + b) // 2, f, 2])
    assert mid_planted and np.median(mid_planted) >= 0.8 * height
    assert np.median(mid_raw) < 0.5 * height
    # the trunk is the decoder's: planting re-solves the legs only
    np.testing.assert_allclose(planted.root_positions[:, :2], raw.root_positions[:, :2], atol=1e-9)


def test_transfer_contacts_time_warped_when_the_length_changes(trot) -> None:
    slower = resample_motion(trot.with_contacts(trot.contacts), trot.fps * 1.5)
    slower.contacts = None  # an output of another length, labelled from the source
    labels, info = transfer_contacts(slower, trot)
    labels = labels.array
    assert info == {"method": "source", "source_frames": trot.num_frames, "time_warped": True}
    assert labels.shape == (slower.num_frames, 4)
    np.testing.assert_array_equal(
        labels, drop_short_runs(warp_contacts(trot.contacts, slower.num_frames))
    )
    # the same footfall schedule: the stance share of every foot is kept
    np.testing.assert_allclose(labels.mean(0), trot.contacts.mean(0), atol=0.03)


def test_transfer_without_source_labels_falls_back_and_says_so(trot) -> None:
    bare = trot.slice(0)
    bare.contacts = None
    for method in ("habit", "direct_relabelled"):
        out = transfer(bare, to="cat", method=method, seed=0)
        how = TransferRecord.from_metadata(out.metadata).contacts
        assert how is not None and how.method in ("detected", "duty")
        assert how.reason_code is ScheduleReason.NO_SOURCE_LABELS
        assert out.contacts is not None and out.contacts.shape == (out.num_frames, 4)


def test_decoded_speed_is_bounded_by_the_source_speed_at_equal_froude(walk) -> None:
    from habitsim.motion import Motion

    cat = generate("cat", like=walk)
    assert cat.num_frames == walk.num_frames
    # a cat walking where the source dog walks at the same Froude number: unchanged
    same, info = bound_speed(cat, walk)
    assert info is None and same is cat
    # ... where the dog stands still: the cat's body does not travel either
    t = walk.num_frames
    still = Motion(
        "dog",
        walk.fps,
        np.repeat(walk.root_positions[:1], t, axis=0),
        np.repeat(walk.rotations[:1], t, axis=0),
    )
    stood, info = bound_speed(cat, still)
    assert info is not None and info["frames"] >= t - 2
    travel = np.linalg.norm(np.diff(stood.root_positions[:, :2], axis=0), axis=1).sum()
    assert travel <= 1e-6
    np.testing.assert_allclose(stood.rotations, cat.rotations, atol=1e-12)
    np.testing.assert_allclose(stood.root_positions[:, 2], cat.root_positions[:, 2], atol=1e-12)
    # ... and where the dog runs three times as fast: the cat speeds up to a third of it
    # (the band's lower edge) along its own path
    root = walk.root_positions.copy()
    root[:, :2] = root[0, :2] + 3.0 * 1.5 * (root[:, :2] - root[0, :2])
    quick = Motion("dog", walk.fps, root, walk.rotations)
    sped, info = bound_speed(cat, quick)
    assert info is not None
    v0 = np.linalg.norm(np.diff(cat.root_positions[:, :2], axis=0), axis=1).sum()
    v1 = np.linalg.norm(np.diff(sped.root_positions[:, :2], axis=0), axis=1).sum()
    assert v1 / v0 == pytest.approx(3.0 * 1.5 / POLICY.speed_band, rel=0.1)


def test_decoded_height_excursions_are_bounded_by_the_source(walk) -> None:
    from habitsim.motion import Motion

    cat = generate("cat", like=walk)
    leg = cat.species_info.leg_length
    # the same gait's bob: unchanged
    same, info = bound_height(cat, walk)
    assert info is None and same is cat
    # a body that sinks by a fifth of its leg over the clip while the dog walks level:
    # the sinking is cut to the band around the dog's own bob
    t = cat.num_frames
    root = cat.root_positions.copy()
    root[:, 2] -= np.linspace(0.0, 0.2 * leg, t)
    sinking = Motion("cat", cat.fps, root, cat.rotations)
    level, info = bound_height(sinking, walk)
    assert info is not None and info["range_per_leg"][0] > 0.15
    dev = walk.root_positions[:, 2] - np.median(walk.root_positions[:, 2])
    src = np.abs(dev).max() / walk.species_info.leg_length
    allowed = max(POLICY.height_band * src, POLICY.height_floor_per_leg)
    z = level.root_positions[:, 2]
    assert np.abs(z - np.median(root[:, 2])).max() <= 1.2 * allowed * leg  # smoothed envelope
    np.testing.assert_allclose(level.root_positions[:, :2], root[:, :2])
    # a source that jumps keeps the target's jump
    jump = generate("dog", "jump", seed=0)
    leap = generate("cat", like=jump)
    _, info = bound_height(leap, jump)
    assert info is None or info["range_per_leg"][1] >= 0.95 * info["range_per_leg"][0]


def test_a_wagging_decoded_heading_is_slowed_to_the_bound(walk) -> None:
    from habitsim.models.features import heading_yaw
    from habitsim.motion import Motion
    from habitsim.rotations import quat_from_axis_angle, quat_mul

    cat = generate("cat", like=walk)
    t = cat.num_frames
    axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (t, 3))

    def turned(angle: np.ndarray) -> Motion:
        rot = cat.rotations.copy()
        rot[:, 0] = quat_mul(quat_from_axis_angle(axis, angle), rot[:, 0])
        return Motion("cat", cat.fps, cat.root_positions, rot, cat.contacts)

    def rate(m: Motion) -> np.ndarray:
        dev = np.unwrap(heading_yaw(m.rotations[:, 0])) - np.unwrap(
            heading_yaw(cat.rotations[:, 0])
        )
        return np.abs(np.gradient(dev)) * m.fps

    # the same heading, or a slow drift of 20° over the clip: left as decoded
    same, info = bound_heading(cat, walk)
    assert info is None and same is cat
    drift = turned(np.linspace(0.0, np.radians(20.0), t))
    assert bound_heading(drift, walk)[1] is None
    # the body wagged by ±60° at 4 Hz about the pelvis (a decoder off its data):
    # the wag is low-passed away, the root path and every other joint kept
    sec = np.arange(t) / cat.fps
    wag = turned(np.radians(60.0) * np.sin(2.0 * np.pi * 4.0 * sec))
    assert rate(wag).max() > 5.0 * POLICY.heading_max_rate
    calm, info = bound_heading(wag, walk)
    assert info is not None and info["max_rate"][0] > 5.0 * POLICY.heading_max_rate
    inner = rate(calm)[t // 4 : -t // 4]  # away from the ends the filter pads
    assert inner.max() < POLICY.heading_max_rate
    np.testing.assert_array_equal(calm.root_positions, wag.root_positions)
    np.testing.assert_allclose(calm.rotations[:, 1:], wag.rotations[:, 1:], atol=1e-12)
    # a steady turn away to 90° over the clip (a target turning at its own rate): kept
    away = turned(np.linspace(0.0, np.radians(90.0), t))
    assert bound_heading(away, walk)[1] is None
    # a swing out to 80° and back within a second, under the rate bound: cut to the band
    # about the departure's slow trend
    swing = np.radians(80.0) * np.exp(-0.5 * ((sec - sec.mean()) / 0.3) ** 2)
    assert rate(turned(swing)).max() < POLICY.heading_max_rate
    held, info = bound_heading(turned(swing), walk)
    assert info is not None and info["max_departure_deg"][0] > 79.0
    dev = np.unwrap(heading_yaw(held.rotations[:, 0])) - np.unwrap(heading_yaw(cat.rotations[:, 0]))
    # the 1 s trend of a 0.3 s swing rises by about a quarter of it: 45° + ~24°
    assert np.radians(60.0) < np.abs(dev).max() < np.radians(72.0)


def test_a_sloping_decoded_trunk_is_levelled_about_the_pelvis(walk) -> None:
    from habitsim.models.features import heading_yaw
    from habitsim.motion import Motion
    from habitsim.rotations import quat_from_axis_angle, quat_mul

    gir = generate("giraffe", like=walk)
    c = gir.contacts
    # its own walk stands level: left as it is
    same, info = level_trunk(gir, c)
    assert info is None and same is gir
    # the trunk tipped nose-down by 8° about the pelvis: the fore toes go under the ground
    # by 6 % of a leg more than the hind ones; pitched back to within the tolerance (a
    # second pass finds nothing to do), legs and root path untouched
    yaw = heading_yaw(gir.rotations[:, 0])
    left = np.stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)], axis=-1)
    rot = gir.rotations.copy()
    rot[:, 0] = quat_mul(quat_from_axis_angle(left, np.full(len(yaw), np.radians(8.0))), rot[:, 0])
    sloped = Motion("giraffe", gir.fps, gir.root_positions, rot, c)
    level, info = level_trunk(sloped, c)
    assert info is not None and info["fore_minus_hind_per_leg"] < -0.05
    assert -8.0 < info["pitch_deg"] < -4.0
    assert level_trunk(level, c)[1] is None
    np.testing.assert_allclose(level.rotations[:, 1:], sloped.rotations[:, 1:], atol=1e-12)
    np.testing.assert_array_equal(level.root_positions, sloped.root_positions)
    # tipped the other way: pitched the other way
    rot[:, 0] = quat_mul(
        quat_from_axis_angle(left, np.full(len(yaw), np.radians(-8.0))), gir.rotations[:, 0]
    )
    _, info = level_trunk(Motion("giraffe", gir.fps, gir.root_positions, rot, c), c)
    assert info is not None and 4.0 < info["pitch_deg"] < 8.0
    # no frame with both girdles in stance: nothing to compare
    fore = np.zeros_like(c)
    fore[:, :2] = True
    assert level_trunk(sloped, fore)[1] is None


def test_a_transfer_keeps_the_sources_frame_count_through_the_models_rate(walk) -> None:
    # 120 fps, 478 frames: 3.98 s that the model's 30 fps grid does not divide; the
    # round trip to its rate and back would add or drop a frame at the end, and the
    # source-relative bounds (speed, height, heading) compare frame for frame
    long = generate("dog", "walk", seed=2, duration_s=4.5)
    src = resample_motion(long, 120.0, 478)
    assert src.num_frames == 478
    held = resample_motion(walk, 120.0, 300)  # 2.5 s of a 2 s clip: its last frame held
    np.testing.assert_allclose(held.root_positions[-60:], walk.root_positions[[-1] * 60])
    with pytest.raises(InvalidMotionError, match="num_frames"):
        resample_motion(walk, 120.0, 0)
    for method in ("habit", "direct_relabelled"):
        out = transfer(src, to="cat", method=method, seed=0)
        assert out.num_frames == src.num_frames and out.fps == src.fps
        assert out.contacts is not None and out.contacts.shape == (src.num_frames, 4)


SHIPPED = shipped_checkpoint("habit")


needs_ckpt = pytest.mark.skipif(
    SHIPPED is None, reason="no shipped habit checkpoint in this checkout"
)


def test_method_registry():
    assert available_methods()[:8] == [
        "habit",
        "habit_ema",
        "no_habit",
        "habit_only",
        "text_only",
        "direct",
        "direct_relabelled",
        "ground_truth",
    ]
    assert METHODS["direct"].variant is None and METHODS["direct_relabelled"].variant is None
    assert all(
        METHODS[v].variant == v and METHODS[v].learned
        for v in ("habit", "habit_ema", "no_habit", "habit_only", "text_only")
    )
    with pytest.raises(UnknownMethodError, match="valid: habit, habit_ema"):
        transfer(generate("cat", "walk", seed=1, duration_s=1.0), to="dog", method="best")


def test_direct_transfer(trot):
    out = transfer(trot, to="cat", method="direct_relabelled")
    assert out.species == "cat" and out.num_frames == trot.num_frames
    np.testing.assert_allclose(out.rotations, trot.rotations)
    from habitsim.species import load_species

    k = load_species("cat").hip_height / load_species("horse").hip_height
    np.testing.assert_allclose(out.root_positions, trot.root_positions * k)
    with pytest.raises(UnknownSpeciesError):
        transfer(trot, to="unicorn", method="direct_relabelled")


@needs_ckpt
def test_habit_transfer_to_training_and_held_out_species(trot):
    cat = transfer(trot, to="cat", seed=3)
    assert cat.species == "cat" and cat.num_frames == trot.num_frames and cat.fps == trot.fps
    assert cat.contacts is not None and cat.contacts.shape == (trot.num_frames, 4)
    assert cat.metadata["transfer"]["habit_species"] == "cat"
    assert cat.metadata["transfer"]["retrieval"] is None
    again = transfer(trot, to="cat", seed=3)
    np.testing.assert_array_equal(cat.rotations, again.rotations)  # same seed, same motion
    tiger = transfer(trot, to="tiger")
    r = tiger.metadata["transfer"]["retrieval"]
    assert tiger.species == "tiger" and r["neighbour"] == "cat"
    assert "tiger" in r["explanation"] and "cat" in r["explanation"]
    # closer to the cat's own trot (the paired synthetic clip: same action and draws) than
    # the direct copy, both in posture (root-relative) and in the whole trajectory
    from habitsim.models.evaluate import clip_mpjpe

    gt = generate("cat", "trot", seed=5, duration_s=3.0)
    direct = transfer(trot, to="cat", method="direct_relabelled")
    e_habit, e_direct = clip_mpjpe(cat, gt), clip_mpjpe(direct, gt)
    assert e_habit["root_relative_mm"] < 0.8 * e_direct["root_relative_mm"]
    assert e_habit["mpjpe_mm"] < 0.8 * e_direct["mpjpe_mm"]
    assert abs(cat.root_positions[:, 2].mean() - gt.root_positions[:, 2].mean()) < abs(
        direct.root_positions[:, 2].mean() - gt.root_positions[:, 2].mean()
    )


@needs_ckpt
def test_long_and_resampled_motions(trot):
    long = generate("dog", "walk", seed=9, duration_s=6.0)  # 181 frames: several windows
    out = transfer(long, to="goat")
    assert out.num_frames == long.num_frames
    assert out.metadata["transfer"]["windows"] >= 3
    assert np.all(np.isfinite(out.global_positions()))
    from habitsim.models.transfer import _resample

    fast = _resample(trot, 60.0)
    out60 = transfer(fast, to="cat")
    assert out60.fps == 60.0 and abs(out60.num_frames - fast.num_frames) <= 1


def test_unavailable_ablation_names_the_fix(tmp_path, monkeypatch, trot):
    monkeypatch.setenv("HABITSIM_MODELS_DIR", str(tmp_path))
    if shipped_checkpoint("no_habit") is None:
        with pytest.raises(MethodNotAvailableError, match="--variant no_habit"):
            transfer(trot, to="cat", method="no_habit")
    if SHIPPED is not None:
        with pytest.raises(MethodNotAvailableError, match="'habit' one"):
            transfer(trot, to="cat", method="no_habit", checkpoint=SHIPPED)
    assert issubclass(MethodNotAvailableError, HabitsimError)


@needs_ckpt
def test_transfer_reuses_the_seeded_prior_draw_kept_on_the_checkpoint():
    """The habit latent a transfer draws is the flow prior's draw for its seed and
    temperature, drawn once and kept on the loaded checkpoint."""
    import importlib

    import torch

    tr = importlib.import_module("habitsim.models.transfer")
    ck = tr.load_model()
    ck.prior_draws.clear()
    z0 = tr._prior_draw(ck, "cat", None, 1.0)
    fresh = ck.model.sample_prior("cat", 1, torch.Generator().manual_seed(0), 1.0)
    torch.testing.assert_close(z0, fresh, rtol=0, atol=0)
    assert tr._prior_draw(ck, "cat", 0, 1.0) is z0  # seed None draws as seed 0
    assert not torch.equal(tr._prior_draw(ck, "cat", 1, 1.0), z0)
    assert not torch.equal(tr._prior_draw(ck, "cat", 0, 0.5), z0)
    assert not torch.equal(tr._prior_draw(ck, "horse", 0, 1.0), z0)
    assert len(ck.prior_draws) == 4
    clip = generate("horse", "trot", seed=7, duration_s=2.0)
    first = transfer(clip, to="cat", seed=3)
    again = transfer(clip, to="cat", seed=3)
    np.testing.assert_array_equal(first.rotations, again.rotations)
    np.testing.assert_array_equal(first.root_positions, again.root_positions)
    ck.prior_draws.clear()  # a fresh draw gives the same transfer
    np.testing.assert_array_equal(transfer(clip, to="cat", seed=3).rotations, first.rotations)
