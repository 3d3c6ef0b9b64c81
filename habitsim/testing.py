"""Assertion helpers for users' own physics regression checks (pytest or plain Python).

Two kinds of check:

* :func:`assert_plausible`: a motion is physically plausible for its species within
  bounds on the kinematic metrics of docs/metrics.md (skating, penetration, floating, joint
  limits, bone lengths). Bounds are per leg length by default, so one set of numbers
  fits a rabbit and an elephant.
* :func:`assert_matches_golden`: figures of a run (any flat ``{metric: number}`` dict,
  e.g. a tracking report's metrics) equal stored golden figures within explicit
  tolerances; a failure prints a table of which metric moved, by how much, and what was
  allowed. Golden files are JSON and record the MuJoCo and habitsim versions they were
  made with, so a figure that moved with an engine upgrade is told apart from one that
  moved with a code change.

The pytest plugin :mod:`habitsim.pytest_plugin` (loaded automatically once habitsim is
installed) wraps these as fixtures and adds ``--habitsim-update-goldens``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from .errors import HabitsimError
from .fileio import atomic_write_text, make_dirs
from .jsonfile import load_json
from .motion import Motion

__all__ = [
    "PlausibilityBounds",
    "Tolerance",
    "Deviation",
    "GoldenMissingError",
    "plausibility_violations",
    "assert_plausible",
    "compare_figures",
    "format_deviations",
    "assert_matches_golden",
    "write_golden",
    "DEFAULT_TOLERANCE",
]

#: Format version of the golden figure files.
GOLDEN_FORMAT = 1


class GoldenMissingError(HabitsimError, AssertionError):
    """A golden file does not exist (run with ``--habitsim-update-goldens`` to create it)."""


@dataclass(frozen=True)
class PlausibilityBounds:
    """Upper bounds on kinematic metrics; ``None`` disables a check.

    ``*_per_leg`` bounds are fractions of the species' hind-leg length (docs/metrics.md's
    size-normalised variants); the others are absolute.

    Attributes:
        skate_per_leg: mean toe slide per frame pair in contact / leg length.
        penetration_per_leg: mean toe depth below ground / leg length.
        float_per_leg: mean hover of the lowest body point / leg length.
        joint_limit_violation_rad: mean hinge-limit excess [rad].
        bone_length_error_mm: max bone length error [mm].
        skate_ratio: share of frame pairs with a skating foot.
    """

    skate_per_leg: float | None = 0.002
    penetration_per_leg: float | None = 0.002
    float_per_leg: float | None = 0.01
    joint_limit_violation_rad: float | None = 0.01
    bone_length_error_mm: float | None = 1.0
    skate_ratio: float | None = None


def plausibility_violations(
    motion: Motion,
    bounds: PlausibilityBounds | None = None,
    *,
    use_contacts: bool = False,
    **overrides: float | None,
) -> dict[str, tuple[float, float]]:
    """The metrics of ``motion`` that exceed their bounds: ``{key: (value, bound)}``.

    Args:
        motion: the motion.
        bounds: the bounds (default :class:`PlausibilityBounds`).
        use_contacts: measure skating with the motion's own contact labels instead of
            docs/metrics.md's height criterion.
        **overrides: replace single bounds, e.g. ``skate_per_leg=0.01`` or ``float_per_leg=None``.

    Raises:
        HabitsimError: an override names no bound (the message lists the valid ones).
    """
    from .metrics.kinematic import kinematic_metrics

    b = asdict(bounds or PlausibilityBounds())
    unknown = set(overrides) - set(b)
    if unknown:
        raise HabitsimError(
            f"unknown plausibility bound(s) {sorted(unknown)}; valid: {', '.join(b)}"
        )
    b.update(overrides)
    contacts = motion.contacts if use_contacts else None
    values = kinematic_metrics(motion, contacts=contacts)
    out: dict[str, tuple[float, float]] = {}
    for key, bound in b.items():
        if bound is None:
            continue
        v = float(values[key])
        if not math.isfinite(v) or v > bound:
            out[key] = (v, float(bound))
    return out


def assert_plausible(
    motion: Motion,
    bounds: PlausibilityBounds | None = None,
    *,
    use_contacts: bool = False,
    **overrides: float | None,
) -> None:
    """Fail (AssertionError) if any kinematic metric of ``motion`` exceeds its bound.

    The message names every violated metric with its value, its bound and the keyword
    argument that changes it (e.g. ``skate_per_leg=0.004``; ``None`` switches it off).

    Args:
        motion: the motion.
        bounds: the bounds (default :class:`PlausibilityBounds`).
        use_contacts: measure skating with the motion's own contact labels.
        **overrides: replace single bounds (see :func:`plausibility_violations`).
    """
    bad = plausibility_violations(motion, bounds, use_contacts=use_contacts, **overrides)
    if bad:
        lines = [f"motion of {motion.species!r} ({motion.num_frames} frames) is not plausible:"]
        lines += [
            f"  {k} = {v:.6g} > {bound:.6g} (raise it with {k}=<bound>, None switches it off)"
            for k, (v, bound) in sorted(bad.items())
        ]
        lines.append(
            "bounds are keyword arguments of assert_plausible / habitsim_assert_plausible "
            "or fields of habitsim.testing.PlausibilityBounds (docs/testing.md)"
        )
        if "skate_per_leg" in bad and not use_contacts:
            lines.append(
                "skating counts toes below 2 % of the leg as standing; use_contacts=True "
                "measures it on the motion's own stance labels"
            )
        raise AssertionError("\n".join(lines))


@dataclass(frozen=True)
class Tolerance:
    """A figure passes when |actual − golden| ≤ abs + rel·|golden|."""

    abs: float = 0.0
    rel: float = 0.0

    def allows(self, golden: float) -> float:
        return self.abs + self.rel * abs(golden)


#: Tolerance used for metrics a golden file gives none for.
DEFAULT_TOLERANCE = Tolerance(abs=1e-6, rel=0.02)


@dataclass(frozen=True)
class Deviation:
    """One compared figure."""

    key: str
    golden: float | None
    actual: float | None
    allowed: float
    ok: bool
    note: str = ""

    @property
    def diff(self) -> float:
        if self.golden is None or self.actual is None:
            return math.nan
        return self.actual - self.golden


def _as_number(v: Any, key: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise HabitsimError(f"figure {key!r} must be a number, got {v!r}")
    return float(v)


def _tolerance(t: Any) -> Tolerance:
    if isinstance(t, Tolerance):
        return t
    if isinstance(t, Mapping):
        return Tolerance(abs=float(t.get("abs", 0.0)), rel=float(t.get("rel", 0.0)))
    if isinstance(t, tuple | list) and len(t) == 2:
        return Tolerance(abs=float(t[0]), rel=float(t[1]))
    raise HabitsimError(f"a tolerance is a Tolerance, {{'abs', 'rel'}} or (abs, rel); got {t!r}")


def compare_figures(
    actual: Mapping[str, Any],
    golden: Mapping[str, Any],
    tolerances: Mapping[str, Any] | None = None,
    default: Tolerance = DEFAULT_TOLERANCE,
) -> list[Deviation]:
    """Compare every golden figure (and any new one) with the actual figures.

    NaN equals NaN; a figure missing on either side fails.
    """
    tol = {k: _tolerance(v) for k, v in (tolerances or {}).items()}
    out = []
    for key in sorted(set(golden) | set(actual)):
        if key not in actual:
            out.append(
                Deviation(key, _as_number(golden[key], key), None, 0.0, False, "missing in actual")
            )
            continue
        if key not in golden:
            out.append(
                Deviation(key, None, _as_number(actual[key], key), 0.0, False, "not in golden")
            )
            continue
        g, a = _as_number(golden[key], key), _as_number(actual[key], key)
        t = tol.get(key, default)
        allowed = t.allows(g)
        if math.isnan(g) or math.isnan(a):
            ok = math.isnan(g) and math.isnan(a)
        else:
            ok = abs(a - g) <= allowed
        out.append(Deviation(key, g, a, allowed, ok))
    return out


def format_deviations(devs: list[Deviation], only_failures: bool = False) -> str:
    """A readable table: metric, golden, actual, diff, allowed, status."""
    rows = [("metric", "golden", "actual", "diff", "allowed", "")]
    for d in devs:
        if only_failures and d.ok:
            continue
        fmt = lambda x: "-" if x is None else f"{x:.6g}"  # noqa: E731
        rows.append(
            (
                d.key,
                fmt(d.golden),
                fmt(d.actual),
                fmt(d.diff) if d.note == "" else "-",
                f"{d.allowed:.3g}",
                "ok" if d.ok else f"MOVED {d.note}".strip(),
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(6)]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows
    )


def _versions() -> dict[str, str]:
    import mujoco

    from . import __version__

    return {"mujoco": mujoco.__version__, "habitsim": __version__}


@dataclass
class _Golden:
    figures: dict[str, float]
    tolerances: dict[str, Any] = field(default_factory=dict)
    versions: dict[str, str] = field(default_factory=dict)


def _read_golden(path: Path) -> _Golden:
    if not path.exists():
        raise GoldenMissingError(
            f"golden file {path} does not exist; run pytest with --habitsim-update-goldens "
            "(or call write_golden) to record it"
        )
    data = load_json(path, "golden file", error=HabitsimError)
    if not isinstance(data, dict) or "figures" not in data:
        raise HabitsimError(f"golden file {path} has no 'figures' object")
    return _Golden(
        figures={k: (math.nan if v is None else v) for k, v in data["figures"].items()},
        tolerances=data.get("tolerances", {}),
        versions=data.get("versions", {}),
    )


def write_golden(
    path: str | Path, figures: Mapping[str, Any], tolerances: Mapping[str, Any] | None = None
) -> None:
    """Record golden figures (atomically), with the current MuJoCo and habitsim versions."""
    clean = {}
    for k, v in figures.items():
        x = _as_number(v, k)
        clean[k] = None if math.isnan(x) else x
    tol = {k: asdict(_tolerance(t)) for k, t in (tolerances or {}).items()}
    doc = {"format": GOLDEN_FORMAT, "versions": _versions(), "tolerances": tol, "figures": clean}
    p = Path(path)
    make_dirs(p.parent, "golden folder")
    atomic_write_text(p, json.dumps(doc, indent=2, sort_keys=True) + "\n")


def assert_matches_golden(
    actual: Mapping[str, Any],
    path: str | Path,
    tolerances: Mapping[str, Any] | None = None,
    *,
    update: bool = False,
) -> list[Deviation]:
    """Assert figures match a golden file within tolerances (or record it with ``update``).

    Tolerances come from (in order of precedence) the ``tolerances`` argument, the golden
    file, then :data:`DEFAULT_TOLERANCE`. On failure the AssertionError carries the table
    of moved figures and the version the golden was recorded with.

    Returns:
        The comparison (all rows) when it passes.
    """
    p = Path(path)
    if update:
        old_tol = {}
        if p.exists():
            try:
                old_tol = _read_golden(p).tolerances
            except HabitsimError:
                old_tol = {}
        write_golden(p, actual, {**old_tol, **(tolerances or {})})
    g = _read_golden(p)
    devs = compare_figures(actual, g.figures, {**g.tolerances, **(tolerances or {})})
    bad = [d for d in devs if not d.ok]
    if bad:
        now = _versions()
        ver = ""
        if g.versions and g.versions != now:
            ver = f"\n(golden recorded with {g.versions}, running {now})"
        raise AssertionError(
            f"{len(bad)} figure(s) moved against {p}:\n"
            f"{format_deviations(devs, only_failures=True)}{ver}"
        )
    return devs
