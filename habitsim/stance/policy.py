"""The knobs and switches of the stance package, as options objects.

:class:`PlantingOptions` holds the knobs of labelling a source's stance and planting legs
by IK (:mod:`habitsim.stance.planting`), which the importer, the planting ladder and
refinement share; pass one as ``options=`` (the ladder takes
:attr:`ConformPolicy.planting`, refinement :attr:`habitsim.refine.RefineOptions.planting`).
Why each default is what it is: ``docs/import.md``, "Why the defaults".

:class:`ConformPolicy` holds every tuning value of the transfer's torch-free half: the
footfall schedule (:mod:`habitsim.stance.schedule`), the bounds to the source
(:mod:`habitsim.stance.bounds`), the trunk levelling (:mod:`habitsim.stance.level`) and
the planting ladder (:mod:`habitsim.stance.ladder`). Pass one to
:func:`habitsim.transfer` (``policy=``) or :func:`habitsim.stance.conform.conform`; left
out, the defaults apply. Change a knob with :func:`dataclasses.replace`. Why each default
is what it is: ``docs/transfer.md``, "Why the defaults".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from ..contacts import ContactOptions
from ..errors import HabitsimError

__all__ = [
    "ConformPolicy",
    "ConformPolicyError",
    "PlantingOptions",
    "PlantingOptionsError",
    "resolve_planting",
    "resolve_policy",
]


class ConformPolicyError(HabitsimError, ValueError):
    """A :class:`ConformPolicy` field outside its valid range."""


class PlantingOptionsError(HabitsimError, ValueError):
    """A :class:`PlantingOptions` field outside its valid range."""


@dataclass(frozen=True)
class PlantingOptions:
    """The knobs of labelling a source's stance and planting legs by IK.

    Pass one as ``options`` to :func:`label_source_stance`, :func:`smooth_path`,
    :func:`plant_legs`, :func:`plant_motion` and the reach tests; left out, the defaults
    apply. Change a knob with :func:`dataclasses.replace`. Why each default is what it
    is: ``docs/import.md``, "Why the defaults".

    Attributes:
        smooth_s: window of the Savitzky–Golay filter a foot path is smoothed with
            before labelling [s] (at least 5 frames).
        velocity_span_s: a foot point's velocity is its displacement over this time span
            (centred; at least two frames) [s].
        floor_window_s: window of a foot's local floor, the lower envelope of its
            resting heights (about a stride) [s].
        floor_spread_per_leg: how far one foot's floor may sit above its partner's (the
            other fore or hind foot) [hind-leg lengths].
        pair_spread_per_leg: how far the fore feet's floor may sit above the hind feet's,
            or the hind feet's above the fore feet's [hind-leg lengths].
        floor_rise_per_leg: how far a foot's local floor may rise above its clip floor
            [hind-leg lengths].
        min_rest_frames: below this many resting frames a foot's floor is taken from all
            its frames [frames].
        stance_speed_per_body: a foot point slower than this share of the body's speed
            counts as at rest, where that is above the contact rule's absolute rest speed
            (``contact.speed_per_leg``) [share, ≥ 0; 0 switches it off].
        body_speed_s: window the body's speed (the four feet's mean velocity) is
            averaged over [s].
        centre_travel_per_leg: a stance run whose shoulder / hip travels this far gets
            its foothold centred under its sweep (``centre``); shorter runs blend towards
            the toe path's own median [leg lengths].
        drop_smooth_s: the pelvis lowering for stance feet out of reach is smoothed by a
            Gaussian of this σ, after a running maximum of twice that width
            (:func:`carriage_drop`) [s].
        contact: the contact rule the source's stance labels are found with
            (:func:`habitsim.contacts.contacts_from_feet`); its speed threshold is also
            the absolute rest speed of the floor and body-speed tests.
    """

    smooth_s: float = 0.1
    velocity_span_s: float = 0.05
    floor_window_s: float = 0.75
    floor_spread_per_leg: float = 0.1
    pair_spread_per_leg: float = 0.25
    floor_rise_per_leg: float = 0.05
    min_rest_frames: int = 3
    stance_speed_per_body: float = 0.35
    body_speed_s: float = 0.5
    centre_travel_per_leg: float = 0.2
    drop_smooth_s: float = 0.3
    contact: ContactOptions = field(default_factory=ContactOptions)

    def __post_init__(self) -> None:
        positive = (
            "smooth_s",
            "velocity_span_s",
            "floor_window_s",
            "body_speed_s",
            "centre_travel_per_leg",
            "drop_smooth_s",
        )
        for name in positive:
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise PlantingOptionsError(f"{name} must be finite and > 0, got {v!r}")
        for name in (
            "floor_spread_per_leg",
            "pair_spread_per_leg",
            "floor_rise_per_leg",
            "stance_speed_per_body",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise PlantingOptionsError(f"{name} must be finite and ≥ 0, got {v!r}")
        if self.min_rest_frames < 1:
            raise PlantingOptionsError(f"min_rest_frames must be ≥ 1, got {self.min_rest_frames}")


_DEFAULT_PLANTING = PlantingOptions()


def resolve_planting(options: PlantingOptions | None) -> PlantingOptions:
    """``options``, or the default :class:`PlantingOptions` when it is None."""
    return _DEFAULT_PLANTING if options is None else options


@dataclass(frozen=True)
class ConformPolicy:
    """Knobs and switches of conforming a decoded motion.

    In the order of the steps: the footfall schedule
    (:func:`~habitsim.stance.schedule.transfer_contacts`,
    :func:`~habitsim.stance.schedule.walking_stance`), the bounds to the source
    (:mod:`habitsim.stance.bounds`), the trunk levelling
    (:func:`~habitsim.stance.level.level_trunk`) and the planting ladder
    (:func:`~habitsim.stance.ladder.plant_decoded`). Lengths are shares of the target's
    leg length.

    Attributes:
        min_source_agreement: a decoded foot whose stance labels match the source's
            footfall schedule with a per-foot F1 below this takes the source's schedule
            [0–1].
        max_duty_gap: ... as does a decoded foot whose stance share differs from the
            source's by more than this [share of the clip, 0–1].
        walk_min_duty: in a transfer at a Froude number the target walks at, every foot
            stands at least this share of the clip [0–1].
        walk_min_feet: ... and at least this many feet are down on every frame (0
            switches the fill off) [feet, 0–4].
        speed_band: the decoded horizontal speed stays within this factor of the
            source's speed at the same Froude number [≥ 1].
        speed_smooth_s: standard deviation of the Gaussian both speeds are smoothed
            with [s].
        height_band: the decoded root height's deviation from its median stays within
            this factor of the source's [≥ 1] ...
        height_floor_per_leg: ... or within this share of leg length, whichever is
            larger.
        height_window_s: half-width of the window the deviations' envelopes are taken
            over [s].
        heading_max_rate: fastest the decoded heading may turn away from the source's
            [rad/s].
        heading_smooth_s: standard deviation of the Gaussian a faster departure is
            low-passed by [s].
        heading_band: largest swing of the departure about its own slow trend [rad].
        heading_trend_s: standard deviation of the Gaussian that gives that slow trend
            [s].
        level_trunk: switch: pitch the decoded trunk so that its fore and hind stance
            toes stand alike above the ground before planting.
        level_tolerance_per_leg: height difference of fore and hind stance toes left as
            it is (the part beyond it is levelled) [share of leg length].
        level_max_pitch: largest pitch applied [rad].
        plant_max_reach_per_leg: a planting is kept only when every held stance toe is
            within this distance of its foothold [share of leg length] ...
        plant_max_swing_reach_per_leg: ... every swing toe between two stance runs
            within this distance of its path [share of leg length] ...
        plant_max_drop_per_leg: ... and the pelvis lowered by at most this much to reach
            them [share of leg length].
        plant_min_speed_ratio: the body is carried only as far as its stance legs carry
            it when that keeps at least this share of its decoded speed [0–1].
        foothold_rules: the foothold rules tried in order, ``False`` for the median of
            the run's decoded toe path, ``True`` for the foothold centred under the
            shoulder's / hip's sweep (at least one).
        swing_lift: switch: lift every planted swing to the species' habitual swing
            height (a half-sine over the swing).
        restep_reach_share: restepping: a leg stretched to this share of its length sets
            the longest stance sweep [0–1] ...
        restep_min_period: ... and no stride gets shorter than this [frames]
            (``math.inf`` switches restepping off).
        partly_on_restep: switch: where the faster steps still miss, the partial
            planting holds the runs the legs reach on the faster steps (off: on the
            decoded ones).
        partial_passes: the partial planting settles the runs it leaves free in at most
            this many IK passes (0 switches partial planting off).
        trim_to_reach: switch: shorten the stance runs the partial planting leaves free
            to the legs' reach and plant again.
        trim_min_run_s: a trimmed stance run keeps at least this long [s] (and 2 frames).
        trim_margin_per_leg: a trimmed run's centred foothold must lie within the
            stretched leg with the pelvis this much higher than it is [share of leg
            length].
        planting: the knobs of each planting the ladder tries (the foothold centring's
            travel, the pelvis lowering's smoothing;
            :class:`~habitsim.stance.planting.PlantingOptions`).
    """

    # footfall schedule
    min_source_agreement: float = 0.8
    max_duty_gap: float = 0.1
    walk_min_duty: float = 0.5
    walk_min_feet: int = 2
    # bounds to the source
    speed_band: float = 1.5
    speed_smooth_s: float = 0.25
    height_band: float = 1.5
    height_floor_per_leg: float = 0.01
    height_window_s: float = 0.5
    heading_max_rate: float = 3.0
    heading_smooth_s: float = 0.25
    heading_band: float = math.pi / 4
    heading_trend_s: float = 1.0
    # trunk levelling
    level_trunk: bool = True
    level_tolerance_per_leg: float = 0.02
    level_max_pitch: float = 0.5
    # planting ladder
    plant_max_reach_per_leg: float = 0.05
    plant_max_swing_reach_per_leg: float = 0.1
    plant_max_drop_per_leg: float = 0.1
    plant_min_speed_ratio: float = 0.7
    foothold_rules: tuple[bool, ...] = (False, True)
    swing_lift: bool = True
    restep_reach_share: float = 0.92
    restep_min_period: float = 4.0
    partly_on_restep: bool = True
    partial_passes: int = 4
    trim_to_reach: bool = True
    trim_min_run_s: float = 0.1
    trim_margin_per_leg: float = 0.1
    planting: PlantingOptions = field(default_factory=PlantingOptions)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and math.isnan(v):
                raise ConformPolicyError(f"{f.name} must be a number, got {v!r}")
        shares = (
            "min_source_agreement",
            "max_duty_gap",
            "walk_min_duty",
            "plant_min_speed_ratio",
            "restep_reach_share",
        )
        for name in shares:
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ConformPolicyError(f"{name} must be in [0, 1], got {v!r}")
        for name in ("speed_band", "height_band"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 1.0):
                raise ConformPolicyError(f"{name} must be a finite factor ≥ 1, got {v!r}")
        positive = (
            "speed_smooth_s",
            "height_window_s",
            "heading_max_rate",
            "heading_smooth_s",
            "heading_band",
            "heading_trend_s",
            "restep_min_period",
        )
        for name in positive:
            v = getattr(self, name)
            if not v > 0.0:
                raise ConformPolicyError(f"{name} must be > 0, got {v!r}")
        non_negative = (
            "height_floor_per_leg",
            "level_tolerance_per_leg",
            "level_max_pitch",
            "plant_max_reach_per_leg",
            "plant_max_swing_reach_per_leg",
            "plant_max_drop_per_leg",
            "trim_min_run_s",
            "trim_margin_per_leg",
        )
        for name in non_negative:
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ConformPolicyError(f"{name} must be finite and ≥ 0, got {v!r}")
        if not 0 <= self.walk_min_feet <= 4:
            raise ConformPolicyError(f"walk_min_feet must be in 0..4, got {self.walk_min_feet}")
        if self.partial_passes < 0:
            raise ConformPolicyError(f"partial_passes must be ≥ 0, got {self.partial_passes}")
        rules = self.foothold_rules
        if not (isinstance(rules, tuple) and rules and all(isinstance(r, bool) for r in rules)):
            raise ConformPolicyError(
                f"foothold_rules must be a non-empty tuple of bools (False: median, True: "
                f"centred), got {rules!r}"
            )


_DEFAULT = ConformPolicy()


def resolve_policy(policy: ConformPolicy | None) -> ConformPolicy:
    """``policy``, or the default :class:`ConformPolicy` when it is None."""
    return _DEFAULT if policy is None else policy
