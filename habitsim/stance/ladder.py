"""The planting ladder: a decoded motion's feet planted on its stance labels, with fallbacks.

:func:`plant_decoded` tries, in order, until the legs reach: the decoded root path with
each foothold rule; the body carried only as far as its stance legs carry it; the legs
stepping faster (:func:`restep`); the stance runs the legs reach held and the others left
free (:func:`plant_partly`, their out-of-reach runs shortened first by
:func:`trim_to_reach`). Each step's planting is :func:`habitsim.stance.planting.plant_motion`;
its knobs and switches are those of :class:`~habitsim.stance.policy.ConformPolicy`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..motion import Motion
from .labels import EditReason, StanceLabels, as_labels
from .policy import ConformPolicy, resolve_policy
from .report import Planting, PlantOutcome, PlantReason, Restep, Trim

__all__ = ["plant_decoded", "restep", "plant_partly", "trim_to_reach", "swing_lift"]


def swing_lift(
    out: Motion, labels: np.ndarray, policy: ConformPolicy | None = None
) -> np.ndarray | None:
    """The lowest toe height [m] of each swing frame of a planting (T, 4; NaN in stance):
    a half-sine over the swing run peaking at the species' habitual swing height
    (``habits.swing_height`` of its species file, share of leg length), so a decoded
    foot that shuffles along the ground in swing is lifted; a toe already higher keeps
    its height. None when ``policy.swing_lift`` is off."""
    from .labels import stance_runs

    if not resolve_policy(policy).swing_lift:
        return None
    lift = np.full(labels.shape, np.nan)
    height = out.species_info.habits.swing_height * out.species_info.leg_length
    for f, runs in enumerate(stance_runs(~np.asarray(labels, dtype=bool))):
        for a, b in runs:
            lift[a:b, f] = height * np.sin(np.pi * (np.arange(b - a) + 0.5) / (b - a))
    return lift


def plant_decoded(
    out: Motion,
    labels: StanceLabels | np.ndarray,
    glob: np.ndarray | None = None,
    policy: ConformPolicy | None = None,
) -> tuple[Motion, PlantOutcome]:
    """Plant ``out``'s feet on ``labels``, falling back rung by rung (module docstring).

    Args:
        out: the decoded motion.
        labels: its (T, 4) stance labels (an array is taken as given labels).
        glob: ``out``'s (T, J, 3) global joint positions, if already at hand.
        policy: the knobs and switches (None: the defaults).

    Returns:
        ``(motion to keep, what was done)``: the planted motion, or ``out`` itself when no
        planting is kept. The kept planting's ``labels`` are those the legs step on:
        ``labels`` with a restep's and a trim's edits recorded.
    """
    from .planting import plant_motion, stance_driven_root, stance_reach_shortfall

    policy = resolve_policy(policy)
    labels = as_labels(labels)
    contacts = labels.array
    leg = out.species_info.leg_length

    def attempt(motion: Motion, glob: np.ndarray) -> tuple[Motion, Planting, Planting]:
        """(planted motion, its planting, the first rule's planting): the first foothold
        rule whose legs reach, else the last rule's result (``glob``: the motion's
        global joint positions)."""
        first: Planting | None = None
        moved = motion
        for centre in policy.foothold_rules:
            rule = "centred" if centre else "median"
            short = stance_reach_shortfall(
                motion,
                contacts,
                centre,
                policy.plant_max_drop_per_leg * leg,
                glob,
                policy.planting,
            )
            if short > policy.plant_max_reach_per_leg * leg:  # no IK can hold these footholds
                rep = Planting(rule, leg, None, short / leg, policy.plant_max_drop_per_leg)
                moved = motion
            else:
                lift = swing_lift(motion, contacts, policy)
                moved, report = plant_motion(
                    motion, contacts, lift, centre=centre, glob=glob, options=policy.planting
                )
                rep = Planting.judged(report, labels, leg, rule)
            first = rep if first is None else first
            if rep.reaches(policy):
                break
        assert first is not None  # a policy has at least one foothold rule
        return moved, rep, first

    if glob is None:
        glob = out.global_positions()  # one forward-kinematics pass for every reach test
    moved, rep, first = attempt(out, glob)
    if rep.reaches(policy):
        return moved, PlantOutcome(True, rep, root="decoded")
    shown = first.to_dict()  # the reasons quote the reported (rounded) figures
    missed = (
        f"the legs do not reach the footholds (toe {shown['max_reach_error_per_leg']:.2f} "
        f"leg lengths off in stance, {shown.get('max_swing_reach_error_per_leg', 0.0):.2f} "
        f"in swing, pelvis lowered {shown['max_pelvis_drop_per_leg']:.2f}; limits "
        f"{policy.plant_max_reach_per_leg}, {policy.plant_max_swing_reach_per_leg}, "
        f"{policy.plant_max_drop_per_leg})"
    )
    carried, ratio = stance_driven_root(out, contacts, glob)
    if ratio >= policy.plant_min_speed_ratio:
        # the carried body only translates: its joints move with its root
        shift = (carried.root_positions - out.root_positions)[:, None, :]
        moved, second, _ = attempt(carried, glob + shift)
        if second.reaches(policy):
            return moved, PlantOutcome(
                True,
                second,
                root="carried",
                speed_ratio=ratio,
                reason=f"{missed} with the decoded root path; the body moved as far "
                f"as its stance legs carry it ({100 * ratio:.0f} % of its decoded speed)",
                reason_codes=(PlantReason.OUT_OF_REACH, PlantReason.CARRIED),
            )
        why = "not even with the body carried by its stance legs"
        codes = [PlantReason.OUT_OF_REACH, PlantReason.CARRY_MISSED]
    else:
        why = (
            f"the stance legs carry the body only {100 * ratio:.0f} % of its decoded "
            f"speed (< {100 * policy.plant_min_speed_ratio:.0f} %)"
        )
        codes = [PlantReason.OUT_OF_REACH, PlantReason.CARRY_TOO_SLOW]
    stepped = restep(out, labels, glob, policy)
    tried: Planting | None = None
    if stepped is not None:
        moved, tried = stepped
        if tried.reaches(policy):
            assert tried.restep is not None
            period = tried.restep.to_dict()["period_s"]
            return moved, PlantOutcome(
                True,
                tried,
                root="decoded",
                reason=f"{missed}, {why}: the legs step faster "
                f"(stride {period[0]:.2f} s → {period[1]:.2f} s)",
                reason_codes=(*codes, PlantReason.RESTEPPED),
            )
        why += ", not even stepping faster"
        codes.append(PlantReason.RESTEP_MISSED)
    partly = None
    if stepped is not None and policy.partly_on_restep:
        # the quickened labels ask the legs for the shorter sweeps: hold what they reach
        assert stepped[1].labels is not None  # a restep's planting is solved
        partly = plant_partly(out, stepped[1].labels, glob, policy.trim_to_reach, policy)
        if partly is not None:
            why += " in every stance run; on the faster steps"
            codes.append(PlantReason.PARTLY_ON_RESTEP)
    if partly is None:
        partly = plant_partly(out, labels, glob, policy.trim_to_reach, policy)
    if partly is not None:
        moved, rep = partly
        shown = rep.to_dict()
        trimmed = rep.trimmed
        cut = (
            ""
            if trimmed is None
            else f"{trimmed.runs} stance runs shortened to the legs' reach "
            f"({trimmed.frames} frames), "
        )
        return moved, PlantOutcome(
            True,
            rep,
            root="decoded",
            reason=f"{missed}, {why}: {cut}the stance runs out of reach keep the decoded "
            f"feet ({shown['free_runs'][0]} of {shown['free_runs'][1]} runs, "
            f"{100 * shown['free_share']:.0f} % of the stance frames)",
            restep_tried=tried,
            reason_codes=(
                *codes,
                *(() if trimmed is None else (PlantReason.TRIMMED,)),
                PlantReason.PARTLY,
            ),
        )
    return out, PlantOutcome(
        False,
        first,
        speed_ratio=ratio,
        reason=f"{missed}, {why}: the decoded feet are kept",
        restep_tried=tried,
        reason_codes=(*codes, PlantReason.DECODED_FEET_KEPT),
    )


def _run_mask(contacts: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """(T, 4) bool: the whole stance runs of ``contacts`` that have a frame in ``hit``."""
    from .labels import stance_runs

    out = np.zeros_like(contacts, dtype=bool)
    for k, segs in enumerate(stance_runs(contacts)):
        for a, b in segs:
            if hit[a:b, k].any():
                out[a:b, k] = True
    return out


def trim_to_reach(
    out: Motion,
    contacts: StanceLabels | np.ndarray,
    glob: np.ndarray | None = None,
    only: np.ndarray | None = None,
    policy: ConformPolicy | None = None,
) -> tuple[StanceLabels, Trim | None]:
    """``contacts`` with every stance run whose centred foothold lies beyond the legs'
    reach shortened at both ends until it does not, and what was changed (``None``:
    nothing). ``contacts``: (T, 4) stance labels (an array is taken as given labels);
    the labels returned record the frames taken off as an :attr:`EditReason.TRIM`
    edit. ``only``: (T, 4) bool, the runs to consider (those with a frame in it;
    default every run).

    A decoded body that moves faster than its legs sweep in a long stance (a real dog's
    walk sent to the cat: duty factor 0.88 at 1.6 leg lengths per second, the legs
    carrying 44 % of that travel) asks each foot to stand where the shoulder or hip has
    already left. Such a run cannot be a foot at rest for its whole length. Its middle
    can: the foot touches down later and lifts earlier, at the same foothold, and the
    frames taken off are swing (lifted like the others). The run's centre, and with it
    the footfall phase, stays; the duty factor falls by what the legs cannot hold. A run
    that misses even at ``policy.trim_min_run_s`` is left as it was (the partial planting
    frees it). The reach test is :func:`habitsim.stance.planting.stance_run_shortfall` of the
    centred foothold with the pelvis raised by ``policy.trim_margin_per_leg``.
    """
    from .labels import stance_runs
    from .planting import stance_run_shortfall

    policy = resolve_policy(policy)
    labels = as_labels(contacts)
    before = labels.array  # read only
    c = before.copy()
    margin = policy.trim_margin_per_leg * out.species_info.leg_length
    glob = out.global_positions() if glob is None else glob
    shortest = max(2, int(round(policy.trim_min_run_s * out.fps)))
    short = stance_run_shortfall(out, c, True, -margin, glob=glob, options=policy.planting)
    # (foot, start, stop) of the runs to trim, by their original extent
    active = [
        (k, a, b)
        for k, segs in enumerate(stance_runs(c))
        for a, b in segs
        if short[a:b, k].max() > 0.0 and (only is None or only[a:b, k].any())
    ]
    if not active:
        return labels, None
    span = {run: (run[1], run[2]) for run in active}  # the run's current extent
    failed: set[tuple[int, int, int]] = set()
    t = len(c)
    while active:
        short = stance_run_shortfall(out, c, True, -margin, glob=glob, options=policy.planting)
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
        return labels, None
    trim = Trim(len(trimmed), int((before & ~c).sum()), before.mean(axis=0), c.mean(axis=0))
    return labels.edited(c, by="stance.ladder.trim_to_reach", reason=EditReason.TRIM), trim


def plant_partly(
    out: Motion,
    contacts: StanceLabels | np.ndarray,
    glob: np.ndarray | None = None,
    trim: bool = False,
    policy: ConformPolicy | None = None,
) -> tuple[Motion, Planting] | None:
    """The decoded motion planted on every stance run its legs reach, the other runs
    keeping the decoded feet; ``None`` when no run can be held (or the runs to free are
    not settled within ``policy.partial_passes`` passes).

    A long clip whose speed changes (a real walk that breaks into a run, a standing
    start the decoder already walks through) can have a few stance runs that sweep
    further than the legs reach while the rest are fine; all-or-nothing planting would
    leave every foot sliding. Runs are released where their centred foothold is beyond
    the stretched leg with the pelvis at its lowest (:func:`~habitsim.stance.planting.
    stance_run_shortfall`), then, pass by pass, where the IK misses the foothold or the
    pelvis would come down further than ``policy.plant_max_drop_per_leg`` (the runs whose
    legs are short there). The released runs stay stance (the foot is on the ground);
    the swings around them start and end where they do. Each run held is a foot at
    rest, however many others are free: there is no share of free runs beyond which the
    held ones are given up. ``glob``: the motion's global joint positions, if already
    at hand. With ``trim``, the runs left free are then shortened to the legs' reach
    (:func:`trim_to_reach`) and planted again; the result that holds more stance frames
    at rest is kept, the trimming reported as ``trimmed`` (the output's labels are the
    trimmed ones). ``contacts``: (T, 4) stance labels (an array is taken as given
    labels); the planting's ``labels`` are those it stepped on.
    """
    from .labels import stance_runs
    from .planting import plant_motion, stance_run_shortfall

    policy = resolve_policy(policy)
    labels = as_labels(contacts)
    c = labels.array
    stance = int(c.sum())
    if stance == 0:
        return None
    leg = out.species_info.leg_length
    reach, low = policy.plant_max_reach_per_leg * leg, policy.plant_max_drop_per_leg * leg
    glob = out.global_positions() if glob is None else glob
    opts = policy.planting
    free = _run_mask(c, stance_run_shortfall(out, c, True, low, glob=glob, options=opts) > reach)
    hang = stance_run_shortfall(out, c, True, 0.0, glob=glob, options=opts) > 0.0
    width = max(1, int(round(0.1 * out.fps)))
    lift = swing_lift(out, c, policy)
    for _ in range(policy.partial_passes):
        if free.sum() >= stance:  # no run left to hold
            return None
        moved, report = plant_motion(out, c, lift, centre=True, free=free, glob=glob, options=opts)
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
    runs = sum(len(s) for s in stance_runs(c))
    loose = sum(len(s) for s in stance_runs(free))
    planting = replace(
        Planting.judged(report, labels, leg, "centred", free),
        free_frames=n_free,
        stance_frames=stance,
        free_runs=(loose, runs),
    )
    if trim and n_free:
        shorter, trimmed = trim_to_reach(out, labels, glob, only=free, policy=policy)
        again = None if trimmed is None else plant_partly(out, shorter, glob, policy=policy)
        if again is not None:
            tighter = again[1]
            assert tighter.free_frames is not None and tighter.stance_frames is not None
            if tighter.stance_frames - tighter.free_frames > stance - n_free:
                return again[0], replace(tighter, trimmed=trimmed)
    return moved, planting


def restep(
    out: Motion,
    contacts: StanceLabels | np.ndarray,
    glob: np.ndarray | None = None,
    policy: ConformPolicy | None = None,
) -> tuple[Motion, Planting] | None:
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

    Args:
        out: the decoded motion.
        contacts: its (T, 4) stance labels (an array is taken as given labels).
        glob: ``out``'s (T, J, 3) global joint positions, if already at hand.
        policy: the knobs (None: the defaults).

    Returns:
        ``(planted motion with the new labels, its planting with its ``restep``)``; the
        planting's ``labels`` record the quickened frames as an
        :attr:`EditReason.RESTEP` edit.
    """
    from ..contacts import quicken_contacts, stride_period
    from .planting import plant_motion, stance_sweep_limit

    policy = resolve_policy(policy)
    given = as_labels(contacts)
    contacts = given.array
    period = stride_period(contacts)
    t = out.num_frames
    if period is None or t < 2 or period > t:
        return None
    sweep = stance_sweep_limit(out, policy.restep_reach_share, glob)
    speed = np.linalg.norm(np.diff(out.root_positions[:, :2], axis=0), axis=1).mean() * out.fps
    stance_s = float(contacts.mean()) * period / out.fps
    k = min(speed * stance_s / max(sweep, 1e-9), period / policy.restep_min_period)
    if k <= 1.0:
        return None
    # one rate for the whole clip: a rate that follows the speed frame by frame makes the
    # stances of a short stride uneven by a frame or two, enough for a leg to miss
    rate = np.full(t, k)
    labels = given.edited(
        quicken_contacts(contacts, rate, period),
        by="stance.ladder.restep",
        reason=EditReason.RESTEP,
    )
    leg = out.species_info.leg_length
    lift = swing_lift(out, labels.array, policy)
    moved, report = plant_motion(
        out, labels.array, lift, centre=True, glob=glob, options=policy.planting
    )
    new_period = stride_period(labels.array)
    step = Restep((period / out.fps, (new_period or period) / out.fps), float(rate[0]), sweep / leg)
    return moved, replace(Planting.judged(report, labels, leg, "centred"), restep=step)
