"""PointNet++ (single-scale grouping) in pure torch: no CUDA-only ops, so it runs on any device.

Set abstraction: farthest-point sampling of centres, ball query of neighbours, a shared MLP on the
neighbours' relative positions and features, max-pooled. Feature propagation: inverse-distance
interpolation from the 3 nearest coarse points, concatenated with the skip features, a shared MLP.

Shapes: ``xyz`` (B, N, 3) metres, features (B, N, C) (channels last throughout).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import nn

from tohgs.models import layers


def farthest_point_sample(xyz: torch.Tensor, npoint: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """(B, npoint) indices of farthest-point samples of (B, N, 3) points; the first index is random when a
    generator is given, else 0 (deterministic)."""
    b, n, _ = xyz.shape
    idx = torch.zeros(b, npoint, dtype=torch.long, device=xyz.device)
    dist = torch.full((b, n), float("inf"), device=xyz.device, dtype=xyz.dtype)
    if generator is None:
        far = torch.zeros(b, dtype=torch.long, device=xyz.device)
    else:
        far = torch.randint(0, n, (b,), generator=generator).to(xyz.device)
    ar = torch.arange(b, device=xyz.device)
    for i in range(npoint):
        idx[:, i] = far
        centre = xyz[ar, far][:, None, :]
        dist = torch.minimum(dist, ((xyz - centre) ** 2).sum(-1))
        far = dist.argmax(-1)
    return idx


def gather(points: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """Rows of (B, N, C) ``points`` at (B, ...) indices -> (B, ..., C)."""
    b = points.shape[0]
    flat = idx.reshape(b, -1)
    out = torch.gather(points, 1, flat[..., None].expand(-1, -1, points.shape[-1]))
    return out.reshape(*idx.shape, points.shape[-1])


def ball_query(radius: float, nsample: int, xyz: torch.Tensor, centres: torch.Tensor) -> torch.Tensor:
    """(B, S, nsample) indices of up to ``nsample`` points of (B, N, 3) ``xyz`` within ``radius`` of each of
    (B, S, 3) ``centres`` (the nearest-indexed first; short lists repeat their first entry; a centre with
    no neighbour gets its nearest point)."""
    b, n, _ = xyz.shape
    d2 = torch.cdist(centres, xyz) ** 2  # (B, S, N)
    idx = torch.where(d2 > radius**2, n, torch.arange(n, device=xyz.device))
    # the nsample smallest indices in order: a partial selection, 2-3x cheaper than sorting all N
    idx = idx.topk(min(nsample, n), -1, largest=False, sorted=True).values
    first = idx[..., :1].clone()
    empty = first == n
    if empty.any():
        first[empty] = d2.argmin(-1, keepdim=True)[empty]
    idx = torch.where(idx == n, first.expand_as(idx), idx)
    return idx


class SetAbstraction(nn.Module):
    """Sample ``npoint`` centres, group ``nsample`` neighbours within ``radius``, shared MLP, max-pool.
    ``npoint = 0`` groups everything into one global feature."""

    def __init__(self, npoint: int, radius: float, nsample: int, in_channels: int, mlp: list[int]):
        super().__init__()
        self.npoint, self.radius, self.nsample = npoint, radius, nsample
        self.mlp = layers.mlp([in_channels + 3, *mlp], last_plain=False)

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor | None, ordered: bool = False
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, N, 3), (B, N, C) -> centres (B, S, 3), features (B, S, mlp[-1]).

        ``ordered``: the points are already in farthest-point order from their first (a previous level's
        centres), so the centres are their first ``npoint`` (farthest-point sampling from index 0 of a prefix
        of a farthest-point order gives that prefix back: each next point was the farthest of the whole
        cloud, so also of the prefix; the orders agree unless two distances tie exactly) and the sequential
        sampling loop is skipped."""
        if self.npoint == 0:
            centre = xyz.mean(1, keepdim=True)
            grouped = (xyz - centre)[:, None]
            if feats is not None:
                grouped = torch.cat([grouped, feats[:, None]], -1)
            return centre, self.mlp(grouped).max(2).values
        if ordered and self.npoint <= xyz.shape[1]:
            centres = xyz[:, : self.npoint]
        else:
            centres = gather(xyz, farthest_point_sample(xyz.detach(), self.npoint))
        idx = ball_query(self.radius, self.nsample, xyz.detach(), centres.detach())
        grouped = gather(xyz, idx) - centres[:, :, None]  # (B, S, K, 3)
        if feats is not None:
            grouped = torch.cat([grouped, gather(feats, idx)], -1)
        return centres, self.mlp(grouped).max(2).values


class FeaturePropagation(nn.Module):
    """Interpolate coarse features to fine points (inverse distance, 3 nearest), concat skip, MLP."""

    def __init__(self, in_channels: int, mlp: list[int]):
        super().__init__()
        self.mlp = layers.mlp([in_channels, *mlp], last_plain=False)

    def forward(self, xyz_fine: torch.Tensor, xyz_coarse: torch.Tensor, feats_fine: torch.Tensor | None,
                feats_coarse: torch.Tensor) -> torch.Tensor:
        if xyz_coarse.shape[1] == 1:
            interp = feats_coarse.expand(-1, xyz_fine.shape[1], -1)
        else:
            d = torch.cdist(xyz_fine, xyz_coarse)
            k = min(3, xyz_coarse.shape[1])
            dist, idx = d.topk(k, dim=-1, largest=False)
            w = 1.0 / (dist + 1e-8)
            w = w / w.sum(-1, keepdim=True)
            interp = (gather(feats_coarse, idx) * w[..., None]).sum(2)
        x = interp if feats_fine is None else torch.cat([feats_fine, interp], -1)
        return self.mlp(x)


@dataclass(frozen=True)
class PointNet2Config:
    """Sizes: per set-abstraction level (npoint, radius m, nsample, mlp widths); the last level is
    global (npoint 0). ``fp`` widths per propagation level (coarse to fine)."""

    in_channels: int = 4
    sa: tuple = ((128, 0.02, 16, (32, 32, 64)), (32, 0.05, 16, (64, 64, 128)), (0, 0.0, 0, (128, 256)))
    fp: tuple = ((128,), (128,), (128, 128))
    local_dim: int = field(default=128)

    @staticmethod
    def from_dict(d: dict) -> "PointNet2Config":
        return PointNet2Config(in_channels=int(d.get("in_channels", 4)),
                               sa=tuple((int(a), float(r), int(k), tuple(m)) for a, r, k, m in d["sa"]),
                               fp=tuple(tuple(m) for m in d["fp"]), local_dim=int(d["fp"][-1][-1]))


class PointNet2(nn.Module):
    """PointNet++ SSG backbone: per-point local features (B, N, fp[-1][-1]) and a global feature
    (B, sa[-1].mlp[-1]) of (B, N, 3) points with (B, N, in_channels) features."""

    def __init__(self, cfg: PointNet2Config):
        super().__init__()
        self.cfg = cfg
        chans = [cfg.in_channels]
        self.sa = nn.ModuleList()
        for npoint, radius, nsample, mlp in cfg.sa:
            self.sa.append(SetAbstraction(npoint, radius, nsample, chans[-1], list(mlp)))
            chans.append(mlp[-1])
        if len(cfg.fp) != len(cfg.sa):
            raise ValueError("PointNet2Config: one feature-propagation level per set-abstraction level")
        self.fp = nn.ModuleList()
        coarse = chans[-1]
        for level, mlp in enumerate(cfg.fp):
            skip = chans[len(cfg.sa) - 1 - level]
            self.fp.append(FeaturePropagation(coarse + skip, list(mlp)))
            coarse = mlp[-1]
        self.global_dim = chans[-1]
        self.local_dim = coarse

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        xyzs, fs = [xyz], [feats]
        for level, sa in enumerate(self.sa):  # a level after a sampled one reads centres in farthest-point order
            x, f = sa(xyzs[-1], fs[-1], ordered=level > 0 and self.sa[level - 1].npoint > 0)
            xyzs.append(x)
            fs.append(f)
        global_feat = fs[-1][:, 0]
        f = fs[-1]
        for level, fp in enumerate(self.fp):
            fine = len(self.sa) - 1 - level
            f = fp(xyzs[fine], xyzs[fine + 1], fs[fine], f)
        return f, global_feat


class PointNet(nn.Module):
    """PointNet without grouping: a shared per-point MLP and a max-pool, the cheap encoder (about a tenth
    of PointNet++'s multiply-adds at the default sizes). Returns per-point features (B, N, mlp[-1]) and the
    pooled feature (B, mlp[-1]) of (B, N, 3) points with (B, N, in_channels) features, as
    :class:`PointNet2` does."""

    def __init__(self, in_channels: int, mlp: list[int]):
        super().__init__()
        self.mlp = layers.mlp([in_channels + 3, *mlp], last_plain=False)
        self.local_dim = self.global_dim = mlp[-1]

    def forward(self, xyz: torch.Tensor, feats: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        local = self.mlp(torch.cat([xyz, feats], -1))
        return local, local.max(1).values
