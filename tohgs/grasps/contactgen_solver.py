"""ContactGen's grasp solver (Liu et al. ICCV 2023): the hand that realises an object-centric contact
representation (:mod:`tohgs.geometry.contact_parts`), by gradient descent on the grasp numbers.

Per hand (each of the B problems has its own energy, so that they are solved together and independently):

- ``E_contact = w_contact sum_i c_i |s_i|``: ``s_i`` the signed distance of object point ``i`` to its
  assigned hand part, ``c_i`` its contact value. ContactGen evaluates a learned per-part SDF of MANO; here
  (``distance: surface``) it is the distance to the closest point of the hand's surface around the
  assigned part's nearest vertex (:mod:`tohgs.geometry.surface_distance`; ``distance: vertex``, the
  distance to that vertex, which is 1-3 mm for a point lying on the surface between vertices). Only the
  points with ``c_i >= min_contact`` enter (the others weigh almost nothing and would cost a search over
  the hand each);
- ``E_direction = w_direction sum_i (1 + c_i) (1 - cos(u_i, u*_i))``: ``u_i`` the point's direction in its
  part's frame for the current hand, ``u*_i`` the representation's;
- ``E_penetration = w_penetration sum_i max(depth_i - 1 mm, 0)``: object points inside the hand by their
  depth (ContactGen: the part SDFs below -1 mm). ``distance: surface``: the depth below the hand's surface
  (the signed distance around the nearest vertex); ``vertex``: points behind their nearest vertex's outward
  normal, by their distance to it, which counts a point on the surface as up to 3 mm deep;
- ``E_pose = w_pose sum_k ((theta_k - mu_k) / sigma_k)^2`` over the 45 finger numbers, about the hand's
  pose prior (ContactGen regularises MANO's PCA coefficients, which are about the mean pose).

The nearest hand vertices (of the assigned part, for ``E_contact``; of the whole hand, for
``E_penetration``) are searched without gradient every ``search_every`` steps and kept in between, as ICP
keeps its correspondences; the distances to them are recomputed, with gradient, every step (1 searches every
step: the exact nearest vertex). The part search finds the nearest of the assigned part's vertices only (on
the CPU a k-d tree per hand whose vertices are lifted by their part, :func:`nearest_part_vertex`).

The point sums are scaled to ContactGen's 2048 points. Two stages with Adam (ContactGen's schedule):
``global_steps`` on the global rotation and translation only, with the contact and direction terms; then
``pose_steps`` on all 51 numbers with every term, the finger numbers clamped to the joint limits after
each step. The start, unless given: the pose prior's mean, no global rotation, the palm's contact
vertices centred on the object (ContactGen starts MANO at its origin, which its objects are centred on).
ContactGen's 200 + 1000 steps are the defaults (100 + 300 left the solver short of the ground truth's own
grasps, docs/baselines.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from tohgs.geometry.contact_parts import N_PARTS, PartContact, part_contact
from tohgs.geometry.hand_object import MATRIX_MAX_CLOUD, distance_to_vertices, nearest_index, vertex_normals
from tohgs.geometry.surface_distance import closest_faces, corner_normals, distance_to_faces, vertex_rings
from tohgs.grasps.tta import clamp_to_limits, pose_problems, problem_histories
from tohgs.hand.layout import GRASP_DIM
from tohgs.hand.model import HandModel

CONTACTGEN_POINTS = 2048  # ContactGen's object points: the point sums are scaled to this many
DISTANCES = ("surface", "vertex")  # how the solver measures a point's distance to the hand (module docstring)
RING_WIDTH = 32  # faces kept around a vertex: its two-ring (tohgs.geometry.surface_distance.vertex_rings)
NEAR_HAND = 0.02  # m: a point farther from every hand vertex is outside the hand (its depth is not measured)
PART_SEPARATION = 1e3  # m: the part search's fourth coordinate per part (nearest_part_vertex), beyond any hand


@dataclass(frozen=True)
class SolverSettings:
    """The two stages and the weights (module docstring). ContactGen: 200 + 1000 steps, lr 5e-2 then
    5e-3, weights contact 0.1, penetration 3, direction 0.01, pose 0.01."""

    global_steps: int = 200
    pose_steps: int = 1000
    global_lr: float = 5e-2
    pose_lr: float = 5e-3
    w_contact: float = 0.1
    w_direction: float = 0.01
    w_penetration: float = 3.0
    w_pose: float = 0.01
    min_contact: float = 0.1
    max_contact_points: int = 256  # at most this many (the highest) contact points per hand enter E_contact
    search_every: int = 10  # steps between searches of the nearest hand vertices (1: every step)
    distance: str = "surface"  # "surface": distances to the hand's surface; "vertex": to the nearest vertex

    def __post_init__(self):
        if self.distance not in DISTANCES:
            raise ValueError(f"distance must be one of {DISTANCES}, got {self.distance!r}")
        if self.global_steps < 0 or self.pose_steps < 0:
            raise ValueError("solver steps must be non-negative")
        if self.search_every < 1:
            raise ValueError(f"search_every must be at least 1, got {self.search_every}")


def part_table(part_labels: torch.Tensor, n_parts: int = N_PARTS) -> torch.Tensor:
    """(n_parts, P) the vertex indices of each part of (V,) ``part_labels``, P the largest part's size; a
    smaller part is padded with its own first vertex (a repeat never changes which vertex is nearest)."""
    members = [torch.nonzero(part_labels == p).flatten() for p in range(n_parts)]
    if any(len(m) == 0 for m in members):
        raise ValueError("every hand part needs at least one vertex")
    size = max(len(m) for m in members)
    return torch.stack([torch.cat([m, m[:1].expand(size - len(m))]) for m in members])


def nearest_part_vertex(points: torch.Tensor, part: torch.Tensor, vertices: torch.Tensor, table: torch.Tensor
                        ) -> torch.Tensor:
    """(B, K) the index of the nearest of the (B, V, 3) hand vertices whose part is the (B, K) ``part`` of
    each of (B, K, 3) points, among that part's vertices only (``table``: :func:`part_table`); no
    gradient.

    On the CPU (a hand of more than :data:`~tohgs.geometry.hand_object.MATRIX_MAX_CLOUD` vertices) the k-d
    trees of :func:`~tohgs.geometry.hand_object.nearest_index`, one per hand, over the vertices lifted to four
    coordinates, the fourth :data:`PART_SEPARATION` times the vertex's part, queried with the points
    lifted by their assigned part: a vertex of another part is at least that far, so the nearest lifted
    vertex is the nearest of the assigned part, at the same squared distance (the fourth coordinates are
    equal). 3-4x faster than the distance matrix at the default's 128 hands x 256 points x 1609 vertices,
    which is memory-bound on a CPU (:func:`tohgs.geometry.hand_object.nearest_index`); elsewhere the
    matrix."""
    with torch.no_grad():
        if points.device.type == "cpu" and vertices.shape[1] > MATRIX_MAX_CLOUD:  # nearest_index's k-d trees
            labels = torch.empty(vertices.shape[1], dtype=vertices.dtype)
            labels[table.flatten()] = torch.arange(table.shape[0], dtype=vertices.dtype).repeat_interleave(table.shape[1])
            lifted_v = torch.cat([vertices, (PART_SEPARATION * labels)[None, :, None].expand(len(vertices), -1, 1)], -1)
            return nearest_index(torch.cat([points, PART_SEPARATION * part[..., None].to(points.dtype)], -1), lifted_v)
        cand = table[part]  # (B, K, P)
        d = torch.gather(torch.cdist(points, vertices), 2, cand)  # the full matrix is one GEMM; cheaper than gathering P vertices per point
        return torch.gather(cand, 2, d.argmin(-1, keepdim=True))[..., 0]


def default_start(hand: HandModel, batch: int) -> torch.Tensor:
    """(B, 51) the start grasps (module docstring): prior-mean fingers, no rotation, the palm's contact
    vertices centred on the origin (the object's centroid in the network frame)."""
    g = torch.zeros(1, GRASP_DIM, dtype=hand.rest_vertices.dtype, device=hand.rest_vertices.device)
    g[0, 6:] = torch.as_tensor(hand.assets.prior_mean, dtype=g.dtype, device=g.device)
    with torch.no_grad():
        palm = hand(g).vertices[0, hand.contact_ids].mean(0)
    g[0, :3] = -palm
    return g.expand(batch, -1).clone()


def solver_energy(hand: HandModel, grasp: torch.Tensor, points: torch.Tensor, target: PartContact,
                  settings: SolverSettings, stage: str, contact_sel: tuple[torch.Tensor, torch.Tensor],
                  nearest: dict | None = None, search: bool = True, sizes: list[int] | None = None
                  ) -> dict[str, torch.Tensor]:
    """The weighted terms (B,) and their sum ``"energy"`` of (B, 51) grasps for the (B, N, 3) points'
    ``target`` representation; ``stage`` ``global`` (contact, direction) or ``pose`` (every term);
    ``contact_sel`` the (B, K) indices of the contact points and their (B, K) weights (0 for padding).

    ``nearest`` keeps the nearest-vertex indices between calls (``part``: (B, K) of the contact points in
    their parts; ``hand``: (B, N) of every point in the hand, with ``normal`` (B, N, 3) that vertex's
    outward normal when it was found; with ``distance: surface`` the faces of the closest surface points
    instead, kept for the contact points of non-zero weight and the points within ``NEAR_HAND`` of the hand
    only, the others' terms being 0): they are searched when ``search`` is true or not yet there, and
    reused otherwise (module docstring). ``sizes``: the hands of each problem when several are solved
    together (:func:`tohgs.grasps.tta.pose_problems`)."""
    s = settings
    nearest = {} if nearest is None else nearest
    scale = CONTACTGEN_POINTS / points.shape[1]
    out = pose_problems(hand, grasp, sizes)
    idx, weight = contact_sel
    sel_points = torch.gather(points, 1, idx[..., None].expand(-1, -1, 3))
    surface = s.distance == "surface"
    if search or "part" not in nearest:
        if "table" not in nearest:
            nearest["table"] = part_table(hand.part_labels)
        sel_part = torch.gather(target.part, 1, idx)
        nearest["part"] = nearest_part_vertex(sel_points, sel_part, out.vertices, nearest["table"])
        if surface:
            if "rings" not in nearest:
                nearest["rings"] = vertex_rings(hand.closed_faces, hand.rest_vertices.shape[0], RING_WIDTH)
            nearest["weighted"] = torch.nonzero(weight > 0, as_tuple=True)  # the entries that count
            nearest["part_faces"] = closest_faces(sel_points, out.vertices, hand.closed_faces, nearest["rings"],
                                                  nearest["part"], weight > 0)
    if surface:  # the distances of the weighted entries only; the others weigh 0
        rows = nearest["weighted"]
        d_part = _scatter_rows(distance_to_faces(sel_points[rows], out.vertices, nearest["part_faces"][rows],
                                                 hands=rows[0]), rows, weight.shape)
    else:
        d_part = distance_to_vertices(sel_points, out.vertices, nearest["part"])
    terms = {"contact": s.w_contact * scale * (weight * d_part).sum(-1)}
    # the current directions of every point in its target part's frame (the nearest-vertex part and the
    # contact of part_contact are not used here: the parts are the target's)
    origin = torch.gather(out.joints[:, :16], 1, target.part[..., None].expand(-1, -1, 3))
    rot = torch.gather(out.rotations, 1, target.part[..., None, None].expand(-1, -1, 3, 3))
    local = (rot.transpose(-1, -2) @ (points - origin)[..., None])[..., 0]
    cos = (local * target.direction).sum(-1) / local.norm(dim=-1).clamp_min(1e-9)
    terms["direction"] = s.w_direction * scale * ((1 + target.contact) * (1 - cos)).sum(-1)
    if stage == "pose":
        if search or "hand" not in nearest:
            nearest["hand"] = idx_h = nearest_index(points, out.vertices)
            with torch.no_grad():  # the normals only decide which points are inside: kept with the index
                normals = vertex_normals(out.vertices.detach(), hand.closed_faces)
                if surface:  # the face of each near point's closest surface point, and its corners' normals
                    near = distance_to_vertices(points, out.vertices, idx_h) < NEAR_HAND
                    rows = nearest["near"] = torch.nonzero(near, as_tuple=True)
                    faces = closest_faces(points, out.vertices, hand.closed_faces, nearest["rings"], idx_h, near)
                    nearest["hand_faces"] = faces[rows]
                    nearest["hand_normals"] = corner_normals(normals, faces)[rows]
                else:  # the nearest vertex's normal
                    nearest["normal"] = torch.gather(normals, 1, idx_h[..., None].expand(-1, -1, 3))
        if surface:  # the near points' depths; a point farther from the hand is outside it
            rows = nearest["near"]
            sd = distance_to_faces(points[rows], out.vertices, nearest["hand_faces"], nearest["hand_normals"],
                                   hands=rows[0])
            depth_beyond = _scatter_rows((-sd - 1e-3).clamp_min(0), rows, points.shape[:2])
        else:
            offset = points - torch.gather(out.vertices, 1, nearest["hand"][..., None].expand(-1, -1, 3))
            inside = ((offset * nearest["normal"]).sum(-1) < 0).float()
            depth_beyond = inside * (offset.norm(dim=-1) - 1e-3).clamp_min(0)
        terms["penetration"] = s.w_penetration * scale * depth_beyond.sum(-1)
        mu = torch.as_tensor(hand.assets.prior_mean, dtype=grasp.dtype, device=grasp.device)
        sigma = torch.as_tensor(hand.assets.prior_std, dtype=grasp.dtype, device=grasp.device).clamp_min(1e-3)
        terms["pose"] = s.w_pose * (((grasp[:, 6:] - mu) / sigma) ** 2).sum(-1)
    return {**terms, "energy": sum(terms.values())}


def _scatter_rows(values: torch.Tensor, rows: tuple[torch.Tensor, torch.Tensor], shape: torch.Size) -> torch.Tensor:
    """(B, N) zeros with the (M,) ``values`` at the ``rows`` (hand, point) indices, differentiable in
    ``values``: the per-point layout the energy sums over, for terms computed on some points only."""
    return values.new_zeros(shape).index_put(rows, values)


def contact_points(contact: torch.Tensor, settings: SolverSettings) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, K) the indices of each map's highest contact values (K = ``max_contact_points`` or fewer) and
    their weights, 0 below ``min_contact``."""
    k = min(settings.max_contact_points, contact.shape[1])
    values, idx = contact.topk(k, dim=-1)
    return idx, torch.where(values >= settings.min_contact, values, torch.zeros_like(values))


def solve(hand: HandModel, points: torch.Tensor, target: PartContact, settings: SolverSettings,
          start: torch.Tensor | None = None) -> tuple[torch.Tensor, dict[str, list[float]]]:
    """The (B, 51) grasps realising the (B, N) representation ``target`` on (B, N, 3) points (network
    frame, m), from ``start`` (B, 51) or :func:`default_start`; and the history of the mean energy and its
    terms per step (stage ``global`` then ``pose``; the last entry after the last step)."""
    grasp, histories = solve_many(hand, points, target, settings, [points.shape[0]], start)
    return grasp, histories[0]


def solve_many(hand: HandModel, points: torch.Tensor, target: PartContact, settings: SolverSettings,
               sizes: list[int], start: torch.Tensor | None = None) -> tuple[torch.Tensor, list[dict[str, list[float]]]]:
    """:func:`solve` of several problems (e.g. the S representations of each of several test
    configurations) as one batch: the B = sum(``sizes``) rows in order, problem ``p`` the next ``sizes[p]``
    rows of ``points`` (B, N, 3), ``target`` (B, N) and ``start`` (B, 51). Every term, each hand's kept
    vertices and Adam are per hand, so a hand's result does not depend on the others in the batch.

    Returns:
        The (B, 51) grasps and one history per problem (the mean over its hands, as :func:`solve`)."""
    if target.part is None or target.direction is None:
        raise ValueError("the solver needs a representation with parts and directions (ContactGen with parts)")
    b = points.shape[0]
    if sum(sizes) != b or any(n < 1 for n in sizes):
        raise ValueError(f"the problem sizes {sizes} must be positive and add up to the {b} hands")
    g0 = default_start(hand, b) if start is None else start.detach().to(points)
    g0 = clamp_to_limits(g0, hand.joint_limits)
    sel = contact_points(target.contact, settings)
    glob = g0[:, :6].clone().requires_grad_(True)
    fingers = g0[:, 6:].clone()
    per_step: list[dict[str, torch.Tensor]] = []  # each step's (B,) terms, averaged per problem at the end
    nearest: dict = {}  # the nearest-vertex indices, kept between searches

    def descend(params: list[torch.Tensor], lr: float, steps: int, stage: str) -> None:
        opt = torch.optim.Adam(params, lr=lr)
        for step in range(steps):
            terms = solver_energy(hand, torch.cat([glob, fingers], -1), points, target, settings, stage, sel,
                                  nearest, search=step % settings.search_every == 0, sizes=sizes)
            per_step.append({k: v.detach() for k, v in terms.items()})
            opt.zero_grad(set_to_none=True)
            terms["energy"].sum().backward()
            opt.step()
            if stage == "pose":  # the finger numbers back within the joint limits
                with torch.no_grad():
                    fingers.copy_(clamp_to_limits(torch.cat([glob, fingers], -1), hand.joint_limits)[:, 6:])

    with torch.enable_grad():
        descend([glob], settings.global_lr, settings.global_steps, "global")
        fingers.requires_grad_(True)
        descend([glob, fingers], settings.pose_lr, settings.pose_steps, "pose")
        grasp = torch.cat([glob, fingers], -1).detach()
        per_step.append({k: v.detach() for k, v in solver_energy(hand, grasp, points, target, settings, "pose", sel,
                                                                  nearest, sizes=sizes).items()})
    return grasp, problem_histories(per_step, sizes)


def representation_of(hand: HandModel, grasp: torch.Tensor, points: torch.Tensor, alpha: float) -> PartContact:
    """The representation (B, N) that (B, 51) hands make on (B, N, 3) points (the ground truth's)."""
    with torch.no_grad():
        out = hand(grasp)
        return part_contact(points, out.vertices, out.joints, out.rotations, hand.part_labels, alpha)
