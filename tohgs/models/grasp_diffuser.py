"""GraspDiffuser (paper section 4.3): diffusion over the 51-number grasp, conditioned on the object cloud
with its (predicted) contact map, with the hand model in the loss.

The grasp (normalised per dimension with the training set's mean and std) is one token; PointNet++ on xyz
with (normal, contact) gives a global feature, the only context, so attention reduces to an MLP with
additive conditioning: residual blocks with the condition and the timestep embedding added. The network
predicts x0. Losses (REFERENCE.md, official code):

``L = w_diff L_diff + w_recon min(L_recon, 1) + w_pen min(L_pen, 1) + w_cons L_cons``

- ``L_diff``: squared error of the normalised grasp, summed over its 51 numbers, mean over the batch;
- ``L_recon``: mean squared distance of the predicted hand's vertices to the true hand's, m^2;
- ``L_pen``: object points inside the predicted hand (behind their nearest hand vertex's normal),
  ``100 sum d^2 (1 + 3 (1 - c)) / B``, d the distance to that vertex (m), c the contact map;
- ``L_cons``: contact-map consistency ``sum (C'(pred hand) - C(true hand))^2 (1 + 5 C) / B``.
Weights (15, 1, 5, 0.002) for Placing and Shelving, (10, 1, 3, 0.005) for Stacking.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from tohgs.hand.model import HandModel
from tohgs.models.diffusion import DiffusionConfig, TimeMLP
from tohgs.models.pointnet2 import PointNet2, PointNet2Config

LOSS_WEIGHTS = {"placing": (15.0, 1.0, 5.0, 0.002), "shelving": (15.0, 1.0, 5.0, 0.002),
                "stacking": (10.0, 1.0, 3.0, 0.005)}


@dataclass(frozen=True)
class GraspDiffuserConfig:
    """Sizes (paper: d_model 512, 4 blocks, PointNet++ global 512). The official model has about 27.7 M
    parameters; this one at config/paper.yaml's sizes has 8.3 M (its blocks are plain residual MLPs with
    additive conditioning, which is what the official single-token attention reduces to)."""

    d_model: int = 128
    n_blocks: int = 3
    ff_mult: int = 2
    dropout: float = 0.0
    pointnet: dict = field(default_factory=lambda: {
        "sa": [[128, 0.02, 16, [32, 32, 64]], [32, 0.05, 16, [64, 64, 128]], [0, 0.0, 0, [128, 256]]],
        "fp": [[128], [96], [64]]})
    diffusion: dict = field(default_factory=lambda: asdict(DiffusionConfig(beta_end=0.01, prediction="sample", clip=0.0)))

    @staticmethod
    def from_dict(d: dict) -> "GraspDiffuserConfig":
        return GraspDiffuserConfig(**d)


class GraspDiffuser(nn.Module):
    """x0-prediction network over normalised grasps; holds the grasp normaliser as buffers."""

    def __init__(self, cfg: GraspDiffuserConfig):
        super().__init__()
        self.cfg = cfg
        self.diffusion = DiffusionConfig(**cfg.diffusion)
        self.backbone = PointNet2(PointNet2Config.from_dict({**cfg.pointnet, "in_channels": 4}))
        d = cfg.d_model
        self.cond = nn.Sequential(nn.Linear(self.backbone.global_dim, d), nn.SiLU(), nn.Linear(d, d))
        self.time = TimeMLP(d)
        self.inp = nn.Linear(51, d)
        self.blocks = nn.ModuleList([nn.Sequential(nn.LayerNorm(d), nn.Linear(d, cfg.ff_mult * d), nn.GELU(),
                                                   nn.Dropout(cfg.dropout), nn.Linear(cfg.ff_mult * d, d))
                                     for _ in range(cfg.n_blocks)])
        self.out = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, 51))
        self.register_buffer("grasp_mean", torch.zeros(51))
        self.register_buffer("grasp_std", torch.ones(51))

    def set_normaliser(self, grasps: torch.Tensor) -> None:
        """Per-dimension mean and std of (G, 51) training grasps (std floored at 1e-3; a single grasp has
        no spread, so its std is that floor, where the unbiased std would be NaN and poison training)."""
        if grasps.ndim != 2 or grasps.shape[0] == 0:
            raise ValueError(f"set_normaliser needs (G >= 1, 51) grasps, got {tuple(grasps.shape)}")
        self.grasp_mean.copy_(grasps.mean(0))
        std = grasps.std(0) if grasps.shape[0] > 1 else torch.zeros_like(grasps[0])
        self.grasp_std.copy_(std.clamp_min(1e-3))

    def normalise(self, g: torch.Tensor) -> torch.Tensor:
        return (g - self.grasp_mean) / self.grasp_std

    def denormalise(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.grasp_std + self.grasp_mean

    def condition(self, points: torch.Tensor, normals: torch.Tensor, contact: torch.Tensor) -> torch.Tensor:
        """(B, d_model) conditioning from the object cloud and its contact map."""
        _, glob = self.backbone(points, torch.cat([normals, contact[..., None]], -1))
        return self.cond(glob)

    def forward(self, x_t: torch.Tensor, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """Predict the normalised grasp x0 (B, 51) from ``x_t`` (B, 51), timesteps (B,) and the condition."""
        c = cond + self.time(t)
        h = self.inp(x_t)
        for block in self.blocks:
            h = h + block(h + c)
        return self.out(h)


def vertex_normals(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(B, V, 3) unit vertex normals (area-weighted face normals) of meshes (B, V, 3) with faces (F, 3)."""
    tri = verts[:, faces]  # (B, F, 3, 3)
    fn = torch.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0], dim=-1)
    vn = torch.zeros_like(verts)
    for k in range(3):
        vn = vn.index_add(1, faces[:, k], fn)
    return vn / vn.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def contact_values(points: torch.Tensor, hand_verts: torch.Tensor, alpha: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Normalised contact map (B, N) of points (B, N, 3) to hands (B, V, 3) and the nearest vertex (B, N)."""
    d = torch.cdist(points, hand_verts)
    dmin, idx = d.min(-1)
    return 1.0 - 2.0 * (torch.sigmoid(alpha * dmin) - 0.5), idx


def grasp_losses(model: GraspDiffuser, hand: HandModel, x0_hat: torch.Tensor, x0: torch.Tensor, points: torch.Tensor,
                 contact: torch.Tensor, alpha_contact: float) -> dict[str, torch.Tensor]:
    """The four loss terms (unweighted, unclamped) of predicted normalised grasps ``x0_hat`` (B, 51) against
    the truth ``x0``, on object points (B, N, 3) with their true contact map (B, N)."""
    b = x0.shape[0]
    l_diff = ((x0_hat - x0) ** 2).sum(-1).mean()
    pred_v = hand(model.denormalise(x0_hat)).vertices
    with torch.no_grad():
        true_v = hand(model.denormalise(x0)).vertices
    l_recon = ((pred_v - true_v) ** 2).sum(-1).mean()
    c_pred, idx = contact_values(points, pred_v, alpha_contact)
    nv = vertex_normals(pred_v, hand.closed_faces)
    near = torch.gather(pred_v, 1, idx[..., None].expand(-1, -1, 3))
    near_n = torch.gather(nv, 1, idx[..., None].expand(-1, -1, 3))
    offset = points - near
    inside = ((offset * near_n).sum(-1) < 0).float()
    l_pen = 100.0 * (inside * (offset**2).sum(-1) * (1 + 3 * (1 - contact))).sum() / b
    l_cons = ((c_pred - contact) ** 2 * (1 + 5 * contact)).sum() / b
    return {"diff": l_diff, "recon": l_recon, "pen": l_pen, "cons": l_cons}


def total_loss(terms: dict[str, torch.Tensor], weights: tuple[float, float, float, float]) -> torch.Tensor:
    """``w_diff L_diff + w_recon min(L_recon, 1) + w_pen min(L_pen, 1) + w_cons L_cons``."""
    w_diff, w_recon, w_pen, w_cons = weights
    return (w_diff * terms["diff"] + w_recon * terms["recon"].clamp(max=1.0) + w_pen * terms["pen"].clamp(max=1.0)
            + w_cons * terms["cons"])
