"""The planting ladder: a decoded motion's feet planted on its stance labels, with fallbacks.

:func:`plant_decoded` tries, in order, until the legs reach: the decoded root path with
each foothold rule; the body carried only as far as its stance legs carry it; the legs
stepping faster (:func:`restep`); the stance runs the legs reach held and the others left
free (:func:`plant_partly`, their out-of-reach runs shortened first by
:func:`trim_to_reach`). Each step's planting is :func:`habitsim.stance.planting.plant_motion`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..motion import Motion

if TYPE_CHECKING:
    from .planting import PlantReport

__all__ = [
    "plant_decoded",
    "restep",
    "plant_partly",
    "trim_to_reach",
    "plant_summary",
    "reaches",
    "swing_lift",
]


#: Planting is kept only when every planted toe reaches its target within this share of
#: leg length ...
PLANT_MAX_REACH_PER_LEG = 0.05
#: ... every swing toe between two stance runs comes within this share of its path (a
#: swing that cannot follow the straight line between footholds is a leg that cannot
#: step there: on real dog trots sent to the tiger and cat, plantings that missed their
#: swings by 0.13–0.36 leg lengths fell after 1.2 s where the carried root survived) ...
PLANT_MAX_SWING_REACH_PER_LEG = 0.1
#: ... and the pelvis is lowered by at most this share of leg length to reach them.
#: Beyond, a stance run sweeps further than the leg reaches: the decoded feet slide in
#: stance, so a foothold held for the whole run lies behind the hip at its end (and a
#: large source's stride sent to a small target keeps its cadence at the target's
#: Froude speed, so the small animal's strides are longer in leg lengths).
PLANT_MAX_DROP_PER_LEG = 0.1
#: When the legs do not reach, the body is moved only as far as its stance legs carry it
#: (:func:`habitsim.stance.planting.stance_driven_root`) and planted again, provided it keeps
#: at least this share of its decoded speed; below, the action itself would change (a
#: trot slowed to a shuffle) and the decoded feet are kept. Measured on the default
#: evaluation (33 synthetic pairs, ``habitsim eval``): carrying down to 40 % of the speed
#: raised habit survival from 0.710 to 0.774 but dropped action accuracy from 0.636 to
#: 0.545 and multiplied the paired MPJPE by 5 (the synthetic transfers' legs carry a
#: median 36 % of the decoded travel); the transfers of real dog clips whose planting
#: missed kept 77-119 % of their speed (one 47 %). 0.6 against 0.7 on the default
#: evaluation's sources to cat, horse, camel and bear (44 habit pairs): survival 0.896
#: against 0.873, but paired MPJPE 1070 against 336 mm, action accuracy 0.727 against
#: 0.750 and sim MPJPE 118 against 89 mm.
PLANT_MIN_SPEED_RATIO = 0.7
#: How each root path is planted, in order: each stance run's foothold at the median of
#: its decoded toe path, then half-way along the shoulder's / hip's travel over the run
#: (:func:`habitsim.stance.planting.plant_motion` with ``centre``: a sliding toe's median can
#: lie so far ahead of or behind the joint that the leg misses it at one end). The first
#: that reaches is kept; a rule whose footholds lie beyond the stretched legs even with
#: the pelvis lowered to the limit is not solved at all
#: (:func:`habitsim.stance.planting.stance_reach_shortfall`). Measured with ``habitsim bench
#: model --real`` (median rule alone → both rules): stance toes at rest on 58.7 → 68.5 %
#: of the synthetic transfers' stance frames with the shipped model (42.9 → 60.3 % with
#: a ``large`` one), the real ones unchanged (62.4 %, 50.9 %); evaluator action accuracy
#: 0.704 → 0.726 (0.830 → 0.868); latency of a 64-frame transfer whose planting misses
#: 13.5 → 8.2 ms (the unsolvable rules are not solved).
FOOTHOLD_RULES: tuple[bool, ...] = (False, True)


def plant_summary(
    report: PlantReport, contacts: np.ndarray, leg: float, free: np.ndarray | None = None
) -> dict[str, Any]:
    """A planting report for the metadata: :meth:`PlantReport.to_dict` with the largest
    reach error over the held stance frames (not the ``free`` runs), over the swings
    between two stance runs, and apart over each foot's swing before its first or after
    its last stance run (with no foothold to head for at the clip's end, the IK may leave
    a toe behind there; that does not decide whether a planting is kept)."""
    d = report.to_dict(leg)
    c = np.asarray(contacts, dtype=bool)
    idx = np.arange(c.shape[0])[:, None]
    first = np.where(c.any(axis=0), c.argmax(axis=0), c.shape[0])
    last = np.where(c.any(axis=0), c.shape[0] - 1 - c[::-1].argmax(axis=0), -1)
    edge = ~c & ((idx < first[None, :]) | (idx > last[None, :]))
    held = c if free is None else c & ~np.asarray(free, dtype=bool)
    err = report.reach_error

    def worst(mask: np.ndarray) -> float:
        return round(float(np.where(mask, err, 0.0).max()) / leg, 5)

    d["max_reach_error_per_leg"] = worst(held)
    d["max_swing_reach_error_per_leg"] = worst(~c & ~edge)
    d["max_edge_reach_error_per_leg"] = worst(edge)
    return d


def reaches(report: dict[str, Any]) -> bool:
    return (
        report["max_reach_error_per_leg"] <= PLANT_MAX_REACH_PER_LEG
        and report.get("max_swing_reach_error_per_leg", 0.0) <= PLANT_MAX_SWING_REACH_PER_LEG
        and report["max_pelvis_drop_per_leg"] <= PLANT_MAX_DROP_PER_LEG
    )


#: Lift every planted swing to the species' habitual swing height (:func:`swing_lift`).
#: The decoder's swing toes stay near the ground (its feet rest in stance, but a swing
#: shuffles forward just above it), so a planting without a lift left swing feet moving
#: below docs/metrics.md's contact height. Measured with the lift: ``habitsim bench
#: model`` (182 synthetic transfers) action accuracy 0.714 → 0.802 (the frozen evaluator
#: reads a shuffling walk as another action), stance toes at rest unchanged (95.7 %);
#: ``habitsim bench real`` habit transfers' skate before refinement 42.5 → 0.0 mm/frame
#: (median).
SWING_LIFT = True


def swing_lift(out: Motion, labels: np.ndarray) -> np.ndarray | None:
    """The lowest toe height [m] of each swing frame of a planting (T, 4; NaN in stance):
    a half-sine over the swing run peaking at the species' habitual swing height
    (``habits.swing_height`` of its species file, share of leg length), so a decoded
    foot that shuffles along the ground in swing is lifted; a toe already higher keeps
    its height. None when :data:`SWING_LIFT` is off."""
    from ..contacts import contact_segments

    if not SWING_LIFT:
        return None
    lift = np.full(labels.shape, np.nan)
    height = out.species_info.habits.swing_height * out.species_info.leg_length
    for f, runs in enumerate(contact_segments(~np.asarray(labels, dtype=bool))):
        for a, b in runs:
            lift[a:b, f] = height * np.sin(np.pi * (np.arange(b - a) + 0.5) / (b - a))
    return lift


def plant_decoded(
    out: Motion, contacts: np.ndarray, glob: np.ndarray | None = None
) -> tuple[Motion, dict[str, Any]]:
    """Plant ``out``'s feet on ``contacts``; fall back to the legs' own travel (module
    constants above). Returns the motion to keep and the report of what was done
    (``glob``: ``out``'s global joint positions, if already at hand)."""
    from .planting import plant_motion, stance_driven_root, stance_reach_shortfall

    leg = out.species_info.leg_length

    def attempt(motion: Motion, glob: np.ndarray) -> tuple[Motion, dict[str, Any], dict[str, Any]]:
        """(planted motion, its report, the first rule's report): the first foothold
        rule whose legs reach, else the last rule's result (``glob``: the motion's
        global joint positions)."""
        first: dict[str, Any] | None = None
        moved = motion
        for centre in FOOTHOLD_RULES:
            rule = "centred" if centre else "median"
            short = stance_reach_shortfall(
                motion, contacts, centre, PLANT_MAX_DROP_PER_LEG * leg, glob
            )
            if short > PLANT_MAX_REACH_PER_LEG * leg:  # no IK can hold these footholds
                rep = {
                    "max_reach_error_per_leg": round(short / leg, 5),
                    "max_pelvis_drop_per_leg": PLANT_MAX_DROP_PER_LEG,
                    "footholds": rule,
                    "solved": False,
                }
                moved = motion
            else:
                moved, report = plant_motion(
                    motion, contacts, swing_lift(motion, contacts), centre=centre, glob=glob
                )
                rep = {**plant_summary(report, contacts, leg), "footholds": rule, "solved": True}
            first = rep if first is None else first
            if reaches(rep):
                break
        assert first is not None  # FOOTHOLD_RULES is not empty
        return moved, rep, first

    if glob is None:
        glob = out.global_positions()  # one forward-kinematics pass for every reach test
    moved, rep, first = attempt(out, glob)
    if reaches(rep):
        return moved, {**rep, "kept": True, "root": "decoded"}
    missed = (
        f"the legs do not reach the footholds (toe {first['max_reach_error_per_leg']:.2f} "
        f"leg lengths off in stance, {first.get('max_swing_reach_error_per_leg', 0.0):.2f} "
        f"in swing, pelvis lowered {first['max_pelvis_drop_per_leg']:.2f}; limits "
        f"{PLANT_MAX_REACH_PER_LEG}, {PLANT_MAX_SWING_REACH_PER_LEG}, {PLANT_MAX_DROP_PER_LEG})"
    )
    carried, ratio = stance_driven_root(out, contacts, glob)
    if ratio >= PLANT_MIN_SPEED_RATIO:
        # the carried body only translates: its joints move with its root
        shift = (carried.root_positions - out.root_positions)[:, None, :]
        moved, second, _ = attempt(carried, glob + shift)
        if reaches(second):
            return moved, {
                **second,
                "kept": True,
                "root": "carried",
                "speed_ratio": round(ratio, 3),
                "reason": f"{missed} with the decoded root path; the body moved as far "
                f"as its stance legs carry it ({100 * ratio:.0f} % of its decoded speed)",
            }
        why = "not even with the body carried by its stance legs"
    else:
        why = (
            f"the stance legs carry the body only {100 * ratio:.0f} % of its decoded "
            f"speed (< {100 * PLANT_MIN_SPEED_RATIO:.0f} %)"
        )
    stepped = restep(out, contacts, glob)
    tried: dict[str, Any] = {}
    if stepped is not None:
        moved, rep = stepped
        tried = {
            "restep": {
                **rep["restep"],
                "max_reach_error_per_leg": rep["max_reach_error_per_leg"],
                "max_pelvis_drop_per_leg": rep["max_pelvis_drop_per_leg"],
            }
        }
        if reaches(rep):
            return moved, {
                **rep,
                "kept": True,
                "root": "decoded",
                "reason": f"{missed}, {why}: the legs step faster "
                f"(stride {rep['restep']['period_s'][0]:.2f} s → "
                f"{rep['restep']['period_s'][1]:.2f} s)",
            }
    if tried:
        why += ", not even stepping faster"
    partly = None
    if stepped is not None and PARTLY_ON_RESTEP:
        # the quickened labels ask the legs for the shorter sweeps: hold what they reach
        assert stepped[0].contacts is not None  # plant_motion labels its output
        partly = plant_partly(out, stepped[0].contacts, glob, trim=TRIM_TO_REACH)
        if partly is not None:
            why += " in every stance run; on the faster steps"
    if partly is None:
        partly = plant_partly(out, contacts, glob, trim=TRIM_TO_REACH)
    if partly is not None:
        moved, rep = partly
        trimmed = rep.get("trimmed")
        cut = (
            ""
            if trimmed is None
            else f"{trimmed['runs']} stance runs shortened to the legs' reach "
            f"({trimmed['frames']} frames), "
        )
        return moved, {
            **rep,
            **tried,
            "kept": True,
            "root": "decoded",
            "reason": f"{missed}, {why}: {cut}the stance runs out of reach keep the decoded "
            f"feet ({rep['free_runs'][0]} of {rep['free_runs'][1]} runs, "
            f"{100 * rep['free_share']:.0f} % of the stance frames)",
        }
    return out, {
        **first,
        **tried,
        "kept": False,
        "speed_ratio": round(ratio, 3),
        "reason": f"{missed}, {why}: the decoded feet are kept",
    }


#: When the legs stepping faster (:func:`restep`) still miss some footholds, the partial
#: planting (:func:`plant_partly`) holds the runs they reach on the faster steps, not on
#: the slower decoded ones, whose longer sweeps leave more runs to free or shorten.
PARTLY_ON_RESTEP = True
#: Partial planting (:func:`plant_partly`) finds the runs to leave free in at most this
#: many IK passes.
PARTIAL_PASSES = 4


def _run_mask(contacts: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """(T, 4) bool: the whole stance runs of ``contacts`` that have a frame in ``hit``."""
    from ..contacts import contact_segments

    out = np.zeros_like(contacts, dtype=bool)
    for k, segs in enumerate(contact_segments(contacts)):
        for a, b in segs:
            if hit[a:b, k].any():
                out[a:b, k] = True
    return out


#: Trimming (:func:`trim_to_reach`): a stance run is shortened at both ends, a frame a
#: step, until its centred foothold is within the legs' reach, but not below this many
#: seconds (at least 2 frames); a run that still misses stays whole and is left free by
#: :func:`plant_partly`.
TRIM_MIN_RUN_S = 0.1
#: Shorten the stance runs the partial planting leaves free and plant again
#: (:func:`plant_partly` with ``trim``, called by :func:`plant_decoded`).
TRIM_TO_REACH = True
#: A trimmed run's centred foothold must lie within the stretched leg with the pelvis
#: this share of leg length *higher* than it is. The cheap reach test counts the leg's
#: segments straight; the IK's legs, within their joint ranges, reach less far. Without
#: the margin the real back-walk sent to the cat was trimmed, the IK still had to lower
#: the pelvis beyond :data:`PLANT_MAX_DROP_PER_LEG`, and the trimmed labels held no more
#: stance (72 % of the stance frames free either way); with 0.1, 24 % are free; with 0.2
#: no run could be trimmed far enough.
TRIM_MARGIN_PER_LEG = 0.1


def trim_to_reach(
    out: Motion,
    contacts: np.ndarray,
    glob: np.ndarray | None = None,
    only: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, Any] | None]:
    """``contacts`` with every stance run whose centred foothold lies beyond the legs'
    reach shortened at both ends until it does not, and what was changed (``None``:
    nothing). ``only``: (T, 4) bool, the runs to consider (those with a frame in it;
    default every run).

    A decoded body that moves faster than its legs sweep in a long stance (a real dog's
    walk sent to the cat: duty factor 0.88 at 1.6 leg lengths per second, the legs
    carrying 44 % of that travel) asks each foot to stand where the shoulder or hip has
    already left. Such a run cannot be a foot at rest for its whole length. Its middle
    can: the foot touches down later and lifts earlier, at the same foothold, and the
    frames taken off are swing (lifted like the others). The run's centre, and with it
    the footfall phase, stays; the duty factor falls by what the legs cannot hold. A run
    that misses even at :data:`TRIM_MIN_RUN_S` is left as it was (the partial planting
    frees it). The reach test is :func:`habitsim.stance.planting.stance_run_shortfall` of the
    centred foothold with the pelvis raised by :data:`TRIM_MARGIN_PER_LEG`.

    Measured with ``habitsim bench model --real`` (the Labrador clips sent to four
    targets): stance toes at rest on 88.8 % of the transfers' stance frames without
    trimming, 96.6 % with it; the back-walk sent to the cat 33 → 78 %.
    """
    from ..contacts import contact_segments
    from .planting import stance_run_shortfall

    before = np.asarray(contacts, dtype=bool)  # read only
    c = before.copy()
    margin = TRIM_MARGIN_PER_LEG * out.species_info.leg_length
    glob = out.global_positions() if glob is None else glob
    shortest = max(2, int(round(TRIM_MIN_RUN_S * out.fps)))
    short = stance_run_shortfall(out, c, True, -margin, glob=glob)
    # (foot, start, stop) of the runs to trim, by their original extent
    active = [
        (k, a, b)
        for k, segs in enumerate(contact_segments(c))
        for a, b in segs
        if short[a:b, k].max() > 0.0 and (only is None or only[a:b, k].any())
    ]
    if not active:
        return c, None
    span = {run: (run[1], run[2]) for run in active}  # the run's current extent
    failed: set[tuple[int, int, int]] = set()
    t = len(c)
    while active:
        short = stance_run_shortfall(out, c, True, -margin, glob=glob)
        still = []
        for run in active:
            k, a, b = run
            lo, hi = span[run]
            if short[lo:hi, k].max() <= 0.0:
                continue  # within reach
            # a run cut by the clip's start or end is trimmed on its inner side only
            lo2 = lo if a == 0 else lo + 1
            hi2 = hi if b == t else hi - 1
            if hi2 - lo2 < shortest or (lo2, hi2) == (lo, hi):
                failed.add(run)
                continue
            c[lo:hi, k] = False
            c[lo2:hi2, k] = True
            span[run] = (lo2, hi2)
            still.append(run)
        active = still
    for k, a, b in failed:  # the runs no trimming brings within reach stay whole
        c[a:b, k] = before[a:b, k]
    trimmed = [run for run in span if run not in failed and span[run] != run[1:]]
    if not trimmed:
        return before, None
    return c, {
        "runs": len(trimmed),
        "frames": int((before & ~c).sum()),
        "duty_before": [round(float(v), 3) for v in before.mean(axis=0)],
        "duty_after": [round(float(v), 3) for v in c.mean(axis=0)],
    }


def plant_partly(
    out: Motion, contacts: np.ndarray, glob: np.ndarray | None = None, trim: bool = False
) -> tuple[Motion, dict[str, Any]] | None:
    """The decoded motion planted on every stance run its legs reach, the other runs
    keeping the decoded feet; ``None`` when no run can be held (or the runs to free are
    not settled within :data:`PARTIAL_PASSES` passes).

    A long clip whose speed changes (a real walk that breaks into a run, a standing
    start the decoder already walks through) can have a few stance runs that sweep
    further than the legs reach while the rest are fine; all-or-nothing planting would
    leave every foot sliding. Runs are released where their centred foothold is beyond
    the stretched leg with the pelvis at its lowest (:func:`~habitsim.stance.planting.
    stance_run_shortfall`), then, pass by pass, where the IK misses the foothold or the
    pelvis would come down further than :data:`PLANT_MAX_DROP_PER_LEG` (the runs whose
    legs are short there). The released runs stay stance (the foot is on the ground);
    the swings around them start and end where they do. Each run held is a foot at
    rest, however many others are free: there is no share of free runs beyond which the
    held ones are given up. ``glob``: the motion's global joint positions, if already
    at hand. With ``trim``, the runs left free are then shortened to the legs' reach
    (:func:`trim_to_reach`) and planted again; the result that holds more stance frames
    at rest is kept, the trimming reported as ``trimmed`` (the output's labels are the
    trimmed ones).
    """
    from ..contacts import contact_segments
    from .planting import plant_motion, stance_run_shortfall

    c = np.asarray(contacts, dtype=bool)
    stance = int(c.sum())
    if stance == 0:
        return None
    leg = out.species_info.leg_length
    reach, low = PLANT_MAX_REACH_PER_LEG * leg, PLANT_MAX_DROP_PER_LEG * leg
    glob = out.global_positions() if glob is None else glob
    free = _run_mask(c, stance_run_shortfall(out, c, True, low, glob=glob) > reach)
    hang = stance_run_shortfall(out, c, True, 0.0, glob=glob) > 0.0
    width = max(1, int(round(0.1 * out.fps)))
    lift = swing_lift(out, c)
    for _ in range(PARTIAL_PASSES):
        if free.sum() >= stance:  # no run left to hold
            return None
        moved, report = plant_motion(out, c, lift, centre=True, free=free, glob=glob)
        held = c & ~free
        miss = held & (report.reach_error > reach)
        deep = report.pelvis_drop > low
        if deep.any():
            near = np.convolve(deep.astype(float), np.ones(2 * width + 1), "same") > 0
            cand = held & near[:, None]
            miss |= cand & hang if (cand & hang).any() else cand
        if not miss.any():
            break
        free |= _run_mask(c, miss)
    else:
        return None
    n_free = int(free.sum())  # checked before the last pass, which freed nothing more
    runs = sum(len(s) for s in contact_segments(c))
    loose = sum(len(s) for s in contact_segments(free))
    summary = plant_summary(report, c, leg, free)
    result = (
        moved,
        {
            **summary,
            "footholds": "centred",
            "solved": True,
            "free_runs": [loose, runs],
            "free_share": round(n_free / stance, 3),
        },
    )
    if trim and n_free:
        labels, trimmed = trim_to_reach(out, c, glob, only=free)
        again = None if trimmed is None else plant_partly(out, labels, glob)
        if again is not None:
            held = (1.0 - again[1]["free_share"]) * labels.sum()
            if held > stance - n_free:
                return again[0], {**again[1], "trimmed": trimmed}
    return result


#: Restepping (:func:`restep`): a leg stretched to this share of its length sets the
#: longest stance sweep (:func:`habitsim.stance.planting.stance_sweep_limit`) ...
RESTEP_REACH_SHARE = 0.92
#: ... and no stride gets shorter than this many frames.
RESTEP_MIN_PERIOD = 4.0


def restep(
    out: Motion, contacts: np.ndarray, glob: np.ndarray | None = None
) -> tuple[Motion, dict[str, Any]] | None:
    """The decoded motion with its legs stepping fast enough for its body, or ``None``
    when its labels do not step or already fit.

    A decoder that gives a small target the source's slow cadence and the target's own
    speed (a camel's walk sent to the cat: strides of 1.4 s at 2.4 leg lengths per
    second) asks each stance foot to hold while the body travels further than the legs
    sweep. The stance labels are played faster (:func:`habitsim.contacts.quicken_contacts`,
    one rate for the clip: the body's mean travel over one stance ÷ the longest sweep),
    which keeps the duty factor and the feet's phase offsets; the legs are solved by IK
    onto footholds centred under each shoulder / hip sweep
    (:func:`habitsim.stance.planting.plant_motion` with ``centre``), lifted in swing
    (:func:`swing_lift`). The trunk, neck and tail and the root path stay the
    decoder's.

    Returns:
        ``(planted motion with the new labels, planting report with a ``restep`` entry)``.
    """
    from ..contacts import quicken_contacts, stride_period
    from .planting import plant_motion, stance_sweep_limit

    period = stride_period(contacts)
    t = out.num_frames
    if period is None or t < 2 or period > t:
        return None
    sweep = stance_sweep_limit(out, RESTEP_REACH_SHARE, glob)
    speed = np.linalg.norm(np.diff(out.root_positions[:, :2], axis=0), axis=1).mean() * out.fps
    stance_s = float(contacts.mean()) * period / out.fps
    k = min(speed * stance_s / max(sweep, 1e-9), period / RESTEP_MIN_PERIOD)
    if k <= 1.0:
        return None
    # one rate for the whole clip: a rate that follows the speed frame by frame makes the
    # stances of a short stride uneven by a frame or two, enough for a leg to miss
    rate = np.full(t, k)
    labels = quicken_contacts(contacts, rate, period)
    leg = out.species_info.leg_length
    lift = swing_lift(out, labels)
    moved, report = plant_motion(out, labels, lift, centre=True, glob=glob)
    new_period = stride_period(labels)
    return moved, {
        **plant_summary(report, labels, leg),
        "footholds": "centred",
        "solved": True,
        "restep": {
            "period_s": [round(period / out.fps, 3), round((new_period or period) / out.fps, 3)],
            "rate": round(float(rate[0]), 3),
            "sweep_limit_per_leg": round(sweep / leg, 3),
        },
    }
