"""The typed batch every component and method reads: a configuration's object, its scene and its maps.

One :class:`Batch` holds B samples (training grasps, or S copies of one test configuration), every
coordinate in the network frame (:mod:`tohgs.data.maps`: the object cloud's centroid at the initial pose
is the origin, z up), in metres, as float32 tensors on one device:

==============  ===========  =================================================================
field           shape        meaning
==============  ===========  =================================================================
points          (B, N, 3)    object surface points at the initial pose, m
normals         (B, N, 3)    their outward unit normals
d_init, d_goal  (B, N)       distance maps (alpha 30) to the initial / goal scene, in [0, 1]
scene           (B, Ns, 3)   scene cloud (support, obstacles, base; never the target), m
scene_normals   (B, Ns, 3)   the scene points' outward unit normals
goal_transform  (B, 4, 4)    ``T_goal T_init^-1`` in the network frame (carries the target)
contact         (B, N)       contact map (alpha 100) of the grasp's hand, in [0, 1]; or None
grasp           (B, 51)      the grasp at the initial pose (:data:`tohgs.hand.layout.GRASP_DIM`); or None
==============  ===========  =================================================================

The scene cloud is the same at the initial and the goal pose (the obstacles do not move);
:meth:`Batch.scene_init` and :meth:`Batch.scene_goal` add the target's points where it stands. Test
batches carry no grasp (and ``contact`` only where a method supplies one). Items come from
:class:`tohgs.data.maps.MapDataset`; :meth:`Batch.collate` stacks them.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
import torch

_POINT_FIELDS = ("points", "normals", "d_init", "d_goal", "contact")  # per object point: a point subset applies


@dataclass(frozen=True)
class Batch:
    """B samples of the network's inputs and targets (shapes in the module table)."""

    points: torch.Tensor
    normals: torch.Tensor
    d_init: torch.Tensor
    d_goal: torch.Tensor
    scene: torch.Tensor
    scene_normals: torch.Tensor
    goal_transform: torch.Tensor
    contact: torch.Tensor | None = None
    grasp: torch.Tensor | None = None

    @property
    def size(self) -> int:
        """B, the number of samples."""
        return self.points.shape[0]

    @property
    def device(self) -> torch.device:
        return self.points.device

    @staticmethod
    def collate(items: list[dict[str, Any]], device: torch.device | str = "cpu", keep: np.ndarray | None = None) -> "Batch":
        """Stack :class:`~tohgs.data.maps.MapDataset` items; ``keep`` (an index array) selects a subset of
        the object points, the same for the whole batch (the scene cloud is kept whole)."""
        out: dict[str, torch.Tensor | None] = {}
        for f in fields(Batch):
            if f.name not in items[0]:
                out[f.name] = None
                continue
            a = np.stack([it[f.name] for it in items])
            if keep is not None and f.name in _POINT_FIELDS:
                a = a[:, keep]
            out[f.name] = torch.as_tensor(a, dtype=torch.float32, device=device)
        missing = [f.name for f in fields(Batch) if f.default is not None and out[f.name] is None]
        if missing:
            raise ValueError(f"a batch needs {missing}; the items have {sorted(items[0])}")
        return Batch(**out)

    def repeat(self, n: int) -> "Batch":
        """A batch of one sample repeated ``n`` times (expanded views, no copies)."""
        if self.size != 1:
            raise ValueError(f"repeat needs a batch of one sample, not {self.size}")
        return replace(self, **{f.name: v.expand(n, *v.shape[1:]) for f in fields(self)
                                if (v := getattr(self, f.name)) is not None})

    def with_contact(self, contact: torch.Tensor) -> "Batch":
        """The batch with (B, N) contact maps (a contact source's output)."""
        if contact.shape != self.points.shape[:2]:
            raise ValueError(f"contact maps of shape {tuple(contact.shape)} for points {tuple(self.points.shape)}")
        return replace(self, contact=contact.to(self.points))

    def index(self, idx: torch.Tensor) -> "Batch":
        """The samples ``idx`` (a (B',) index tensor) of the batch."""
        return replace(self, **{f.name: v[idx] for f in fields(self) if (v := getattr(self, f.name)) is not None})

    def object_at_goal(self) -> torch.Tensor:
        """(B, N, 3) the object points carried to the goal pose, m."""
        T = self.goal_transform
        return self.points @ T[:, :3, :3].transpose(-1, -2) + T[:, None, :3, 3]

    def scene_init(self) -> torch.Tensor:
        """(B, Ns + N, 3) the initial scene: the scene cloud and the target at its initial pose, m."""
        return torch.cat([self.scene, self.points], 1)

    def scene_goal(self) -> torch.Tensor:
        """(B, Ns + N, 3) the goal scene: the scene cloud and the target at its goal pose, m."""
        return torch.cat([self.scene, self.object_at_goal()], 1)

    def normals_at_goal(self) -> torch.Tensor:
        """(B, N, 3) the object normals turned to the goal pose."""
        return self.normals @ self.goal_transform[:, :3, :3].transpose(-1, -2)
