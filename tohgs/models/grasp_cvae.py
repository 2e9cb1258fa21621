"""GraspCVAE (GraspTTA's generator, Jiang et al. ICCV 2021): a conditional VAE over the 51-number grasp,
conditioned on the object cloud, with the hand model in the loss.

- Object encoder: a PointNet (shared per-point MLP, max-pool) on xyz with the bounding-box diagonal
  repeated per point (GraspTTA's fourth channel, so the encoder knows the object's size), and with
  ``contact_channel`` the contact map as one more channel: M-GraspTTA (paper section 5.1), whose input
  carries a (predicted or ground-truth) task-aware map. Without it the model is object-centric: it sees
  the object cloud only, no scene, no task.
- Hand encoder (training only): a PointNet on the true hand's vertices, each carrying its rest position
  as its feature (which vertex it is).
- Both PointNets read coordinates in decimetres (``ENCODER_SCALE``: in metres the LayerNorms leave
  almost no geometry, and the model does not learn).
- Encoder MLP on both global features -> mean and log-variance of a ``latent``-d Gaussian; decoder MLP on
  ``[z, object feature]`` -> the grasp as a normalised palm-centred 6D vector (54 numbers,
  :mod:`tohgs.geometry.rot6d`: continuous where the axis-angle jumps; per-dimension mean and std of the
  training grasps after the augmentation, as GraspDiffuser's normaliser), turned back into the 51 numbers.
  At inference z ~ N(0, I).

Sizes (GraspTTA: 1024-d PointNet features, encoder [2048, 512, 256], decoder [1088, 1024, 256], 64-d latent,
3000 points) are config values; the default is laptop-sized.

Loss per sample, averaged over the batch (the official code's terms; its weights [1, 0.1, 1000, 10, 10]
are for its units, ours are for the units below and are config values):

``L = w_param L_param + w_recon L_recon + w_kl KL + w_pen min(L_pen, 1) + w_cons L_cons``

- ``L_param``: squared error of the normalised vector, summed over its 54 numbers;
- ``L_recon``: squared distance of the decoded hand's vertices to the true hand's, summed (m^2);
- ``KL``: of the posterior from N(0, I), summed over the latent;
- ``L_pen``, ``L_cons``: GraspDiffuser's penetration and contact-consistency terms
  (:mod:`tohgs.models.hand_object_loss`, the two models' one definition: point sums scaled to 2048 points).

Shapes: points (B, N, 3) m (network frame), contact (B, N) in [0, 1], grasp (B, 51).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from tohgs.data.batch import Batch
from tohgs.geometry.rot6d import VECTOR_DIM, grasp_from_palm_rot6d, palm_rot6d
from tohgs.hand.model import HandModel
from tohgs.models.component import Component, seen_grasps
from tohgs.models.hand_object_loss import hand_object_terms, weighted_pen_cons
from tohgs.models.layers import mlp
from tohgs.models.pointnet2 import PointNet
from tohgs.settings import settings_from

# The PointNets read coordinates (and the bounding-box diagonal) in decimetres: in metres a hand or an
# object spans about 0.2 units, so the first layer's output is its bias plus a small xyz term, and the
# LayerNorm after it all but removes the geometry (a model trained so did not learn: its posterior
# collapsed and its grasps were the mean grasp). GraspTTA's PointNets normalise with BatchNorm instead.
ENCODER_SCALE = 10.0


@dataclass(frozen=True)
class GraspCVAEConfig:
    """Sizes, the contact channel and the loss weights (module docstring)."""

    latent: int = 64
    object_mlp: tuple = (64, 128, 256)
    hand_mlp: tuple = (64, 128, 256)
    encoder: tuple = (256, 128)
    decoder: tuple = (256, 128)
    contact_channel: bool = False  # M-GraspTTA: the contact map as a fourth-plus-one input channel
    hand_points: int = 256  # hand vertices the hand encoder reads (a fixed, evenly spread subset; 0: all)
    w_param: float = 1.0
    w_recon: float = 1.0
    w_kl: float = 0.05
    w_pen: float = 5.0
    w_cons: float = 0.002

    def __post_init__(self):
        if self.latent < 1:
            raise ValueError(f"GraspCVAE latent must be at least 1, not {self.latent}")

    @staticmethod
    def from_dict(d: dict) -> "GraspCVAEConfig":
        return settings_from(GraspCVAEConfig, d)  # YAML lists as tuples; an unknown key named


def bbox_diagonal(points: torch.Tensor) -> torch.Tensor:
    """(B,) the axis-aligned bounding-box diagonal of (B, N, 3) points, m."""
    return (points.max(1).values - points.min(1).values).norm(dim=-1)


class GraspCVAE(Component):
    """Conditional VAE over normalised grasps (a grasp generator: :meth:`sample_grasps`); holds the grasp
    normaliser as buffers (set from the training data by :meth:`prepare`)."""

    kind = "grasp_cvae"
    Config = GraspCVAEConfig
    role = "grasp"
    needs_hand = True

    @property
    def reads_contact(self) -> bool:
        """Whether it reads the batch's contact maps (``contact_channel``: M-GraspTTA's)."""
        return bool(self.cfg.contact_channel)

    def __init__(self, cfg: GraspCVAEConfig):
        super().__init__()
        self.cfg = cfg
        self._training: dict = {}
        self.object_encoder = PointNet(1 + int(cfg.contact_channel), list(cfg.object_mlp))
        self.hand_encoder = PointNet(3, list(cfg.hand_mlp))  # posed xyz, with each vertex's rest xyz
        fo, fh = self.object_encoder.global_dim, self.hand_encoder.global_dim
        self.encoder = mlp([fo + fh, *cfg.encoder], last_plain=False)
        self.to_stats = nn.Linear(cfg.encoder[-1] if cfg.encoder else fo + fh, 2 * cfg.latent)
        self.decoder = mlp([cfg.latent + fo, *cfg.decoder, VECTOR_DIM])
        self.register_buffer("grasp_mean", torch.zeros(VECTOR_DIM))
        self.register_buffer("grasp_std", torch.ones(VECTOR_DIM))
        self.register_buffer("wrist", torch.zeros(3))
        self.register_buffer("palm", torch.zeros(3))

    # -- the data the training fixes ---------------------------------------------------------------------
    def prepare(self, data, task: str, hand: HandModel | None = None) -> None:
        """Before training: the hand (the loss poses it), the normaliser of the training grasps as the
        augmentation presents them, and the shards' contact alpha."""
        if hand is None:
            raise ValueError("GraspCVAE trains with the hand model in the loss; pass hand=")
        self.wrist.copy_(hand.rest_joints[0].to(self.wrist))
        self.palm.copy_(hand.rest_vertices[torch.as_tensor(hand.assets.palm_ids)].mean(0).to(self.palm))
        grasps = seen_grasps(self, data, self.grasp_mean.device)
        self.grasp_mean.copy_(grasps.mean(0))
        std = grasps.std(0) if grasps.shape[0] > 1 else torch.zeros_like(grasps[0])
        self.grasp_std.copy_(std.clamp_min(1e-3))
        self._training = {"hand": hand, "alpha_contact": data.shards[0].alpha_contact}

    def in_frame(self, grasp: torch.Tensor, points: torch.Tensor, contact: torch.Tensor, normals: torch.Tensor
                 ) -> torch.Tensor:
        """(B, 54) the grasps as the network regresses them: palm-centred 6D vectors of the network frame
        (:mod:`tohgs.geometry.rot6d`; what the normaliser measures)."""
        return palm_rot6d(grasp, self.wrist, self.palm)

    def normaliser(self) -> dict[str, torch.Tensor]:
        return {"mean": self.grasp_mean.detach().cpu().clone(), "std": self.grasp_std.detach().cpu().clone()}

    # -- the network ---------------------------------------------------------------------------------------
    def object_feature(self, points: torch.Tensor, contact: torch.Tensor | None) -> torch.Tensor:
        """(B, F) the object encoder's global feature of (B, N, 3) points (with their (B, N) map when the
        model has the contact channel)."""
        diag = ENCODER_SCALE * bbox_diagonal(points)[:, None, None].expand(-1, points.shape[1], 1)
        feats = [diag]
        if self.cfg.contact_channel:
            if contact is None:
                raise ValueError("this GraspCVAE reads a contact map (contact_channel); the batch has none")
            feats.append(contact[..., None])
        return self.object_encoder(ENCODER_SCALE * points, torch.cat(feats, -1))[1]

    def hand_feature(self, hand_verts: torch.Tensor, rest_vertices: torch.Tensor) -> torch.Tensor:
        """(B, F) the hand encoder's global feature of (B, V, 3) posed hand vertices; each vertex carries its
        (V, 3) rest position as its feature (which vertex it is: a max-pooled PointNet that sees only the
        posed cloud must infer the hand's orientation from its shape, and learned it too slowly here)."""
        v = hand_verts.shape[1]
        k = v if self.cfg.hand_points <= 0 else min(v, self.cfg.hand_points)
        ids = torch.linspace(0, v - 1, k, device=hand_verts.device).round().long()
        rest = (ENCODER_SCALE * rest_vertices[ids].to(hand_verts))[None].expand(hand_verts.shape[0], -1, -1)
        return self.hand_encoder(ENCODER_SCALE * hand_verts[:, ids], rest)[1]

    def posterior(self, obj: torch.Tensor, hand_feat: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance (B, latent) of q(z | object, hand)."""
        stats = self.to_stats(self.encoder(torch.cat([obj, hand_feat], -1)))
        mu, logvar = stats.chunk(2, -1)
        return mu, logvar.clamp(-10.0, 10.0)

    def decode_vector(self, z: torch.Tensor, obj: torch.Tensor) -> torch.Tensor:
        """(B, 54) normalised vectors from latents (B, latent) and object features (B, F)."""
        return self.decoder(torch.cat([z, obj], -1))

    def decode(self, z: torch.Tensor, obj: torch.Tensor) -> torch.Tensor:
        """(B, 51) network-frame grasps from latents (B, latent) and object features (B, F)."""
        return grasp_from_palm_rot6d(self.decode_vector(z, obj) * self.grasp_std + self.grasp_mean, self.wrist, self.palm)

    def normalise(self, grasp: torch.Tensor) -> torch.Tensor:
        """(B, 54) the normalised vectors of (B, 51) grasps."""
        return (palm_rot6d(grasp, self.wrist, self.palm) - self.grasp_mean) / self.grasp_std

    # -- training and sampling ---------------------------------------------------------------------------
    def loss(self, batch: Batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The weighted sum of the five terms (module docstring), each term's mean and its weighted
        contribution (``w_<term>``) for the log."""
        if not self._training:
            raise ValueError("GraspCVAE.loss needs prepare() first (the hand and the normaliser)")
        hand, dev = self._training["hand"], batch.device
        with torch.no_grad():
            true_v = hand(batch.grasp).vertices
        obj = self.object_feature(batch.points, batch.contact)
        mu, logvar = self.posterior(obj, self.hand_feature(true_v, hand.rest_vertices))
        eps = torch.randn(mu.shape, generator=generator).to(dev)
        z = mu + (0.5 * logvar).exp() * eps
        vec = self.decode_vector(z, obj)
        pred = grasp_from_palm_rot6d(vec * self.grasp_std + self.grasp_mean, self.wrist, self.palm)
        terms = self.terms(hand, pred, vec, batch, true_v)
        terms["kl"] = 0.5 * (mu**2 + logvar.exp() - 1 - logvar).sum(-1)
        c = self.cfg
        weighted = {"param": c.w_param * terms["param"].mean(), "recon": c.w_recon * terms["recon"].mean(),
                    "kl": c.w_kl * terms["kl"].mean(), **weighted_pen_cons(terms, c.w_pen, c.w_cons)}
        return {"loss": sum(weighted.values()), **{k: v.mean() for k, v in terms.items()},
                **{f"w_{k}": v for k, v in weighted.items()}}

    def terms(self, hand: HandModel, pred: torch.Tensor, vec: torch.Tensor, batch: Batch, true_v: torch.Tensor
              ) -> dict[str, torch.Tensor]:
        """The per-sample (B,) parameter, vertex, penetration and consistency terms of (B, 51) decoded grasps
        (their (B, 54) normalised vectors ``vec``) against the batch's true grasps (whose (B, V, 3) vertices
        are ``true_v``)."""
        l_param = ((vec - self.normalise(batch.grasp)) ** 2).sum(-1)
        pred_v = hand(pred).vertices
        return {"param": l_param, **hand_object_terms(batch.points, pred_v, true_v, batch.contact, hand.closed_faces,
                                                      self._training["alpha_contact"])}

    @torch.no_grad()
    def reconstruct(self, batch: Batch, hand: HandModel) -> torch.Tensor:
        """(B, 51) the posterior-mean reconstructions of the batch's grasps (the sanity check's measure)."""
        obj = self.object_feature(batch.points, batch.contact)
        mu, _ = self.posterior(obj, self.hand_feature(hand(batch.grasp).vertices, hand.rest_vertices))
        return self.decode(mu, obj)

    @torch.no_grad()
    def sample_grasps(self, batch: Batch, sampler: str, steps: int, generator: torch.Generator,
                      guidance: float = 1.0) -> torch.Tensor:
        """(B, 51) network-frame grasps, one per sample, from z ~ N(0, I) (``generator``); the diffusion
        settings (``sampler``, ``steps``, ``guidance``) do not apply."""
        obj = self.object_feature(batch.points, batch.contact)
        z = torch.randn((batch.size, self.cfg.latent), generator=generator).to(batch.device)
        return self.decode(z, obj)


COMPONENT = GraspCVAE
