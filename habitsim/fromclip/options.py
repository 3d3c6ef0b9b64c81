"""The knobs of making a species from a clip (:class:`FromClipOptions`; why each default:
docs/species.md, "Why the defaults")."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ArgumentRangeError


@dataclass(frozen=True)
class FromClipOptions:
    """How a species is measured from a clip and checked.

    Attributes:
        min_frames: fewest frames a clip may have [frames].
        min_duration_s: shortest clip [s]: about one slow stride of a small animal.
        stance_height_share: a foot lower than this over the ground counts as standing
            [share of the hind-leg length].
        ground_percentile: the ground is this percentile of the feet's heights over the
            clip [%].
        limit_margin_deg: a borrowed joint range is widened, where it has to be, to hold
            the measured standing angle this far inside its ends [deg].
        mass_exponent: body mass scales with this power of the size length
            √(trunk · hip height) (3: geometric similarity) [unitless].
        stand_seconds: the built model must stand this long on ``home`` [s].
        stand_height_share: while standing its pelvis stays within this share of its
            ``home`` height (0.95: within 5 %) [unitless].
        stand_upright_deg: and its pelvis' up axis within this angle of its ``home``
            direction [deg].
    """

    min_frames: int = 8
    min_duration_s: float = 0.5
    stance_height_share: float = 0.05
    ground_percentile: float = 5.0
    limit_margin_deg: float = 5.0
    mass_exponent: float = 3.0
    stand_seconds: float = 3.0
    stand_height_share: float = 0.95
    stand_upright_deg: float = 20.0

    def __post_init__(self) -> None:
        checks = {
            "min_frames": self.min_frames >= 2,
            "min_duration_s": self.min_duration_s >= 0,
            "stance_height_share": 0 < self.stance_height_share < 1,
            "ground_percentile": 0 <= self.ground_percentile <= 50,
            "limit_margin_deg": 0 <= self.limit_margin_deg <= 45,
            "mass_exponent": 0 < self.mass_exponent <= 5,
            "stand_seconds": 0 < self.stand_seconds <= 60,
            "stand_height_share": 0 < self.stand_height_share < 1,
            "stand_upright_deg": 0 < self.stand_upright_deg < 90,
        }
        bad = [k for k, ok in checks.items() if not ok]
        if bad:
            raise ArgumentRangeError(
                f"FromClipOptions: {', '.join(f'{k}={getattr(self, k)!r}' for k in bad)} out "
                "of range (see the attribute docs: shares in (0, 1), percentile 0–50, "
                "margin 0–45 deg, exponent 0–5, stand time 0–60 s)"
            )
