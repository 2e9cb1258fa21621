"""DexGraspNet-style force-closure grasp synthesis for any MANO-layout hand.

Energy per grasp (weights from DexGraspNet-MANO, all settings in :class:`SynthesisSettings`):

``E = E_fc + w_dis E_dis + w_pen E_pen + w_prior E_prior + w_spen E_spen + w_joint E_joint + w_plane E_plane``

- ``E_fc``: squared norm of the net wrench of unit contact normals at ``n_contact`` points chosen from
  the hand's contact candidates: ``|sum n_i|^2 + |sum x_i x n_i|^2`` (object frame, metres).
- ``E_dis``: sum of |signed distance| of the contact points to the object surface.
- ``E_pen``: penetration, the depth of the hand's vertices inside the object (sum of ``relu(-sdf)``).
  DexGraspNet measures the opposite (object points inside the hand, through the nearest hand vertex);
  with 1609 hand vertices the hand side is dense enough and costs B x V grid queries instead of
  B x N x V distances (1.6 GB at B = 128 on a CPU).
- ``E_prior``: mean squared z-score of the 45 finger parameters under the hand's pose prior.
- ``E_spen``: self-penetration, the hinge ``relu(thr - d)`` over pairs of distal keypoints of different
  fingers (DexGraspNet's MANO branch has a sign bug here; this is the intended hinge).
- ``E_joint``: violation of the anatomical joint limits (sum of hinge distances, radians).
- ``E_plane``: hand vertices beyond a support plane ``n . v < offset`` (sum of depths), so that grasps
  stay on the free side of a table. A fraction ``plane_fraction`` of the batch gets a plane tangent to the
  object's far side along a direction d: under one of the object's stable rest poses (``"stable"``:
  objects, which settle on a support in one of them; drawn by their quasi-static probabilities), a
  random direction (``"random"``) or -z (``"down"``: bricks, which rest upright); the others have none.

Contact normals are the SDF's central differences at the contact points, so they are differentiable in the
points' positions (treating them as constants, as a first version here did, left E_fc barely moving).

The optimiser is DexGraspNet's annealing (not Langevin): an RMSProp-normalised gradient step on the pose,
each contact index resampled with probability ``switch_probability``, and a Metropolis accept/reject
per grasp with a temperature that decays geometrically. DexGraspNet anneals for 6000 iterations; a CPU
budget of a few hundred needs the same schedule compressed (decays every few steps), followed by a
polishing phase with the contacts fixed (:func:`_refine`).

The annealing measures E_pen and E_plane on a farthest-point subset of the hand's vertices
(``anneal_vertices``, a fraction; the contact candidates and fingertips always among them,
:func:`vertex_subset`): a step's cost is mostly per vertex (the skinning GEMM and its gradient, the SDF
lower bound), and the annealing only has to find the grasp. The polishing phase and the final energies
(those the filter reads) use every vertex.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from tohgs.geometry.sdf import SDFGrid
from tohgs.hand.layout import FINGER_POSE_DIM, FINGERS, KEYPOINT_NAMES
from tohgs.hand.model import HandModel
from tohgs.hand.rotations import axis_angle_to_matrix, matrix_to_axis_angle


@dataclass(frozen=True)
class SynthesisSettings:
    """Grasp synthesis settings (SI units). Weights follow DexGraspNet-MANO; the budget, the schedule's
    decay intervals and the initial distance are set for CPU runs (see the config)."""

    batch: int = 128
    iterations: int = 600
    n_contact: int = 4
    w_dis: float = 100.0
    w_pen: float = 100.0
    w_prior: float = 0.5
    w_spen: float = 10.0
    w_joint: float = 10.0
    w_plane: float = 40.0
    spen_threshold: float = 0.018
    step_size: float = 0.005
    step_decay: float = 0.95
    step_decay_every: int = 16
    rmsprop_mu: float = 0.98
    switch_probability: float = 0.1
    temperature: float = 18.0
    temperature_decay: float = 0.95
    temperature_decay_every: int = 4
    refine_iterations: int = 100
    refine_lr: float = 0.001
    init_distance: tuple[float, float] = (0.01, 0.04)
    init_jitter: float = 0.1
    init_preset: str = "relaxed"
    anneal_vertices: float = 0.33
    plane_fraction: float = 0.0
    plane_direction: str = "random"  # "random", "stable" (needs rest directions) or "down"


@dataclass
class Energies:
    """Per-grasp energy terms, each (B,)."""

    total: torch.Tensor
    fc: torch.Tensor
    dis: torch.Tensor
    pen: torch.Tensor
    prior: torch.Tensor
    spen: torch.Tensor
    joint: torch.Tensor
    plane: torch.Tensor

    def detach(self) -> "Energies":
        return Energies(**{k: v.detach() for k, v in self.__dict__.items()})


@dataclass
class SynthesisResult:
    """Optimised grasps of one object: ``pose`` (B, 51), ``contact_idx`` (B, n) into the hand's
    contact candidates, ``planes`` (B, 4) the support planes (zero rows: none), the final
    :class:`Energies` (on every hand vertex), and the mean total energy per iteration (the annealing's on
    its vertex subset)."""

    pose: torch.Tensor
    contact_idx: torch.Tensor
    planes: torch.Tensor
    energies: Energies
    history: list[float] = field(default_factory=list)


def wrench_energy(x: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """Force-closure energy of unit contact normals: ``|sum n_i|^2 + |sum x_i x n_i|^2``.

    Args:
        x: (B, n, 3) contact points, metres (object frame).
        normal: (B, n, 3) unit normals at them.

    Returns:
        (B,) squared norm of the net wrench (zero when the normals balance in force and torque).
    """
    force = normal.sum(1)
    torque = torch.cross(x, normal, dim=-1).sum(1)
    return (force**2).sum(-1) + (torque**2).sum(-1)


def _distal_keypoints() -> list[tuple[int, str]]:
    """(keypoint index in the 21, finger) for the last two joints and the tip of every finger."""
    out = []
    for finger, ks in FINGERS.items():
        out += [(ks[1], finger), (ks[2], finger), (KEYPOINT_NAMES.index(f"{finger}_tip"), finger)]
    return out


class GraspEnergy:
    """The energy of grasps on one object (its SDF grid), for one hand model."""

    def __init__(self, hand: HandModel, sdf: SDFGrid, settings: SynthesisSettings,
                 planes: torch.Tensor | None = None, vertex_ids: torch.Tensor | None = None):
        """``planes``: optional (B, 4) support planes ``[nx, ny, nz, offset]`` (keep ``n . v >= offset``);
        a row with a zero normal means no plane for that grasp. ``vertex_ids``: optional (S,) increasing
        hand vertex ids, the only vertices E_pen and E_plane see (:func:`vertex_subset`; it must hold the
        contact candidates and the fingertips); None: every vertex."""
        self.hand, self.sdf, self.s = hand, sdf, settings
        self.planes = planes
        self.vertex_ids = vertex_ids
        if vertex_ids is not None:
            pos = {int(v): i for i, v in enumerate(vertex_ids.tolist())}
            missing = sorted({int(v) for v in torch.cat([hand.contact_ids, hand.tip_ids]).tolist()} - set(pos))
            if missing or not bool((vertex_ids[1:] > vertex_ids[:-1]).all()):
                raise ValueError("vertex_ids must be increasing and hold every contact candidate and fingertip"
                                 + (f" (missing {missing[:5]})" if missing else ""))
            device = hand.contact_ids.device
            self.contact_pos = torch.tensor([pos[int(v)] for v in hand.contact_ids.tolist()], device=device)
            self.tip_pos = torch.tensor([pos[int(v)] for v in hand.tip_ids.tolist()], device=device)
            # The subset's columns of the skinning matrix: its vertices cost a GEMM of their number.
            self.skin_sub = hand.skin_rest_t[:, vertex_ids].contiguous() if hand.linear_skinning else None
        # The grasps that have a plane (a zero normal means none): only their vertices are tested.
        self.plane_rows = None if planes is None else (planes[:, :3].norm(dim=-1) > 0).nonzero()[:, 0]
        kp = _distal_keypoints()
        self.kp_idx = torch.tensor([k for k, _ in kp])
        fingers = [f for _, f in kp]
        pairs = [(i, j) for i in range(len(kp)) for j in range(i + 1, len(kp)) if fingers[i] != fingers[j]]
        self.pairs = torch.tensor(pairs)
        # (P, 21): row p is +1 at the pair's first keypoint and -1 at its second, so that
        # pair_diff @ joints is every pair's difference in one matmul (gathers backpropagate slowly).
        self.pair_diff = torch.zeros(len(pairs), len(KEYPOINT_NAMES), dtype=hand.rest_joints.dtype,
                                     device=hand.rest_joints.device)
        rows = torch.arange(len(pairs))
        self.pair_diff[rows, self.kp_idx[self.pairs[:, 0]]] = 1.0
        self.pair_diff[rows, self.kp_idx[self.pairs[:, 1]]] = -1.0

    def distance_and_normals(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The SDF at (B, n, 3) points -> (B, n) metres, and its outward unit normals there -> (B, n, 3), by
        central differences (differentiable in x); one grid lookup for the points and their 6 neighbours."""
        h = self.sdf.spacing
        offsets = h * torch.cat([torch.zeros(1, 3), torch.eye(3), -torch.eye(3)]).to(x)  # (7, 3)
        d = self.sdf(x[..., None, :] + offsets)  # (B, n, 7)
        grad = (d[..., 1:4] - d[..., 4:7]) / (2 * h)
        return d[..., 0], grad / grad.norm(dim=-1, keepdim=True).clamp_min(1e-9)

    def _posed(self, pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The (B, 3, S) vertices the energy sees (all, or the subset), coordinate-major, the (B, 21, 3)
        joints, and the contact candidates' (C,) positions among those vertices; metres."""
        hand, b = self.hand, pose.shape[0]
        if self.vertex_ids is None:
            out = hand(pose)
            return out.vertices.transpose(1, 2), out.joints, hand.contact_ids  # contiguous (B, 3, V)
        if self.skin_sub is None:  # pose blend shapes: pose every vertex, keep the subset's
            out = hand(pose)
            return out.vertices.transpose(1, 2)[:, :, self.vertex_ids], out.joints, self.contact_pos
        rows, joints16 = hand.skinning_rows(pose)  # (B, 3, 65), (B, 16, 3)
        verts_t = (rows.reshape(b * 3, -1) @ self.skin_sub).reshape(b, 3, -1)  # (B, 3, S)
        tips = verts_t[:, :, self.tip_pos].transpose(1, 2)  # (B, 5, 3)
        return verts_t, torch.cat([joints16, tips], 1), self.contact_pos

    def __call__(self, pose: torch.Tensor, contact_idx: torch.Tensor) -> Energies:
        """Energies of (B, 51) poses with (B, n) contact indices."""
        s, hand = self.s, self.hand
        verts_t, joints, candidates = self._posed(pose)  # (B, 3, S), (B, 21, 3), (C,)
        verts = verts_t.transpose(1, 2)  # (B, S, 3) view
        b = pose.shape[0]
        cid = candidates[contact_idx]  # (B, n) positions among the vertices
        x = torch.gather(verts_t, 2, cid[:, None, :].expand(-1, 3, -1)).transpose(1, 2)  # (B, n, 3)
        dist_x, normal = self.distance_and_normals(x)
        e_fc = wrench_energy(x, normal)
        e_dis = dist_x.abs().sum(-1)
        e_pen = self.sdf.penetration(verts)
        fingers = pose[:, 6:]
        e_prior = (((fingers - hand.prior_mean) / hand.prior_std) ** 2).mean(-1)
        dist = (self.pair_diff @ joints).norm(dim=-1)  # (B, P) distances of the keypoint pairs
        e_spen = torch.relu(s.spen_threshold - dist).sum(-1)
        lim = hand.joint_limits.reshape(FINGER_POSE_DIM, 2)
        e_joint = (torch.relu(fingers - lim[:, 1]) + torch.relu(lim[:, 0] - fingers)).sum(-1)
        e_plane = torch.zeros(b, dtype=verts.dtype, device=verts.device)
        if self.plane_rows is not None and len(self.plane_rows):
            rows = self.plane_rows
            n, offset = self.planes[rows, :3].to(verts.dtype), self.planes[rows, 3:4].to(verts.dtype)
            vx, vy, vz = verts_t[rows].unbind(1)  # (R, V) each
            height = vx * n[:, 0:1] + vy * n[:, 1:2] + vz * n[:, 2:3]  # n . v
            e_plane = e_plane.index_add(0, rows, torch.relu(offset - height).sum(-1))
        total = (e_fc + s.w_dis * e_dis + s.w_pen * e_pen + s.w_prior * e_prior + s.w_spen * e_spen
                 + s.w_joint * e_joint + s.w_plane * e_plane)
        return Energies(total, e_fc, e_dis, e_pen, e_prior, e_spen, e_joint, e_plane)


def rest_directions(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The object's stable rest poses on a horizontal support as "down" directions in its mesh frame.

    Args:
        mesh: a watertight ``trimesh.Trimesh`` (its convex hull and centre of mass are used).

    Returns:
        (K, 3) unit directions d (the support lies along d: for a rest pose T, ``d = R^T (0, 0, -1)``) and
        (K,) their quasi-static probabilities (trimesh's estimate), summing to 1.
    """
    import trimesh

    transforms, probs = trimesh.poses.compute_stable_poses(mesh, n_samples=1)
    d = -np.asarray(transforms)[:, 2, :3]  # R^T e_z is the third row of R
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = np.asarray(probs, dtype=np.float64)
    return d, p / p.sum()


def support_planes(vertices: np.ndarray, settings: SynthesisSettings, generator: torch.Generator,
                   rest: tuple[np.ndarray, np.ndarray] | None = None) -> torch.Tensor:
    """(B, 4) support planes ``[nx, ny, nz, offset]`` for the first ``plane_fraction`` of the batch (zero
    rows for the rest): tangent to the object at its extreme point along a direction d, normal ``n = -d``
    pointing at the object, so ``n . v >= offset`` is the free side. d is a random unit vector
    (``plane_direction="random"``), -z (``"down"``) or the down direction of a rest pose drawn by its
    probability from ``rest`` = :func:`rest_directions` (``"stable"``)."""
    s, b = settings, settings.batch
    verts = torch.as_tensor(vertices, dtype=torch.float32)
    k = int(round(s.plane_fraction * b))
    d = torch.randn(b, 3, generator=generator)
    if s.plane_direction == "down":
        d = torch.tensor([0.0, 0.0, -1.0]).expand(b, 3).clone()
    elif s.plane_direction == "stable":
        if rest is None or len(rest[0]) == 0:
            raise ValueError("plane_direction 'stable' needs the object's rest directions (rest_directions)")
        pick = torch.multinomial(torch.as_tensor(rest[1], dtype=torch.float64), b, replacement=True, generator=generator)
        d = torch.as_tensor(rest[0], dtype=torch.float32)[pick]
    elif s.plane_direction != "random":
        raise ValueError(f"plane_direction must be 'random', 'stable' or 'down', not {s.plane_direction!r}")
    d = d / d.norm(dim=-1, keepdim=True)
    offset = -(verts @ d.T).max(0).values  # n . v >= offset with n = -d  <=>  d . v <= max_v d . v
    planes = torch.cat([-d, offset[:, None]], 1)
    planes[k:] = 0.0
    return planes


def initial_grasps(hand: HandModel, vertices: np.ndarray, settings: SynthesisSettings, generator: torch.Generator,
                   planes: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Hands around the object, palm facing it: (B, 51) poses and (B, n) contact indices.

    Each hand's palm centre is put at ``init_distance`` beyond the object's extent along a random
    direction u, the palm normal (-y in the hand frame) pointing along -u, with a random roll about u;
    fingers in ``init_preset`` with Gaussian jitter (``init_jitter`` radians). With (B, 4) ``planes``, u
    is flipped into the free side of its grasp's plane.
    """
    s, b = settings, settings.batch
    dtype = hand.rest_vertices.dtype
    verts = torch.as_tensor(vertices, dtype=dtype)
    centre = verts.mean(0)
    u = torch.randn(b, 3, generator=generator, dtype=dtype)
    u = u / u.norm(dim=-1, keepdim=True)
    if planes is not None:
        n = planes[:, :3].to(dtype)
        u = torch.where(((u * n).sum(-1, keepdim=True) < 0), -u, u)
    extent = ((verts - centre) @ u.T).max(0).values  # (B,) support distance along u
    dist = s.init_distance[0] + (s.init_distance[1] - s.init_distance[0]) * torch.rand(b, generator=generator, dtype=dtype)
    palm_target = centre + u * (extent + dist)[:, None]
    # Rotation taking the hand's +y (the back of the hand) to u, then a random roll about u.
    y = torch.tensor([0.0, 1.0, 0.0], dtype=dtype).expand(b, 3)
    axis = torch.cross(y, u, dim=-1)
    sin = axis.norm(dim=-1, keepdim=True)
    cos = (y * u).sum(-1, keepdim=True)
    angle = torch.atan2(sin, cos)
    align = axis / sin.clamp_min(1e-9) * angle
    roll = (2 * math.pi * torch.rand(b, 1, generator=generator, dtype=dtype)) * u
    rot = axis_angle_to_matrix(roll) @ axis_angle_to_matrix(align)
    pose = hand.preset(s.init_preset, b).to(dtype)
    pose[:, 6:] += s.init_jitter * torch.randn(b, FINGER_POSE_DIM, generator=generator, dtype=dtype)
    pose[:, 3:6] = matrix_to_axis_angle(rot)
    with torch.no_grad():
        rest = hand(torch.cat([torch.zeros(b, 6, dtype=dtype), pose[:, 6:]], 1)).vertices
    palm = rest[:, hand.assets.palm_ids].mean(1)  # the palm centre, in the unrotated hand
    j0 = hand.rest_joints[0]
    pose[:, :3] = palm_target - j0 - ((rot @ (palm - j0)[..., None])[..., 0])
    n_cand = len(hand.contact_ids)
    contact = torch.randint(0, n_cand, (b, s.n_contact), generator=generator)
    return pose, contact


def vertex_subset(hand: HandModel, fraction: float) -> torch.Tensor | None:
    """(S,) increasing ids of about ``fraction`` of the hand's vertices, evenly spread over the rest hand
    (farthest-point sampling from vertex 0, deterministic), with every contact candidate and fingertip
    added; None for ``fraction >= 1`` (every vertex)."""
    if fraction >= 1:
        return None
    if fraction <= 0:
        raise ValueError(f"anneal_vertices must be in (0, 1], not {fraction}")
    from tohgs.geometry.sampling import farthest_point_sampling

    rest = hand.rest_vertices.detach().cpu().numpy()
    k = max(1, int(round(fraction * len(rest))))
    ids = np.concatenate([farthest_point_sampling(rest, k), hand.contact_ids.cpu().numpy(), hand.tip_ids.cpu().numpy()])
    return torch.as_tensor(np.unique(ids), device=hand.contact_ids.device)


def synthesize(hand: HandModel, sdf: SDFGrid, vertices: np.ndarray, settings: SynthesisSettings, seed: int,
               progress: bool = False, rest: tuple[np.ndarray, np.ndarray] | None = None) -> SynthesisResult:
    """Optimise ``settings.batch`` grasps of one object by annealing (on ``settings.anneal_vertices`` of the
    hand's vertices), then polishing (on all of them); the returned energies are on every vertex.

    Args:
        hand: the hand model (its device is used).
        sdf: the object's signed-distance grid (same device).
        vertices: (V, 3) the object's mesh vertices, for the initialisation, metres.
        settings: energy weights and optimiser settings.
        seed: the seed of every random draw (initialisation, contact switches, Metropolis).
        progress: show a progress bar.
        rest: the object's rest directions and probabilities (:func:`rest_directions`), needed by
            ``plane_direction="stable"``.
    """
    s = settings
    g = torch.Generator().manual_seed(int(seed))
    planes = support_planes(vertices, s, g, rest)
    full = GraspEnergy(hand, sdf, s, planes)
    subset = vertex_subset(hand, s.anneal_vertices)
    energy = full if subset is None else GraspEnergy(hand, sdf, s, planes, subset)
    pose, contact = initial_grasps(hand, vertices, s, g, planes)
    pose = pose.detach().requires_grad_(True)
    e = energy(pose, contact)
    (grad,) = torch.autograd.grad(e.total.sum(), pose)
    ema = torch.zeros_like(pose)
    history = [float(e.total.detach().mean())]
    n_cand = len(hand.contact_ids)
    steps = range(s.iterations)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc="synthesis", mininterval=5.0)
    for t in steps:
        lr = s.step_size * s.step_decay ** (t // s.step_decay_every)
        temp = s.temperature * s.temperature_decay ** (t // s.temperature_decay_every)
        ema = s.rmsprop_mu * ema + (1 - s.rmsprop_mu) * grad**2
        step = lr * grad / (ema.sqrt() + 1e-6)
        new_pose = (pose.detach() - step).requires_grad_(True)
        switch = torch.rand(contact.shape, generator=g) < s.switch_probability
        new_contact = torch.where(switch, torch.randint(0, n_cand, contact.shape, generator=g), contact)
        new_e = energy(new_pose, new_contact)
        (new_grad,) = torch.autograd.grad(new_e.total.sum(), new_pose)
        with torch.no_grad():
            accept = torch.rand(pose.shape[0], generator=g) < torch.exp((e.total - new_e.total) / temp)
            a = accept[:, None]
            pose = torch.where(a, new_pose, pose).detach().requires_grad_(True)
            grad = torch.where(a, new_grad, grad)
            contact = torch.where(a, new_contact, contact)
            e = Energies(**{k: torch.where(accept, getattr(new_e, k), getattr(e, k)).detach()
                            for k in e.__dict__})
        history.append(float(e.total.mean()))
    if subset is not None:  # the energies on every vertex, from here on
        with torch.no_grad():
            e = full(pose.detach(), contact).detach()
    if s.refine_iterations > 0:
        pose, e = _refine(full, pose.detach(), contact, e, s, history, progress)
    return SynthesisResult(pose.detach(), contact, planes, e.detach(), history)


def _refine(energy: GraspEnergy, pose: torch.Tensor, contact: torch.Tensor, e: Energies, s: SynthesisSettings,
            history: list[float], progress: bool) -> tuple[torch.Tensor, Energies]:
    """Polish the annealed grasps with their contacts fixed: Adam on the same energy (betas 0.9, 0.999,
    eps 1e-8), the learning rate decaying to zero on a cosine; every grasp keeps the lowest-energy pose it
    visited. Adam is written out: creating a ``torch.optim`` optimiser imports ``torch._dynamo``, seconds
    per job."""
    best_pose, best = pose.clone(), e
    x = pose.clone().requires_grad_(True)
    m, v = torch.zeros_like(x), torch.zeros_like(x)
    beta1, beta2, eps = 0.9, 0.999, 1e-8
    steps = range(s.refine_iterations)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc="refine", mininterval=5.0)
    for t in steps:
        cur = energy(x, contact)
        with torch.no_grad():
            better = cur.total < best.total
            best_pose = torch.where(better[:, None], x.detach(), best_pose)
            best = Energies(**{k: torch.where(better, getattr(cur, k), getattr(best, k)).detach()
                               for k in best.__dict__})
        (grad,) = torch.autograd.grad(cur.total.sum(), x)
        with torch.no_grad():
            lr = s.refine_lr * 0.5 * (1 + math.cos(math.pi * t / s.refine_iterations))
            m.lerp_(grad, 1 - beta1)
            v.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
            denom = (v.sqrt() / math.sqrt(1 - beta2 ** (t + 1))).add_(eps)
            x.addcdiv_(m, denom, value=-lr / (1 - beta1 ** (t + 1)))
        history.append(float(best.total.mean()))
    return best_pose, best
