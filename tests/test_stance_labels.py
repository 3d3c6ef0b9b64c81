"""Stance labels and the run algebra (habitsim.stance.labels): hand-computed cases, and
agreement with reference implementations written as explicit per-frame loops."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from habitsim.errors import HabitsimError, InvalidMotionError
from habitsim.stance.labels import (
    EditReason,
    StanceEdit,
    StanceLabels,
    StanceSource,
    duty_factors,
    pooled_stance_f1,
    runs,
    runs_holding,
    stance_f1,
    stance_runs,
    swing_bounds,
    swing_gaps,
)


def _arr(*rows: str) -> np.ndarray:
    """(T, F) bool from one string per foot ("1101" = stance, stance, swing, stance)."""
    return np.array([[ch == "1" for ch in r] for r in rows], dtype=bool).T


# ----------------------------------------------------------------- reference loops
def _ref_runs(col: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of the True runs, by walking the frames."""
    out, start = [], None
    for k, v in enumerate(col.tolist()):
        if v and start is None:
            start = k
        if not v and start is not None:
            out.append((start, k))
            start = None
    if start is not None:
        out.append((start, len(col)))
    return out


def _ref_holding(loose: np.ndarray, strict: np.ndarray) -> np.ndarray:
    out = np.zeros_like(loose)
    for f in range(loose.shape[1]):
        for a, b in _ref_runs(loose[:, f]):
            if strict[a:b, f].any():
                out[a:b, f] = True
    return out


def _ref_swing_bounds(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lift-off: the last swing start at or before k; touch-down: the next stance start
    after k (T if none), scanning the frames forward and backward."""
    t, nf = c.shape
    lo = np.full((t, nf), -1, dtype=int)
    td = np.full((t, nf), -1, dtype=int)
    for f in range(nf):
        last = 0
        for k in range(t):
            if not c[k, f] and (k == 0 or c[k - 1, f]):
                last = k
            if not c[k, f]:
                lo[k, f] = last
        nxt = t
        for k in range(t - 1, -1, -1):
            if c[k, f] and (k == 0 or not c[k - 1, f]):
                nxt = k
            if not c[k, f]:
                td[k, f] = nxt
    return lo, td


def _ref_f1(p: np.ndarray, r: np.ndarray) -> float:
    tp = int((p & r).sum())
    fp = int((p & ~r).sum())
    fn = int((~p & r).sum())
    return 1.0 if tp + fp + fn == 0 else 2 * tp / (2 * tp + fp + fn)


def _random_labels(rng: np.random.Generator, t: int, nf: int) -> np.ndarray:
    """Labels with runs of random lengths (some feet all stance or all swing)."""
    c = np.zeros((t, nf), dtype=bool)
    for f in range(nf):
        k, v = 0, bool(rng.integers(2))
        while k < t:
            n = int(rng.integers(1, 6))
            c[k : k + n, f] = v
            k, v = k + n, not v
    if nf > 2:
        c[:, 0] = rng.integers(3) == 0  # sometimes a foot that never (or always) stands
    return c


# ------------------------------------------------------------------------- the runs
def test_runs_by_hand() -> None:
    assert runs(np.array([1, 1, 0, 1, 0, 0, 1], bool)) == [(0, 2), (3, 4), (6, 7)]
    assert runs(np.array([0, 1, 1, 0], bool)) == [(1, 3)]
    assert runs(np.zeros(4, bool)) == []
    assert runs(np.ones(3, bool)) == [(0, 3)]
    assert runs(np.zeros(0, bool)) == []
    assert runs(np.array([0, 2, 1, 0])) == [(1, 3)]  # nonzero counts as True
    assert all(type(v) is int for r in runs(np.ones(2, bool)) for v in r)
    with pytest.raises(InvalidMotionError, match=r"shape \(T,\)"):
        runs(np.ones((3, 2), bool))


def test_stance_runs_and_gaps_at_the_clip_ends() -> None:
    c = _arr("110111", "001100", "000000", "111111")
    assert stance_runs(c) == [[(0, 2), (3, 6)], [(2, 4)], [], [(0, 6)]]
    # gaps touching the clip's start or end are listed too (start 0, stop T)
    assert swing_gaps(c) == [[(2, 3)], [(0, 2), (4, 6)], [(0, 6)], []]
    assert stance_runs(np.zeros((0, 2), bool)) == [[], []]
    with pytest.raises(InvalidMotionError, match=r"shape \(T, F\)"):
        stance_runs(np.ones(5, bool))
    with pytest.raises(InvalidMotionError):
        swing_gaps(np.ones(5, bool))


def test_runs_holding_keeps_seeded_runs() -> None:
    loose = _arr("1101110", "1111111")
    seed = _arr("0000100", "0000000")
    assert np.array_equal(runs_holding(loose, seed), _arr("0001110", "0000000"))
    # a seed frame outside the flags seeds nothing
    assert not runs_holding(_arr("1100"), _arr("0010")).any()
    assert runs_holding(np.zeros((0, 3), bool), np.zeros((0, 3), bool)).shape == (0, 3)
    with pytest.raises(InvalidMotionError, match="one shape"):
        runs_holding(np.ones((4, 2), bool), np.ones((4, 3), bool))


def test_swing_bounds_by_hand() -> None:
    c = _arr("1001100", "0110111", "1111111")
    lo, td = swing_bounds(c)
    # LF: swing 1..2 lifted off at 1, lands at 3; swing 5..6 runs to the clip's end (T=7)
    assert lo[:, 0].tolist() == [-1, 1, 1, -1, -1, 5, 5]
    assert td[:, 0].tolist() == [-1, 3, 3, -1, -1, 7, 7]
    # RF: a swing at the clip's start lifted off at 0
    assert lo[:, 1].tolist() == [0, -1, -1, 3, -1, -1, -1]
    assert td[:, 1].tolist() == [1, -1, -1, 4, -1, -1, -1]
    assert (lo[:, 2] == -1).all() and (td[:, 2] == -1).all()


def test_duty_factors() -> None:
    c = _arr("1100", "1111", "0000")
    np.testing.assert_array_equal(duty_factors(c), [0.5, 1.0, 0.0])
    with pytest.raises(InvalidMotionError, match="T >= 1"):
        duty_factors(np.zeros((0, 4), bool))


def test_algebra_agrees_with_frame_loops() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        t, nf = int(rng.integers(1, 25)), int(rng.integers(1, 5))
        c = _random_labels(rng, t, nf)
        seed = rng.random((t, nf)) < 0.15
        assert stance_runs(c) == [_ref_runs(c[:, f]) for f in range(nf)]
        assert swing_gaps(c) == [_ref_runs(~c[:, f]) for f in range(nf)]
        assert np.array_equal(runs_holding(c, seed), _ref_holding(c, seed))
        lo, td = swing_bounds(c)
        rlo, rtd = _ref_swing_bounds(c)
        assert np.array_equal(lo, rlo) and np.array_equal(td, rtd)
        # runs and gaps tile the clip
        for f in range(nf):
            spans = sorted(stance_runs(c)[f] + swing_gaps(c)[f])
            assert sum(b - a for a, b in spans) == t
            assert all(b0 == a1 for (_, b0), (a1, _) in zip(spans, spans[1:], strict=False))


# ---------------------------------------------------------------------------- F1
def test_stance_f1_per_foot_by_hand() -> None:
    pred = _arr("1100", "0000", "1111", "0000")
    ref = _arr("1000", "0000", "0000", "1010")
    # LF: TP 1, FP 1, FN 0 -> 2/3; RF: neither stands -> 1; LH, RH: one side only -> 0
    np.testing.assert_allclose(stance_f1(pred, ref), [2 / 3, 1.0, 0.0, 0.0])
    with pytest.raises(InvalidMotionError, match="must match"):
        stance_f1(pred, ref[:3])
    with pytest.raises(InvalidMotionError, match="must match"):
        stance_f1(pred[:, 0], ref[:, 0])


def test_pooled_stance_f1_by_hand() -> None:
    ref = np.array([[1, 1, 0, 0], [1, 0, 0, 1]], bool)
    sim = np.array([[1, 0, 0, 0], [1, 0, 1, 1]], bool)
    assert pooled_stance_f1(sim, ref) == pytest.approx(6 / 8)  # TP 3, FP 1, FN 1
    assert pooled_stance_f1(np.zeros((3, 4), bool), np.zeros((3, 4), bool)) == 1.0
    assert pooled_stance_f1(np.zeros((0, 4), bool), np.zeros((0, 4), bool)) == 1.0
    assert pooled_stance_f1(np.ones((2, 2), bool), np.zeros((2, 2), bool)) == 0.0
    with pytest.raises(InvalidMotionError, match="shapes differ"):
        pooled_stance_f1(sim, ref[:1])


def test_f1_variants_agree_with_counts() -> None:
    rng = np.random.default_rng(3)
    for _ in range(100):
        t, nf = int(rng.integers(1, 20)), int(rng.integers(1, 5))
        p, r = _random_labels(rng, t, nf), _random_labels(rng, t, nf)
        per_foot = stance_f1(p, r)
        assert per_foot.tolist() == [_ref_f1(p[:, f], r[:, f]) for f in range(nf)]
        assert pooled_stance_f1(p, r) == _ref_f1(p, r)
        # one foot pooled is that foot's F1
        assert pooled_stance_f1(p[:, :1], r[:, :1]) == per_foot[0]


# ------------------------------------------------------------------ StanceLabels
def test_labels_hold_a_read_only_copy() -> None:
    raw = _arr("1100", "0110")
    labels = StanceLabels(raw, StanceSource.DETECTED)
    raw[0, 0] = False  # the caller's array stays the caller's
    assert labels.array[0, 0]
    with pytest.raises(ValueError):
        labels.array[0, 0] = False
    with pytest.raises(dataclasses.FrozenInstanceError):
        labels.source = StanceSource.GIVEN  # type: ignore[misc]
    assert (labels.n_frames, labels.n_feet) == (4, 2) and labels.edits == ()
    # 0/1 numbers are labels too; the source may be given by its code
    assert StanceLabels(raw.astype(np.uint8), "given").source is StanceSource.GIVEN
    assert StanceLabels(raw, "given").array.dtype == bool


def test_labels_reject_bad_input() -> None:
    with pytest.raises(InvalidMotionError, match=r"shape \(T, F\)"):
        StanceLabels(np.ones(4, bool), StanceSource.GIVEN)
    with pytest.raises(InvalidMotionError, match="booleans"):
        StanceLabels(np.full((4, 2), 0.5), StanceSource.GIVEN)
    with pytest.raises(InvalidMotionError, match="unknown stance source 'guessed'; known: given"):
        StanceLabels(np.ones((4, 2), bool), "guessed")  # type: ignore[arg-type]
    edit = StanceEdit("test", EditReason.GAP_FILL, ((1,), (), ()))
    with pytest.raises(InvalidMotionError, match="names 3 feet"):
        StanceLabels(np.ones((4, 2), bool), StanceSource.GIVEN, (edit,))
    assert issubclass(InvalidMotionError, HabitsimError)


def test_edited_records_the_frames_that_changed() -> None:
    before = StanceLabels(_arr("111100", "001111"), StanceSource.INPUT)
    new = _arr("011100", "001101")
    after = before.edited(new, by="test.trim", reason=EditReason.SLIP_TRIM)
    assert after is not before and np.array_equal(after.array, new)
    assert before.edits == () and np.array_equal(before.array, _arr("111100", "001111"))
    assert after.source is StanceSource.INPUT
    (edit,) = after.edits
    assert edit == StanceEdit("test.trim", EditReason.SLIP_TRIM, ((0,), (4,)))
    assert edit.n_changed == 2
    assert np.array_equal(edit.mask(6), new != before.array)
    # an edit that changes nothing is not recorded
    assert after.edited(new.copy(), by="test.noop", reason=EditReason.GAP_FILL) is after
    with pytest.raises(InvalidMotionError, match="keep the shape"):
        after.edited(new[:3], by="test", reason=EditReason.GAP_FILL)
    with pytest.raises(InvalidMotionError, match="unknown edit reason 'no such reason'"):
        after.edited(new, by="test", reason="no such reason")  # type: ignore[arg-type]


def test_changed_since_is_the_net_change() -> None:
    c0 = _arr("110011")
    a = StanceLabels(c0, StanceSource.GIVEN)
    b = a.edited(_arr("100011"), by="t", reason=EditReason.SLIP_TRIM)  # frame 1 off
    c = b.edited(_arr("111111"), by="t", reason=EditReason.GAP_FILL)  # frames 1-3 on
    assert [e.frames for e in c.edits] == [((1,),), ((1, 2, 3),)]
    # frame 1 went off and back on: unchanged against the original
    assert np.flatnonzero(c.changed_since(0)[:, 0]).tolist() == [2, 3]
    assert np.flatnonzero(c.changed_since(1)[:, 0]).tolist() == [1, 2, 3]
    assert not c.changed_since(2).any()


def test_labels_equality_and_methods() -> None:
    c = _arr("1100", "0111")
    a = StanceLabels(c, StanceSource.GIVEN)
    assert a == StanceLabels(c.copy(), "given")
    assert a != StanceLabels(c, StanceSource.DETECTED)
    assert a != a.edited(_arr("1000", "0111"), by="t", reason=EditReason.BLIP_DROP)
    assert a != StanceLabels(c[:3], StanceSource.GIVEN)
    with pytest.raises(TypeError):
        hash(a)
    assert a.runs() == stance_runs(c) and a.gaps() == swing_gaps(c)
    np.testing.assert_array_equal(a.duty_factors(), [0.5, 0.75])
    np.testing.assert_array_equal(a.f1(a), [1.0, 1.0])
    np.testing.assert_array_equal(a.f1(~c), [0.0, 0.0])


def test_codes_are_their_report_strings() -> None:
    assert StanceSource("input") is StanceSource.INPUT and f"{StanceSource.DETECTED}" == "detected"
    assert {r.value for r in EditReason} >= {"slip_trim", "gap_fill", "blip_drop", "restep", "trim"}
    assert all(r.value == r.name.lower() for r in EditReason)


# ------------------------------------------------------- edit records of the stance stages
@pytest.fixture(scope="module")
def dog_walk():
    from habitsim.gaits import generate

    return generate("dog", "walk", seed=2, duration_s=2.0)


def _faster(walk, k: float):
    """The walk with its body ``k`` times as fast (the legs' labels unchanged)."""
    from habitsim.motion import Motion

    step = np.diff(walk.root_positions[:, :2], axis=0) * k
    root = walk.root_positions.copy()
    root[1:, :2] = root[0, :2] + np.cumsum(step, axis=0)
    return Motion("dog", walk.fps, root, walk.rotations, walk.contacts)


def test_schedule_records_where_labels_came_from_and_each_edit(dog_walk) -> None:
    from habitsim.motion import Motion
    from habitsim.stance.schedule import transfer_contacts

    src = dog_walk
    out = Motion("horse", src.fps, src.root_positions * 2.0, src.rotations)
    labels, info = transfer_contacts(out, src)
    assert labels.source is StanceSource.SOURCE and info["method"] == "source"
    bad = src.contacts.copy()
    bad[:, 2] = ~bad[:, 2]
    a, b = max(stance_runs(bad)[0], key=lambda r: r[1] - r[0])
    mid = (a + b) // 2
    bad[mid, 0] = False  # a one-frame flicker in a stance run: filled
    labels, info = transfer_contacts(out, src, bad)
    assert labels.source is StanceSource.DECODED
    reasons = [e.reason for e in labels.edits]
    assert reasons == [EditReason.SHORT_RUN_DROP, EditReason.SOURCE_FOOT]
    drop, swap = labels.edits
    assert drop.frames[0] == (mid,) and drop.by == "stance.schedule.transfer_contacts"
    assert swap.frames[2] == tuple(range(len(bad))) and swap.frames[0] == ()
    np.testing.assert_array_equal(labels.array, src.contacts)
    np.testing.assert_array_equal(labels.changed_since(0), bad != src.contacts)


def test_walking_stance_records_the_frames_it_added() -> None:
    from habitsim.gaits import generate
    from habitsim.stance.schedule import walking_stance

    slow = generate("cat", "walk", seed=1, duration_s=3.0, froude=0.3, duty_factor=0.35)
    given = StanceLabels(slow.contacts, StanceSource.SOURCE)
    labels, info = walking_stance(slow, given, slow)
    assert info is not None and labels.source is StanceSource.SOURCE
    assert [e.reason for e in labels.edits][0] is EditReason.WALK_LENGTHEN
    assert {e.reason for e in labels.edits} <= {EditReason.WALK_LENGTHEN, EditReason.WALK_SUPPORT}
    added = labels.changed_since(0)
    np.testing.assert_array_equal(added, labels.array & ~slow.contacts)  # stance only grows
    assert added.any()
    trot = generate("cat", "trot", seed=1, duration_s=3.0, froude=0.6, duty_factor=0.4)
    kept, none = walking_stance(trot, StanceLabels(trot.contacts, StanceSource.SOURCE), trot)
    assert none is None and kept.edits == ()


def test_ladder_records_trims_and_resteps(dog_walk) -> None:
    from habitsim.stance.ladder import restep, trim_to_reach

    fast = _faster(dog_walk, 3.0)
    given = StanceLabels(dog_walk.contacts, StanceSource.DECODED)
    trimmed, rep = trim_to_reach(fast, given)
    assert rep is not None and trimmed.source is StanceSource.DECODED
    (edit,) = trimmed.edits
    assert edit.reason is EditReason.TRIM and edit.n_changed == rep.frames
    stepped = restep(fast, given)
    assert stepped is not None
    moved, planting = stepped
    assert planting.restep is not None and planting.labels is not None
    assert [e.reason for e in planting.labels.edits] == [EditReason.RESTEP]
    np.testing.assert_array_equal(planting.labels.array, moved.contacts)
    # an array is taken as given labels
    assert trim_to_reach(fast, dog_walk.contacts)[0].source is StanceSource.GIVEN
