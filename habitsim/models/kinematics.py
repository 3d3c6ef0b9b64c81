"""Differentiable rotations and forward kinematics in torch (the learning core's only).

The numpy side of habitsim (:mod:`habitsim.rotations`, :func:`habitsim.skeleton.fk`)
never imports torch; everything batched and differentiable lives here, under
:mod:`habitsim.models`. The torch rotation functions wrap ``roma`` (batched,
differentiable), which stores quaternions scalar-last; habitsim stores them scalar-first
(w, x, y, z), and the two conventions meet in this module only.

One forward kinematics serves a single skeleton (:func:`fk_torch`, any batch shape) and a
mixed-species batch (:func:`batched_fk`, per-item bone offsets): same maths as
:func:`habitsim.skeleton.fk`.
"""

from __future__ import annotations

import roma
import torch

from ..errors import InvalidMotionError
from ..skeleton import PARENTS, Skeleton

__all__ = [
    "torch_quat_mul",
    "torch_quat_apply",
    "torch_quat_to_matrix",
    "torch_matrix_to_quat",
    "torch_sixd_to_matrix",
    "torch_matrix_to_6d",
    "fk_torch",
    "batched_fk",
]


def _to_xyzw(q: torch.Tensor) -> torch.Tensor:
    return torch.cat([q[..., 1:], q[..., :1]], dim=-1)


def _to_wxyz(q: torch.Tensor) -> torch.Tensor:
    return torch.cat([q[..., 3:], q[..., :3]], dim=-1)


def torch_quat_mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product of wxyz quaternions (…, 4), differentiable."""
    return _to_wxyz(roma.quat_product(_to_xyzw(a), _to_xyzw(b)))


def torch_quat_apply(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors (…, 3) by wxyz quaternions (…, 4), differentiable."""
    return roma.quat_action(_to_xyzw(q), v, is_normalized=True)


def torch_quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (…, 3, 3) from wxyz quaternions (…, 4) (normalised first)."""
    return roma.unitquat_to_rotmat(roma.quat_normalize(_to_xyzw(q)))


def torch_matrix_to_quat(m: torch.Tensor) -> torch.Tensor:
    """wxyz quaternions (…, 4) from rotation matrices (…, 3, 3)."""
    return _to_wxyz(roma.rotmat_to_unitquat(m))


def torch_sixd_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (…, 3, 3) from the 6-D form (…, 6) (Gram–Schmidt, via roma)."""
    cols = torch.stack([d6[..., :3], d6[..., 3:]], dim=-1)  # (…, 3, 2)
    return roma.special_gramschmidt(cols)


def torch_matrix_to_6d(m: torch.Tensor) -> torch.Tensor:
    """6-D form (…, 6) of rotation matrices (…, 3, 3)."""
    return torch.cat([m[..., :, 0], m[..., :, 1]], dim=-1)


def _chain(
    parents: tuple[int, ...], root: torch.Tensor, quats: torch.Tensor, off: tuple[torch.Tensor, ...]
) -> torch.Tensor:
    """Joint positions (…, J, 3) of the topology ``parents`` (parent index per joint).

    ``off[j]`` is joint j's offset from its parent as a column (…, 3, 1) that broadcasts
    against the (…, 3, 3) rotations.
    """
    local = torch_quat_to_matrix(quats).unbind(-3)  # J × (…, 3, 3); one backward stack
    glob: list[torch.Tensor] = []
    pos: list[torch.Tensor] = []
    for j, p in enumerate(parents):
        if p < 0:
            glob.append(local[j])
            pos.append(root.to(quats.dtype))
        else:
            glob.append(glob[p] @ local[j])
            pos.append(pos[p] + (glob[p] @ off[j]).squeeze(-1))
    return torch.stack(pos, dim=-2)


def fk_torch(skel: Skeleton, root_pos: torch.Tensor, quats: torch.Tensor) -> torch.Tensor:
    """Batched, differentiable forward kinematics of one skeleton (same maths as
    :func:`habitsim.skeleton.fk`).

    Args:
        skel: the skeleton.
        root_pos: (…, 3) root positions [m].
        quats: (…, J, 4) local rotations wxyz (normalised inside).

    Returns:
        (…, J, 3) global joint positions, in ``quats``' dtype and device.
    """
    j = skel.num_joints
    q_shape, r_shape = tuple(quats.shape), tuple(root_pos.shape)
    if len(q_shape) < 2 or q_shape[-2:] != (j, 4):
        raise InvalidMotionError(f"quaternions must have shape (..., {j}, 4), got {q_shape}")
    if r_shape[-1:] != (3,) or r_shape[:-1] != q_shape[:-2]:
        raise InvalidMotionError(
            f"root positions must have shape {(*q_shape[:-2], 3)}, got {r_shape}"
        )
    offsets = torch.as_tensor(skel.offsets, dtype=quats.dtype, device=quats.device)
    return _chain(skel.parents, root_pos, quats, offsets.unsqueeze(-1).unbind(0))


def batched_fk(root: torch.Tensor, quats: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """Forward kinematics of the shared topology with per-item bone offsets, differentiable.

    Same maths as :func:`fk_torch`, but every batch item may have its own species: one
    pass over the joints for a whole mixed-species batch.

    Args:
        root: (B, T, 3) pelvis positions [m].
        quats: (B, T, J, 4) local rotations wxyz (normalised inside).
        offsets: (B, J, 3) canonical-pose offsets from each joint's parent [m].

    Returns:
        (B, T, J, 3) global joint positions [m].
    """
    off = offsets[:, None, :, :, None].to(quats.dtype).unbind(2)  # J × (B, 1, 3, 1)
    return _chain(PARENTS, root, quats, off)
