"""The hand model every backend shares: MANO-layout linear blend skinning in torch.

A backend (``anny``, ``mano``) only produces :class:`HandAssets`, arrays in MANO's canonical frame; one
:class:`HandModel` turns them into a batched, differentiable forward pass on any device:

``forward(pose (B, 51), betas (B, 10) or None) -> HandOutput(vertices (B, V, 3), joints (B, 21, 3), rotations
(B, 16, 3, 3))``, metres.

The kinematics are MANO's: rest joints with world-aligned frames; joint ``k``'s global transform is
``G_k = G_parent(k) [R_k | J_k - J_parent(k)]`` with ``G_0 = [R_0 | J_0]`` (so the global rotation turns
the hand about the rest wrist joint), vertices are skinned with ``sum_k w_vk G_k [I | -J_k]``, and the
translation is added last (it moves every vertex by exactly itself).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from tohgs.hand.assets import LEVELS as _LEVELS
from tohgs.hand.assets import HandAssets
from tohgs.hand.layout import GRASP_DIM, N_BETAS, N_JOINTS, PARENTS
from tohgs.hand.rotations import axis_angle_to_matrix

__all__ = ["HandAssets", "HandModel", "HandOutput"]


def _chain() -> list[tuple[list[int], list[int] | None]]:
    """Per level below the wrist: its joints, and the positions of their parents in the previous level
    (None where the parents are that level, in order)."""
    out = []
    for prev, level in zip(_LEVELS[:-1], _LEVELS[1:]):
        pidx = [prev.index(PARENTS[k]) for k in level]
        out.append((list(level), None if pidx == list(range(len(prev))) else pidx))
    return out


_CHAIN = _chain()
_LEVEL_ORDER_INV = np.argsort(np.concatenate(_LEVELS)).tolist()  # level order -> joint order


@dataclass
class HandOutput:
    """Result of :meth:`HandModel.forward`.

    Attributes:
        vertices: (B, V, 3) metres. Without betas and pose blend shapes, a transposed view of a contiguous
            (B, 3, V) tensor: ``vertices.transpose(1, 2)`` is free, and per-coordinate work streams.
        joints: (B, 21, 3) metres: the 16 joints in MANO order, then the 5 fingertips
            (thumb, index, middle, ring, pinky).
        rotations: (B, 16, 3, 3) each joint's global rotation (its frame's axes in world coordinates;
            the rest frames are world-aligned): joint ``k``'s frame is ``(rotations[:, k], joints[:, k])``,
            the frame ContactGen's part directions are expressed in.
    """

    vertices: torch.Tensor
    joints: torch.Tensor
    rotations: torch.Tensor


class HandModel(torch.nn.Module):
    """MANO-layout hand: linear blend skinning over :class:`HandAssets`, batched and differentiable.

    Buffers move with ``.to(device)``; computations run in the buffers' dtype (float32 by default).
    """

    def __init__(self, assets: HandAssets, dtype: torch.dtype = torch.float32) -> None:
        super().__init__()
        assets.validate(assets.name)
        self.assets = assets
        self.name = assets.name

        def buf(name: str, x: np.ndarray, dt: torch.dtype = dtype) -> None:
            self.register_buffer(name, torch.as_tensor(np.asarray(x), dtype=dt), persistent=False)

        buf("rest_vertices", assets.rest_vertices)
        buf("shape_dirs", assets.shape_dirs)
        buf("rest_joints", assets.rest_joints)
        buf("joint_shape_dirs", assets.joint_shape_dirs)
        buf("weights", assets.weights)
        if assets.pose_dirs is not None:
            buf("pose_dirs", assets.pose_dirs.reshape(-1, 135).T)  # (135, V*3)
        else:
            self.pose_dirs = None
        buf("faces", assets.faces, torch.long)
        buf("closed_faces", assets.closed_faces, torch.long)
        buf("part_labels", assets.part_labels, torch.long)
        buf("tip_ids", assets.tip_ids, torch.long)
        buf("contact_ids", assets.contact_ids, torch.long)
        buf("joint_limits", assets.joint_limits)
        buf("prior_mean", assets.prior_mean)
        buf("prior_std", assets.prior_std)
        # Fast path when every hand of a batch has the same rest shape (no betas, no pose blend shapes):
        # skinning becomes one GEMM, v[c, v] = sum_{k, j} A_k[c, j] (w_vk [v_rest | 1]_j) + trans[c] * 1,
        # computed coordinate-major, (B*3, 65) @ (65, V), so that the vertices are contiguous as
        # (B, 3, V): the layout that the optimiser's per-axis tests and gradients stream through.
        vh = torch.cat([self.rest_vertices, torch.ones_like(self.rest_vertices[:, :1])], 1)  # (V, 4)
        skin = (self.weights[:, :, None] * vh[:, None, :]).reshape(-1, 4 * N_JOINTS)  # (V, 64)
        skin_t = torch.cat([skin.T, torch.ones_like(skin[:, :1]).T])  # (65, V): last row for the translation
        self.register_buffer("skin_rest_t", skin_t.contiguous(), persistent=False)

    @staticmethod
    def _chain_offsets(j_rest: torch.Tensor) -> list[torch.Tensor]:
        """(B, n, 3) rest offsets of each level's joints from their parents."""
        return [j_rest[:, ks] - j_rest[:, [PARENTS[k] for k in ks]] for ks, _ in _CHAIN]

    @property
    def n_vertices(self) -> int:
        return int(self.rest_vertices.shape[0])

    def preset(self, name: str, batch: int = 1) -> torch.Tensor:
        """A named pose preset as a (batch, 51) tensor on the model's device."""
        if name not in self.assets.presets:
            raise KeyError(f"unknown pose preset '{name}'; known: {sorted(self.assets.presets)}")
        p = torch.as_tensor(self.assets.presets[name], dtype=self.rest_vertices.dtype, device=self.rest_vertices.device)
        return p.expand(batch, GRASP_DIM).clone()

    def shaped(self, betas: torch.Tensor | None, batch: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Rest vertices (B, V, 3) and joints (B, 16, 3) for ``betas`` (B, 10) (``None`` = zeros)."""
        if betas is None:
            return (self.rest_vertices.expand(batch, -1, -1), self.rest_joints.expand(batch, -1, -1))
        if betas.shape != (batch, N_BETAS):
            raise ValueError(f"betas must have shape ({batch}, {N_BETAS}), got {tuple(betas.shape)}")
        v = self.rest_vertices + torch.einsum("vcl,bl->bvc", self.shape_dirs, betas)
        j = self.rest_joints + torch.einsum("jcl,bl->bjc", self.joint_shape_dirs, betas)
        return v, j

    @property
    def linear_skinning(self) -> bool:
        """Whether the vertices of a hand without betas are linear in its :meth:`skinning_rows` (no pose blend
        shapes): ``vertices_t = rows @ skin_rest_t``, so any subset of vertices costs a GEMM of its size."""
        return self.pose_dirs is None

    def _kinematics(self, pose: torch.Tensor, betas: torch.Tensor | None
                    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """The shaped rest vertices (B, V, 3) (with pose blend shapes), the joints' global rotations
        (B, 16, 3, 3) and positions (B, 16, 3) (without the translation), and the skinning transforms
        ``[R | P - R J_rest]`` (B, 16, 3, 4) of (B, 51) poses; metres."""
        if pose.ndim != 2 or pose.shape[1] != GRASP_DIM:
            raise ValueError(f"pose must have shape (B, {GRASP_DIM}), got {tuple(pose.shape)}")
        pose = pose.to(self.rest_vertices.dtype)
        b = pose.shape[0]
        v_rest, j_rest = self.shaped(betas, b)
        rot = axis_angle_to_matrix(pose[:, 3:].reshape(b, N_JOINTS, 3))  # (B, 16, 3, 3)
        if self.pose_dirs is not None:
            eye = torch.eye(3, dtype=rot.dtype, device=rot.device)
            feat = (rot[:, 1:] - eye).reshape(b, 135)
            v_rest = v_rest + (feat @ self.pose_dirs).reshape(b, -1, 3)

        # Global rotations and joint positions, one tree level at a time (a level's joints are chained
        # onto the previous level's as whole (B, n, 3, 3) blocks), then back into joint order.
        r_lvl, p_lvl = rot[:, :1], j_rest[:, :1]
        rs, ps = [r_lvl], [p_lvl]
        for (ks, pidx), offset in zip(_CHAIN, self._chain_offsets(j_rest)):
            pr, pp = (r_lvl, p_lvl) if pidx is None else (r_lvl[:, pidx], p_lvl[:, pidx])
            r_lvl = pr @ rot[:, ks]
            p_lvl = pp + (pr @ offset[..., None])[..., 0]
            rs.append(r_lvl)
            ps.append(p_lvl)
        R = torch.cat(rs, 1)[:, _LEVEL_ORDER_INV]  # (B, 16, 3, 3)
        P = torch.cat(ps, 1)[:, _LEVEL_ORDER_INV]  # (B, 16, 3)
        # Skinning transforms [R | P - R J_rest], blended per vertex.
        t = P - (R @ j_rest[..., None])[..., 0]
        A = torch.cat([R, t[..., None]], -1)  # (B, 16, 3, 4)
        return v_rest, R, P, A

    @staticmethod
    def _rows(A: torch.Tensor, trans: torch.Tensor) -> torch.Tensor:
        """(B, 3, 65) skinning rows of (B, 16, 3, 4) transforms and (B, 1, 3) translations."""
        b = A.shape[0]
        return torch.cat([A.permute(0, 2, 1, 3).reshape(b, 3, 4 * N_JOINTS), trans.transpose(1, 2)], 2)

    def skinning_rows(self, pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The linear map from the rest hand to the posed one (only where :attr:`linear_skinning`).

        Args:
            pose: (B, 51) grasp vectors (as :meth:`forward`), no betas.

        Returns:
            rows (B, 3, 65): ``(rows.reshape(B * 3, 65) @ skin_rest_t).reshape(B, 3, V)`` is the posed
            vertices, coordinate-major, by the GEMM of :meth:`forward`; ``skin_rest_t[:, ids]`` gives a
            subset of them for a GEMM of its size. And the 16 joints (B, 16, 3), translated (the first 16 of
            :meth:`forward`'s joints). Metres; differentiable.
        """
        if not self.linear_skinning:
            raise ValueError(f"hand '{self.name}' has pose blend shapes: its vertices are not linear in skinning rows")
        _, _, P, A = self._kinematics(pose, None)
        trans = pose.to(self.rest_vertices.dtype)[:, None, :3]
        return self._rows(A, trans), P + trans

    def forward(self, pose: torch.Tensor, betas: torch.Tensor | None = None) -> HandOutput:
        """Pose the hand.

        Args:
            pose: (B, 51) grasp vectors: translation (3, m), global axis-angle (3, about the rest wrist
                joint), 15 finger joints x axis-angle (3) in MANO joint order, canonical-frame axes.
            betas: (B, 10) shape parameters, or ``None`` for the average hand.

        Returns:
            :class:`HandOutput` with vertices (B, V, 3) and joints (B, 21, 3), metres, and the joints'
            global rotations (B, 16, 3, 3).
        """
        v_rest, R, P, A = self._kinematics(pose, betas)
        pose = pose.to(self.rest_vertices.dtype)
        b = pose.shape[0]
        trans = pose[:, None, :3]
        if betas is None and self.pose_dirs is None:
            a2 = self._rows(A, trans)  # (B, 3, 65)
            verts_t = (a2.reshape(b * 3, -1) @ self.skin_rest_t).reshape(b, 3, -1)  # (B, 3, V)
            verts = verts_t.transpose(1, 2)  # (B, V, 3): a view, each coordinate contiguous
            tips = verts_t[:, :, self.tip_ids].transpose(1, 2)  # indexed in that layout: so is its gradient
        else:
            T = torch.matmul(self.weights, A.reshape(b, N_JOINTS, 12)).reshape(b, -1, 3, 4)  # (B, V, 3, 4)
            verts = (T[..., :3] * v_rest[:, :, None, :]).sum(-1) + T[..., 3] + trans
            tips = verts[:, self.tip_ids]
        joints = torch.cat([P + trans, tips], 1)
        return HandOutput(vertices=verts, joints=joints, rotations=R)
