"""The parsed BVH file (:class:`BVHData`): hierarchy, channels, frames, forward
kinematics and its own BVH text."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotations import quat_identity, quat_mul, quat_to_matrix

ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
_CHANNEL_CANON = {c.lower(): c for c in ROTATION_CHANNELS + POSITION_CHANNELS}
#: Name suffix of the joints the reader creates for End Sites (``LeftHand_End``).
END_SITE_SUFFIX = "_End"


@dataclass(frozen=True, eq=False)
class BVHData:
    """A parsed BVH file, in the file's own units and axes.

    Attributes:
        names: (J,) joint names, depth-first file order; End Sites included as
            ``<parent>_End`` joints.
        parents: (J,) parent index per joint, -1 for the root.
        offsets: (J, 3) OFFSET of each joint relative to its parent [file units].
        channels: per joint, the canonical channel names in file order (empty for End
            Sites), e.g. ``("Xposition", "Yposition", "Zposition", "Zrotation", ...)``.
        is_end_site: (J,) True for End Site joints.
        frame_time: seconds per frame (> 0).
        frames: (F, C) channel values per frame, C = total channel count, angles in degrees.
        source: file name (or ``"<string>"``) for messages.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    is_end_site: tuple[bool, ...]
    frame_time: float
    frames: np.ndarray
    source: str = "<string>"

    # ------------------------------------------------------------------ basics
    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def num_channels(self) -> int:
        return int(self.frames.shape[1])

    @property
    def fps(self) -> float:
        """Frame rate [Hz] = 1 / frame_time, snapped to an integer within 1e-6 relative."""
        fps = 1.0 / self.frame_time
        r = round(fps)
        return float(r) if r > 0 and abs(fps - r) <= 1e-6 * fps else fps

    @property
    def channel_start(self) -> tuple[int, ...]:
        """(J,) column of each joint's first channel in :attr:`frames`."""
        out, c = [], 0
        for ch in self.channels:
            out.append(c)
            c += len(ch)
        return tuple(out)

    def index(self, name: str) -> int:
        """Index of a joint by name.

        Raises:
            KeyError: with the list of joint names.
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(
                f"no joint {name!r} in {self.source}; joints: {', '.join(self.names)}"
            ) from None

    def children(self, j: int) -> list[int]:
        """Indices of the children of joint ``j``."""
        return [i for i, p in enumerate(self.parents) if p == j]

    def channel_values(self, j: int, channel: str) -> np.ndarray | None:
        """(F,) values of one channel of joint ``j`` or None if the joint lacks it."""
        if channel not in self.channels[j]:
            return None
        return self.frames[:, self.channel_start[j] + self.channels[j].index(channel)]

    # ------------------------------------------------------------------ pose
    def local_rotations(self) -> np.ndarray:
        """(F, J, 4) local joint rotations, unit quaternions wxyz.

        The rotation channels of each joint are composed in file order as intrinsic
        rotations (R = R_1 · R_2 · R_3); joints without rotation channels get identity.
        """
        f = self.num_frames
        q = quat_identity((f, self.num_joints))
        starts = self.channel_start
        for j, chans in enumerate(self.channels):
            acc = None
            for k, c in enumerate(chans):
                if c not in ROTATION_CHANNELS:
                    continue
                half = np.radians(self.frames[:, starts[j] + k]) * 0.5
                axis_q = np.zeros((f, 4))
                axis_q[:, 0] = np.cos(half)
                axis_q[:, 1 + ROTATION_CHANNELS.index(c)] = np.sin(half)
                acc = axis_q if acc is None else quat_mul(acc, axis_q)
            if acc is not None:
                q[:, j] = acc
        return q

    def local_translations(self) -> np.ndarray:
        """(F, J, 3) translation of each joint relative to its parent [file units].

        The OFFSET, with the axes that have a position channel replaced by its values.
        """
        t = np.broadcast_to(self.offsets, (self.num_frames, self.num_joints, 3)).copy()
        starts = self.channel_start
        for j, chans in enumerate(self.channels):
            for k, c in enumerate(chans):
                if c in POSITION_CHANNELS:
                    t[:, j, POSITION_CHANNELS.index(c)] = self.frames[:, starts[j] + k]
        return t

    def root_translation(self) -> np.ndarray:
        """(F, 3) root joint position per frame [file units]."""
        return self.local_translations()[:, 0]

    def fk(self, return_rotations: bool = False, rest: bool = False):
        """Forward kinematics of the BVH skeleton in the file's frame and units.

        Args:
            return_rotations: also return the global rotation matrices (F, J, 3, 3).
            rest: evaluate the rest pose (OFFSETs only, identity rotations, root at its
                OFFSET) instead of the frames; then F = 1.

        Returns:
            (F, J, 3) global joint positions [file units] (and the global rotations).
        """
        if rest:
            f = 1
            trans = self.offsets[None].copy()
            local = np.broadcast_to(np.eye(3), (1, self.num_joints, 3, 3))
        else:
            f = self.num_frames
            trans = self.local_translations()
            local = quat_to_matrix(self.local_rotations())
        glob = np.empty((f, self.num_joints, 3, 3))
        pos = np.empty((f, self.num_joints, 3))
        for j, p in enumerate(self.parents):
            if p < 0:
                glob[:, j] = local[:, j]
                pos[:, j] = trans[:, j]
            else:
                glob[:, j] = glob[:, p] @ local[:, j]
                pos[:, j] = pos[:, p] + np.einsum("fab,fb->fa", glob[:, p], trans[:, j])
        return (pos, glob) if return_rotations else pos

    def to_text(self) -> str:
        """Serialise back to BVH text (same hierarchy, channels and values).

        End Site joints are written as ``End Site`` blocks, so ``parse_bvh(d.to_text())``
        reproduces ``d`` (values printed with 10 significant digits).
        """
        kids: list[list[int]] = [[] for _ in range(self.num_joints)]
        for j, p in enumerate(self.parents):
            if p >= 0:
                kids[p].append(j)
        out = ["HIERARCHY"]

        def emit(j: int, depth: int) -> None:
            ind = "\t" * depth
            off = " ".join(_fmt(v) for v in self.offsets[j])
            if self.is_end_site[j]:
                out.extend([f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {off}", f"{ind}}}"])
                return
            out.append(f"{ind}{'ROOT' if self.parents[j] < 0 else 'JOINT'} {self.names[j]}")
            out.append(f"{ind}{{")
            out.append(f"{ind}\tOFFSET {off}")
            out.append(
                f"{ind}\tCHANNELS {len(self.channels[j])} {' '.join(self.channels[j])}".rstrip()
            )
            for c in kids[j]:
                emit(c, depth + 1)
            out.append(f"{ind}}}")

        emit(0, 0)
        out += ["MOTION", f"Frames: {self.num_frames}", f"Frame Time: {self.frame_time!r}"]
        out += [" ".join(_fmt(v) for v in row) for row in self.frames]
        return "\n".join(out) + "\n"


def _fmt(v: float) -> str:
    s = f"{v:.10g}"
    return "0" if s in ("-0", "0") else s
