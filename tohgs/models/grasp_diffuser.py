"""GraspDiffuser (paper section 4.3): diffusion over the 51-number grasp, conditioned on the object cloud
with its (predicted) contact map, with the hand model in the loss.

The grasp (normalised per dimension with the training set's mean and std, as the network sees it) is one
token. The object encoder (``encoder``) is PointNet++ (``"pointnet2"``, the paper's) or a shared
per-point MLP with a max-pool (``"pointnet"``, the default: about a tenth of the cost and as good here) on
xyz with (normal, contact). Two ways of reading the condition (``context``):

- ``"global"`` (the official model): the pooled feature is the only context, so attention reduces to an
  MLP with additive conditioning.
- ``"tokens"`` (the default, as SceneDiffuser and the paper's own description): the same pooled feature
  plus cross-attention from the grasp token to the per-point features, so the network can read *where*
  the contact is instead of a summary of it. With ``contact_features`` the contact region's moments
  (:func:`contact_moments`) are added to the pooled feature.

Three frames the grasp is expressed in (``frame``):

- ``"network"``: the map shards' frame (object cloud centred at the origin, z up).
- ``"contact"``: a frame derived from the contact map itself: the origin at the contact-weighted centroid
  of the object points and the x axis turned (about z, so up stays up) towards the horizontal direction
  from the object's centre to that centroid. Points, normals and the grasp are expressed in it, so the
  network learns the hand's pose *relative to where it touches*, a residual, instead of the absolute pose;
  an upright rotation of the input does not change what the network sees, any other does.
- ``"canonical"``: the same idea with all three axes from the inputs
  (:func:`tohgs.geometry.frames.contact_frame_3d`: x from the object towards the contact, y along the
  contact region), so that *any* rotation of the input leaves what the network sees unchanged and turns
  the sampled hand with it: under the paper's SO(3)-augmented training the network need not learn
  orientation invariance from data. Its origin (``origin``) is the contact-weighted centroid or the
  object point nearest to it.

What the network denoises (``representation``): the 51 numbers themselves (``"axis_angle"``, the paper's)
or ``"palm_rot6d"``: the palm centre's position (3), the global rotation's first two columns (6, the
continuous 6D representation of Zhou et al.) and the 45 finger numbers. The MANO translation places the
*wrist*, 8-10 cm from where the hand touches, so it moves with the rotation; the palm centre sits at the
contact and does not, and an axis-angle jumps where the angle nears pi. The decoder turns the 54 numbers
back into the 51 (Gram-Schmidt, then the wrist translation).

With ``skip`` (off by default) the network's x0 estimate is ``sqrt(a_t) x_t + sqrt(1 - a_t) F(x_t, t, c)``
(a_t = alpha-bar), the minimum-variance estimate for unit-variance data plus a learnt residual of unit
scale: exact at t = 0, where a plain x0 network has to learn the identity (the v-parameterisation,
``F = -v``). Measured, it made the samples overdispersed (diversity 157 against the data's 104, TS 0.28
against 0.46 without it; docs/graspdiffuser.md), so the default is the official plain x0 network.

Losses (REFERENCE.md, official code), per sample then averaged over the batch:

``L = w_diff L_diff + w_recon mean_b min(L_recon, r) + w_pen mean_b min(L_pen, 1) + w_cons mean_b L_cons``

(r, ``recon_clamp``: the official code's 1 by default, reached at a 3.6 cm RMS vertex error, beyond which a
sample's L_recon gives no gradient; 0 leaves it unclamped)

- ``L_diff``: squared error of the normalised vector, summed over its numbers (``diff_units: normalised``),
  or of the vector in its own units, m and rad (``official``: the official code's sum-MSE of the raw numbers,
  the units its loss weights were set for; the normalised error weighs the palm's position about 900x and
  the fingers about 80x more against the hand terms);
- ``L_recon``: squared distance of the predicted hand's vertices to the true hand's, summed over the
  vertices (m^2), as the official code;
- ``L_pen``: object points inside the predicted hand (behind their nearest hand vertex's normal),
  ``100 sum d^2 (1 + 3 (1 - c))``, d the distance to that vertex (m), c the contact map;
- ``L_cons``: contact-map consistency ``sum (C'(pred hand) - C(true hand))^2 (1 + 5 C)``.

The two point sums are scaled to the paper's 2048 points (``sum x (2048 / N)``), so that the paper's weights
mean the same with any number of training points. The clamps act per sample: a batch with one far-off hand
keeps the gradient of the others (clamping the batch mean, as the official code, zeroed it for whole runs).
Weights (15, 1, 5, 0.002) for Placing and Shelving, (10, 1, 3, 0.005) for Stacking.

With ``thumb_sign`` (beyond the paper; off by default) the contact channel the network reads is signed: negative
where the hand's nearest vertex is the thumb's (:func:`tohgs.geometry.contact_parts.thumb_signed`). The frame,
the contact moments and the losses read its absolute value, the paper's map; training signs each map from its
own grasp, and sampling expects signed maps (given by the ground truth's grasps: ``contact: ground_truth``).

With ``contact_input`` false the network reads the object alone (xyz and normals, no contact channel, the
network frame, no contact moments): SceneDiffuser's object-only grasp diffusion (Huang et al. CVPR 2023, as
the paper re-implements it: the same auxiliary losses, which still compare the predicted hand with the true
hand's map at training time, and no optimisation at inference). It samples grasps without a map.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from tohgs.data.batch import Batch
from tohgs.geometry.contact_parts import thumb_signed_by
from tohgs.geometry.frames import contact_frame_3d
from tohgs.geometry.rot6d import grasp_from_palm_rot6d, palm_rot6d
from tohgs.hand.layout import GRASP_DIM
from tohgs.hand.model import HandModel
from tohgs.hand.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from tohgs.models.component import Component, seen_grasps
from tohgs.models.diffusion import DiffusionConfig, NoiseSchedule, TimeMLP, sample
from tohgs.models.guidance import GuidanceEnergy, GuidanceSettings, guidance_step
from tohgs.models.hand_object_loss import hand_object_terms, weighted_pen_cons
from tohgs.models.pointnet2 import PointNet, PointNet2, PointNet2Config

LOSS_WEIGHTS = {"placing": (15.0, 1.0, 5.0, 0.002), "shelving": (15.0, 1.0, 5.0, 0.002),
                "stacking": (10.0, 1.0, 3.0, 0.005)}
CONTEXTS = ("global", "tokens")
FRAMES = ("network", "contact", "canonical")
ORIGINS = ("centroid", "surface")
DIFF_UNITS = ("normalised", "official")
ENCODERS = ("pointnet2", "pointnet")
REPRESENTATIONS = ("axis_angle", "palm_rot6d")
N_CONTACT_FEATURES = 10  # weighted mean normal (3), second moments of the points (6), log contact mass (1)


@dataclass(frozen=True)
class GraspDiffuserConfig:
    """Sizes and the three choices of the module docstring. The official model (``context="global"``,
    ``frame="network"``, ``skip=False``; d_model 512, 4 blocks, PointNet++ global 512) has about 27.7 M
    parameters; this one at config/paper.yaml's sizes has 8.3 M (its blocks are plain residual MLPs with
    additive conditioning, which is what the official single-token attention reduces to)."""

    d_model: int = 64
    n_blocks: int = 3
    ff_mult: int = 2
    dropout: float = 0.0
    n_heads: int = 4
    context: str = "tokens"
    frame: str = "canonical"
    skip: bool = False
    contact_power: float = 2.0  # the contact frame's weights are c ** contact_power
    origin: str = "centroid"  # the canonical frame's origin: the contact centroid or the object point nearest it
    diff_units: str = "official"  # L_diff in the vector's own units (m, rad), or "normalised": on the normalised one
    recon_clamp: float = 1.0  # L_recon enters as min(L_recon, recon_clamp) per sample (m^2; 0: unclamped)
    encoder: str = "pointnet"  # or "pointnet2": PointNet++ of sizes ``pointnet`` (the paper's)
    representation: str = "palm_rot6d"  # or "axis_angle": the 51 numbers (the paper's)
    contact_features: bool = True  # the contact region's moments added to the pooled condition
    cond_dropout: float = 0.0  # training: the share of samples whose context is replaced by a learnt null
    contact_input: bool = True  # false: the object alone is the condition (SceneDiffuser)
    thumb_sign: bool = False  # the contact channel signed by the thumb's contact (module docstring)
    mlp: tuple = (64, 128)
    pointnet: dict = field(default_factory=lambda: {
        "sa": [[128, 0.02, 16, [32, 32, 64]], [32, 0.05, 16, [64, 64, 128]], [0, 0.0, 0, [128, 256]]],
        "fp": [[128], [96], [64]]})
    diffusion: dict = field(default_factory=lambda: asdict(DiffusionConfig(beta_end=0.01, prediction="sample", clip=0.0)))

    def __post_init__(self):
        if self.context not in CONTEXTS:
            raise ValueError(f"GraspDiffuser context must be one of {CONTEXTS}, not {self.context!r}")
        if self.frame not in FRAMES:
            raise ValueError(f"GraspDiffuser frame must be one of {FRAMES}, not {self.frame!r}")
        if self.origin not in ORIGINS:
            raise ValueError(f"GraspDiffuser origin must be one of {ORIGINS}, not {self.origin!r}")
        if self.diff_units not in DIFF_UNITS:
            raise ValueError(f"GraspDiffuser diff_units must be one of {DIFF_UNITS}, not {self.diff_units!r}")
        if self.representation not in REPRESENTATIONS:
            raise ValueError(f"GraspDiffuser representation must be one of {REPRESENTATIONS}, not {self.representation!r}")
        if self.encoder not in ENCODERS:
            raise ValueError(f"GraspDiffuser encoder must be one of {ENCODERS}, not {self.encoder!r}")
        if not self.contact_input and (self.frame != "network" or self.contact_features):
            raise ValueError("a GraspDiffuser without contact_input reads no map: it needs frame 'network' and "
                             "contact_features false")
        if self.thumb_sign and not self.contact_input:
            raise ValueError("a GraspDiffuser with thumb_sign reads signed contact maps: it needs contact_input")
        if self.recon_clamp < 0:
            raise ValueError(f"GraspDiffuser recon_clamp must be >= 0 (0: unclamped), not {self.recon_clamp}")
        if self.d_model % self.n_heads:
            raise ValueError(f"GraspDiffuser d_model {self.d_model} is not a multiple of n_heads {self.n_heads}")

    @staticmethod
    def from_dict(d: dict) -> "GraspDiffuserConfig":
        return GraspDiffuserConfig(**{k: tuple(v) if k == "mlp" else v for k, v in d.items()})


@dataclass
class GraspCondition:
    """What the network reads of one batch of objects with contact maps (B of them, N points).

    Attributes:
        glob: (B, d_model) the pooled condition.
        tokens: (B, N, d_model) per-point tokens, or None (``context="global"``).
        rotation: (B, 3, 3) the frame's axes in the network frame (columns); identity for ``"network"``.
        origin: (B, 3) the frame's origin in the network frame, m; zeros for ``"network"``.
        points: (B, N, 3) the object points in the frame, m (the hand losses compare hands to them).
        keys_values: per block, the tokens' attention keys and values ((B, heads, N, d_model / heads) each),
            projected once and reused by every denoising step (None: not yet; the network fills it in).
    """

    glob: torch.Tensor
    tokens: torch.Tensor | None
    rotation: torch.Tensor
    origin: torch.Tensor
    points: torch.Tensor
    keys_values: list[tuple[torch.Tensor, torch.Tensor]] | None = None

    def expand(self, n: int) -> "GraspCondition":
        """The condition of one object repeated for ``n`` samples (every field has batch 1)."""
        return GraspCondition(*(None if v is None else v.expand(n, *v.shape[1:]) for v in
                                (self.glob, self.tokens, self.rotation, self.origin, self.points)))


def contact_frame(points: torch.Tensor, contact: torch.Tensor, power: float = 2.0) -> tuple[torch.Tensor, torch.Tensor]:
    """The frame a contact map defines on its object cloud.

    Args:
        points: (B, N, 3) object points (network frame: centred on the object, z up), m.
        contact: (B, N) contact values in [0, 1] (1 at contact).
        power: weights are ``contact ** power`` (sharper than the map itself, whose tail is long).

    Returns:
        ``rotation`` (B, 3, 3), a turn about z (columns: the frame's axes), and ``origin`` (B, 3), the
        contact-weighted centroid. The x axis points along the centroid's horizontal offset from the
        cloud's centre (an arbitrary but fixed direction where that offset is under 1 mm); a map without
        contact gives the cloud's centre and no turn.
    """
    w = contact.clamp_min(0) ** power
    total = w.sum(-1, keepdim=True)
    centre = points.mean(1)
    origin = torch.where(total > 1e-6, (w[..., None] * points).sum(1) / total.clamp_min(1e-6), centre)
    off = origin[:, :2] - centre[:, :2]
    norm = off.norm(dim=-1, keepdim=True)
    direction = torch.where(norm > 1e-3, off / norm.clamp_min(1e-12), torch.tensor([1.0, 0.0], dtype=points.dtype,
                                                                                      device=points.device))
    c, s = direction[:, 0], direction[:, 1]
    zero, one = torch.zeros_like(c), torch.ones_like(c)
    rotation = torch.stack([torch.stack([c, -s, zero], -1), torch.stack([s, c, zero], -1),
                            torch.stack([zero, zero, one], -1)], -2)
    return rotation, origin


def contact_moments(points: torch.Tensor, normals: torch.Tensor, contact: torch.Tensor, power: float = 2.0
                    ) -> torch.Tensor:
    """(B, 10) the contact region in numbers: its weighted mean normal (3), the weighted second moments of
    its points about their centroid (xx, yy, zz, xy, xz, yz, in cm^2), and the log of its mean weight over
    the points, the share of the object in contact, which does not depend on how many points sample it
    (weights ``contact ** power``; points (B, N, 3) m, normals (B, N, 3), contact (B, N)). (Until the
    point-count fix it was the log of the summed weight: training on 256 of 512 points, that read every test
    map as twice the contact.)"""
    w = contact.clamp_min(0) ** power
    total = w.sum(-1, keepdim=True).clamp_min(1e-6)
    wn = w / total
    mean_normal = (wn[..., None] * normals).sum(1)
    centred = (points - (wn[..., None] * points).sum(1, keepdim=True)) * 100.0  # cm
    xx, yy, zz = [(wn * centred[..., k] ** 2).sum(-1) for k in range(3)]
    xy, xz, yz = [(wn * centred[..., i] * centred[..., j]).sum(-1) for i, j in ((0, 1), (0, 2), (1, 2))]
    mean = w.mean(-1, keepdim=True).clamp_min(1e-6 / w.shape[-1])
    return torch.cat([mean_normal, torch.stack([xx, yy, zz, xy, xz, yz], -1), mean.log()], -1)


def grasp_to_frame(grasp: torch.Tensor, rotation: torch.Tensor, origin: torch.Tensor, wrist: torch.Tensor) -> torch.Tensor:
    """(B, 51) grasps of the network frame expressed in frames (rotation (B, 3, 3), origin (B, 3)).

    The hand model turns its global rotation about the rest wrist ``wrist`` (3,) and then translates by t
    (:func:`tohgs.geometry.grasp.transform_grasp`), so in a frame ``x' = R^T (x - o)`` the rotation is
    ``R^T R_g`` and the translation ``R^T (j0 + t - o) - j0``; the finger numbers do not change.
    """
    rt = rotation.transpose(-1, -2)
    rot = matrix_to_axis_angle(rt @ axis_angle_to_matrix(grasp[:, 3:6]))
    trans = (rt @ (wrist + grasp[:, :3] - origin)[..., None])[..., 0] - wrist
    return torch.cat([trans, rot, grasp[:, 6:]], -1)


def grasp_from_frame(grasp: torch.Tensor, rotation: torch.Tensor, origin: torch.Tensor, wrist: torch.Tensor) -> torch.Tensor:
    """The inverse of :func:`grasp_to_frame`: (B, 51) grasps of the frames back in the network frame."""
    rot = matrix_to_axis_angle(rotation @ axis_angle_to_matrix(grasp[:, 3:6]))
    trans = (rotation @ (wrist + grasp[:, :3])[..., None])[..., 0] + origin - wrist
    return torch.cat([trans, rot, grasp[:, 6:]], -1)


class _Block(nn.Module):
    """A residual MLP with the additive condition, then (with tokens) cross-attention to the object."""

    def __init__(self, d: int, mult: int, dropout: float, heads: int, tokens: bool):
        super().__init__()
        self.mlp = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, mult * d), nn.GELU(), nn.Dropout(dropout),
                                 nn.Linear(mult * d, d))
        self.attn = nn.MultiheadAttention(d, heads, dropout=dropout, batch_first=True) if tokens else None
        self.norm = nn.LayerNorm(d) if tokens else None

    def keys_values(self, tokens: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The attention's keys and values of (B, N, d) tokens, each (B, heads, N, d / heads): the projections
        of :class:`torch.nn.MultiheadAttention`'s own weights, computed once per condition."""
        d, heads = self.attn.embed_dim, self.attn.num_heads
        w, bias = self.attn.in_proj_weight, self.attn.in_proj_bias
        b, n = tokens.shape[:2]
        k = nn.functional.linear(tokens, w[d:2 * d], bias[d:2 * d]).view(b, n, heads, d // heads).transpose(1, 2)
        v = nn.functional.linear(tokens, w[2 * d:], bias[2 * d:]).view(b, n, heads, d // heads).transpose(1, 2)
        return k, v

    def forward(self, h: torch.Tensor, c: torch.Tensor, kv: tuple[torch.Tensor, torch.Tensor] | None) -> torch.Tensor:
        """(B, d) token updated with the (B, d) condition and, with tokens, attention to their keys and values
        (:meth:`keys_values`): :class:`torch.nn.MultiheadAttention`'s computation with the tokens' projections
        reused across denoising steps (the same numbers, to float rounding)."""
        h = h + self.mlp(h + c)
        if self.attn is not None:
            d, heads = self.attn.embed_dim, self.attn.num_heads
            w, bias = self.attn.in_proj_weight, self.attn.in_proj_bias
            q = nn.functional.linear(self.norm(h), w[:d], bias[:d]).view(-1, heads, 1, d // heads)
            k, v = kv
            drop = self.attn.dropout if self.training else 0.0
            o = nn.functional.scaled_dot_product_attention(q, k, v, dropout_p=drop)  # (B, heads, 1, d / heads)
            h = h + self.attn.out_proj(o.reshape(-1, d))
        return h


class GraspDiffuser(Component):
    """x0-prediction network over normalised grasps (a grasp generator: :meth:`sample_grasps`); holds the
    grasp normaliser and the hand's rest wrist as buffers (both set from the training data)."""

    kind = "grasp_diffuser"
    Config = GraspDiffuserConfig
    role = "grasp"
    steerable = True
    needs_hand = True

    @property
    def reads_contact(self) -> bool:
        """Whether it is conditioned on the batch's contact maps (``contact_input``; SceneDiffuser's is not)."""
        return bool(self.cfg.contact_input)

    @property
    def reads_signed_contact(self) -> bool:
        """Whether the maps it samples for are signed by the thumb's contact (``thumb_sign``)."""
        return bool(self.cfg.thumb_sign)

    def maps_read(self, contact: torch.Tensor, points: torch.Tensor, grasp: torch.Tensor, hand: HandModel
                  ) -> torch.Tensor:
        """(B, N) the contact maps of (B, 51) ``grasp`` on (B, N, 3) ``points`` as the network reads them: with
        ``thumb_sign`` signed by each grasp's thumb (:func:`tohgs.geometry.contact_parts.thumb_signed`), else
        ``contact`` itself."""
        return thumb_signed_by(hand, grasp, points, contact) if self.cfg.thumb_sign else contact

    def __init__(self, cfg: GraspDiffuserConfig):
        super().__init__()
        self.cfg = cfg
        self.diffusion = DiffusionConfig(**cfg.diffusion)
        self.schedule = NoiseSchedule(self.diffusion)
        self._training = {}  # what prepare() sets for the loss: the hand (not a submodule), weights, alpha
        channels = 4 if cfg.contact_input else 3  # normals (3) and the contact value
        if cfg.encoder == "pointnet2":
            self.backbone = PointNet2(PointNet2Config.from_dict({**cfg.pointnet, "in_channels": channels}))
        else:
            self.backbone = PointNet(channels, list(cfg.mlp))
        d = cfg.d_model
        self.cond = nn.Sequential(nn.Linear(self.backbone.global_dim, d), nn.SiLU(), nn.Linear(d, d))
        tokens = cfg.context == "tokens"
        self.token_proj = (nn.Sequential(nn.Linear(self.backbone.local_dim + channels, d), nn.SiLU(), nn.Linear(d, d))
                           if tokens else None)
        self.time = TimeMLP(d)
        self.dim = GRASP_DIM if cfg.representation == "axis_angle" else GRASP_DIM + 3
        self.features = (nn.Sequential(nn.Linear(N_CONTACT_FEATURES, d), nn.SiLU(), nn.Linear(d, d))
                         if cfg.contact_features else None)
        self.inp = nn.Linear(self.dim, d)
        self.blocks = nn.ModuleList([_Block(d, cfg.ff_mult, cfg.dropout, cfg.n_heads, tokens) for _ in range(cfg.n_blocks)])
        self.out = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, self.dim))
        if cfg.cond_dropout > 0:  # classifier-free guidance: a learnt "no context" for the unconditional model
            self.null_glob = nn.Parameter(torch.zeros(d))
            self.null_tokens = nn.Parameter(torch.zeros(d)) if tokens else None
        self.register_buffer("grasp_mean", torch.zeros(self.dim))
        self.register_buffer("grasp_std", torch.ones(self.dim))
        self.register_buffer("wrist", torch.zeros(3))
        self.register_buffer("palm", torch.zeros(3))
        self.register_buffer("alphas_cumprod", NoiseSchedule(self.diffusion).alphas_cumprod.clone(), persistent=False)

    def set_normaliser(self, grasps: torch.Tensor) -> None:
        """Per-dimension mean and std of (G, D) training vectors *as the network sees them* (in its frame,
        after augmentation, in its representation: :meth:`in_frame`); std floored at 1e-3 (a single grasp
        has no spread, so its std is that floor, where the unbiased std would be NaN and poison training)."""
        if grasps.ndim != 2 or grasps.shape[0] == 0 or grasps.shape[1] != self.dim:
            raise ValueError(f"set_normaliser needs (G >= 1, {self.dim}) vectors, got {tuple(grasps.shape)}")
        self.grasp_mean.copy_(grasps.mean(0))
        std = grasps.std(0) if grasps.shape[0] > 1 else torch.zeros_like(grasps[0])
        self.grasp_std.copy_(std.clamp_min(1e-3))

    def normaliser(self) -> dict[str, torch.Tensor]:
        """The grasp normaliser (per-dimension ``mean`` and ``std`` of the network's vectors)."""
        return {"mean": self.grasp_mean.detach().cpu().clone(), "std": self.grasp_std.detach().cpu().clone()}

    def prepare(self, data, task: str, hand: HandModel | None = None) -> None:
        """Before training: the hand (its rest wrist and palm; the losses pose it), the normaliser of the
        training grasps as the network sees them (:func:`seen_grasps`), the task's loss weights and the
        shards' contact alpha."""
        if hand is None:
            raise ValueError("GraspDiffuser trains with the hand model in the loss; pass hand=")
        self.set_hand(hand)
        self.set_normaliser(seen_grasps(self, data, self.wrist.device))
        self._training = {"hand": hand, "weights": LOSS_WEIGHTS.get(task, LOSS_WEIGHTS["placing"]),
                          "alpha_contact": data.shards[0].alpha_contact}

    def loss(self, batch: Batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The weighted sum of the four terms (module docstring) at a uniform timestep per sample, with each
        term's mean and weighted contribution (``w_<term>``) for the log."""
        if not self._training:
            raise ValueError("GraspDiffuser.loss needs prepare() first (the hand and the normaliser)")
        b, dev = batch.size, batch.device
        t = torch.randint(0, self.schedule.timesteps, (b,), generator=generator).to(dev)
        contact = self.maps_read(batch.contact, batch.points, batch.grasp, self._training["hand"])
        cond = self.condition(batch.points, batch.normals, contact)
        x0 = self.encode(batch.grasp, cond)
        noise = torch.randn(x0.shape, generator=generator).to(dev)
        x_t = self.schedule.q_sample(x0, noise, t)
        if self.cfg.cond_dropout > 0:
            drop = (torch.rand(b, generator=generator) < self.cfg.cond_dropout).to(dev)
            x0_hat = self(x_t, t, self.drop_context(cond, drop))
        else:
            x0_hat = self(x_t, t, cond)
        terms = grasp_losses(self, self._training["hand"], x0_hat, x0, cond, batch.contact,
                             self._training["alpha_contact"])
        weighted = weighted_terms(terms, self._training["weights"], self.cfg.recon_clamp)
        return {"loss": sum(weighted.values()), **{k: v.mean() for k, v in terms.items()},
                **{f"w_{k}": v for k, v in weighted.items()}}

    @torch.no_grad()
    def sample_grasps(self, batch: Batch, sampler: str, steps: int, generator: torch.Generator,
                      guidance: float = 1.0, steer: GuidanceSettings | None = None, hand=None) -> torch.Tensor:
        """(B, 51) grasps in the network frame for the batch's objects and contact maps (``batch.contact``;
        none without ``contact_input``), with classifier-free ``guidance`` (1: none) and, with an active
        ``steer``, each guided step's x0 moved down the scene-aware energy of the grasp it decodes to
        (:mod:`tohgs.models.guidance`; needs the ``hand`` model)."""
        if batch.contact is None and self.cfg.contact_input:
            raise ValueError("GraspDiffuser samples grasps for contact maps; the batch has none")
        cond = self.condition(batch.points, batch.normals, batch.contact)
        guide = None
        if steer is not None and steer.active:
            if hand is None:
                raise ValueError("guided sampling (steer) poses hands: it needs the hand model")
            energy_batch = batch.with_contact(batch.contact.abs()) if self.cfg.thumb_sign else batch  # the paper's map
            guide = guidance_step(lambda x: self.decode(x, cond), GuidanceEnergy.of_batch(hand, energy_batch, steer), steer,
                                  self.diffusion.timesteps)
        x0 = sample(lambda xt, tt: self.guided(xt, tt, cond, guidance), (batch.size, self.dim), self.diffusion,
                    sampler, steps, generator, batch.device, guide)
        return self.decode(x0, cond)

    def set_hand(self, hand: HandModel) -> None:
        """The hand's rest wrist joint (grasps turn about it: the contact frame needs it) and its rest palm
        centre (the mean of its palm vertices; ``palm_rot6d`` places it), m."""
        self.wrist.copy_(hand.rest_joints[0].to(self.wrist))
        self.palm.copy_(hand.rest_vertices[torch.as_tensor(hand.assets.palm_ids)].mean(0).to(self.palm))

    def vector_of(self, grasp: torch.Tensor) -> torch.Tensor:
        """(B, 51) grasps -> (B, D) vectors of the representation (unnormalised)."""
        if self.cfg.representation == "axis_angle":
            return grasp
        return palm_rot6d(grasp, self.wrist, self.palm)

    def grasp_of(self, vec: torch.Tensor) -> torch.Tensor:
        """The inverse of :meth:`vector_of` (any 6D vector is projected onto a rotation, Gram-Schmidt)."""
        if self.cfg.representation == "axis_angle":
            return vec
        return grasp_from_palm_rot6d(vec, self.wrist, self.palm)

    def normalise(self, g: torch.Tensor) -> torch.Tensor:
        return (g - self.grasp_mean) / self.grasp_std

    def denormalise(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.grasp_std + self.grasp_mean

    def frame_of(self, points: torch.Tensor, normals: torch.Tensor, contact: torch.Tensor
                 ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(rotation (B, 3, 3), origin (B, 3))`` of the network's frame for (B, N, 3) points and normals
        with their (B, N) contact map: :func:`contact_frame` (a turn about z), the rotation-equivariant
        :func:`tohgs.geometry.frames.contact_frame_3d` (``"canonical"``), or the identity (``"network"``)."""
        if self.cfg.frame == "contact":
            return contact_frame(points, contact, self.cfg.contact_power)
        if self.cfg.frame == "canonical":
            return contact_frame_3d(points, normals, contact, self.cfg.contact_power, self.cfg.origin)
        b = points.shape[0]
        return (torch.eye(3, dtype=points.dtype, device=points.device).expand(b, 3, 3),
                torch.zeros(b, 3, dtype=points.dtype, device=points.device))

    def _framed_vector(self, grasp: torch.Tensor, rotation: torch.Tensor, origin: torch.Tensor) -> torch.Tensor:
        """(B, 51) network-frame grasps -> (B, D) unnormalised vectors in the frame (rotation, origin)."""
        if self.cfg.frame != "network":
            grasp = grasp_to_frame(grasp, rotation, origin, self.wrist)
        return self.vector_of(grasp)

    def in_frame(self, grasp: torch.Tensor, points: torch.Tensor, contact: torch.Tensor, normals: torch.Tensor
                 ) -> torch.Tensor:
        """(B, 51) network-frame grasps as (B, D) unnormalised vectors in the network's frame (what the
        normaliser measures), for (B, N, 3) points, (B, N) contact maps and (B, N, 3) normals."""
        return self._framed_vector(grasp, *self.frame_of(points, normals, contact))

    def condition(self, points: torch.Tensor, normals: torch.Tensor, contact: torch.Tensor | None) -> GraspCondition:
        """The condition of (B, N, 3) points with (B, N, 3) normals and their (B, N) contact map (not read,
        and may be None, without ``contact_input``; signed by the thumb's contact with ``thumb_sign``, whose
        frame and moments read its absolute value)."""
        unsigned = contact.abs() if self.cfg.thumb_sign else contact
        rot, origin = self.frame_of(points, normals, unsigned)
        points = (points - origin[:, None]) @ rot  # x' = R^T (x - o), as row vectors
        normals = normals @ rot
        extra = [contact[..., None]] if self.cfg.contact_input else []
        local, glob = self.backbone(points, torch.cat([normals, *extra], -1))
        tokens = None
        if self.token_proj is not None:
            tokens = self.token_proj(torch.cat([local, points, *extra], -1))
        c = self.cond(glob)
        if self.features is not None:
            c = c + self.features(contact_moments(points, normals, unsigned, self.cfg.contact_power))
        return GraspCondition(c, tokens, rot, origin, points)

    def encode(self, grasp: torch.Tensor, cond: GraspCondition) -> torch.Tensor:
        """(B, 51) network-frame grasps -> the (B, D) normalised vectors the network denoises (its frame)."""
        return self.normalise(self._framed_vector(grasp, cond.rotation, cond.origin))

    def in_frame_grasp(self, x: torch.Tensor) -> torch.Tensor:
        """(B, D) normalised vectors -> (B, 51) grasps in the network's frame (the hand losses pose them)."""
        return self.grasp_of(self.denormalise(x))

    def decode(self, x: torch.Tensor, cond: GraspCondition) -> torch.Tensor:
        """The inverse of :meth:`encode`: (B, D) normalised vectors -> network-frame grasps (B, 51)."""
        grasp = self.in_frame_grasp(x)
        if self.cfg.frame != "network":
            grasp = grasp_from_frame(grasp, cond.rotation, cond.origin, self.wrist)
        return grasp

    def drop_context(self, cond: GraspCondition, drop: torch.Tensor) -> GraspCondition:
        """The condition with the context of the samples where (B,) bool ``drop`` replaced by the learnt
        null (the frame stays: it is a function of the map, not something the network reads)."""
        if self.cfg.cond_dropout <= 0:
            raise ValueError("this GraspDiffuser was trained without cond_dropout: it has no unconditional model")
        glob = torch.where(drop[:, None], self.null_glob.expand_as(cond.glob), cond.glob)
        tokens = cond.tokens
        if tokens is not None:
            tokens = torch.where(drop[:, None, None], self.null_tokens.expand_as(tokens), tokens)
        return GraspCondition(glob, tokens, cond.rotation, cond.origin, cond.points)

    def guided(self, x_t: torch.Tensor, t: torch.Tensor, cond: GraspCondition, scale: float) -> torch.Tensor:
        """Classifier-free guidance: ``u + scale (c - u)`` of the conditional and unconditional x0 estimates
        (``scale`` 1 is the conditional model alone)."""
        c = self(x_t, t, cond)
        if scale == 1.0:
            return c
        u = self(x_t, t, self.drop_context(cond, torch.ones(x_t.shape[0], dtype=torch.bool, device=x_t.device)))
        return u + scale * (c - u)

    def forward(self, x_t: torch.Tensor, t: torch.Tensor, cond: GraspCondition) -> torch.Tensor:
        """Predict the normalised vector x0 (B, D) from ``x_t`` (B, D), timesteps (B,) and the condition."""
        c = cond.glob + self.time(t)
        h = self.inp(x_t)
        if cond.tokens is not None and cond.keys_values is None:
            cond.keys_values = [block.keys_values(cond.tokens) for block in self.blocks]
        for i, block in enumerate(self.blocks):
            h = block(h, c, None if cond.tokens is None else cond.keys_values[i])
        out = self.out(h)
        if self.cfg.skip:
            a = self.alphas_cumprod.to(x_t.device)[t][:, None]
            out = a.sqrt() * x_t + (1 - a).sqrt() * out
        return out


def grasp_losses(model: GraspDiffuser, hand: HandModel, x0_hat: torch.Tensor, x0: torch.Tensor, cond: GraspCondition,
                 contact: torch.Tensor, alpha_contact: float) -> dict[str, torch.Tensor]:
    """The four loss terms per sample (unweighted, unclamped; each (B,)) of predicted normalised vectors
    ``x0_hat`` (B, D) against the truth ``x0``, on the condition's object points (B, N, 3, in the
    network's frame) with their true contact map (B, N): ``diff`` here, the hand-object terms ``recon``,
    ``pen`` and ``cons`` from :func:`tohgs.models.hand_object_loss.hand_object_terms`."""
    points = cond.points
    err = x0_hat - x0
    if model.cfg.diff_units == "official":  # in the vector's own units (m, rad): the official code's balance
        err = err * model.grasp_std
    l_diff = (err ** 2).sum(-1)
    pred_v = hand(model.in_frame_grasp(x0_hat)).vertices
    with torch.no_grad():
        true_v = hand(model.in_frame_grasp(x0)).vertices
    return {"diff": l_diff, **hand_object_terms(points, pred_v, true_v, contact, hand.closed_faces, alpha_contact)}


def weighted_terms(terms: dict[str, torch.Tensor], weights: tuple[float, float, float, float],
                   recon_clamp: float = 1.0) -> dict[str, torch.Tensor]:
    """Each term's contribution to the loss (scalars): ``w_diff mean L_diff``, ``w_recon mean min(L_recon,
    recon_clamp)`` (no clamp where ``recon_clamp`` is 0), ``w_pen mean min(L_pen, 1)``, ``w_cons mean L_cons``
    (clamps per sample)."""
    w_diff, w_recon, w_pen, w_cons = weights
    recon = terms["recon"] if recon_clamp == 0 else terms["recon"].clamp(max=recon_clamp)
    return {"diff": w_diff * terms["diff"].mean(), "recon": w_recon * recon.mean(),
            **weighted_pen_cons(terms, w_pen, w_cons)}


COMPONENT = GraspDiffuser
