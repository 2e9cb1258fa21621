"""ContactGen's sequential CVAE (Liu et al. ICCV 2023) and ContactCVAE, its contact-only reduction (the
paper's Table 5 ``CC``): generators of the object-centric contact representation
(:mod:`tohgs.geometry.contact_parts`: per object point a contact value, one of 16 hand parts and a unit
direction in that part's frame).

- Object encoder: PointNet++ (:class:`tohgs.models.pointnet2.PointNet2`, SA levels then feature
  propagation back to every point) on xyz and the point normals: per-point features ``f`` and a global one.
  It sees the object only (object-centric): no scene, no task.
- Three conditional VAEs in sequence, each with a ``latent``-d Gaussian latent (ContactGen's 16):
  contact ``c`` given ``f``; part ``p`` given ``f, c``; direction ``d`` given ``f, c, p``. Each encoder is a
  per-point MLP on the stage's inputs and target, max-pooled with the global feature, to the latent's mean
  and log-variance; each decoder a per-point MLP on the stage's inputs and the latent. At training the
  later stages read the true contact and part (teacher forcing); at sampling each reads the previous
  stage's sample (the part as its most likely label).
- ``parts: false`` keeps only the contact stage: ContactCVAE, a contact source for GraspDiffuser.

Loss (ContactGen's terms), per point weighted by ``1 + 5 c`` (c the true contact) and averaged over the
points: L1 of the contact, the parts' negative log-likelihood, the directions' ``1 - cos``; plus each
stage's KL in ContactGen's robust form ``sqrt(1 + KL^2) - 1``, its weight rising linearly from 0 to
``w_kl`` over the first ``kl_anneal_steps`` training steps (a step counter kept with the weights).

Targets come from the true hands of the training batch (the hand model poses ``batch.grasp``); the contact
target is the map shards' own map. Shapes: points and normals (B, N, 3), contact (B, N), part (B, N)
long, direction (B, N, 3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import nn
from torch.nn import functional as F

from tohgs.data.batch import Batch
from tohgs.geometry.contact_parts import N_PARTS, PartContact, part_contact
from tohgs.geometry.maps import ALPHA_CONTACT
from tohgs.hand.model import HandModel
from tohgs.models.component import Component
from tohgs.models.layers import mlp
from tohgs.models.pointnet2 import PointNet2, PointNet2Config
from tohgs.settings import settings_from

STAGES = ("contact", "part", "direction")


@dataclass(frozen=True)
class ContactGenConfig:
    """Sizes, the stages and the loss weights (module docstring). ContactGen: PointNet++ SA
    512 / 0.2 / 32 -> 128 / 0.4 / 64 -> global (object units; ours in metres), 64-d point features,
    latents 16."""

    latent: int = 16
    hidden: tuple = (64, 64)
    parts: bool = True  # False: ContactCVAE (the contact stage only)
    pointnet: dict = field(default_factory=lambda: {
        "sa": [[128, 0.02, 16, [32, 32, 64]], [32, 0.05, 16, [64, 64, 128]], [0, 0.0, 0, [128, 128]]],
        "fp": [[128], [96], [64]]})
    w_contact: float = 1.0
    w_part: float = 1.0
    w_direction: float = 1.0
    w_kl: float = 0.05
    kl_anneal_steps: int = 200

    def __post_init__(self):
        if self.latent < 1:
            raise ValueError(f"ContactGen latent must be at least 1, not {self.latent}")

    @staticmethod
    def from_dict(d: dict) -> "ContactGenConfig":
        return settings_from(ContactGenConfig, d)  # YAML lists as tuples; an unknown key named


class _Stage(nn.Module):
    """One conditional VAE over a per-point target given per-point inputs (module docstring)."""

    def __init__(self, in_dim: int, target_dim: int, out_dim: int, global_dim: int, latent: int, hidden: tuple):
        super().__init__()
        self.encoder = mlp([in_dim + target_dim, *hidden], last_plain=False)
        self.to_stats = nn.Linear(hidden[-1] + global_dim, 2 * latent)
        self.decoder = mlp([in_dim + latent, *hidden, out_dim])
        self.latent = latent

    def posterior(self, inputs: torch.Tensor, target: torch.Tensor, glob: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance (B, latent) from (B, N, I) inputs, (B, N, T) targets and (B, G) global."""
        pooled = self.encoder(torch.cat([inputs, target], -1)).max(1).values
        mu, logvar = self.to_stats(torch.cat([pooled, glob], -1)).chunk(2, -1)
        return mu, logvar.clamp(-10.0, 10.0)

    def decode(self, inputs: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """(B, N, out) raw outputs from (B, N, I) inputs and (B, latent) latents."""
        return self.decoder(torch.cat([inputs, z[:, None].expand(-1, inputs.shape[1], -1)], -1))


def robust_kl(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """(B,) ContactGen's ``sqrt(1 + KL^2) - 1`` of the (B, latent) posterior from N(0, I)."""
    kl = 0.5 * (mu**2 + logvar.exp() - 1 - logvar).sum(-1)
    return torch.sqrt(1 + kl**2) - 1


class ContactGen(Component):
    """The sequential CVAE (a contact source, :meth:`sample_contact`; with parts, the representation
    :meth:`sample_representation`)."""

    kind = "contact_gen"
    Config = ContactGenConfig
    role = "contact"
    needs_hand = True

    @property
    def samples_parts(self) -> bool:
        """Whether it samples parts and directions besides the contact (``parts``)."""
        return bool(self.cfg.parts)

    def __init__(self, cfg: ContactGenConfig):
        super().__init__()
        self.cfg = cfg
        self._training: dict = {}
        self.backbone = PointNet2(PointNet2Config.from_dict({**cfg.pointnet, "in_channels": 3}))
        f, g, z, h = self.backbone.local_dim, self.backbone.global_dim, cfg.latent, tuple(cfg.hidden)
        self.contact_stage = _Stage(f, 1, 1, g, z, h)
        if cfg.parts:
            self.part_stage = _Stage(f + 1, N_PARTS, N_PARTS, g, z, h)
            self.direction_stage = _Stage(f + 1 + N_PARTS, 3, 3, g, z, h)
        self.register_buffer("alpha_contact", torch.tensor(ALPHA_CONTACT))
        self.register_buffer("steps_seen", torch.tensor(0, dtype=torch.long))

    def prepare(self, data, task: str, hand: HandModel | None = None) -> None:
        """Before training: the hand (the part and direction targets pose it) and the shards' alpha."""
        if hand is None and self.cfg.parts:
            raise ValueError("ContactGen's part and direction targets need the hand model; pass hand=")
        self.alpha_contact.fill_(data.shards[0].alpha_contact)
        self._training = {"hand": hand}

    def features(self, batch: Batch) -> tuple[torch.Tensor, torch.Tensor]:
        """The object encoder's per-point (B, N, F) and global (B, G) features."""
        return self.backbone(batch.points, batch.normals)

    def targets(self, batch: Batch) -> PartContact:
        """The representation of the batch's true hands on its points (contact: the shards' maps)."""
        hand = self._training["hand"]
        with torch.no_grad():
            out = hand(batch.grasp)
            rep = part_contact(batch.points, out.vertices, out.joints, out.rotations, hand.part_labels,
                               float(self.alpha_contact))
        return PartContact(batch.contact, rep.part, rep.direction)

    def loss(self, batch: Batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The weighted per-point terms and the annealed KLs (module docstring)."""
        if not self._training:
            raise ValueError("ContactGen.loss needs prepare() first")
        c = self.cfg
        f, glob = self.features(batch)
        if c.parts:
            target = self.targets(batch)
        else:
            target = PartContact(batch.contact, None, None)
        w = 1.0 + 5.0 * target.contact  # (B, N)

        def latent(stage: _Stage, inputs, tgt):
            mu, logvar = stage.posterior(inputs, tgt, glob)
            eps = torch.randn(mu.shape, generator=generator).to(mu)
            return mu + (0.5 * logvar).exp() * eps, robust_kl(mu, logvar)

        c_in = target.contact[..., None]
        z, kl_c = latent(self.contact_stage, f, c_in)
        c_pred = torch.sigmoid(self.contact_stage.decode(f, z)[..., 0])
        terms = {"contact": (w * (c_pred - target.contact).abs()).mean(-1), "kl_contact": kl_c}
        if c.parts:
            onehot = F.one_hot(target.part, N_PARTS).to(f)
            p_inputs = torch.cat([f, c_in], -1)
            z, kl_p = latent(self.part_stage, p_inputs, onehot)
            logits = self.part_stage.decode(p_inputs, z)
            nll = F.cross_entropy(logits.transpose(1, 2), target.part, reduction="none")  # (B, N)
            d_inputs = torch.cat([f, c_in, onehot], -1)
            z, kl_d = latent(self.direction_stage, d_inputs, target.direction)
            d_pred = F.normalize(self.direction_stage.decode(d_inputs, z), dim=-1)
            ang = 1.0 - (d_pred * target.direction).sum(-1)
            terms.update(part=(w * nll).mean(-1), kl_part=kl_p, direction=(w * ang).mean(-1), kl_direction=kl_d)
        if self.training:
            self.steps_seen += 1
        anneal = min(1.0, float(self.steps_seen) / max(1, c.kl_anneal_steps))
        weights = {"contact": c.w_contact, "part": c.w_part, "direction": c.w_direction}
        weighted = {k: weights[k] * v.mean() for k, v in terms.items() if k in weights}
        weighted["kl"] = c.w_kl * anneal * sum(v.mean() for k, v in terms.items() if k.startswith("kl_"))
        return {"loss": sum(weighted.values()), **{k: v.mean() for k, v in terms.items()},
                **{f"w_{k}": v for k, v in weighted.items()}}

    @torch.no_grad()
    def reconstruct(self, batch: Batch) -> PartContact:
        """The posterior-mean reconstruction of the batch's true representation (the sanity check's
        measure): each stage from its true target's posterior mean, with the true earlier stages."""
        f, glob = self.features(batch)
        target = self.targets(batch) if self.cfg.parts else PartContact(batch.contact, None, None)
        c_in = target.contact[..., None]
        contact = self._contact_from_posterior(f, glob, target.contact)
        if not self.cfg.parts:
            return PartContact(contact, None, None)
        onehot = F.one_hot(target.part, N_PARTS).to(f)
        p_inputs = torch.cat([f, c_in], -1)
        mu, _ = self.part_stage.posterior(p_inputs, onehot, glob)
        part = self.part_stage.decode(p_inputs, mu).argmax(-1)
        d_inputs = torch.cat([f, c_in, onehot], -1)
        mu, _ = self.direction_stage.posterior(d_inputs, target.direction, glob)
        return PartContact(contact, part, F.normalize(self.direction_stage.decode(d_inputs, mu), dim=-1))

    @torch.no_grad()
    def reconstruct_contact(self, batch: Batch) -> torch.Tensor:
        """(B, N) the contact stage's posterior-mean reconstruction of the batch's true maps (its latent from
        the true map, as :meth:`reconstruct`): how much of a map the stage can carry, apart from sampling."""
        f, glob = self.features(batch)
        return self._contact_from_posterior(f, glob, batch.contact)

    def _contact_from_posterior(self, f: torch.Tensor, glob: torch.Tensor, contact: torch.Tensor) -> torch.Tensor:
        """(B, N) the contact decoded from the posterior mean of the (B, N) ``contact`` maps, given the
        encoder's per-point (B, N, F) and global (B, G) features."""
        mu, _ = self.contact_stage.posterior(f, contact[..., None], glob)
        return torch.sigmoid(self.contact_stage.decode(f, mu)[..., 0])

    @torch.no_grad()
    def sample_representation(self, batch: Batch, generator: torch.Generator) -> PartContact:
        """One sample per batch element: contact (B, N), part (B, N) (the most likely label given the
        sampled contact) and direction (B, N, 3), each stage's latent drawn from N(0, I)."""
        f, _ = self.features(batch)

        def z():
            return torch.randn((batch.size, self.cfg.latent), generator=generator).to(f)

        contact = torch.sigmoid(self.contact_stage.decode(f, z())[..., 0])
        if not self.cfg.parts:
            return PartContact(contact, None, None)
        c_in = contact[..., None]
        part = self.part_stage.decode(torch.cat([f, c_in], -1), z()).argmax(-1)
        onehot = F.one_hot(part, N_PARTS).to(f)
        direction = F.normalize(self.direction_stage.decode(torch.cat([f, c_in, onehot], -1), z()), dim=-1)
        return PartContact(contact, part, direction)

    @torch.no_grad()
    def sample_contact(self, batch: Batch, sampler: str, steps: int, generator: torch.Generator) -> torch.Tensor:
        """(B, N) contact maps in [0, 1] (the contact stage; the diffusion settings do not apply)."""
        f, _ = self.features(batch)
        z = torch.randn((batch.size, self.cfg.latent), generator=generator).to(f)
        return torch.sigmoid(self.contact_stage.decode(f, z)[..., 0])


COMPONENT = ContactGen
