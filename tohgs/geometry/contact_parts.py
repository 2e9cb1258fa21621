"""ContactGen's object-centric contact representation (Liu et al. ICCV 2023): per object point, how much it
is touched, by which of the hand's 16 parts, and from which direction in that part's frame.

For (B, N, 3) object points and posed hands (:class:`tohgs.hand.model.HandOutput`):

- ``contact`` (B, N) in [0, 1]: the map of the map shards, ``1 - 2 (sigmoid(alpha d) - 0.5)`` with ``d``
  the distance to the nearest hand vertex (:func:`tohgs.geometry.hand_object.contact_values`), so that
  object-centric, task-aware and ground-truth maps are one quantity (ContactGen measures contact with
  capsules on the hand's normals; its maps and ours are both 1 at the surface and fall off within a few
  millimetres);
- ``part`` (B, N) in [0, 16): the part label (the joint of largest skinning weight,
  :attr:`tohgs.hand.assets.HandAssets.part_labels`) of the nearest hand vertex, as ContactGen;
- ``direction`` (B, N, 3) unit vectors: the point's offset from that part's joint, in the joint's frame,
  normalised (ContactGen's "uv" map). A point on a rigidly skinned vertex keeps its direction whatever the
  pose: the rest offset of that vertex from its joint.

:func:`directions_to_world` inverts the last step: given parts and directions, the world direction from
each assigned joint, which is what ContactGen's solver pulls each hand part toward.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch

from tohgs.geometry.hand_object import contact_values, nearest_vertex
from tohgs.hand.layout import FINGERS, N_JOINTS

if TYPE_CHECKING:
    from tohgs.hand.model import HandModel

N_PARTS = N_JOINTS  # one part per MANO joint (16)


@dataclass(frozen=True)
class PartContact:
    """One hand's representation on an object cloud: ``contact`` (B, N), ``part`` (B, N) long,
    ``direction`` (B, N, 3) unit (module docstring)."""

    contact: torch.Tensor
    part: torch.Tensor
    direction: torch.Tensor


def _unit(x: torch.Tensor) -> torch.Tensor:
    return x / x.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def part_contact(points: torch.Tensor, vertices: torch.Tensor, joints: torch.Tensor, rotations: torch.Tensor,
                 part_labels: torch.Tensor, alpha: float) -> PartContact:
    """The representation of (B, N, 3) object points for hands with (B, V, 3) ``vertices``, (B, >=16, 3)
    ``joints`` (the first 16 are the joint centres), (B, 16, 3, 3) global ``rotations`` and (V,)
    ``part_labels``; ``alpha`` (1/m) the contact map's sharpness (the map shards' ``alpha_contact``).
    Differentiable in the hand for ``contact`` and ``direction``."""
    if points.ndim != 3 or points.shape[-1] != 3:
        raise ValueError(f"points must have shape (B, N, 3), got {tuple(points.shape)}")
    if rotations.shape[1:] != (N_PARTS, 3, 3):
        raise ValueError(f"rotations must have shape (B, {N_PARTS}, 3, 3), got {tuple(rotations.shape)}")
    contact, idx = contact_values(points, vertices, alpha)
    part = part_labels.to(idx.device)[idx]  # (B, N)
    origin = torch.gather(joints[:, :N_PARTS], 1, part[..., None].expand(-1, -1, 3))  # (B, N, 3)
    rot = torch.gather(rotations, 1, part[..., None, None].expand(-1, -1, 3, 3))  # (B, N, 3, 3)
    local = (rot.transpose(-1, -2) @ (points - origin)[..., None])[..., 0]
    return PartContact(contact, part, _unit(local))


def directions_to_world(part: torch.Tensor, direction: torch.Tensor, rotations: torch.Tensor) -> torch.Tensor:
    """(B, N, 3) unit world directions of (B, N, 3) part-frame ``direction`` for (B, N) ``part`` labels of
    hands with (B, 16, 3, 3) global joint ``rotations``."""
    rot = torch.gather(rotations, 1, part[..., None, None].expand(-1, -1, 3, 3))
    return _unit((rot @ direction[..., None])[..., 0])


def thumb_signed(contact: torch.Tensor, points: torch.Tensor, vertices: torch.Tensor, part_labels: torch.Tensor
                 ) -> torch.Tensor:
    """(B, N) the contact map ``contact`` (B, N, in [0, 1]) of (B, N, 3) object points made negative where the
    nearest of the (B, V, 3) hand ``vertices`` belongs to the thumb (its ``part_labels`` (V,) one of the thumb's
    joints, as :func:`part_contact` assigns parts): the map with a two-part label, in [-1, 1]. A scalar map
    says where the hand touches, not with what: grasps of one object with much alike maps point different
    ways (docs/graspdiffuser.md), which the thumb's contact tells apart. No gradient."""
    with torch.no_grad():
        _, idx = nearest_vertex(points, vertices)
        thumb = torch.isin(part_labels, torch.as_tensor(FINGERS["thumb"], device=part_labels.device))
        return torch.where(thumb[idx], -contact, contact)


def thumb_signed_by(hand: HandModel, grasp: torch.Tensor, points: torch.Tensor, contact: torch.Tensor) -> torch.Tensor:
    """(B, N) the (B, N) maps ``contact`` of the (B, 51) grasps ``grasp`` on (B, N, 3) ``points``, signed by
    each grasp's thumb (:func:`thumb_signed`; the hands posed without gradient)."""
    with torch.no_grad():
        vertices = hand(grasp).vertices
    return thumb_signed(contact, points, vertices, hand.part_labels)
