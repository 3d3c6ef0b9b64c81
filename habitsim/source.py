"""A clip as a user gives it: a habitsim motion (``.npz``) or motion capture (BVH, glTF)
imported onto a species, cut to a span of time.

Every command that reads a clip reads it through :func:`load_clip` with one
:class:`SourceOptions`, so ``--map``, ``--units``, ``--up``, ``--species``/``--from``,
``--animation``, ``--fps``, ``--start`` and ``--end`` mean the same everywhere
(:func:`habitsim.cli.conventions.add_source_options` adds them to a command).

A span of a motion-capture file is cut *before* the import, so the frames outside it take
no part in the mapping's frame detection or in the stance found on the source's feet.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from .bvh import BVHData
from .bvh_mapping import SOURCE_SUFFIXES, JointMapping, import_bvh, read_source
from .errors import ArgumentRangeError, MotionFileError
from .motion import Motion, load_motion
from .species import load_species

#: File types :func:`load_clip` reads: habitsim motions and the importer's sources.
CLIP_SUFFIXES: tuple[str, ...] = (".npz", *SOURCE_SUFFIXES)


@dataclass(frozen=True)
class Span:
    """A span of a clip in seconds from its first frame.

    Attributes:
        start_s: first second kept (None: the clip's start).
        end_s: second the span ends at, exclusive (None: the clip's end).
    """

    start_s: float | None = None
    end_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("start_s", "end_s"):
            v = getattr(self, name)
            if v is not None and (not math.isfinite(v) or v < 0):
                flag = "--start" if name == "start_s" else "--end"
                raise ArgumentRangeError(f"{flag} must be a finite time ≥ 0 s, got {v!r}")
        if self.start_s is not None and self.end_s is not None and self.end_s <= self.start_s:
            raise ArgumentRangeError(
                f"--end ({self.end_s:g} s) must come after --start ({self.start_s:g} s)"
            )

    @property
    def whole(self) -> bool:
        """True when the span keeps the whole clip."""
        return self.start_s is None and self.end_s is None

    def frames(self, num_frames: int, fps: float, what: str = "the clip") -> tuple[int, int]:
        """The span as frames ``start:stop`` of a ``num_frames``-frame clip at ``fps``.

        Raises:
            ArgumentRangeError: the span starts at or after the clip's end, or keeps fewer
                than two frames (names the clip's duration).
        """
        duration = num_frames / fps
        start = 0 if self.start_s is None else int(round(self.start_s * fps))
        stop = num_frames if self.end_s is None else min(num_frames, int(round(self.end_s * fps)))
        if stop - start < 2:
            raise ArgumentRangeError(
                f"--start {self.start_s if self.start_s is not None else 0:g} s / --end "
                f"{self.end_s if self.end_s is not None else duration:g} s keeps "
                f"{max(0, stop - start)} frame(s) of {what} ({num_frames} frames, "
                f"{duration:.2f} s): give a span inside 0–{duration:.2f} s of at least two frames"
            )
        return start, stop

    def cut(self, motion: Motion, what: str = "the motion") -> Motion:
        """The frames of ``motion`` inside the span (the motion itself when whole)."""
        if self.whole:
            return motion
        return motion.slice(*self.frames(motion.num_frames, motion.fps, what=what))


@dataclass(frozen=True)
class SourceOptions:
    """How a clip file is read.

    Attributes:
        species: the catalog species a BVH/glTF source is imported onto (required for
            those; ignored for ``.npz``, which carries its species).
        joint_map: a joint-map file or dict for the import (None: automatic mapping).
        units: source length unit (``"m"``, ``"cm"``, ``"mm"``, ``"in"`` or metres per
            unit; None: detect).
        up: source up axis (``"y"``, ``"-z"``…; None: detect).
        animation: glTF only: the animation's name or index (None: the first).
        fps: glTF only: the sampling rate [Hz] (None: 30).
        span: the part of the clip kept.
        plant: plant the imported legs on the source's footholds.
        strict: BVH only: refuse a truncated file (False keeps its complete frames).
        loop: play the clip (after the span is cut) this many times as a seamless loop
            (:func:`habitsim.bvh_mapping.loops.repeat_loop`; None: once, as it is).
        loop_seconds: or repeat it as a loop to this length [s] (None: as it is).
    """

    species: str | None = None
    joint_map: str | Path | Mapping[str, str] | None = None
    units: str | float | None = None
    up: str | None = None
    animation: str | int | None = None
    fps: float | None = None
    span: Span = Span()
    plant: bool = True
    strict: bool = True
    loop: int | None = None
    loop_seconds: float | None = None

    def shape(self, motion: Motion, what: str = "the motion") -> Motion:
        """A habitsim motion cut to :attr:`span` and repeated as :attr:`loop` asks.

        Raises:
            ArgumentRangeError: a span outside the motion.
            LoopError: a loop asked for of a motion that is not a loop.
        """
        motion = self.span.cut(motion, what=what)
        if self.loop is None and self.loop_seconds is None:
            return motion
        from .bvh_mapping.loops import repeat_loop

        return repeat_loop(motion, cycles=self.loop, seconds=self.loop_seconds)

    def import_options_given(self) -> list[str]:
        """The options that only apply to motion capture, by their flags, when given."""
        given = {
            "--map": self.joint_map,
            "--units": self.units,
            "--up": self.up,
            "--animation": self.animation,
            "--fps": self.fps,
        }
        out = [flag for flag, v in given.items() if v is not None]
        if not self.plant:
            out.append("--no-plant")
        return out


@dataclass(frozen=True)
class LoadedClip:
    """A clip read by :func:`load_clip`.

    Attributes:
        motion: the motion (on the clip's species; cut to the span).
        mapping: the joint mapping of an imported BVH/glTF (None for ``.npz``).
        path: the file read.
        first_frame: the span's first frame in the file (at the file's frame rate).
        source_frames: the file's frame count.
        source_fps: the file's frame rate [Hz].
        span_frames: the span's frame count before a loop repeated it (None: the
            motion's).
    """

    motion: Motion
    mapping: JointMapping | None
    path: Path
    first_frame: int
    source_frames: int
    source_fps: float
    span_frames: int | None = None

    @property
    def _frames(self) -> int:
        return self.motion.num_frames if self.span_frames is None else self.span_frames

    @property
    def cut(self) -> bool:
        """True when the span left part of the file out."""
        return self.first_frame > 0 or self._frames < self.source_frames

    def kept(self) -> str:
        """The span kept, as "a–b s of the file's T s" ("" when the whole file was read)."""
        if not self.cut:
            return ""
        t0 = self.first_frame / self.source_fps
        total = self.source_frames / self.source_fps
        return f"{t0:.2f}–{t0 + self._frames / self.motion.fps:.2f} s of the file's {total:.2f} s"

    def looped(self) -> str:
        """How a loop was repeated, as "played as a loop: a s → b s" ("" when it was not)."""
        if self.span_frames is None:
            return ""
        before = self.span_frames / self.motion.fps
        return f"played as a loop: {before:.2f} s → {self.motion.duration:.2f} s"


def _looped(clip: LoadedClip, o: SourceOptions) -> LoadedClip:
    """The clip repeated as a loop when ``o`` asks for it (the clip itself otherwise)."""
    if o.loop is None and o.loop_seconds is None:
        return clip
    from .bvh_mapping.loops import repeat_loop

    motion = repeat_loop(clip.motion, cycles=o.loop, seconds=o.loop_seconds)
    return dataclasses.replace(clip, motion=motion, span_frames=clip.motion.num_frames)


def cut_source(bvh: BVHData, span: Span) -> tuple[BVHData, int]:
    """The frames of a parsed motion-capture clip inside ``span``, and the first one's index."""
    if span.whole:
        return bvh, 0
    start, stop = span.frames(bvh.num_frames, bvh.fps, what=bvh.source)
    return dataclasses.replace(bvh, frames=bvh.frames[start:stop].copy()), start


def load_clip(path: str | Path, options: SourceOptions | None = None) -> LoadedClip:
    """Read a clip file: a habitsim motion, or a BVH/glTF clip imported onto a species.

    Args:
        path: a ``.npz``, ``.bvh``, ``.glb`` or ``.gltf`` file.
        options: how to read it (default :class:`SourceOptions`: the whole clip, automatic
            mapping and frame detection).

    Returns:
        The :class:`LoadedClip`.

    Raises:
        MotionFileError: an unknown file type (lists the valid ones), a BVH/glTF source
            without a species, or import options given for a ``.npz`` motion.
        ArgumentRangeError: a span outside the clip.
        LoopError: a loop asked for of a clip that is not a loop (says why and where it
            could be cut), or both ``loop`` and ``loop_seconds``.
        UnknownSpeciesError, BVHParseError, GLTFError, SkeletonMappingError: from the
            import (:func:`habitsim.bvh_mapping.import_bvh`).
    """
    o = options or SourceOptions()
    p = Path(path)
    kind = p.suffix.lower()
    if kind not in CLIP_SUFFIXES:
        raise MotionFileError(
            f"{p.name}: unknown clip file type {p.suffix!r}; valid: {', '.join(CLIP_SUFFIXES)}"
        )
    if kind == ".npz":
        extra = o.import_options_given()
        if extra:
            raise MotionFileError(
                f"{', '.join(extra)} appl{'ies' if len(extra) == 1 else 'y'} to motion capture "
                f"(.bvh, .glb, .gltf), not to the habitsim motion {p.name}"
            )
        whole = load_motion(p)
        if o.span.whole:
            motion, first = whole, 0
        else:
            first, stop = o.span.frames(whole.num_frames, whole.fps, what=p.name)
            motion = whole.slice(first, stop)
        return _looped(LoadedClip(motion, None, p, first, whole.num_frames, whole.fps), o)
    if o.species is None:
        raise MotionFileError(
            f"a {kind} source needs a species to import it onto (--from SPECIES or "
            "--species SPECIES, e.g. dog)"
        )
    sp = load_species(o.species)  # unknown species: the known ones listed
    bvh = read_source(p, animation=o.animation, fps=o.fps, strict=o.strict)
    cut, first = cut_source(bvh, o.span)
    motion, mapping = import_bvh(
        cut, sp, joint_map=o.joint_map, units=o.units, up=o.up, plant=o.plant
    )
    return _looped(LoadedClip(motion, mapping, p, first, bvh.num_frames, bvh.fps), o)
