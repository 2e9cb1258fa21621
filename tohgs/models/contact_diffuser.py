"""ContactDiffuser (paper section 4.2): a per-point diffusion over the task-aware contact map.

One token per object point carries the noisy contact value ``x = 2 c - 1``. PointNet++ on xyz with
(normal, D_init, D_goal) gives per-point local and global features; projected, they are added inside every
block as the positional embedding, with the timestep embedding. Each block is a residual MLP block followed
by a self-attention transformer layer over the points. The network predicts epsilon (the official code), or
the clean map x0 with ``diffusion.prediction: sample`` (the laptop default's components).

With ``local_k`` > 0 every block also mixes each point's token with its ``local_k`` nearest object points'
tokens (:class:`LocalMix`, the mean and the max of the neighbours' tokens less its own): a denoiser that sees
its neighbours' noisy values can keep contact in regions, where global attention alone, at the laptop's
width and depth, denoised nearly point by point (docs/history.md, issue 39). The official model gets its
local context from PointNet++ in every block; ``local_k: 0`` (config/paper.yaml) is that architecture.

With ``frame: canonical`` (beyond the official model) the points and normals enter in a frame computed
from the object and its two distance maps (:func:`tohgs.geometry.frames.scene_frame`), so the map does not
depend on how the input is turned: the SO(3) rotations of training leave its input unchanged.

Shapes: points (B, N, 3) m, normals (B, N, 3), d_init / d_goal / contact (B, N) in [0, 1].
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from tohgs.data.batch import Batch
from tohgs.geometry.frames import scene_frame
from tohgs.geometry.maps import ALPHA_DISTANCE
from tohgs.geometry.neighbours import nearest_neighbours
from tohgs.models.component import Component
from tohgs.models.diffusion import DiffusionConfig, NoiseSchedule, TimeMLP, sample
from tohgs.models.guidance import GuidanceSettings, contact_guidance_step, near_scene_weights
from tohgs.models.pointnet2 import PointNet2, PointNet2Config


FRAMES = ("network", "canonical")


@dataclass(frozen=True)
class ContactDiffuserConfig:
    """Sizes (paper: d_model 256, 8 blocks, 4 heads, PointNet++ 512 + 512). The official model has about
    16.9 M parameters; this one at config/paper.yaml's sizes has 12.7 M (a GELU feed-forward instead of
    GEGLU). ``local_k`` (0: the official architecture) adds :class:`LocalMix` to every block; the laptop
    default's components set 16 (workflow/schemas/config.schema.yaml)."""

    d_model: int = 64
    n_blocks: int = 2
    n_heads: int = 4
    ff_mult: int = 2
    dropout: float = 0.0
    local_k: int = 0
    frame: str = "canonical"  # points and normals in the scene frame of the inputs; "network": as given
    pointnet: dict = field(default_factory=lambda: {
        "sa": [[128, 0.02, 16, [32, 32, 64]], [32, 0.05, 16, [64, 64, 128]], [0, 0.0, 0, [128, 128]]],
        "fp": [[128], [96], [64]]})
    diffusion: dict = field(default_factory=lambda: asdict(DiffusionConfig(beta_end=0.02, prediction="epsilon")))

    def __post_init__(self):
        if self.frame not in FRAMES:
            raise ValueError(f"ContactDiffuser frame must be one of {FRAMES}, not {self.frame!r}")

    @staticmethod
    def from_dict(d: dict) -> "ContactDiffuserConfig":
        return ContactDiffuserConfig(**d)


class ResBlock(nn.Module):
    """LayerNorm -> Linear -> GELU -> Linear with a residual connection, after adding the conditioning."""

    def __init__(self, d: int, mult: int, dropout: float):
        super().__init__()
        self.net = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, mult * d), nn.GELU(), nn.Dropout(dropout),
                                 nn.Linear(mult * d, d))

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        return x + self.net(x + cond)


class LocalMix(nn.Module):
    """A residual update of each point's token from its k nearest points' tokens: LayerNorm, then the
    neighbours' mean and max less the point's own token, through Linear -> GELU -> Linear."""

    def __init__(self, d: int):
        super().__init__()
        self.norm = nn.LayerNorm(d)
        self.net = nn.Sequential(nn.Linear(2 * d, d), nn.GELU(), nn.Linear(d, d))

    def forward(self, h: torch.Tensor, neighbours: torch.Tensor) -> torch.Tensor:
        """(B, N, d) tokens and (B, N, k) neighbour indices -> (B, N, d)."""
        x = self.norm(h)
        mean, top = neighbour_mean_max(x, neighbours)
        return h + self.net(torch.cat([mean - x, top - x], -1))


def neighbour_mean_max(x: torch.Tensor, neighbours: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The mean and the maximum of (B, N, d) features over each point's (B, N, k) neighbours, each (B, N, d).

    Never gathers (B, N, k, d) and reduces over k: the reduction over a middle axis of a large gathered tensor
    dominated every denoising step. Without autograd (sampling) it takes one neighbour at a time (k gathers of
    (B, N, d), in place): 6-7x faster than the gathered reduction on a CPU at the default's sizes. With
    autograd (training) it is two ``embedding_bag`` calls over the flattened tokens: the same values bit for
    bit, and a backward pass that scatters into the tokens once per call instead of differentiating k
    gathers, k additions and k elementwise maxima (3x faster forward and backward at the default's sizes;
    the gradients equal to rounding, summed in another order). A tie between neighbours sends the maximum's
    gradient to one of them (the elementwise maxima split it)."""
    b, n, d = x.shape
    k = neighbours.shape[-1]
    flat = x.reshape(b * n, d)
    rows = (neighbours + (torch.arange(b, device=x.device) * n)[:, None, None]).reshape(b * n, k)
    if torch.is_grad_enabled() and x.requires_grad:
        mean = nn.functional.embedding_bag(rows, flat, mode="mean")
        top = nn.functional.embedding_bag(rows, flat, mode="max")
        return mean.reshape(b, n, d), top.reshape(b, n, d)
    total = flat[rows[:, 0]].clone()
    top = total.clone()
    for j in range(1, k):
        v = flat[rows[:, j]]
        total += v
        torch.maximum(top, v, out=top)
    return (total / k).reshape(b, n, d), top.reshape(b, n, d)


class PointAttention(nn.TransformerEncoderLayer):
    """:class:`torch.nn.TransformerEncoderLayer` (batch first, pre-norm) over the points, its self-attention
    computed batch first: one projection of (B, N, d) tokens to queries, keys and values, viewed as (B, heads,
    N, d / heads) for ``scaled_dot_product_attention``. The same parameters (a checkpoint of either loads into
    the other) and the same numbers bit for bit, forward and backward; torch's own layer transposes the
    tokens to (N, B, d) and copies the packed projection apart in both directions (the backward's copies were
    a seventh of a ContactDiffuser training step at the default's sizes), and its inference fast path
    materialises the (N, N) attention (:func:`tohgs.methods.predict.predict` turns it off). No masks:
    every point attends to every point."""

    def __init__(self, d: int, heads: int, ff: int, dropout: float):
        super().__init__(d, heads, ff, dropout, activation="gelu", batch_first=True, norm_first=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, N, d) tokens -> (B, N, d): self-attention, then the feed-forward, each after its LayerNorm and
        added to its input."""
        x = x + self._sa_block(self.norm1(x), None, None)
        return x + self._ff_block(self.norm2(x))

    def _sa_block(self, x: torch.Tensor, attn_mask: None, key_padding_mask: None, is_causal: bool = False) -> torch.Tensor:
        a = self.self_attn
        b, n, d = x.shape
        heads = a.num_heads
        qkv = nn.functional.linear(x, a.in_proj_weight, a.in_proj_bias).view(b, n, 3, heads, d // heads)
        q, k, v = qkv.permute(2, 0, 3, 1, 4).unbind(0)  # each (B, heads, N, d / heads)
        out = nn.functional.scaled_dot_product_attention(q, k, v, dropout_p=a.dropout if self.training else 0.0)
        out = nn.functional.linear(out.transpose(1, 2).reshape(b, n, d), a.out_proj.weight, a.out_proj.bias)
        return self.dropout1(out)


@dataclass(frozen=True)
class ContactCondition:
    """What the network reads of one batch of scene-aware object clouds (B of them, N points).

    Attributes:
        embedding: (B, N, d_model) the positional embedding added inside every block.
        neighbours: (B, N, k) each point's k nearest points (itself excluded), or None (``local_k`` 0).
    """

    embedding: torch.Tensor
    neighbours: torch.Tensor | None


class ContactDiffuser(Component):
    """Denoising network over per-point contact values (a contact source: :meth:`sample_contact`)."""

    kind = "contact_diffuser"
    Config = ContactDiffuserConfig
    role = "contact"
    steerable = True

    def __init__(self, cfg: ContactDiffuserConfig):
        super().__init__()
        self.cfg = cfg
        self.diffusion = DiffusionConfig(**cfg.diffusion)
        self.schedule = NoiseSchedule(self.diffusion)
        pcfg = PointNet2Config.from_dict({**cfg.pointnet, "in_channels": 5})
        self.backbone = PointNet2(pcfg)
        d = cfg.d_model
        self.pos = nn.Linear(self.backbone.local_dim + self.backbone.global_dim, d)
        self.time = TimeMLP(d)
        self.inp = nn.Linear(1, d)
        self.res = nn.ModuleList([ResBlock(d, cfg.ff_mult, cfg.dropout) for _ in range(cfg.n_blocks)])
        self.attn = nn.ModuleList([PointAttention(d, cfg.n_heads, cfg.ff_mult * d, cfg.dropout) for _ in range(cfg.n_blocks)])
        self.local = nn.ModuleList([LocalMix(d) for _ in range(cfg.n_blocks)]) if cfg.local_k > 0 else None
        self.out = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, 1))

    def condition(self, points: torch.Tensor, normals: torch.Tensor, d_init: torch.Tensor, d_goal: torch.Tensor
                  ) -> ContactCondition:
        """The :class:`ContactCondition` of the scene-aware object cloud (computed once per sample). With
        ``frame: canonical`` the points and normals are first expressed in
        :func:`tohgs.geometry.frames.scene_frame` (from the object and its two distance maps), so that a
        turned input gives the same map."""
        if self.cfg.frame == "canonical":
            rot, origin = scene_frame(points, d_init, d_goal)
            points, normals = (points - origin[:, None]) @ rot, normals @ rot
        feats = torch.cat([normals, d_init[..., None], d_goal[..., None]], -1)
        local, glob = self.backbone(points, feats)
        emb = self.pos(torch.cat([local, glob[:, None].expand(-1, local.shape[1], -1)], -1))
        k = min(self.cfg.local_k, points.shape[1] - 1)
        return ContactCondition(emb, nearest_neighbours(points, k) if self.local is not None and k > 0 else None)

    def forward(self, x_t: torch.Tensor, t: torch.Tensor, cond: ContactCondition) -> torch.Tensor:
        """Predict epsilon, or x0 (B, N) (``diffusion.prediction``), from noisy contact values ``x_t`` (B, N),
        timesteps (B,) and the :meth:`condition`."""
        c = cond.embedding + self.time(t)[:, None]
        h = self.inp(x_t[..., None])
        for i, (res, attn) in enumerate(zip(self.res, self.attn)):
            h = res(h, c)
            if cond.neighbours is not None:
                h = self.local[i](h, cond.neighbours)
            h = attn(h + c)
        return self.out(h)[..., 0]

    def batch_condition(self, batch: Batch) -> ContactCondition:
        """:meth:`condition` of a batch's object cloud and distance maps."""
        return self.condition(batch.points, batch.normals, batch.d_init, batch.d_goal)

    def loss(self, batch: Batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The denoising loss: the mean squared error of the network's target (the noise for ``epsilon``, the
        clean map ``2 c - 1`` for ``sample``) at a uniform timestep per sample."""
        dev = batch.device
        t = torch.randint(0, self.schedule.timesteps, (batch.size,), generator=generator).to(dev)
        x0 = 2 * batch.contact - 1
        noise = torch.randn(x0.shape, generator=generator).to(dev)
        x_t = self.schedule.q_sample(x0, noise, t)
        target = noise if self.diffusion.prediction == "epsilon" else x0
        return {"loss": nn.functional.mse_loss(self(x_t, t, self.batch_condition(batch)), target)}

    @torch.no_grad()
    def sample_contact(self, batch: Batch, sampler: str, steps: int, generator: torch.Generator,
                       steer: GuidanceSettings | None = None, distance_alpha: float = ALPHA_DISTANCE) -> torch.Tensor:
        """(B, N) contact maps in [0, 1] for the batch's scenes (one reverse process per sample); with a
        ``steer`` whose ``contact_scale`` is positive, each guided step's x0 moves contact off the object
        points near the scene at either pose (:func:`tohgs.models.guidance.contact_guidance_step`; the distance
        maps' ``distance_alpha``, 1/m, says how near)."""
        cond = self.batch_condition(batch)
        guide = None
        if steer is not None and steer.contact_active:
            guide = contact_guidance_step(near_scene_weights(batch.d_init, batch.d_goal, steer.near, distance_alpha), steer,
                                          self.schedule.timesteps)
        x = sample(lambda xt, tt: self(xt, tt, cond), tuple(batch.points.shape[:2]), self.diffusion, sampler, steps,
                   generator, batch.device, guide)
        return (x.clamp(-1, 1) + 1) / 2


COMPONENT = ContactDiffuser
