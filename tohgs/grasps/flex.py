"""FLEX for hands (Tendulkar et al. CVPR 2023, re-purposed as the paper's section 5.1 does): grasps found
by optimisation in the latent space of a learned pose prior, kept out of the scene at the initial and at
the goal pose.

FLEX poses a full body with a VPoser latent, a global rotation and translation, and drives them with
hand-object, penetration and pose-prior losses; its released code has no hand-only variant, so tohgs
follows ``../shared/BASELINES.md`` ("FLEX"). Per test configuration, a batch of ``batch`` candidates
(more than the S grasps asked for), each its own problem:

- unknowns: z (the :class:`tohgs.models.pose_prior.PosePrior` latent; its decoder gives the 45 finger
  numbers, clamped to the joint limits), the global rotation (axis-angle) and translation;
- ``E_fit = w_fit sum_g min_{c in g} |c - o(c)|``: each of the six contact groups (the five fingers' and
  the palm's contact candidates, :attr:`tohgs.hand.assets.HandAssets.contact_ids`) touches the object
  with its nearest candidate, ``o(c)`` the nearest object point (FLEX's hand-object term pulls the hand's
  contact vertices onto the object);
- ``E_object = w_object sum_v max(-s_o(v), 0)``: hand vertices inside the object, ``s_o`` the point-to-plane
  signed distance to the object cloud (:class:`tohgs.geometry.cloud.CloudIndex`);
- ``E_obstacle = w_obstacle sum_{pose} sum_v |min(s_s(v) - margin, 0)|`` at the initial pose and at the
  goal pose (the hand carried by ``T_goal T_init^-1``), ``s_s`` the signed distance to the **scene cloud**
  the method is given (support, obstacles, base; never the evaluation's meshes): FLEX's obstacle loss on
  the inside points, with its 5 mm margin;
- ``E_prior = w_prior |z|^2``.

The penetration sums run over an even subset of ``hand_points`` hand vertices, and a point deeper than
``max_depth`` behind a cloud counts as outside (a cloud is open: see :mod:`tohgs.geometry.cloud`). The
nearest cloud points are searched every ``search_every`` steps and kept in between (as ICP keeps its
correspondences). Adam for ``steps`` steps; at each step of ``drop_at`` the worse half of the candidates
(by their current energy) is dropped; each candidate's best iterate is kept, and the S best of the
survivors are returned. Start: the hands around the object with the palm facing it
(:func:`tohgs.grasps.synthesis.initial_grasps`'s placement), z = 0 (the prior's mean pose). FLEX runs
about 500 steps and drops at 100, 150, 200, 250 and 300 (``config/paper.yaml``); the laptop default is
smaller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from tohgs.geometry.cloud import CloudIndex, clearance_violation, even_subset
from tohgs.grasps.synthesis import SynthesisSettings, initial_grasps
from tohgs.grasps.tta import clamp_to_limits
from tohgs.hand.layout import FINGERS
from tohgs.hand.model import HandModel


@dataclass(frozen=True)
class FlexSettings:
    """The optimisation (module docstring); lengths in metres, learning rates per unknown."""

    steps: int = 200
    batch: int = 64
    drop_at: tuple = (60, 120)
    lr_latent: float = 0.05
    lr_rotation: float = 0.02
    lr_translation: float = 0.005
    w_fit: float = 10.0
    w_object: float = 10.0
    w_obstacle: float = 10.0
    w_prior: float = 0.01
    margin: float = 0.005
    max_depth: float = 0.05
    hand_points: int = 512
    search_every: int = 5
    init_distance: tuple = (0.01, 0.03)

    def __post_init__(self):
        if self.steps < 0 or self.batch < 1 or self.search_every < 1:
            raise ValueError("FLEX needs steps >= 0, batch >= 1 and search_every >= 1")
        if list(self.drop_at) != sorted(set(self.drop_at)) or any(d < 1 for d in self.drop_at):
            raise ValueError(f"drop_at must be increasing positive steps, got {list(self.drop_at)}")

    def survivors(self) -> int:
        """How many candidates are left after the drops within ``steps``."""
        n = self.batch
        for d in self.drop_at:
            if d < self.steps:
                n = max(1, n // 2)
        return n


def contact_groups(hand: HandModel) -> torch.Tensor:
    """(C,) the group of each contact candidate: 0-4 the five fingers (in :data:`FINGERS`' order), 5 the palm."""
    of_part = torch.full((16,), 5, dtype=torch.long)
    for g, parts in enumerate(FINGERS.values()):
        of_part[list(parts)] = g
    return of_part[hand.part_labels[hand.contact_ids].cpu()].to(hand.part_labels.device)


class FlexProblem:
    """One configuration's energy (module docstring) for (B, 51) grasps; the nearest cloud points are
    kept per candidate between searches (:meth:`energy` with ``search``)."""

    def __init__(self, hand: HandModel, points: torch.Tensor, normals: torch.Tensor, scene: torch.Tensor,
                 scene_normals: torch.Tensor, goal_transform: torch.Tensor, settings: FlexSettings):
        self.hand, self.s = hand, settings
        self.object = CloudIndex(points, normals)
        self.scene = CloudIndex(scene, scene_normals)
        self.goal = goal_transform
        self.sub = even_subset(hand.rest_vertices.shape[0], settings.hand_points, points.device)
        self.groups = contact_groups(hand)
        self.kept: dict[str, torch.Tensor] = {}

    def select(self, keep: torch.Tensor) -> None:
        """Keep the kept correspondences of the (B',) candidates ``keep`` only."""
        self.kept = {k: v[keep] for k, v in self.kept.items()}

    def energy(self, grasp: torch.Tensor, z: torch.Tensor, search: bool = True) -> dict[str, torch.Tensor]:
        """The weighted terms (B,) and their sum ``"energy"`` of (B, 51) grasps with (B, L) latents."""
        s = self.s
        verts = self.hand(grasp).vertices
        sub = verts[:, self.sub]
        cand = verts[:, self.hand.contact_ids]
        goal = sub @ self.goal[:3, :3].T + self.goal[:3, 3]
        if search or not self.kept:
            self.kept = {"object": self.object.nearest(sub), "contact": self.object.nearest(cand),
                         "init": self.scene.nearest(sub), "goal": self.scene.nearest(goal)}
        d = self.object.distance(cand, self.kept["contact"])  # (B, C)
        per_group = torch.full((d.shape[0], 6), float("inf"), dtype=d.dtype, device=d.device)
        per_group = per_group.scatter_reduce(1, self.groups.expand_as(d), d, "amin")
        terms = {"fit": s.w_fit * per_group.sum(-1)}
        so = self.object.signed_distance(sub, self.kept["object"])
        terms["object"] = s.w_object * ((so < 0) & (so > -s.max_depth)).float().mul(-so).sum(-1)
        obstacle = 0
        for key, pts in (("init", sub), ("goal", goal)):
            ss = self.scene.signed_distance(pts, self.kept[key])
            obstacle = obstacle + clearance_violation(ss, s.margin, s.max_depth)
        terms["obstacle"] = s.w_obstacle * obstacle
        terms["prior"] = s.w_prior * (z**2).sum(-1)
        return {**terms, "energy": sum(terms.values())}

    def opp(self, grasp: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B,) each hand's share of (subset) vertices inside the scene cloud at the initial and the goal pose."""
        with torch.no_grad():
            sub = self.hand(grasp).vertices[:, self.sub]
            goal = sub @ self.goal[:3, :3].T + self.goal[:3, 3]
            out = []
            for pts in (sub, goal):
                ss = self.scene.signed_distance(pts, self.scene.nearest(pts))
                out.append(((ss < 0) & (ss > -self.s.max_depth)).float().mean(-1))
            return out[0], out[1]


def start_grasps(hand: HandModel, points: torch.Tensor, batch: int, settings: FlexSettings,
                 generator: torch.Generator) -> torch.Tensor:
    """(B, 51) starts: hands around the object, palm facing it, at ``init_distance`` beyond its extent
    (the prior synthesis' placement); the finger numbers are replaced by the prior's."""
    syn = SynthesisSettings(batch=batch, init_distance=tuple(settings.init_distance), init_jitter=0.0)
    pose, _ = initial_grasps(hand, points.detach().cpu().numpy().astype(np.float64), syn, generator)
    return pose.to(points)


def optimise(hand: HandModel, prior, points: torch.Tensor, normals: torch.Tensor, scene: torch.Tensor,
             scene_normals: torch.Tensor, goal_transform: torch.Tensor, samples: int, settings: FlexSettings,
             generator: torch.Generator, start: torch.Tensor | None = None
             ) -> tuple[torch.Tensor, dict[str, list[float]]]:
    """The ``samples`` best grasps (S, 51) of one configuration (module docstring) and the history of the
    mean energy and its terms over the live candidates per step.

    Args:
        hand: the hand model; ``prior``: a :class:`tohgs.models.pose_prior.PosePrior` (eval mode).
        points, normals: (N, 3) the object cloud and its outward normals (network frame, m).
        scene, scene_normals: (M, 3) the scene cloud and its outward normals.
        goal_transform: (4, 4) ``T_goal T_init^-1`` in the network frame.
        samples: S; the candidates left after the drops must be at least S.
        start: (B, 51) starting grasps (their finger numbers are ignored: z starts at 0); default
            :func:`start_grasps`.
    """
    s = settings
    if s.survivors() < samples:
        raise ValueError(f"FLEX keeps {s.survivors()} of {s.batch} candidates after the drops at {list(s.drop_at)}, "
                         f"fewer than the {samples} grasps asked for: raise flex.batch")
    problem = FlexProblem(hand, points, normals, scene, scene_normals, goal_transform, s)
    g0 = start_grasps(hand, points, s.batch, s, generator) if start is None else start.detach().to(points)
    z = torch.zeros(g0.shape[0], prior.cfg.latent, dtype=points.dtype, device=points.device, requires_grad=True)
    rot = g0[:, 3:6].clone().requires_grad_(True)
    trans = g0[:, :3].clone().requires_grad_(True)
    opt = torch.optim.Adam([{"params": [z], "lr": s.lr_latent}, {"params": [rot], "lr": s.lr_rotation},
                            {"params": [trans], "lr": s.lr_translation}])
    for p in prior.parameters():
        p.requires_grad_(False)

    def grasp_of(z_, rot_, trans_):
        fingers = prior.decode(z_)
        return clamp_to_limits(torch.cat([trans_, rot_, fingers], -1), hand.joint_limits)

    best_e = torch.full((g0.shape[0],), float("inf"), dtype=points.dtype, device=points.device)
    best_g = torch.zeros_like(g0)
    history: dict[str, list[float]] = {}
    with torch.enable_grad():
        for step in range(s.steps + 1):
            grasp = grasp_of(z, rot, trans)
            terms = problem.energy(grasp, z, search=step % s.search_every == 0)
            for k, v in terms.items():
                history.setdefault(k, []).append(float(v.detach().mean()))
            with torch.no_grad():
                better = terms["energy"] < best_e
                best_e = torch.where(better, terms["energy"].detach(), best_e)
                best_g = torch.where(better[:, None], grasp.detach(), best_g)
            if step == s.steps:
                break
            if step in s.drop_at and len(best_e) > samples:  # the worse half (by the current energy) goes
                keep = terms["energy"].detach().argsort()[:max(samples, len(best_e) // 2)].sort().values
                z, rot, trans = (p.detach()[keep].requires_grad_(True) for p in (z, rot, trans))
                state = opt.state_dict()  # the moments of the kept candidates carry over
                for i, p in enumerate((z, rot, trans)):
                    for key in ("exp_avg", "exp_avg_sq"):
                        if key in state["state"].get(i, {}):
                            state["state"][i][key] = state["state"][i][key][keep]
                opt = torch.optim.Adam([{"params": [z], "lr": s.lr_latent}, {"params": [rot], "lr": s.lr_rotation},
                                        {"params": [trans], "lr": s.lr_translation}])
                opt.load_state_dict(state)
                best_e, best_g = best_e[keep], best_g[keep]
                problem.select(keep)
                grasp = grasp_of(z, rot, trans)
                terms = problem.energy(grasp, z, search=False)
            opt.zero_grad(set_to_none=True)
            terms["energy"].sum().backward()
            opt.step()
    order = best_e.argsort()[:samples]
    return best_g[order], history
