"""Option conventions shared by every ``habitsim`` command.

* **Lists of names.** An option that takes several names (species, targets, sources,
  methods, actions, stages) is added with :func:`add_list_option` and accepts them
  comma-separated, space-separated or both: ``--species cat,dog``, ``--species cat dog``
  and ``--species cat,dog horse`` all give ``["cat", "dog"(, "horse")]``. The parsed value
  is a list of str (or the option's default when it is not given).
* **Clips.** A command that reads a clip file takes the same options for it
  (:func:`add_source_options`): ``--map``, ``--units``, ``--up``, ``--animation`` and
  ``--fps`` for motion capture, ``--start`` and ``--end`` for any clip, read into one
  :class:`habitsim.source.SourceOptions` by :func:`source_options`.
* **Tables.** A printed table is followed by a legend of its columns
  (:func:`format_legend`).
* **Targets.** Every benchmark prints its targets with the verdict ``met`` or
  ``MISSED``. With ``--check`` (:func:`add_check_option`) a run that misses one exits with
  code 1 (:func:`check_exit`); without it the verdicts are printed and the run exits 0.
  Bad input is exit code 2, as for every command. ``bench real`` always exits 1 on a
  miss (its ``--no-check`` skips the refinement check, a different thing).
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..source import SourceOptions

__all__ = [
    "CHECK_HELP",
    "ListAction",
    "add_list_option",
    "add_frame_options",
    "add_source_options",
    "source_options",
    "split_names",
    "add_check_option",
    "check_exit",
    "format_legend",
]

#: Help text of ``--check`` (the benchmarks' one flag for a failing exit code).
CHECK_HELP = "exit with code 1 when a target is MISSED (default: print the verdicts, exit 0)"


def split_names(values: str | Iterable[str] | None) -> list[str]:
    """Names of ``"a,b"``, ``["a,b", "c"]`` or ``["a", "b"]``: split on commas, blanks
    dropped, first occurrence kept. None gives [].
    """
    if values is None:
        return []
    if isinstance(values, str):
        values = [values]
    out: list[str] = []
    for v in values:
        for name in str(v).split(","):
            name = name.strip()
            if name and name not in out:
                out.append(name)
    return out


class ListAction(argparse.Action):
    """argparse action of :func:`add_list_option`: one or more tokens, each may hold
    comma-separated names; stores the list of names (converted by ``convert`` and
    checked against ``names`` when given)."""

    def __init__(
        self,
        option_strings: Sequence[str],
        dest: str,
        convert: Callable[[str], Any] | None = None,
        names: Sequence[str] | None = None,
        **kwargs: Any,
    ) -> None:
        self.convert = convert
        self.names = tuple(names) if names is not None else None
        super().__init__(option_strings, dest, nargs="+", **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        names = split_names(values)
        if not names:
            parser.error(f"{option_string}: expected at least one name")
        if self.names is not None:
            bad = [n for n in names if n not in self.names]
            if bad:
                parser.error(
                    f"{option_string}: invalid choice {', '.join(map(repr, bad))} "
                    f"(choose from {', '.join(self.names)})"
                )
        if self.convert is not None:
            try:
                names = [self.convert(n) for n in names]
            except ValueError as e:
                parser.error(f"{option_string}: {e}")
        setattr(namespace, self.dest, names)


#: ``--units`` choices: the length units a source file may be told to be in.
UNIT_CHOICES = ("cm", "m", "mm", "in")
#: ``--up`` choices: a source file's up axis.
UP_CHOICES = ("y", "z", "-y", "-z", "x", "-x")


def add_frame_options(p: argparse.ArgumentParser, of: str = "the file") -> None:
    """``--units`` and ``--up`` of a motion-capture source (None: detect), as
    :func:`habitsim.bvh_mapping.import_bvh` takes them (``of``: what they describe, for
    the help)."""
    p.add_argument(
        "--units",
        choices=UNIT_CHOICES,
        default=None,
        help=f"length unit of {of} (default: detect; inches are never detected)",
    )
    p.add_argument(
        "--up", choices=UP_CHOICES, default=None, help=f"up axis of {of} (default: detect)"
    )


def add_source_options(
    p: argparse.ArgumentParser,
    of: str = "the file",
    motion_capture: bool = True,
    span: bool = True,
) -> None:
    """The options of a clip file, as :class:`habitsim.source.SourceOptions` holds them.

    Args:
        p: the (sub)command's parser.
        of: what the options describe, for the help (e.g. "every clip").
        motion_capture: add ``--map``, ``--units``, ``--up``, ``--animation``, ``--fps``
            (the import of a BVH/glTF source).
        span: add ``--start`` and ``--end`` (seconds of the clip kept).
    """
    if motion_capture:
        p.add_argument(
            "--map",
            type=Path,
            default=None,
            dest="joint_map",
            metavar="MAP",
            help=(
                f"joint-map JSON or TOML for {of} (motion capture): "
                '{"map": {"habitsim_joint": "SourceJoint"}}; with "extends": "auto" it '
                "overrides only the joints it names (see 'habitsim data inspect-bvh')"
            ),
        )
        add_frame_options(p, of)
        p.add_argument(
            "--animation",
            default=None,
            metavar="NAME|INDEX",
            help=f"glTF/GLB: the animation of {of} to read (default: the first)",
        )
        p.add_argument(
            "--fps", type=float, default=None, help="glTF/GLB: sampling rate in Hz (default 30)"
        )
    if span:
        p.add_argument(
            "--start",
            type=float,
            default=None,
            metavar="S",
            help=f"first second of {of} kept (default: its start)",
        )
        p.add_argument(
            "--end",
            type=float,
            default=None,
            metavar="S",
            help=f"second {of} is cut at (default: its end)",
        )


def source_options(
    ns: argparse.Namespace, species: str | None = None, **fields: Any
) -> SourceOptions:
    """The :class:`habitsim.source.SourceOptions` of a command's parsed
    :func:`add_source_options` (options it did not add keep their defaults).

    Args:
        ns: the parsed namespace.
        species: the species a BVH/glTF source is imported onto.
        fields: other fields of the options (e.g. ``plant=False``).
    """
    from ..source import SourceOptions, Span

    animation = getattr(ns, "animation", None)
    if animation is not None:
        try:
            animation = int(animation)
        except ValueError:
            pass
    return SourceOptions(
        species=species,
        joint_map=getattr(ns, "joint_map", None),
        units=getattr(ns, "units", None),
        up=getattr(ns, "up", None),
        animation=animation,
        fps=getattr(ns, "fps", None),
        span=Span(getattr(ns, "start", None), getattr(ns, "end", None)),
        **fields,
    )


def add_list_option(
    parser: argparse.ArgumentParser,
    *flags: str,
    default: Any = None,
    help: str,
    metavar: str = "NAME",
    choices: Sequence[str] | None = None,
    convert: Callable[[str], Any] | None = None,
) -> argparse.Action:
    """Add an option taking several names as ``A,B``, ``A B`` or both.

    Args:
        parser: the (sub)command's parser.
        flags: option strings, e.g. ``"--species"``.
        default: value when the option is absent (kept as given, e.g. None or a list).
        help: help text; "; A,B or A B" is appended.
        metavar: shown in the usage.
        choices: allowed names (checked after splitting); None allows any.
        convert: applied to each name after splitting (e.g. ``int``).
    """
    return parser.add_argument(
        *flags,
        action=ListAction,
        default=default,
        metavar=metavar,
        names=choices,
        convert=convert,
        help=f"{help}; A,B or A B",
    )


def add_check_option(parser: argparse.ArgumentParser, help: str = CHECK_HELP) -> None:
    """Add ``--check``: exit 1 when a target is MISSED."""
    parser.add_argument("--check", action="store_true", help=help)


def check_exit(missed: Sequence[str], check: bool) -> int:
    """Exit code of a benchmark: 1 when ``check`` and a target was missed, else 0.

    The missed targets are named on stderr when they set the exit code.
    """
    if check and missed:
        print(f"MISSED {len(missed)} target(s): {'; '.join(missed)}", file=sys.stderr)
        return 1
    return 0


#: Width the legends are wrapped to [characters].
LEGEND_WIDTH = 100


def format_legend(text: str, indent: str = "") -> str:
    """A table's legend, wrapped to :data:`LEGEND_WIDTH` columns, every line indented."""
    return textwrap.fill(
        text,
        width=LEGEND_WIDTH,
        initial_indent=indent,
        subsequent_indent=indent,
        break_on_hyphens=False,
    )
