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

from tohgs.geometry.cloud import (CloudIndex, clearance_violation, cloud_distance, cloud_signed_distance_at,
                                  even_subset)
from tohgs.grasps.synthesis import SynthesisSettings, initial_grasps
from tohgs.grasps.tta import by_problem, clamp_to_limits, pose_problems
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
    """The energy (module docstring) of the candidates of C configurations: (C, N, 3) object clouds and
    normals, (C, M, 3) scene clouds and normals, (C, 4, 4) goal transforms (one configuration's arrays
    without the leading axis are taken as C = 1). The (B, 51) grasps it is given are the configurations'
    candidates in order, B / C each (every configuration keeps as many). Each cloud has its own
    :class:`tohgs.geometry.cloud.CloudIndex`; the nearest cloud points are kept per candidate between
    searches (:meth:`energy` with ``search``). Every term is per candidate, so a candidate's energy does
    not depend on the other candidates or configurations."""

    def __init__(self, hand: HandModel, points: torch.Tensor, normals: torch.Tensor, scene: torch.Tensor,
                 scene_normals: torch.Tensor, goal_transform: torch.Tensor, settings: FlexSettings):
        if points.ndim == 2:
            points, normals, scene, scene_normals, goal_transform = (
                x[None] for x in (points, normals, scene, scene_normals, goal_transform))
        self.hand, self.s = hand, settings
        self.n_configs = len(points)
        self.objects = [CloudIndex(p, n) for p, n in zip(points, normals)]
        self.scenes = [CloudIndex(p, n) for p, n in zip(scene, scene_normals)]
        # every configuration's cloud end to end: a candidate's kept index points into its own block
        self.object_flat = (points.reshape(-1, 3), normals.reshape(-1, 3))
        self.scene_flat = (scene.reshape(-1, 3), scene_normals.reshape(-1, 3))
        self.goal = goal_transform
        self.sub = even_subset(hand.rest_vertices.shape[0], settings.hand_points, points.device)
        self.groups = contact_groups(hand)
        self.kept: dict[str, torch.Tensor] = {}

    def select(self, keep: torch.Tensor) -> None:
        """Keep the kept correspondences of the (B',) candidates ``keep`` only (B' / C per configuration)."""
        self.kept = {k: v[keep] for k, v in self.kept.items()}

    def _blocks(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The (B / C, ...) rows of each configuration of (B, ...) ``x``."""
        if x.shape[0] % self.n_configs:
            raise ValueError(f"{x.shape[0]} candidates do not split evenly over {self.n_configs} configurations")
        return x.split(x.shape[0] // self.n_configs)

    def _nearest(self, indices: list[CloudIndex], query: torch.Tensor) -> torch.Tensor:
        """(B, Q) each of (B, Q, 3) queries' nearest point in its configuration's cloud, as an index into
        the clouds end to end."""
        return torch.cat([idx.nearest(q) + c * len(idx.cloud)
                          for c, (idx, q) in enumerate(zip(indices, self._blocks(query)))])

    def at_goal(self, pts: torch.Tensor) -> torch.Tensor:
        """(B, Q, 3) hand points carried by their configuration's goal transform."""
        return torch.cat([q @ T[:3, :3].T + T[:3, 3] for q, T in zip(self._blocks(pts), self.goal)])

    def energy(self, grasp: torch.Tensor, z: torch.Tensor, search: bool = True) -> dict[str, torch.Tensor]:
        """The weighted terms (B,) and their sum ``"energy"`` of (B, 51) grasps with (B, L) latents."""
        s = self.s
        verts = pose_problems(self.hand, grasp, [grasp.shape[0] // self.n_configs] * self.n_configs).vertices
        sub = verts[:, self.sub]
        cand = verts[:, self.hand.contact_ids]
        goal = self.at_goal(sub)
        if search or not self.kept:
            self.kept = {"object": self._nearest(self.objects, sub), "contact": self._nearest(self.objects, cand),
                         "init": self._nearest(self.scenes, sub), "goal": self._nearest(self.scenes, goal)}
        d = cloud_distance(cand, self.object_flat[0], self.kept["contact"])  # (B, C)
        per_group = torch.full((d.shape[0], 6), float("inf"), dtype=d.dtype, device=d.device)
        per_group = per_group.scatter_reduce(1, self.groups.expand_as(d), d, "amin")
        terms = {"fit": s.w_fit * per_group.sum(-1)}
        so = cloud_signed_distance_at(sub, *self.object_flat, self.kept["object"])
        terms["object"] = s.w_object * ((so < 0) & (so > -s.max_depth)).float().mul(-so).sum(-1)
        obstacle = 0
        for key, pts in (("init", sub), ("goal", goal)):
            ss = cloud_signed_distance_at(pts, *self.scene_flat, self.kept[key])
            obstacle = obstacle + clearance_violation(ss, s.margin, s.max_depth)
        terms["obstacle"] = s.w_obstacle * obstacle
        terms["prior"] = s.w_prior * (z**2).sum(-1)
        return {**terms, "energy": sum(terms.values())}

    def opp(self, grasp: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B,) each hand's share of (subset) vertices inside the scene cloud at the initial and the goal pose."""
        with torch.no_grad():
            sub = pose_problems(self.hand, grasp, [grasp.shape[0] // self.n_configs] * self.n_configs).vertices[:, self.sub]
            out = []
            for pts in (sub, self.at_goal(sub)):
                ss = cloud_signed_distance_at(pts, *self.scene_flat, self._nearest(self.scenes, pts))
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
    grasp, histories = optimise_many(hand, prior, points[None], normals[None], scene[None], scene_normals[None],
                                     goal_transform[None], samples, settings, [generator],
                                     None if start is None else [start])
    return grasp, histories[0]


def optimise_many(hand: HandModel, prior, points: torch.Tensor, normals: torch.Tensor, scene: torch.Tensor,
                  scene_normals: torch.Tensor, goal_transform: torch.Tensor, samples: int, settings: FlexSettings,
                  generators: list[torch.Generator], starts: list[torch.Tensor] | None = None
                  ) -> tuple[torch.Tensor, list[dict[str, list[float]]]]:
    """:func:`optimise` of C configurations as one batch of C x ``batch`` candidates: (C, N, 3) ``points``
    and ``normals``, (C, M, 3) ``scene`` and ``scene_normals``, (C, 4, 4) ``goal_transform``, one generator
    (and start, (B, 51)) per configuration. Each configuration keeps its own candidates: its starts from its
    generator, its drops (the worse half of its own candidates) and its S best. Every term, each
    candidate's kept cloud points and Adam are per candidate, so a configuration's grasps do not depend on
    the others in the batch.

    Returns:
        (C S, 51) the S best grasps of each configuration in order, and one history per configuration
        (the mean over its live candidates per step).
    """
    s = settings
    n_cfg = len(points)
    if len(generators) != n_cfg or (starts is not None and len(starts) != n_cfg):
        raise ValueError(f"{n_cfg} configurations need as many generators (and starts), got {len(generators)}")
    if s.survivors() < samples:
        raise ValueError(f"FLEX keeps {s.survivors()} of {s.batch} candidates after the drops at {list(s.drop_at)}, "
                         f"fewer than the {samples} grasps asked for: raise flex.batch")
    problem = FlexProblem(hand, points, normals, scene, scene_normals, goal_transform, s)
    if starts is None:
        starts = [start_grasps(hand, p, s.batch, s, g) for p, g in zip(points, generators)]
    g0 = torch.cat([st.detach().to(points) for st in starts])
    if len({len(st) for st in starts}) != 1:
        raise ValueError("every configuration needs as many starting candidates")
    z = torch.zeros(g0.shape[0], prior.cfg.latent, dtype=points.dtype, device=points.device, requires_grad=True)
    rot = g0[:, 3:6].clone().requires_grad_(True)
    trans = g0[:, :3].clone().requires_grad_(True)
    opt = torch.optim.Adam([{"params": [z], "lr": s.lr_latent}, {"params": [rot], "lr": s.lr_rotation},
                            {"params": [trans], "lr": s.lr_translation}])
    for p in prior.parameters():
        p.requires_grad_(False)

    def grasp_of(z_, rot_, trans_):  # the prior per configuration: its products' rounding is then the same alone
        fingers = by_problem(prior.decode, [len(z_) // n_cfg] * n_cfg, z_)
        return clamp_to_limits(torch.cat([trans_, rot_, fingers], -1), hand.joint_limits)

    def rows(order: torch.Tensor, width: int) -> torch.Tensor:
        """The (C, k) ``order`` (indices within each configuration's ``width`` live candidates) as global rows."""
        return (order + width * torch.arange(n_cfg, device=order.device)[:, None]).reshape(-1)

    best_e = torch.full((g0.shape[0],), float("inf"), dtype=points.dtype, device=points.device)
    best_g = torch.zeros_like(g0)
    per_step: list[dict[str, torch.Tensor]] = []  # each step's (C, K) terms of the live candidates
    with torch.enable_grad():
        for step in range(s.steps + 1):
            grasp = grasp_of(z, rot, trans)
            terms = problem.energy(grasp, z, search=step % s.search_every == 0)
            per_step.append({k: v.detach().reshape(n_cfg, -1) for k, v in terms.items()})
            with torch.no_grad():
                better = terms["energy"] < best_e
                best_e = torch.where(better, terms["energy"].detach(), best_e)
                best_g = torch.where(better[:, None], grasp.detach(), best_g)
            if step == s.steps:
                break
            live = len(best_e) // n_cfg
            if step in s.drop_at and live > samples:  # the worse half of each configuration (current energy) goes
                ranks = terms["energy"].detach().reshape(n_cfg, live).argsort(dim=1, stable=True)
                keep = rows(ranks[:, :max(samples, live // 2)].sort(dim=1).values, live)
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
    live = len(best_e) // n_cfg
    order = rows(best_e.reshape(n_cfg, live).argsort(dim=1, stable=True)[:, :samples], live)
    histories = [{k: [float(v[c].mean()) for v in (st[k] for st in per_step)] for k in (per_step[0] if per_step else {})}
                 for c in range(n_cfg)]
    return best_g[order], histories
