"""The palm-centred 6D grasp vector: a continuous stand-in for the 51 grasp numbers that networks regress.

``(B, 51)`` grasps (wrist translation, global axis-angle, 45 finger numbers) <-> ``(B, 54)`` vectors: the
palm centre's position (3, m), the global rotation's first two columns (6; the continuous 6D
representation of Zhou et al., CVPR 2019) and the 45 finger numbers. An axis-angle jumps where the angle
nears pi, and the wrist translation moves with the rotation (the wrist is 8-10 cm from where a hand
touches); the palm centre and the two columns do neither. Any 6 numbers map back to a rotation
(Gram-Schmidt). The hand turns its global rotation about the rest ``wrist`` joint, and ``palm`` is the rest
palm centre (both (3,), m; :class:`tohgs.hand.model.HandModel` gives them).
"""

from __future__ import annotations

import torch

from tohgs.hand.rotations import axis_angle_to_matrix, matrix_to_axis_angle

VECTOR_DIM = 54


def palm_rot6d(grasp: torch.Tensor, wrist: torch.Tensor, palm: torch.Tensor) -> torch.Tensor:
    """(B, 51) grasps -> (B, 54) palm-centred 6D vectors (module docstring)."""
    rot = axis_angle_to_matrix(grasp[:, 3:6])
    centre = grasp[:, :3] + wrist + (rot @ (palm - wrist)[:, None])[..., 0]
    return torch.cat([centre, rot[..., 0], rot[..., 1], grasp[:, 6:]], -1)


def grasp_from_palm_rot6d(vec: torch.Tensor, wrist: torch.Tensor, palm: torch.Tensor) -> torch.Tensor:
    """The inverse of :func:`palm_rot6d`: (B, 54) vectors (any 6 rotation numbers) -> (B, 51) grasps."""
    a, b = vec[:, 3:6], vec[:, 6:9]
    x = a / a.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    y = b - (x * b).sum(-1, keepdim=True) * x
    y = y / y.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    rot = torch.stack([x, y, torch.cross(x, y, dim=-1)], -1)
    trans = vec[:, :3] - wrist - (rot @ (palm - wrist)[:, None])[..., 0]
    return torch.cat([trans, matrix_to_axis_angle(rot), vec[:, 9:]], -1)
