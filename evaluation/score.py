"""Scoring motions from anywhere (``habitsim score``): every per-clip metric of
docs/metrics.md on motion files as they are.

Usage (CLI: ``habitsim score DIR|FILES``)::

    from habitsim.evaluation.score import ScoreOptions, score_files
    result = score_files(["outputs/"], ScoreOptions(species="dog", track=True))
    print(result.table_text())

Each file (``.npz``, ``.bvh``, ``.glb``, ``.gltf``; a folder: every such file under it)
is read as it is (:func:`read_motion`: a motion-capture file imported onto its species
without planting its legs) and scored by :func:`score_motion`: kinematic plausibility,
the dynamic plausibility under its stance (the residual root force and torque the ground
cannot give, the share of frames whose joint torques exceed the motors), the
biomechanical consistency with the species' gait table and, with ``track``, an
unassisted MuJoCo tracking run (survival, sim MPJPE, …). Nothing is refined unless
``refine`` asks for it; then every column describes the refined motion.

**Stance.** The dynamic metrics, the labelled skating and the tracking's contact schedule
need each foot's stance. The rule (``contacts``) is the same for every file: ``auto``
takes the labels a ``.npz`` file carries and detects the others' on the geometry
(:func:`habitsim.contacts.detect_contacts`, the project's contact rule); ``labels``
insists on the file's labels; ``geometry`` detects them for every file, so a ``.npz`` and
its BVH export score alike. Each row says which it used (``stance``: ``labels from
file`` or ``detected from geometry``). BVH and glTF files carry no stance labels: the
importer's own stance guess is not used.

**Species.** A ``.npz`` file names its species; a BVH written by habitsim (its joint
names and hierarchy) is the species whose skeleton its bone offsets are. Any other
motion-capture file needs ``species``. A file of another species than ``species`` names is
a :class:`ScoreError` for that file.

A file that cannot be scored becomes a row with ``status = "error"``, the error's class in
``error`` and its message in ``note``; the other files are scored all the same.
"""

from __future__ import annotations

import csv
import io
import json
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from habitsim.errors import HabitsimError, brief_path, unknown_choice
from habitsim.motion import Motion

if TYPE_CHECKING:  # pragma: no cover
    from habitsim.bvh import BVHData
    from habitsim.pipeline import ClipRun
    from habitsim.source import SourceOptions

__all__ = [
    "CONTACT_RULES",
    "STANCE_FROM_FILE",
    "STANCE_DETECTED",
    "ScoreError",
    "ScoreOptions",
    "ScoreResult",
    "motion_files",
    "bvh_species",
    "read_motion",
    "stance_of",
    "score_motion",
    "score_run",
    "score_files",
    "check_outputs",
]

#: ``contacts`` choices: where the stance of a file comes from.
CONTACT_RULES = ("auto", "labels", "geometry")
#: The ``stance`` of a row whose stance labels are the file's own.
STANCE_FROM_FILE = "labels from file"
#: The ``stance`` of a row whose stance was detected on the motion's geometry.
STANCE_DETECTED = "detected from geometry"
#: Columns of the printed table (key, header); every column is in the CSV / JSON.
TABLE_COLUMNS = (
    ("species", "species"),
    ("frames", "frames"),
    ("stance", "stance"),
    ("root_residual_mg", "residual F [mg]"),
    ("root_residual_torque_mgl", "residual T [mgL]"),
    ("torque_saturation", "torque>motor"),
    ("skate_mm", "skate mm"),
    ("penetration_mm", "penetr. mm"),
    ("float_mm", "float mm"),
    ("biomech_score", "biomech"),
)
#: The tracking's columns of the printed table.
TRACK_COLUMNS = (("survival", "survival"), ("sim_mpjpe_per_leg", "sim MPJPE/L"))


class ScoreError(HabitsimError, ValueError):
    """Bad input to scoring: no motion file given or found, a file of another species
    than the one named, a file whose species cannot be determined, stance labels asked
    for of a file without them."""


@dataclass(frozen=True)
class ScoreOptions:
    """How motions are scored (``habitsim score``'s options).

    Attributes:
        species: the species of the files (None: each file's own; required for
            motion-capture files that are not habitsim-written BVH).
        contacts: the stance rule, one of :data:`CONTACT_RULES` (module docstring).
        refine: ``none`` (judge the motion as it is), ``kinematic`` or ``dynamics``
            (refine it first, :func:`habitsim.refine.refine`).
        track: track every motion in MuJoCo, unassisted (survival, sim MPJPE, …).
        controller: the tracking controller (:data:`habitsim.controllers.CONTROLLERS`).
        dynamic: compute the dynamic plausibility (inverse dynamics).
        evaluator: classify every motion with the frozen evaluator network
            (``pred_species``, ``pred_action``, ``habit_correct``: the predicted species is
            the file's; imports torch).
        seed: the tracking's seed.
        source: how motion-capture files are read (``joint_map``, ``units``, ``up``,
            ``animation``, ``fps``; None: automatic). Their legs are never planted.
        follow_symlinks: read through links in a given folder that lead out of it
            (refused by default, :func:`habitsim.folders.input_files`).
    """

    species: str | None = None
    contacts: str = "auto"
    refine: str = "none"
    track: bool = False
    controller: str = "mpc"
    dynamic: bool = True
    evaluator: bool = True
    seed: int = 0
    source: SourceOptions | None = None
    follow_symlinks: bool = False

    def __post_init__(self) -> None:
        from habitsim.controllers import CONTROLLERS
        from habitsim.pipeline import REFINE_ALIASES, REFINE_MODES

        if self.contacts not in CONTACT_RULES:
            raise ScoreError(
                unknown_choice("stance rule (--contacts)", self.contacts, CONTACT_RULES)
            )
        if self.refine not in (*REFINE_MODES, *REFINE_ALIASES):
            raise ScoreError(
                unknown_choice("refine mode", self.refine, ("none", "kinematic", "dynamics"))
            )
        if self.controller not in CONTROLLERS:
            raise ScoreError(unknown_choice("controller", self.controller, CONTROLLERS))
        if self.species is not None:
            from habitsim.species import load_species

            object.__setattr__(self, "species", load_species(self.species).name)

    def to_dict(self) -> dict[str, Any]:
        """The options as JSON-ready values (the source options as given)."""
        d = asdict(self)
        src = self.source
        d["source"] = (
            None
            if src is None
            else {
                "joint_map": None if src.joint_map is None else str(src.joint_map),
                "units": src.units,
                "up": src.up,
                "animation": src.animation,
                "fps": src.fps,
            }
        )
        return d


@dataclass
class ScoreResult:
    """The scores of a set of files.

    Attributes:
        rows: one row per file, in the order of :func:`motion_files`.
        options: the options they were scored with.
        wall_time_s: wall time of the scoring [s].
        traces: per scored file (by name): ``stance`` (T, 4) the stance the metrics used
            and, when tracked, ``simulated`` (K, 4) the simulated foot contacts (the
            report's gait diagrams).
        written: the files :meth:`write` wrote.
    """

    rows: list[dict[str, Any]]
    options: ScoreOptions
    wall_time_s: float = 0.0
    traces: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    written: list[Path] = field(default_factory=list)

    @property
    def errors(self) -> list[dict[str, Any]]:
        """The rows of files that could not be scored."""
        return [r for r in self.rows if r["status"] != "ok"]

    @property
    def exit_code(self) -> int:
        """0: every file scored; 1: scoring a file failed (a bug); 2: a file was bad input."""
        states = {r["status"] for r in self.rows}
        return 1 if "failed" in states else 2 if "error" in states else 0

    def stance_lines(self) -> list[str]:
        """One line per stance source used: the rule and the files it applied to."""
        rule = {
            "auto": "a .npz file's own labels, else detected from the geometry",
            "labels": "the file's own labels",
            "geometry": "detected from the geometry for every file",
        }[self.options.contacts]
        lines = [f"stance rule (--contacts {self.options.contacts}): {rule}"]
        for how in (STANCE_FROM_FILE, STANCE_DETECTED):
            n = sum(r.get("stance") == how for r in self.rows)
            if n:
                lines.append(f"stance: {how}: {n} file(s)")
        return lines

    def columns(self) -> list[tuple[str, str]]:
        """(key, header) of the printed table."""
        return [("file", "file"), *TABLE_COLUMNS, *(TRACK_COLUMNS if self.options.track else ())]

    def table_text(self, markdown: bool = False) -> str:
        """The table: one line per file (an error row shows its error class)."""
        cols = self.columns()
        head = [h for _, h in cols]
        body = []
        for r in self.rows:
            if r["status"] != "ok":
                cells = [r["file"], r.get("species") or "—", "—", f"error: {r['error']}"]
                body.append(cells + ["—"] * (len(cols) - len(cells)))
            else:
                body.append([_cell(r.get(k)) for k, _ in cols])
        if markdown:
            lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
            return "\n".join(lines + ["| " + " | ".join(b) + " |" for b in body])
        widths = [max(len(x[i]) for x in [head, *body]) for i in range(len(head))]
        return "\n".join(
            "  ".join(
                c.ljust(w) if i < 4 else c.rjust(w)
                for i, (c, w) in enumerate(zip(x, widths, strict=True))
            )
            for x in [head, *body]
        )

    def to_json(self) -> dict[str, Any]:
        """The JSON document of ``scores.json``."""
        return {
            "kind": "habitsim.scores",
            "format_version": 1,
            "options": self.options.to_dict(),
            "rows": self.rows,
        }

    def csv_text(self) -> str:
        """``scores.csv``: every column of every row (NaN and None as empty cells)."""
        first = ["file", "path", "status", "error", "note", "species", "stance"]
        rest = sorted({k for r in self.rows for k in r} - set(first))
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(first + rest)
        for r in self.rows:
            w.writerow([_csv_cell(r.get(k)) for k in first + rest])
        return buf.getvalue()

    def write(self, out: str | Path) -> list[Path]:
        """Write ``scores.csv`` and ``scores.json`` into the folder ``out``, each
        atomically, both paths checked before the first is written (the report:
        :func:`habitsim.evaluation.score_report.write_score_report`).

        Raises:
            OutputPathError: a path that cannot be written.
        """
        from habitsim.fileio import atomic_write_text, json_safe, make_dirs

        folder = Path(out)
        check_outputs(folder)
        make_dirs(folder, "--out")
        atomic_write_text(folder / "scores.csv", self.csv_text())
        atomic_write_text(
            folder / "scores.json", json.dumps(json_safe(self.to_json()), indent=1) + "\n"
        )
        self.written = [folder / "scores.csv", folder / "scores.json"]
        return self.written


def check_outputs(out: str | Path, *, report: bool = False) -> None:
    """Check that the files of :meth:`ScoreResult.write` can be written into ``out``
    (before any file is scored).

    Raises:
        OutputPathError: a path that cannot be written (a folder of that name, a
            read-only folder).
    """
    from habitsim.fileio import check_writable

    for name in ("scores.csv", "scores.json"):
        check_writable(Path(out) / name, "--out")
    if report:
        from .report import check_report_outputs

        check_report_outputs(out)


def _cell(v: Any) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    if isinstance(v, bool | str | int):
        return str(v)
    a = abs(float(v))
    return "0" if a == 0 else f"{v:.3f}" if a < 10 else f"{v:.1f}"


def _csv_cell(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return ""
    return repr(v) if isinstance(v, float) else str(v)


# ---------------------------------------------------------------------------- files


def motion_files(inputs: Iterable[str | Path], follow_symlinks: bool = False) -> list[Path]:
    """The motion files of ``inputs``: each file as given, each folder's ``.npz``,
    ``.bvh``, ``.glb`` and ``.gltf`` files at any depth (sorted), duplicates once.

    Raises:
        ScoreError: a path that does not exist, a file of another type, or nothing found.
        InputPathError: a link in a folder that leads out of it (without
            ``follow_symlinks``).
    """
    from habitsim.folders import input_files
    from habitsim.source import CLIP_SUFFIXES

    out: list[Path] = []
    given = [Path(p) for p in inputs]
    for p in given:
        if p.is_dir():
            out += input_files(
                p, tuple(CLIP_SUFFIXES), follow_symlinks=follow_symlinks, what="folder"
            )
        elif p.is_file():
            if p.suffix.lower() not in CLIP_SUFFIXES:
                raise ScoreError(
                    f"{brief_path(p)}: not a motion file; valid: {', '.join(CLIP_SUFFIXES)} "
                    "files or folders holding them"
                )
            out.append(p)
        else:
            raise ScoreError(f"{brief_path(p)}: no such file or folder")
    first: dict[Path, Path] = {}
    for f in out:
        first.setdefault(f.resolve(), f)
    files = list(first.values())
    if not files:
        raise ScoreError(
            f"no motion files ({', '.join(CLIP_SUFFIXES)}) in "
            + ", ".join(brief_path(p) for p in given)
        )
    return files


def bvh_species(bvh: BVHData) -> str | None:
    """The species of a habitsim-written BVH (habitsim's joint names and hierarchy): the
    species (built-in, then user) whose skeleton has its bone offsets (None: another rig,
    or offsets of no known species)."""
    from habitsim.bvh_mapping.identity import identity_root_scale, is_habitsim_bvh
    from habitsim.species import load_species, species_names

    if not is_habitsim_bvh(bvh):
        return None
    built_in = species_names()
    user = [n for n in species_names(include_user=True) if n not in built_in]
    for name in built_in + user:
        if identity_root_scale(bvh, load_species(name)) == 1.0:
            return name
    return None


def _mismatch(path: Path, found: str, named: str) -> ScoreError:
    return ScoreError(
        f"{path.name}: a {found} motion, but --species names {named}; "
        f"give --species {found} or leave it out for files that name their species"
    )


def read_motion(
    path: str | Path, species: str | None = None, source: SourceOptions | None = None
) -> Motion:
    """Read a motion file as it is: a habitsim ``.npz`` (its labels kept), or a BVH/glTF
    clip imported onto its species without planting its legs (no stance labels).

    Args:
        path: a ``.npz``, ``.bvh``, ``.glb`` or ``.gltf`` file.
        species: the species the file must be (None: the file's own, when it can be told).
        source: how a motion-capture file is read (its ``species`` and ``plant`` are
            ignored).

    Raises:
        ScoreError: a file of another species than ``species``; a motion-capture file
            whose species cannot be told and no ``species``.
        MotionFileError, BVHParseError, GLTFError, SkeletonMappingError: an unreadable
            file (from the readers).
    """
    from habitsim.bvh_mapping import import_bvh, read_source
    from habitsim.motion import load_motion
    from habitsim.source import SourceOptions

    p = Path(path)
    if p.suffix.lower() == ".npz":
        m = load_motion(p)
        if species is not None and m.species != species:
            raise _mismatch(p, m.species, species)
        return m
    o = source or SourceOptions()
    bvh = read_source(p, animation=o.animation, fps=o.fps, strict=o.strict)
    found = bvh_species(bvh) if o.joint_map is None else None
    if species is not None and found is not None and found != species:
        raise _mismatch(p, found, species)
    sp = species or found
    if sp is None:
        raise ScoreError(
            f"{p.name}: the species of this {p.suffix.lower()} file cannot be told (only a "
            "habitsim-written BVH names it); give --species NAME (habitsim species list)"
        )
    motion, _ = import_bvh(bvh, sp, joint_map=o.joint_map, units=o.units, up=o.up, plant=False)
    return Motion(motion.species, motion.fps, motion.root_positions, motion.rotations, None, {})


def stance_of(motion: Motion, rule: str, name: str = "the motion") -> tuple[np.ndarray, str]:
    """A motion's (T, 4) stance labels under a stance rule and where they came from
    (:data:`STANCE_FROM_FILE` or :data:`STANCE_DETECTED`).

    Raises:
        ScoreError: ``rule == "labels"`` and the motion has none; an unknown rule.
    """
    if rule not in CONTACT_RULES:
        raise ScoreError(unknown_choice("stance rule (--contacts)", rule, CONTACT_RULES))
    if rule == "labels" and motion.contacts is None:
        raise ScoreError(
            f"{name}: --contacts labels, but it carries no stance labels (BVH and glTF "
            "never do); use --contacts auto or geometry"
        )
    if rule != "geometry" and motion.contacts is not None:
        return np.asarray(motion.contacts, dtype=bool).copy(), STANCE_FROM_FILE
    from habitsim.contacts import detect_contacts

    return detect_contacts(motion), STANCE_DETECTED


# ---------------------------------------------------------------------------- scoring


def _as_given(motion: Motion, target: str, **_: Any) -> Motion:
    """The "transfer" of a scored motion: the motion itself."""
    del target
    return motion


def score_run(motion: Motion, stance: np.ndarray, options: ScoreOptions | None = None) -> ClipRun:
    """Run a motion with the given stance through the pipeline as it is (no transfer;
    refinement and tracking as ``options`` ask): :func:`habitsim.pipeline.run_clip` with
    the motion itself as the transfer's output."""
    from habitsim.pipeline import run_clip
    from habitsim.transfer_methods import TransferMethod

    o = options or ScoreOptions()
    given = Motion(motion.species, motion.fps, motion.root_positions, motion.rotations, stance, {})
    as_given = TransferMethod("as_given", "the motion as given", _as_given, "external")
    return run_clip(
        given,
        motion.species,
        method=as_given,
        refine=o.refine,
        controller=o.controller,
        seed=o.seed,
        track=o.track,
        guard=False,
    )


def score_motion(
    motion: Motion,
    stance: np.ndarray,
    options: ScoreOptions | None = None,
    how: str = "",
    trace: dict[str, np.ndarray] | None = None,
) -> dict[str, Any]:
    """Every per-clip metric of docs/metrics.md of one motion under a stance.

    Args:
        motion: the motion (its own labels are not used: ``stance`` is).
        stance: (T, 4) bool stance labels (LF, RF, LH, RH): the dynamic metrics' feet in
            contact, the labelled skating's contacts and the tracking's contact schedule.
        options: the options (:class:`ScoreOptions`; its refine, track, controller,
            dynamic and seed apply).
        how: where ``stance`` came from (:data:`STANCE_FROM_FILE` / :data:`STANCE_DETECTED`):
            the biomechanical score adds its allowance for detected contacts.
        trace: filled with ``stance`` (the scored reference's labels) and, when tracked,
            ``simulated`` (the simulated foot contacts), when given.

    Returns:
        The row's metric columns: the kinematic keys, ``skate_labelled_mm``,
        ``stance_toe_height_per_leg``, the dynamic keys, the biomechanical keys, the
        evaluator's ``pred_species``, ``pred_action`` and ``habit_correct`` (NaN for a
        species it has no class for), and with tracking the simulated keys,
        ``sim_biomech_score`` / ``sim_biomech_gait``; ``refine_status`` and
        ``track_status``.
    """
    from habitsim.metrics.biomech import biomech_metrics

    from .rows import reference_dynamics, run_row

    o = options or ScoreOptions()
    run = score_run(motion, stance, o)
    figures = run_row(run)
    row: dict[str, Any] = {
        "species": motion.species,
        "frames": motion.num_frames,
        "fps": float(motion.fps),
        "duration_s": float(motion.duration),
        "refine_status": figures.refine_status,
        "track_status": figures.track_status,
    }
    row.update({k: float(v) for k, v in figures.refine_metrics.items()})
    if o.dynamic:
        row.update(reference_dynamics(run, strict=True))
    ref = run.reference
    if trace is not None:
        trace["stance"] = np.asarray(run.reference_contacts, dtype=bool)
        if run.track_result is not None:
            trace["simulated"] = np.asarray(run.track_result.contacts, dtype=bool)
    bare = Motion(ref.species, ref.fps, ref.root_positions, ref.rotations, None, {})
    if how == STANCE_DETECTED:
        bio = biomech_metrics(bare, use_labels=False)
    else:
        bio = biomech_metrics(bare, contacts=run.reference_contacts)
    row.update(bio.to_dict())
    if o.evaluator:
        row.update(_classified(ref))
    if o.track and run.track_result is not None:
        row.update(figures.track_columns())
        row["sim_biomech_score"], row["sim_biomech_gait"] = math.nan, ""
        if math.isfinite(bio.score):
            sim_m = run.track_result.motion()
            sb = biomech_metrics(sim_m, species=motion.species, contacts=sim_m.contacts)
            row["sim_biomech_score"], row["sim_biomech_gait"] = sb.score, sb.gait
    return row


def _classified(motion: Motion) -> dict[str, Any]:
    """The evaluator network's species and action of a motion, and whether the species
    is the motion's own (NaN for a species it has no class for)."""
    from .evaluator import load_evaluator

    ev = load_evaluator()
    p = ev.predict([motion])
    known = motion.species in ev.config.species
    return {
        "pred_species": p.species[0],
        "pred_action": p.actions[0],
        "habit_correct": float(p.species[0] == motion.species) if known else math.nan,
    }


def _score_file(path: Path, options: ScoreOptions, trace: dict[str, np.ndarray]) -> dict[str, Any]:
    row: dict[str, Any] = {"file": path.name, "path": str(path), "status": "ok", "error": ""}
    row["note"] = ""
    t0 = time.perf_counter()
    try:
        motion = read_motion(path, options.species, options.source)
        row["species"] = motion.species
        stance, how = stance_of(motion, options.contacts, path.name)
        row["stance"] = how
        row.update(score_motion(motion, stance, options, how, trace))
    except HabitsimError as e:
        row.update(status="error", error=type(e).__name__, note=str(e))
    except Exception as e:  # noqa: BLE001 - a failure of one file is its row, the rest go on
        row.update(status="failed", error=type(e).__name__, note=str(e))
    row["time_s"] = time.perf_counter() - t0
    return row


def score_files(
    inputs: Sequence[str | Path],
    options: ScoreOptions | None = None,
    *,
    log: Callable[[str], None] | None = None,
) -> ScoreResult:
    """Score every motion file of ``inputs`` (files and folders, :func:`motion_files`).

    Args:
        inputs: files and folders.
        options: the options (default :class:`ScoreOptions`).
        log: called with one line per file as it is done (None: silent).

    Returns:
        The :class:`ScoreResult`, one row per file (a file that could not be scored has
        ``status`` ``error`` (a typed habitsim error: bad input) or ``failed`` (a bug),
        ``error`` = the exception's class name and ``note`` = its message).

    Raises:
        ScoreError: no motion file given or found; a path that does not exist.
    """
    o = options or ScoreOptions()
    files = motion_files(inputs, o.follow_symlinks)
    t0 = time.perf_counter()
    rows = []
    traces: dict[str, dict[str, np.ndarray]] = {}
    for f in files:
        trace: dict[str, np.ndarray] = {}
        row = _score_file(f, o, trace)
        rows.append(row)
        if row["status"] == "ok":
            traces[row["file"]] = trace
        if log is not None:
            state = "ok" if row["status"] == "ok" else f"{row['status']}: {row['error']}"
            log(f"{f.name}: {state} ({row['time_s']:.1f} s)")
    return ScoreResult(rows, o, time.perf_counter() - t0, traces)
