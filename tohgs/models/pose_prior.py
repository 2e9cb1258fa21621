"""A learned hand-pose prior (FLEX's hand adaptation, paper section 5.1): a small VAE over the 45 finger
numbers of the training split's task grasps, whose decoder FLEX's optimisation searches
(:mod:`tohgs.grasps.flex`).

FLEX (Tendulkar et al. CVPR 2023) optimises the latent of VPoser, a body-pose VAE trained on motion
capture; the paper re-purposes it for hands without saying which prior. Here the prior is learnt from
the task grasps themselves (``../shared/BASELINES.md``, "FLEX"): finger numbers (axis-angle, radians)
normalised per dimension with the training grasps' mean and std, an MLP encoder to a ``latent``-d Gaussian,
an MLP decoder back, and the loss

``L = sum_k (x_k - x'_k)^2 + beta KL(q(z | x) || N(0, I))``

(normalised numbers, summed; KL in nats). A z of the standard normal then decodes to a plausible finger
pose, and ``|z|^2`` is the prior's cost of a pose in the optimisation. The grasp's global rotation and
translation are not the prior's: FLEX optimises them directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from tohgs.data.batch import Batch
from tohgs.hand.layout import FINGER_POSE_DIM
from tohgs.models.component import Component
from tohgs.models.layers import mlp
from tohgs.settings import settings_from


@dataclass(frozen=True)
class PosePriorConfig:
    """Sizes and the KL weight ``beta`` (module docstring)."""

    latent: int = 16
    hidden: tuple = (128, 128)
    beta: float = 0.1

    def __post_init__(self):
        if self.latent < 1 or not self.hidden:
            raise ValueError("a pose prior needs latent >= 1 and at least one hidden layer")

    @staticmethod
    def from_dict(d: dict) -> "PosePriorConfig":
        return settings_from(PosePriorConfig, d)


class PosePrior(Component):
    """The finger-pose VAE (role ``pose_prior``: :meth:`decode` a (B, latent) z into (B, 45) finger
    numbers); holds the finger numbers' normaliser as buffers."""

    kind = "pose_prior"
    Config = PosePriorConfig
    role = "pose_prior"

    def __init__(self, cfg: PosePriorConfig):
        super().__init__()
        self.cfg = cfg
        self.encoder = mlp([FINGER_POSE_DIM, *cfg.hidden, 2 * cfg.latent])
        self.decoder = mlp([cfg.latent, *reversed(cfg.hidden), FINGER_POSE_DIM])
        self.register_buffer("mean", torch.zeros(FINGER_POSE_DIM))
        self.register_buffer("std", torch.ones(FINGER_POSE_DIM))

    def prepare(self, data, task: str, hand=None) -> None:
        """The normaliser of the training grasps' finger numbers (std floored at 1e-3); augmentation turns
        the whole hand, never the fingers, so the stored grasps are what the prior sees."""
        stored = [np.asarray(sh.grasp) for sh in data.shards if sh.n_grasps]
        if not stored:
            raise ValueError("a pose prior needs at least one training grasp")
        fingers = torch.as_tensor(np.concatenate(stored)[:, 6:], dtype=torch.float32)
        self.mean.copy_(fingers.mean(0))
        self.std.copy_((fingers.std(0) if len(fingers) > 1 else torch.zeros(FINGER_POSE_DIM)).clamp_min(1e-3))

    def normaliser(self) -> dict[str, torch.Tensor]:
        return {"mean": self.mean.detach().cpu().clone(), "std": self.std.detach().cpu().clone()}

    def encode(self, fingers: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, latent) mean and log-variance of q(z | x) for (B, 45) finger numbers (radians)."""
        mu, logvar = self.encoder((fingers - self.mean) / self.std).chunk(2, -1)
        return mu, logvar.clamp(-10.0, 10.0)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """(B, 45) finger numbers (radians) of (B, latent) latents."""
        return self.decoder(z) * self.std + self.mean

    def loss(self, batch: Batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The VAE loss of the batch's grasps' finger numbers (module docstring)."""
        x = (batch.grasp[:, 6:] - self.mean) / self.std
        mu, logvar = self.encode(batch.grasp[:, 6:])
        z = mu + (0.5 * logvar).exp() * torch.randn(mu.shape, generator=generator).to(mu)
        recon = (((self.decoder(z) - x) ** 2).sum(-1)).mean()
        kl = (0.5 * (mu**2 + logvar.exp() - 1 - logvar).sum(-1)).mean()
        return {"loss": recon + self.cfg.beta * kl, "recon": recon, "kl": kl}


COMPONENT = PosePrior
