"""In-place clips (habitsim.bvh_mapping.inplace) and loops (habitsim.bvh_mapping.loops):
detection, the travel recovered from the stance feet, the report, seamless repeats."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from habitsim.bvh import write_bvh
from habitsim.bvh_mapping import ImportReport, import_bvh
from habitsim.bvh_mapping.inplace import InPlaceOptions, InPlaceOptionsError
from habitsim.bvh_mapping.loops import LoopError, detect_loop, repeat_loop
from habitsim.bvh_mapping.report import in_place_note
from habitsim.errors import HabitsimError
from habitsim.evaluation.bench.inplace import (
    HEADING_DEG,
    PATH_SHARE,
    STANCE_F1,
    recovery_row,
    synthetic_walk,
)
from habitsim.motion import Motion


@pytest.fixture(scope="module")
def walks(tmp_path_factory: pytest.TempPathFactory) -> tuple[Motion, Motion]:
    """The import of a synthetic walk loop and of the same walk made in place (the moving
    one retargeted like any rig, ``units=1.0``, rather than copied)."""
    d = tmp_path_factory.mktemp("inplace")
    walk = write_bvh(synthetic_walk(3, in_place=False), d / "w.bvh")
    moving, _ = import_bvh(walk, "dog", units=1.0)
    still, _ = import_bvh(write_bvh(synthetic_walk(3, in_place=True), d / "s.bvh"), "dog")
    return moving, still


def test_in_place_walk_is_detected_and_its_travel_recovered(walks) -> None:
    moving, still = walks
    rep = ImportReport.from_metadata(still.metadata)
    assert rep is not None and rep.in_place is not None
    assert rep.in_place.detected
    assert rep.in_place.root_travel_m < 0.05 * rep.in_place.foot_sweep_m
    row = recovery_row("w", moving, still)
    assert row.detected
    assert row.path_share <= PATH_SHARE
    assert row.heading_error_deg <= HEADING_DEG
    assert row.stance_f1 >= STANCE_F1
    # the heading reported is the moving walk's own direction of travel
    d = moving.root_positions[-1, :2] - moving.root_positions[0, :2]
    want = math.degrees(math.atan2(d[1], d[0]))
    assert abs((rep.in_place.heading_deg - want + 180) % 360 - 180) <= HEADING_DEG
    note = in_place_note(still.metadata)
    assert note is not None and "in place" in note


def test_moving_clip_is_not_flagged(walks) -> None:
    moving, _ = walks
    rep = ImportReport.from_metadata(moving.metadata)
    assert rep is not None and rep.in_place is not None
    assert not rep.in_place.detected
    assert "trunk travels" in rep.in_place.reason
    assert in_place_note(moving.metadata) is None


def test_detection_can_be_switched_off(tmp_path: Path) -> None:
    p = write_bvh(synthetic_walk(3, in_place=True), tmp_path / "s.bvh")
    m, _ = import_bvh(p, "dog", inplace=InPlaceOptions(enabled=False))
    rep = ImportReport.from_metadata(m.metadata)
    # the copied file keeps its still root: no travel added
    assert np.ptp(m.root_positions[:, 0]) < 0.02
    assert rep is None or rep.in_place is None or not rep.in_place.detected
    with pytest.raises(InPlaceOptionsError):
        InPlaceOptions(max_root_share=0.0)


def test_report_round_trip(walks) -> None:
    _, still = walks
    rep = ImportReport.from_metadata(still.metadata)
    assert rep is not None
    assert ImportReport.from_metadata({"import": rep.to_metadata()}) == rep


def _jump(m: Motion) -> np.ndarray:
    """(T-1,) per-frame displacement of every joint, largest over joints [m]."""
    pos = m.global_positions()
    return np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=1)


def test_loop_repeated_seamlessly() -> None:
    loop = synthetic_walk(3, seconds=1.0, in_place=False)
    fit = detect_loop(
        loop.global_positions() - loop.root_positions[:, None], loop.species_info.leg_length
    )
    assert fit.kind == "closed"
    period = loop.num_frames - 1
    n = 3
    rep = repeat_loop(loop, cycles=n)
    assert rep.num_frames == n * period + 1
    assert math.isclose(rep.duration - 1 / rep.fps, n * (loop.duration - 1 / loop.fps))
    step = _jump(loop)
    seams = _jump(rep)[[period - 1, 2 * period - 1]]
    assert seams.max() <= 1.5 * step.max()
    # travel accumulated: each cycle moves on by the loop's own displacement
    d = loop.root_positions[-1, :2] - loop.root_positions[0, :2]
    assert np.allclose(rep.root_positions[-1, :2] - rep.root_positions[0, :2], n * d, atol=1e-9)
    longer = repeat_loop(loop, seconds=2.5)
    assert longer.num_frames == round(2.5 * loop.fps)


def test_repeated_import_records_its_cycles(walks) -> None:
    _, still = walks
    rep = repeat_loop(still, cycles=2)
    rec = ImportReport.from_metadata(rep.metadata)
    assert rec is not None and rec.in_place is not None and rec.in_place.cycles == 2


def test_not_a_loop_is_refused() -> None:
    loop = synthetic_walk(3, seconds=1.0, in_place=False)
    half = loop.slice(0, loop.num_frames // 2 + 3)
    with pytest.raises(LoopError, match="not a loop") as e:
        repeat_loop(half, cycles=2)
    assert isinstance(e.value, HabitsimError)
    assert "first and last poses match" in str(e.value) or "cut the clip" in str(e.value)
    with pytest.raises(LoopError, match="cycles or as seconds"):
        repeat_loop(loop)
    with pytest.raises(LoopError, match="cycles must be"):
        repeat_loop(loop, cycles=0)


def test_source_options_loop(tmp_path: Path) -> None:
    from habitsim.source import SourceOptions, Span, load_clip

    loop = synthetic_walk(3, seconds=1.0, in_place=False)
    p = loop.save(tmp_path / "loop.npz")
    clip = load_clip(p, SourceOptions(loop=2))
    assert clip.motion.num_frames == 2 * (loop.num_frames - 1) + 1
    assert clip.looped() and not clip.cut
    assert SourceOptions(loop_seconds=1.5).shape(loop).num_frames == round(1.5 * loop.fps)
    with pytest.raises(LoopError, match="not a loop"):
        load_clip(p, SourceOptions(loop=2, span=Span(0.0, 0.5 * loop.duration)))


def test_cli_loop_flags(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from habitsim.cli import main
    from habitsim.motion import load_motion

    src = write_bvh(synthetic_walk(3, seconds=1.0, in_place=True), tmp_path / "s.bvh")
    out = tmp_path / "s.npz"
    code = main(
        ["data", "import-bvh", str(src), "--species", "dog", "--out", str(out), "--loop", "3"]
    )
    text = capsys.readouterr().out
    assert code == 0
    assert "in place: yes" in text and "played 3 times" in text
    m = load_motion(out)
    rep = ImportReport.from_metadata(m.metadata)
    assert rep is not None and rep.in_place is not None and rep.in_place.cycles == 3
    assert np.ptp(m.root_positions[:, 0]) > 1.0  # the recovered travel, carried on


def test_malformed_in_place_record_is_named(walks) -> None:
    from habitsim.errors import MetadataError

    _, still = walks
    meta = ImportReport.from_metadata(still.metadata)
    assert meta is not None
    bad = meta.to_metadata()
    bad["in_place"] = dict(bad["in_place"], loop="sometimes")
    with pytest.raises(MetadataError, match="import.in_place.loop"):
        ImportReport.from_metadata({"import": bad})
    bad["in_place"] = dict(meta.to_metadata()["in_place"], unreached_frames=-1)
    with pytest.raises(MetadataError, match="import.in_place.unreached_frames"):
        ImportReport.from_metadata({"import": bad})


def test_stance_centres_trim_touch_down_and_lift_off() -> None:
    from habitsim.bvh_mapping.inplace import stance_centres

    c = np.zeros((30, 2), bool)
    c[5:15, 0] = True  # a whole run: 2 of its 10 frames off at each end
    c[:6, 1] = True  # cut by the clip's start: only its lift-off end is trimmed
    c[25:, 1] = True  # cut by the clip's end: only its touch-down end
    out = stance_centres(c, 0.2)
    assert np.flatnonzero(out[:, 0]).tolist() == list(range(7, 13))
    assert np.flatnonzero(out[:, 1]).tolist() == [0, 1, 2, 3, 4, 26, 27, 28, 29]
    # a loop's run across the seam is one run of 11 frames: 2 off at each end
    loop = stance_centres(c[:, 1:], 0.2, cyclic=True)[:, 0]
    assert np.flatnonzero(loop).tolist() == [0, 1, 2, 3, 27, 28, 29]
    assert not stance_centres(np.zeros((8, 4), bool), 0.2).any()


def _rolling_gait(
    fps: float = 60.0, seconds: float = 4.0, speed: float = 1.0, roll: float = 0.6
) -> tuple[list[np.ndarray], np.ndarray]:
    """Four in-place feet (T, 1, 3) of a walk at ``speed`` [m/s] (stride 1 s, duty 0.6)
    whose paws rest in the world over the middle of each stance and move forward at
    ``roll`` times the body's speed over its first and last 15 % (settling and rolling
    over the toes), and their stance labels (T, 4)."""
    t = int(seconds * fps)
    phase_of = (np.arange(t) / fps)[:, None] + np.array([0.0, 0.5, 0.25, 0.75])[None, :]
    ph = phase_of % 1.0
    stance = ph < 0.6
    ends = stance & ((ph < 0.09) | (ph > 0.51))
    # world velocity of each paw along x: 0 at rest, roll * speed at the stance ends, and
    # in swing whatever makes a stride of 1 s cover the body's travel
    v = np.where(ends, roll * speed, 0.0)
    swing_share = 0.4
    carried = roll * speed * 0.18  # the paw's travel over the stance ends of one stride
    v = np.where(stance, v, (speed - carried) / swing_share)
    world = np.cumsum(v, axis=0) / fps
    x = world - (np.arange(t) / fps * speed)[:, None]
    z = np.where(stance, 0.0, 0.05 * np.sin(np.pi * np.clip((ph - 0.6) / 0.4, 0, 1)))
    feet = [np.stack([x[:, k], np.zeros(t), z[:, k]], axis=-1)[:, None, :] for k in range(4)]
    return feet, stance


def test_refit_leaves_out_the_rolling_ends_of_stance() -> None:
    from habitsim.bvh_mapping.inplace import recover_in_place, refit_in_place

    fps, speed = 60.0, 1.0
    feet, stance = _rolling_gait(fps, speed=speed)
    t = stance.shape[0]
    forward = np.tile([1.0, 0.0, 0.0], (t, 1))
    fit = recover_in_place(feet, np.zeros((t, 3)), forward, fps, 0.5)
    assert fit.detected
    want = speed * (t - 1) / fps
    got = refit_in_place(fit, feet, stance, fps)
    whole = refit_in_place(fit, feet, stance, fps, options=InPlaceOptions(stance_trim_share=0.0))
    # the whole runs count the rolling ends: the body seems slower than it is
    assert whole.travel[-1, 0] < 0.9 * want
    assert abs(got.travel[-1, 0] - want) < 0.02 * want
    assert abs(got.heading_deg) < 1.0 and got.recovered_m > 0.95 * want
    # not detected: the fit is returned as it came
    off = dataclasses.replace(fit, detected=False)
    assert refit_in_place(off, feet, stance, fps) is off
    with pytest.raises(InPlaceOptionsError, match="stance_trim_share"):
        InPlaceOptions(stance_trim_share=0.5)


def test_trim_unreached_takes_off_high_run_ends() -> None:
    from habitsim.bvh_mapping.inplace import trim_unreached
    from habitsim.stance.labels import EditReason, StanceLabels, StanceSource

    c = np.zeros((20, 4), bool)
    c[2:12, 0] = True
    c[2:12, 1] = True
    c[15:, 2] = True
    c[:4, 2] = True  # a loop's run across the seam: frames 15..19, 0..3
    h = np.zeros((20, 4))
    h[[2, 3, 11], 0] = 0.01  # two high frames at touch-down, one at lift-off
    h[7, 0] = 0.01  # high in the middle: not an end, kept
    h[[2, 11], 1] = 0.01  # foot 1 is not a swept foot: kept
    h[[3, 15], 2] = 0.01  # the seam run's lift-off and touch-down ends
    h[10, 2] = 0.01  # a swing frame: nothing to take off
    labels = StanceLabels(c, StanceSource.IMPORTED)
    out, n = trim_unreached(labels, h, (0, 2), 0.005, cyclic=True)
    assert n == 5
    assert np.flatnonzero(out.array[:, 0]).tolist() == list(range(4, 11))
    assert np.array_equal(out.array[:, 1], c[:, 1])
    assert np.flatnonzero(out.array[:, 2]).tolist() == [0, 1, 2, 16, 17, 18, 19]
    assert out.edits[-1].reason == EditReason.IN_PLACE_REACH
    # not a loop: the run cut by the clip's start keeps its first frame
    _, n_open = trim_unreached(labels, h, (2,), 0.005)
    assert n_open == 2  # frame 3 (lift-off) and frame 15 (touch-down); frame 0 stays
    same, none = trim_unreached(labels, h, (0, 2), 1.0)
    assert none == 0 and same is labels


def test_swept_stance_ends_out_of_reach_become_swing(tmp_path: Path) -> None:
    """A gallop made in place whose feet all take their sweeps as stance: its sweeps are
    longer than the legs reach planted; the ends the legs do not reach become swing."""
    from habitsim.gaits import generate
    from habitsim.physics_constants import CONTACT_HEIGHT_PER_LEG

    g = generate("dog", "gallop", seed=3, duration_s=1.5)
    root = g.root_positions.copy()
    root[:, :2] = root[0, :2]
    p = write_bvh(Motion(g.species, g.fps, root, g.rotations), tmp_path / "g.bvh")
    top, frames = [], []
    for reach in (InPlaceOptions().reach_per_leg, 1.0):  # 1 leg length: nothing taken off
        m, _ = import_bvh(p, "dog", inplace=InPlaceOptions(relabel_share=5.0, reach_per_leg=reach))
        rep = ImportReport.from_metadata(m.metadata)
        assert rep is not None and rep.in_place is not None and len(rep.in_place.swept_feet) == 4
        assert m.contacts is not None
        toes = m.foot_positions()[..., 2] / m.species_info.leg_length
        top.append(float(toes[m.contacts].max()))
        frames.append(rep.in_place.unreached_frames)
    assert frames[0] > 0 and frames[1] == 0
    assert top[1] > CONTACT_HEIGHT_PER_LEG  # the untrimmed sweeps leave toes in the air
    assert top[0] <= CONTACT_HEIGHT_PER_LEG
