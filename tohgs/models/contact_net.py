"""ContactNet (GraspTTA's contact predictor, Jiang et al. ICCV 2021): the contact map a good grasp near a
given hand would make on the object. GraspTTA's test-time adaptation pulls the hand's own map towards it
(the consistency term, :mod:`tohgs.grasps.tta`).

Per object point the network reads the object's PointNet features (per point and pooled), the hand's
pooled PointNet feature and the point's current contact value with the hand (``1 - 2 (sigmoid(alpha d)
- 0.5)``, d the distance to the nearest hand vertex); a per-point MLP with a sigmoid gives the map. The
official network fuses the two clouds' per-point features with a convolution across their point indices
(3778 -> 3000), which fixes the point count and has to learn distance from scratch; giving the distance
directly does neither. Both PointNets read decimetres, as GraspCVAE's (``ENCODER_SCALE``).

Training (the official training code is not public): the input hand is the true grasp perturbed (Gaussian
noise on the translation, the global rotation and the finger numbers, ``noise``), the target the true
hand's contact map, so the network learns the map that the nearby good grasp makes: a denoiser of contact,
which is what the adaptation needs from it. Loss: the mean squared error of the maps.

Shapes: points (B, N, 3) m, hand vertices (B, V, 3) m, maps (B, N) in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from tohgs.data.batch import Batch
from tohgs.geometry.hand_object import contact_values
from tohgs.geometry.maps import ALPHA_CONTACT
from tohgs.hand.layout import FINGER_POSE_DIM, GLOBAL_ROTATION_DIM, TRANSLATION_DIM
from tohgs.hand.model import HandModel
from tohgs.models.component import Component
from tohgs.models.grasp_cvae import ENCODER_SCALE, bbox_diagonal
from tohgs.models.layers import mlp
from tohgs.models.pointnet2 import PointNet
from tohgs.settings import settings_from


@dataclass(frozen=True)
class ContactNetConfig:
    """Sizes; ``noise`` the training perturbation's standard deviations (translation m, global rotation
    rad, finger numbers rad); ``hand_points`` as GraspCVAE's."""

    object_mlp: tuple = (64, 128)
    hand_mlp: tuple = (64, 128)
    head: tuple = (128, 64)
    hand_points: int = 256
    noise: tuple = (0.01, 0.1, 0.1)

    @staticmethod
    def from_dict(d: dict) -> "ContactNetConfig":
        return settings_from(ContactNetConfig, d)  # YAML lists as tuples; an unknown key named


def perturb_grasps(grasp: torch.Tensor, noise: tuple, generator: torch.Generator) -> torch.Tensor:
    """(B, 51) grasps with Gaussian noise of standard deviations ``noise`` = (translation m, global
    rotation rad, finger numbers rad) added to the three parts (drawn from ``generator``)."""
    sigma = torch.cat([torch.full((TRANSLATION_DIM,), noise[0]), torch.full((GLOBAL_ROTATION_DIM,), noise[1]),
                       torch.full((FINGER_POSE_DIM,), noise[2])])
    return grasp + torch.randn(grasp.shape, generator=generator).to(grasp) * sigma.to(grasp)


@dataclass(frozen=True)
class ObjectCache:
    """What ContactNet computes of fixed object points once for a whole adaptation (:meth:`ContactNet.object_cache`).

    Attributes:
        local: (B, N, F) the object encoder's per-point features.
        glob: (B, F) its pooled feature.
        projected: (B, N, H) the per-point part of the head's first layer without the contact value,
            ``local @ W_local^T + b`` (H = ``head[0]``).
    """

    local: torch.Tensor
    glob: torch.Tensor
    projected: torch.Tensor


class ContactNet(Component):
    """Per-point contact regression from an object and a hand (role ``hand_contact``: :meth:`predict_map`)."""

    kind = "contact_net"
    Config = ContactNetConfig
    role = "hand_contact"
    needs_hand = True

    def __init__(self, cfg: ContactNetConfig):
        super().__init__()
        self.cfg = cfg
        self._training: dict = {}
        self.object_encoder = PointNet(1, list(cfg.object_mlp))
        self.hand_encoder = PointNet(0, list(cfg.hand_mlp))
        # the head's first layer, split: per point (local feature, current contact) plus the pooled features
        # (the same for every point, so projected once per sample; equal to one layer on the concatenation)
        h0 = cfg.head[0]
        self.point_in = nn.Linear(self.object_encoder.local_dim + 1, h0)
        self.pooled_in = nn.Linear(self.object_encoder.global_dim + self.hand_encoder.global_dim, h0, bias=False)
        self.head = nn.Sequential(nn.LayerNorm(h0), nn.GELU(), mlp([*cfg.head, 1]))
        self.register_buffer("alpha_contact", torch.tensor(ALPHA_CONTACT))

    def prepare(self, data, task: str, hand: HandModel | None = None) -> None:
        """Before training: the hand (the loss poses it) and the shards' contact alpha."""
        if hand is None:
            raise ValueError("ContactNet trains with the hand model; pass hand=")
        self.alpha_contact.fill_(data.shards[0].alpha_contact)
        self._training = {"hand": hand}

    def object_features(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The object encoder's per-point (B, N, F) and pooled (B, F) features of (B, N, 3) points (what
        does not change while a hand is adapted: computed once)."""
        diag = ENCODER_SCALE * bbox_diagonal(points)[:, None, None].expand(-1, points.shape[1], 1)
        return self.object_encoder(ENCODER_SCALE * points, diag)

    def object_cache(self, points: torch.Tensor) -> ObjectCache:
        """:class:`ObjectCache` of (B, N, 3) points (no gradient needed: the points do not move)."""
        local, glob = self.object_features(points)
        h = self.point_in.in_features - 1
        return ObjectCache(local, glob, nn.functional.linear(local, self.point_in.weight[:, :h], self.point_in.bias))

    def predict_map_cached(self, cache: ObjectCache, hand_verts: torch.Tensor, current: torch.Tensor,
                           rows: int = 4) -> torch.Tensor:
        """:meth:`predict_map` with the object's part from ``cache`` (:meth:`object_cache`): (B, N) maps of
        the (B, V, 3) hands with their (B, N) current maps. The same network; the first layer is split
        into the cached ``local @ W_local^T + b`` plus ``current w_current`` (the same sum in another order:
        float32 rounding, about 1e-7 of the map), which removes its (N x F x H) product per hand.

        The hands go through ``rows`` at a time, so that their (rows N, H) activations stay in the cache
        (the whole batch's are several MB): 2.2x faster than :meth:`predict_map` at 16 hands of 512
        points. Every layer is per point or per hand, so a hand's map does not depend on the other hands'
        numbers; the products' rounding may depend on how many hands share a chunk (1 ulp), so a hand's
        map is bit for bit the same whenever its chunk starts at the same hand of its problem (run each
        problem's rows alone, :func:`tohgs.grasps.tta.by_problem`)."""
        v = hand_verts.shape[1]
        k = v if self.cfg.hand_points <= 0 else min(v, self.cfg.hand_points)
        sub = torch.linspace(0, v - 1, k, device=hand_verts.device).round().long()
        h = self.point_in.in_features - 1
        w_current = self.point_in.weight[:, h]  # (H,)
        out = []
        for start in range(0, hand_verts.shape[0], rows):
            part = slice(start, start + rows)
            hp = hand_verts[part, sub]  # (r, k, 3)
            hand_glob = self.hand_encoder(ENCODER_SCALE * hp, hp[..., :0])[1]  # (r, F)
            pooled = self.pooled_in(torch.cat([cache.glob[part], hand_glob], -1))  # (r, H)
            x = torch.addcmul(cache.projected[part], current[part, :, None], w_current) + pooled[:, None]  # (r, N, H)
            out.append(torch.sigmoid(self.head(x)[..., 0]))
        return torch.cat(out) if out else current.new_zeros(current.shape)

    def predict_map(self, points: torch.Tensor, hand_verts: torch.Tensor, current: torch.Tensor | None = None,
                    object_features: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
        """(B, N) the contact map a good grasp near the (B, V, 3) hands would make on the (B, N, 3) points.
        ``current``, the hands' own (B, N) map, and ``object_features`` (:meth:`object_features`) are
        computed when not given."""
        v = hand_verts.shape[1]
        if current is None:
            current, _ = contact_values(points, hand_verts, float(self.alpha_contact))
        local, glob = self.object_features(points) if object_features is None else object_features
        k = v if self.cfg.hand_points <= 0 else min(v, self.cfg.hand_points)
        hp = hand_verts[:, torch.linspace(0, v - 1, k, device=hand_verts.device).round().long()]
        hand_glob = self.hand_encoder(ENCODER_SCALE * hp, hp[..., :0])[1]
        h = self.point_in(torch.cat([local, current[..., None]], -1)) + self.pooled_in(torch.cat([glob, hand_glob], -1))[:, None]
        return torch.sigmoid(self.head(h)[..., 0])

    def loss(self, batch: Batch, generator: torch.Generator) -> dict[str, torch.Tensor]:
        """The maps' mean squared error for perturbed true hands (module docstring)."""
        if not self._training:
            raise ValueError("ContactNet.loss needs prepare() first (the hand)")
        hand = self._training["hand"]
        with torch.no_grad():
            verts = hand(perturb_grasps(batch.grasp, self.cfg.noise, generator)).vertices
        pred = self.predict_map(batch.points, verts)
        return {"loss": nn.functional.mse_loss(pred, batch.contact)}


COMPONENT = ContactNet
