"""Scene-aware guidance of diffusion sampling: physics energies of a grasp, applied to the denoiser's x0.

Beyond the paper (issue 20; the idea of DexGrasp Anything, CVPR 2025): at each guided denoising step the
network's estimate of the clean sample ``x0`` is moved by a *normalised* gradient step down an energy of the
grasp it decodes to,

    x0 <- x0 - scale * g / max(||g||, eps),    g = d E(decode(x0)) / d x0,

and the sampler continues from the moved estimate with the network's noise estimate kept, so the sample itself moves by
``sqrt(alpha-bar_prev)`` times the shift (:func:`tohgs.models.diffusion.sample`'s ``guide``; letting the
sampler re-derive the noise from the moved x0 would cancel most of the shift at every step but the
last). The step has the same length whatever the energy's units, so ``scale`` (in the network's normalised
units) is the one knob of its strength and the weights only mix the terms. Guidance acts on the last ``start`` fraction of
the reverse process (``t <= start * T``), where x0 is a grasp worth correcting.

The energy, per sample, from what a method is given (:class:`tohgs.data.batch.Batch`, the network frame,
metres); never the evaluation's meshes:

- ``scene``: the hand's penetration into the scene cloud at the initial pose and at the goal pose (the
  hand carried by ``goal_transform`` = ``T_goal T_init^-1``), ``sum_v |min(d_v - margin, 0)|`` over the
  hand's vertices, ``d_v`` the point-to-plane signed distance to the scene cloud
  (:func:`tohgs.geometry.cloud.cloud_signed_distance`); a vertex deeper than ``max_depth`` is not counted
  (behind an open edge of the cropped cloud).
- ``object``: the hand's penetration into the object cloud, ``sum_v max(-d_v, 0)`` for vertices at most
  ``max_depth`` inside.
- ``contact``: consistency with the contact map the grasp was sampled for, ``sum_i (c_i - c_i(hand))^2``,
  ``c_i(hand) = 1 - 2 (sigmoid(alpha d_i) - 0.5)`` of each object point's distance to the nearest vertex
  (the maps' own definition, :func:`tohgs.geometry.hand_object.contact_values`).
- ``joints``: distance of the 45 finger numbers outside the hand's joint-limit box, radians (0 for a hand
  without limits, e.g. a MANO file's).

All weights 0 (or ``scale`` 0) is no guidance: :func:`guidance_step` gives the sampler no guide, so the
samples are exactly the unguided ones.

Two more levers, each off by default:

- **Guided contact sampling** (``contact_scale``): ContactDiffuser's x0 estimate (the map ``2 c - 1``) moves
  by ``contact_scale * w / ||w||`` at the guided steps, down the energy ``sum_i w_i c_i`` whose weight
  ``w_i`` in [0, 1] grows from 0 at ``near`` metres to 1 at the scene from an object point's distance map at
  the initial or the goal pose, whichever is closer (:func:`near_scene_weights`): contact moves off the
  points a hand could only touch from inside the scene (:func:`contact_guidance_step`).
- **Sample, score, keep** (``candidates``): ``candidates x S`` grasps are sampled, each scored by the
  energy above, and S kept by :func:`select_diverse`: among the lowest-energy ``pool`` fraction (at
  least S), a farthest-point pick in the evaluation's diversity distance (the summed per-vertex distance of
  two hands), starting at the lowest energy.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch

from tohgs.geometry.cloud import clearance_violation, cloud_signed_distance, even_subset
from tohgs.geometry.hand_object import contact_of_distance, contact_values
from tohgs.geometry.maps import ALPHA_DISTANCE
from tohgs.hand.layout import FINGER_POSE_DIM
from tohgs.models.guidance_settings import GuidanceSettings  # noqa: F401 (re-exported: the settings live without torch)

TERMS = ("scene", "object", "contact", "joints")


class GuidanceEnergy:
    """The guidance energy of (B, 51) network-frame grasps for one batch's objects and scenes.

    Args:
        hand: a :class:`tohgs.hand.model.HandModel` (its dtype and device are the batch's).
        points, normals: (B, N, 3) object cloud and unit outward normals at the initial pose, m.
        scene, scene_normals: (B, M, 3) scene cloud and normals (the same at both poses).
        goal_transform: (B, 4, 4) ``T_goal T_init^-1`` in the network frame.
        contact: (B, N) the sampled contact map in [0, 1], or None (the contact term is then 0).
        settings: the weights and distances.
    """

    def __init__(self, hand, points: torch.Tensor, normals: torch.Tensor, scene: torch.Tensor,
                 scene_normals: torch.Tensor, goal_transform: torch.Tensor, contact: torch.Tensor | None,
                 settings: GuidanceSettings):
        self.hand, self.s = hand, settings
        self.points, self.normals, self.scene, self.scene_normals = points, normals, scene, scene_normals
        self.goal, self.contact = goal_transform, contact
        self.sub = even_subset(hand.rest_vertices.shape[0], settings.hand_points, points.device)
        lim = hand.joint_limits.reshape(FINGER_POSE_DIM, 2).to(points)
        self.limits = lim if bool((lim[:, 1] > lim[:, 0]).any()) else None

    @classmethod
    def of_batch(cls, hand, batch, settings: GuidanceSettings) -> "GuidanceEnergy":
        """The energy of a :class:`tohgs.data.batch.Batch` (its contact map, if it has one)."""
        return cls(hand, batch.points, batch.normals, batch.scene, batch.scene_normals, batch.goal_transform,
                   batch.contact, settings)

    def terms(self, grasp: torch.Tensor) -> dict[str, torch.Tensor]:
        """The unweighted terms, each (B,), of (B, 51) grasps (differentiable in the grasps)."""
        s = self.s
        verts = self.hand(grasp).vertices
        sub = verts[:, self.sub]
        goal = sub @ self.goal[:, :3, :3].transpose(1, 2) + self.goal[:, None, :3, 3]
        scene = 0
        for pts in (sub, goal):
            d = cloud_signed_distance(pts, self.scene, self.scene_normals)
            scene = scene + clearance_violation(d, s.margin, s.max_depth)
        obj = clearance_violation(cloud_signed_distance(sub, self.points, self.normals), 0.0, s.max_depth)
        out = {"scene": scene, "object": obj}
        if self.contact is not None and s.w_contact > 0:
            c, _ = contact_values(self.points, verts, s.alpha)
            out["contact"] = ((c - self.contact) ** 2).sum(-1)
        else:
            out["contact"] = torch.zeros_like(obj)
        if self.limits is not None and s.w_joints > 0:
            q = grasp[:, 6:]
            out["joints"] = ((self.limits[:, 0] - q).clamp(min=0) + (q - self.limits[:, 1]).clamp(min=0)).sum(-1)
        else:
            out["joints"] = torch.zeros_like(obj)
        return out

    def __call__(self, grasp: torch.Tensor) -> torch.Tensor:
        """(B,) the weighted sum of the terms."""
        w = self.s.weights
        return sum(w[k] * v for k, v in self.terms(grasp).items() if w[k] > 0)


def guidance_step(decode: Callable[[torch.Tensor], torch.Tensor], energy: Callable[[torch.Tensor], torch.Tensor],
                  settings: GuidanceSettings, timesteps: int, eps: float = 1e-8
                  ) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor | None] | None:
    """The ``guide`` of :func:`tohgs.models.diffusion.sample`: at the guided steps (``t <= start * T``) the
    (B, D) shift ``scale * g / ||g||`` per sample, ``g`` the gradient in x0 of ``energy(decode(x0))`` (B,)
    (a sample whose gradient vanishes is not moved); None at the other steps.

    ``decode`` maps (B, D) normalised vectors to (B, 51) grasps, differentiably; ``timesteps`` is the
    schedule's T. Without :attr:`GuidanceSettings.active`: None (no guide: the unguided sampler).
    """
    if not settings.active:
        return None
    t_max = settings.start * timesteps

    def guide(x0: torch.Tensor, t: torch.Tensor) -> torch.Tensor | None:
        if float(t.max()) > t_max:
            return None
        with torch.enable_grad():
            x = x0.detach().requires_grad_(True)
            (g,) = torch.autograd.grad(energy(decode(x)).sum(), x)
        norm = g.flatten(1).norm(dim=1).reshape(-1, *([1] * (g.dim() - 1)))
        return torch.where(norm > eps, settings.scale * g / norm.clamp(min=eps), torch.zeros_like(g))

    return guide


def near_scene_weights(d_init: torch.Tensor, d_goal: torch.Tensor, near: float, alpha: float = ALPHA_DISTANCE) -> torch.Tensor:
    """(B, N) weights in [0, 1] of object points by their nearness to the scene at either pose: 0 at
    ``near`` metres or farther, 1 at the scene, linear in the distance map's value in between.

    Args:
        d_init, d_goal: (B, N) distance maps ``1 - 2 (sigmoid(alpha d) - 0.5)`` to the initial and goal
            scene (:mod:`tohgs.data.maps`), in [0, 1] (1 at the scene).
        near: the distance (m) at which the weight reaches 0.
        alpha: the maps' sharpness, 1/m.
    """
    at_near = contact_of_distance(torch.tensor(alpha * near, dtype=torch.float64), 1.0)
    d = torch.maximum(d_init, d_goal)
    return ((d - float(at_near)) / (1.0 - float(at_near))).clamp(0.0, 1.0)


def contact_guidance_step(weights: torch.Tensor, settings: GuidanceSettings, timesteps: int, eps: float = 1e-8
                          ) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor | None] | None:
    """The ``guide`` of ContactDiffuser's sampler: at the guided steps the (B, N) shift
    ``contact_scale * w / ||w||`` of the x0 estimate (the map ``2 c - 1``), the normalised gradient of
    ``sum_i w_i c_i`` (linear in x0, so the gradient is ``w / 2`` wherever x0 is); a sample with no point near
    the scene is not moved. None without :attr:`GuidanceSettings.contact_active`.

    Args:
        weights: (B, N) :func:`near_scene_weights`.
        settings: ``contact_scale`` and ``start``.
        timesteps: the schedule's T.
    """
    if not settings.contact_active:
        return None
    t_max = settings.start * timesteps
    norm = weights.norm(dim=1, keepdim=True)
    shift = torch.where(norm > eps, settings.contact_scale * weights / norm.clamp(min=eps), torch.zeros_like(weights))

    def guide(x0: torch.Tensor, t: torch.Tensor) -> torch.Tensor | None:
        return None if float(t.max()) > t_max else shift.to(x0)

    return guide


def hand_distances(vertices: torch.Tensor) -> torch.Tensor:
    """(K, K) the evaluation's diversity distance of K hands: the summed per-vertex L2 distance, m.

    Args:
        vertices: (K, V, 3) hand vertices, m.
    """
    k = vertices.shape[0]
    flat = vertices.reshape(k, 1, -1, 3)
    return torch.stack([(flat[i] - vertices).norm(dim=-1).sum(-1) for i in range(k)])


def select_diverse(energy: torch.Tensor, vertices: torch.Tensor, keep: int, pool: float) -> torch.Tensor:
    """Indices of ``keep`` of K candidates: the lowest-energy ``max(keep, ceil(pool * K))`` form the pool,
    and from it a farthest-point pick in :func:`hand_distances` starting at the lowest energy (each next
    candidate the one farthest from those picked; ties to the lower energy).

    Args:
        energy: (K,) candidates' energies (lower is better).
        vertices: (K, V, 3) their hands' vertices (any even subset), m.
        keep: how many to keep, at most K.
        pool: the fraction of the candidates, by energy, the pick chooses from, in (0, 1].

    Returns:
        (keep,) long indices into the candidates, in pick order.
    """
    k = energy.shape[0]
    if not 0 < keep <= k:
        raise ValueError(f"cannot keep {keep} of {k} candidates")
    size = min(k, max(keep, math.ceil(pool * k)))
    order = torch.argsort(energy, stable=True)[:size]  # the pool, lowest energy first
    dist = hand_distances(vertices[order])
    picked = [0]
    nearest = dist[0].clone()
    for _ in range(keep - 1):
        nearest[picked] = -1.0
        nxt = int(torch.argmax(nearest))  # the first maximum: the lowest energy among ties
        picked.append(nxt)
        nearest = torch.minimum(nearest, dist[nxt])
    return order[torch.as_tensor(picked, device=order.device)]
