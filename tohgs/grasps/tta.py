"""GraspTTA's test-time adaptation (Jiang et al. ICCV 2021): the grasp parameters (not the networks) are
optimised so that the hand touches the object where a good grasp would, without entering it.

The energy of S hands on one object cloud (each hand's own sum, so that the S optimisations are
independent; the official code generated one grasp at a time):

``E = w_contact E_contact + w_consistency E_consistency + w_penetration E_penetration``

- ``E_contact`` (hand-centric contact): for the object points within ``contact_radius`` of the hand, the
  mean squared distance to the nearest of the hand's contact-candidate vertices (palm side, fingertips:
  :attr:`tohgs.hand.assets.HandAssets.contact_ids`, the counterpart of the official code's fingertip and
  palm vertex lists), times 7500 (the official 2.5 x 3000);
- ``E_consistency``: the squared difference, summed over the points, of the contact map the hand makes
  (alpha of the map shards) and ContactNet's map for the current hand (held fixed per step), times 1e-4;
- ``E_penetration``: object points inside the hand (behind their nearest hand vertex's normal), the sum of
  their squared distances to it, times 120.

The point sums are scaled to the official 3000 points. Optimiser: SGD with momentum (the official lr
6.25e-6, momentum 0.8, 300 steps; all settings, the laptop default 50 steps). After every step the finger numbers are clamped to the
hand's joint limits (the official MANO PCA space needed no clamp; our 45 axis-angle numbers do).

The nearest hand vertex of each object point (for the contact map and the inside test) can be searched
without gradient every ``search_every`` steps and kept in between, as ContactGen's solver keeps its
correspondences (:mod:`tohgs.grasps.contactgen_solver`); the distances to the kept vertices are
recomputed, with gradient, every step. The default searches every step (exact): keeping them for 5 steps
made a configuration 1.65x faster at the same end energy, but pushed more hands off the object (a hand
deep in the object has a large penetration gradient; stale correspondences keep pushing it for up to 5
steps), and the M-GraspTTA rows lost 10-35 points of QR (docs/baselines.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from tohgs.geometry.hand_object import (contact_of_distance, contact_values, distance_to_vertices, inside_hand,
                                       nearest_vertex, vertex_normals)
from tohgs.hand.layout import FINGER_POSE_DIM
from tohgs.hand.model import HandModel, HandOutput
from tohgs.models.contact_net import ObjectCache

OFFICIAL_POINTS = 3000  # the official code's object points: the point sums are scaled to this many
TOUCH = 0.005  # m: a hand with an object point this near one of its vertices touches the object (recorded)


@dataclass(frozen=True)
class TTASettings:
    """The adaptation's optimiser and weights (module docstring); ``steps`` 0 returns the input."""

    steps: int = 50  # the paper's 300 (config/paper.yaml)
    lr: float = 6.25e-6
    momentum: float = 0.8
    w_contact: float = 1.0
    w_consistency: float = 1.0
    w_penetration: float = 7.0
    contact_radius: float = 0.02
    search_every: int = 1  # steps between searches of the nearest hand vertices (1: every step, exact)

    def __post_init__(self):
        if self.steps < 0:
            raise ValueError(f"TTA steps must be non-negative, got {self.steps}")
        if self.search_every < 1:
            raise ValueError(f"search_every must be at least 1, got {self.search_every}")


@dataclass(frozen=True)
class RefineSettings(TTASettings):
    """The adaptation run on a contact-map method's sampled hands with its own maps as the consistency
    target (:func:`refine_to_maps`; beyond the paper, whose GraspDiffuser hands are final): off (``steps``
    0) by default; the consistency weighed 100x GraspTTA's, so that the given map, not only the nearest
    object points, moves the hand."""

    steps: int = 0
    w_consistency: float = 100.0


class FixedMaps:
    """A stand-in for ContactNet in :func:`adapt_many` whose map is a given one: (B, N) ``maps`` of the
    B hands' object points, whatever the hand (what a contact-map method's hand should touch)."""

    def __init__(self, maps: torch.Tensor):
        self.maps = maps

    def object_cache(self, points: torch.Tensor) -> ObjectCache:
        """The maps of the hands whose (b, N, 3) ``points`` these are (all of them, or one problem's rows)."""
        if points.shape[0] != self.maps.shape[0]:
            raise ValueError(f"FixedMaps holds {self.maps.shape[0]} maps, asked for {points.shape[0]} hands")
        empty = points.new_zeros(points.shape[0], 0)
        return ObjectCache(self.maps.to(points), empty, points.new_zeros(*points.shape[:2], 0))

    @staticmethod
    def predict_map_cached(cache: ObjectCache, vertices: torch.Tensor, contact: torch.Tensor) -> torch.Tensor:
        return cache.local


def refine_to_maps(hand: HandModel, grasp: torch.Tensor, points: torch.Tensor, maps: torch.Tensor, alpha: float,
                   settings: TTASettings) -> tuple[torch.Tensor, dict[str, list[float]]]:
    """(B, 51) ``grasp`` on (B, N, 3) ``points`` refined by the adaptation (:func:`adapt`) with the (B, N)
    ``maps`` in [0, 1] as the consistency term's target (each hand its own), and the energy's history."""
    return adapt(hand, grasp, points, FixedMaps(maps), alpha, settings)


def clamp_to_limits(grasp: torch.Tensor, limits: torch.Tensor) -> torch.Tensor:
    """(B, 51) grasps with the 45 finger numbers clamped to (15, 3, 2) ``[min, max]`` limits, radians."""
    lim = limits.reshape(FINGER_POSE_DIM, 2).to(grasp)
    return torch.cat([grasp[:, :6], torch.maximum(torch.minimum(grasp[:, 6:], lim[:, 1]), lim[:, 0])], -1)


def pose_problems(hand: HandModel, grasp: torch.Tensor, sizes: list[int] | None = None) -> HandOutput:
    """The (B, 51) hands posed problem by problem (consecutive ``sizes`` rows; None: all at once) and put
    back together. The skinning product's rounding can depend on how many hands it poses at once, so
    posing each problem's hands alone keeps every vertex bit for bit what it is when the problem is
    solved alone (the vertices keep the model's layout: a transposed view of (B, 3, V))."""
    if sizes is None or len(sizes) == 1:
        return hand(grasp)
    outs = [hand(g) for g in grasp.split(sizes)]
    return HandOutput(vertices=torch.cat([o.vertices.transpose(1, 2) for o in outs]).transpose(1, 2),
                      joints=torch.cat([o.joints for o in outs]), rotations=torch.cat([o.rotations for o in outs]))


def by_problem(fn, sizes: list[int] | None, *args):
    """``fn`` applied to each problem's rows (consecutive ``sizes`` rows of every tensor argument, or of
    each tensor of a tuple argument) and the results put back together along the first axis (a tuple
    result element by element). A network's products can round differently on more rows, so running it
    per problem keeps its output bit for bit what it is when the problem is solved alone."""
    if sizes is None or len(sizes) == 1:
        return fn(*args)

    def split(a):
        if isinstance(a, torch.Tensor):
            return a.split(sizes)
        if isinstance(a, tuple):
            return list(zip(*(x.split(sizes) for x in a)))
        return [a] * len(sizes)

    outs = [fn(*part) for part in zip(*(split(a) for a in args))]
    if isinstance(outs[0], tuple):
        return tuple(torch.cat(parts) for parts in zip(*outs))
    return torch.cat(outs)


def object_caches(contact_net, points: torch.Tensor, sizes: list[int] | None = None):
    """ContactNet's :class:`tohgs.models.contact_net.ObjectCache` of (B, N, 3) object points, computed
    problem by problem (consecutive ``sizes`` rows; :func:`by_problem`) without gradient: what does not
    change while the hands move."""
    with torch.no_grad():
        parts = by_problem(lambda p: tuple(vars(contact_net.object_cache(p)).values()), sizes, points)
    return ObjectCache(*parts)


def _map_value_at(alpha: float, r: float) -> torch.Tensor:
    """The contact map ``1 - 2 (sigmoid(alpha d) - 0.5)`` at distance ``r`` (m): a point is nearer than ``r``
    to its vertex exactly where the map exceeds this value (the map falls with the distance)."""
    return contact_of_distance(torch.tensor(alpha * r), 1.0)  # alpha * r rounded once, as the threshold always was


def tta_energy(hand: HandModel, grasp: torch.Tensor, points: torch.Tensor, contact_net, alpha: float,
               settings: TTASettings, object_features=None, nearest: torch.Tensor | None = None,
               sizes: list[int] | None = None) -> dict[str, torch.Tensor]:
    """The three weighted terms and their sum ``"energy"``, each (B,), of (B, 51) grasps on (B, N, 3)
    object points; ``contact_net`` is a :class:`tohgs.models.contact_net.ContactNet` (``object_features``,
    its :class:`~tohgs.models.contact_net.ObjectCache` of the points (:func:`object_caches`), may be
    given: it does not change while the hands move).

    ``nearest``: (B, N) each point's kept nearest hand vertex (module docstring); searched when not given.
    The returned dict holds the one used under ``"nearest"``, without gradient, and under ``"touching"``
    (B,) 1 where some object point is within :data:`TOUCH` of its kept nearest vertex (not part of the energy:
    a record of hands the adaptation pushes off the object). ``sizes``: the hands of
    each problem when several are solved together (:func:`pose_problems`).

    ContactNet's map runs through its cached first layer (:meth:`~tohgs.models.contact_net.ContactNet.predict_map_cached`,
    float32 rounding away from :meth:`~tohgs.models.contact_net.ContactNet.predict_map`) and the vertex
    normals without gradient (they only decide which points are inside); the rest is the module
    docstring's energy as written."""
    scale = OFFICIAL_POINTS / points.shape[1]
    cache = object_caches(contact_net, points, sizes) if object_features is None else object_features
    verts = pose_problems(hand, grasp, sizes).vertices
    if nearest is None:
        c_hand, idx = contact_values(points, verts, alpha)
    else:
        idx = nearest
        d = distance_to_vertices(points, verts, idx)
        c_hand = contact_of_distance(d, alpha)
    with torch.no_grad():
        c_target = by_problem(lambda lo, gl, pr, v, c: contact_net.predict_map_cached(ObjectCache(lo, gl, pr), v, c),
                              sizes, cache.local, cache.glob, cache.projected, verts, c_hand.detach())
        normals = vertex_normals(verts, hand.closed_faces)
    consistency = 1e-4 * scale * ((c_hand - c_target) ** 2).sum(-1)
    inside, offset = inside_hand(points, verts, normals, idx)
    penetration = 120.0 * scale * (inside * (offset**2).sum(-1)).sum(-1)
    d_candidates, _ = nearest_vertex(points, verts[:, hand.contact_ids])
    with torch.no_grad():
        close = (c_hand > _map_value_at(alpha, settings.contact_radius)).float()
        touching = (c_hand.max(-1).values > _map_value_at(alpha, TOUCH)).float()
    contact = 7500.0 * (close * d_candidates**2).sum(-1) / close.sum(-1).clamp_min(1.0)
    terms = {"contact": settings.w_contact * contact, "consistency": settings.w_consistency * consistency,
             "penetration": settings.w_penetration * penetration}
    return {**terms, "energy": terms["contact"] + terms["consistency"] + terms["penetration"], "nearest": idx.detach(),
            "touching": touching}


def adapt(hand: HandModel, grasp: torch.Tensor, points: torch.Tensor, contact_net, alpha: float,
          settings: TTASettings) -> tuple[torch.Tensor, dict[str, list[float]]]:
    """Run the adaptation from (B, 51) grasps on (B, N, 3) object points (network frame, m).

    Returns:
        The adapted (B, 51) grasps (finger numbers within the joint limits) and the history of the mean
        energy and its terms (one value per step, before the step, with the vertices kept at that step;
        the last after the last step, searched afresh).
    """
    out, histories = adapt_many(hand, grasp, points, contact_net, alpha, settings, [grasp.shape[0]])
    return out, histories[0]


def adapt_many(hand: HandModel, grasp: torch.Tensor, points: torch.Tensor, contact_net, alpha: float,
               settings: TTASettings, sizes: list[int]) -> tuple[torch.Tensor, list[dict[str, list[float]]]]:
    """:func:`adapt` of several problems (e.g. the S hands of each of several test configurations, each on
    its own object) as one batch: the B = sum(``sizes``) hands in order, problem ``p`` the next
    ``sizes[p]`` rows of ``grasp`` (B, 51) and ``points`` (B, N, 3). Every term is per hand and SGD is
    per number, so a hand's result does not depend on the others in the batch, bit for bit as the
    problem's alone: each problem's hands are posed, and ContactNet run, on its rows alone
    (:func:`pose_problems`, :func:`by_problem`), the rest is per hand.

    Returns:
        The adapted (B, 51) grasps and one history per problem (the mean over its hands, as :func:`adapt`).
    """
    if sum(sizes) != grasp.shape[0] or any(n < 1 for n in sizes):
        raise ValueError(f"the problem sizes {sizes} must be positive and add up to the {grasp.shape[0]} hands")
    g = clamp_to_limits(grasp.detach().clone(), hand.joint_limits).requires_grad_(True)
    opt = torch.optim.SGD([g], lr=settings.lr, momentum=settings.momentum)
    per_step: list[dict[str, torch.Tensor]] = []  # each step's (B,) terms, averaged per problem at the end
    features = object_caches(contact_net, points, sizes)
    nearest = None
    with torch.enable_grad():
        for step in range(settings.steps + 1):
            search = step % settings.search_every == 0 or step == settings.steps
            terms = tta_energy(hand, g, points, contact_net, alpha, settings, features, None if search else nearest,
                               sizes)
            nearest = terms.pop("nearest")
            per_step.append({k: v.detach() for k, v in terms.items()})
            if step == settings.steps:
                break
            opt.zero_grad(set_to_none=True)
            terms["energy"].sum().backward()
            opt.step()
            with torch.no_grad():
                g.copy_(clamp_to_limits(g, hand.joint_limits))
    return g.detach(), problem_histories(per_step, sizes)


def problem_histories(per_step: list[dict[str, torch.Tensor]], sizes: list[int]) -> list[dict[str, list[float]]]:
    """Per problem (consecutive ``sizes`` rows of the B hands), the mean of each recorded (B,) term at each
    step that recorded it."""
    keys = list(dict.fromkeys(k for step in per_step for k in step))  # in order of appearance
    out, start = [], 0
    for n in sizes:
        out.append({k: [float(step[k][start:start + n].mean()) for step in per_step if k in step] for k in keys})
        start += n
    return out
