"""Optimising methods batched across the configurations of a prediction job: the hands of several
configurations (different objects, scenes, goals and random streams) solved as one batch give each hand
exactly the result of its configuration solved alone."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pytest
import torch
import trimesh

from helpers import pose_prior
from tohgs.data.batch import Batch
from tohgs.geometry.contact_parts import PartContact
from tohgs.geometry.maps import sample_surface
from tohgs.geometry.registration import ICPSettings, register, register_many
from tohgs.grasps.contactgen_solver import SolverSettings, representation_of, solve, solve_many
from tohgs.grasps.flex import FlexSettings, optimise, optimise_many
from tohgs.grasps.starts import near_object
from tohgs.grasps.tta import TTASettings, adapt, adapt_many
from tohgs.hand import load_hand
from tohgs.methods.base import Request
from tohgs.models.component import build_component

N = 128  # object points
MESHES = (lambda: trimesh.creation.icosphere(2, 0.035), lambda: trimesh.creation.box((0.05, 0.07, 0.09)),
          lambda: trimesh.creation.capsule(height=0.08, radius=0.025))


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


def _objects() -> list[tuple[torch.Tensor, torch.Tensor]]:
    """Three objects' (N, 3) clouds and normals, centred (the network frame)."""
    out = []
    for i, make in enumerate(MESHES):
        p, n = sample_surface(make(), N, np.random.default_rng(i))
        out.append((torch.as_tensor(p - p.mean(0), dtype=torch.float32), torch.as_tensor(n, dtype=torch.float32)))
    return out


def _scene(points: torch.Tensor, shift: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A table top under the object and a wall beside it as a (600, 3) cloud with normals, and a goal
    transform that moves the object ``shift`` m along y and turns it 30 degrees about z."""
    rng = np.random.default_rng(int(shift * 100))
    z0 = float(points[:, 2].min())
    table = np.c_[rng.uniform(-0.15, 0.15, (400, 2)), np.full(400, z0)]
    wall = np.c_[np.full(200, 0.06), rng.uniform(-0.15, 0.15, 200), rng.uniform(z0, z0 + 0.1, 200)]
    normals = np.r_[np.tile([0.0, 0.0, 1.0], (400, 1)), np.tile([-1.0, 0.0, 0.0], (200, 1))]
    goal = np.eye(4)
    a = np.radians(30)
    goal[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    goal[1, 3] = shift
    return (torch.as_tensor(np.r_[table, wall], dtype=torch.float32), torch.as_tensor(normals, dtype=torch.float32),
            torch.as_tensor(goal, dtype=torch.float32))


def test_tta_of_several_configurations_equals_each_alone(hand):
    torch.manual_seed(0)
    net = build_component("contact_net", {"object_mlp": [16], "hand_mlp": [16], "head": [16]}).eval()
    sizes = [3, 3, 3]  # S hands each, as in a prediction job (module docstring of tohgs.grasps.tta: unequal sizes)
    objects = _objects()
    grasps = [near_object(hand, p, n, seed) for seed, ((p, _), n) in enumerate(zip(objects, sizes))]
    points = [p[None].expand(n, -1, -1) for (p, _), n in zip(objects, sizes)]
    s = TTASettings(steps=12)
    alone = [adapt(hand, g, p, net, 100.0, s) for g, p in zip(grasps, points)]
    together, histories = adapt_many(hand, torch.cat(grasps), torch.cat(points), net, 100.0, s, sizes)
    assert torch.equal(together, torch.cat([g for g, _ in alone])), "bit for bit, hand by hand"
    assert histories == [h for _, h in alone], "each configuration's own energy history"
    assert len({round(h["energy"][-1], 6) for h in histories}) == 3, "the configurations differ"
    with pytest.raises(ValueError, match="add up"):
        adapt_many(hand, torch.cat(grasps), torch.cat(points), net, 100.0, s, [3, 3, 2])


def test_contactgen_solver_of_several_configurations_equals_each_alone(hand):
    sizes = [2, 2, 2]
    objects = _objects()
    reps, points = [], []
    for seed, ((p, _), n) in enumerate(zip(objects, sizes)):
        pts = p[None].expand(n, -1, -1)
        reps.append(representation_of(hand, near_object(hand, p, n, 10 + seed), pts, 100.0))
        points.append(pts)
    s = SolverSettings(global_steps=8, pose_steps=16, search_every=3, max_contact_points=32)
    alone = [solve(hand, p, r, s) for p, r in zip(points, reps)]
    target = PartContact(*(torch.cat([getattr(r, k) for r in reps]) for k in ("contact", "part", "direction")))
    together, histories = solve_many(hand, torch.cat(points), target, s, sizes)
    assert torch.equal(together, torch.cat([g for g, _ in alone]))
    assert histories == [h for _, h in alone]


def test_flex_of_several_configurations_equals_each_alone(hand):
    """Each configuration keeps its own starts (its generator), drops its own worse half and returns its
    own best S: a drop or a choice across configurations would change some configuration's grasps."""
    prior = pose_prior(hand)
    objects = _objects()
    scenes = [_scene(p, shift) for (p, _), shift in zip(objects, (0.1, 0.2, 0.3))]
    s = FlexSettings(steps=14, batch=8, drop_at=(4, 9), search_every=3, hand_points=128)
    gens = lambda: [torch.Generator().manual_seed(100 + i) for i in range(3)]  # noqa: E731
    alone = [optimise(hand, prior, p, n, sc, scn, goal, 2, s, g)
             for (p, n), (sc, scn, goal), g in zip(objects, scenes, gens())]
    stack = [torch.stack(x) for x in ([o[0] for o in objects], [o[1] for o in objects], *zip(*scenes))]
    together, histories = optimise_many(hand, prior, *stack, 2, s, gens())
    assert torch.equal(together, torch.cat([g for g, _ in alone]))
    assert histories == [h for _, h in alone]
    assert len(histories[0]["energy"]) == s.steps + 1


def _icp_pairs() -> list[tuple[np.ndarray, np.ndarray]]:
    """Each object's cloud and a second sample of it turned and moved (the goal scene's moved points)."""
    rng = np.random.default_rng(5)
    pairs = []
    for make in MESHES:
        src, _ = sample_surface(make(), 96, rng)
        tgt, _ = sample_surface(make(), 96, rng)
        pairs.append((src, tgt @ trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3].T + [0.2, 0.1, 0]))
    return pairs


def test_icp_of_several_configurations_equals_each_alone():
    pairs = _icp_pairs()
    settings = ICPSettings(z_turns=1, max_iterations=15)
    together = register_many(pairs, settings)
    for (src, tgt), reg in zip(pairs, together):
        alone = register(src, tgt, settings)
        np.testing.assert_array_equal(reg.transform, alone.transform)
        assert (reg.fitness, reg.chamfer) == (alone.fitness, alone.chamfer)
    with pytest.raises(ValueError, match="at least 3 points"):
        register_many([pairs[0], (pairs[1][0][:2], pairs[1][1])], settings)


@dataclass
class _Shard:
    """What the methods read of a map shard: the objects vocabulary, ids, indices and centroids."""

    attrs: dict = field(default_factory=lambda: {"objects": ["sphere", "box", "capsule"]})
    object_id: np.ndarray = field(default_factory=lambda: np.arange(3))
    config_index: np.ndarray = field(default_factory=lambda: np.array([4, 0, 7]))
    centroid: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    alpha_contact: float = 100.0


def _requests(samples: int) -> list[Request]:
    """A request per object, each with its own scene, goal and streams (fresh on every call)."""
    out = []
    for c, ((p, n), shift) in enumerate(zip(_objects(), (0.1, 0.2, 0.3))):
        scene, scene_n, goal = _scene(p, shift)
        zeros = torch.zeros(1, N)
        batch = Batch(points=p[None], normals=n[None], d_init=zeros, d_goal=zeros, scene=scene[None],
                      scene_normals=scene_n[None], goal_transform=goal[None]).repeat(samples)
        out.append(Request(batch, _Shard(), c, torch.Generator().manual_seed(1000 + c), np.random.default_rng(c)))
    return out


def _same(a, b) -> None:
    """Two lists of predictions equal: maps, grasps, kept flags and records."""
    assert len(a) == len(b)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.grasp, y.grasp)
        np.testing.assert_array_equal(x.contact, y.contact)
        assert (x.kept is None) == (y.kept is None) and (x.kept is None or np.array_equal(x.kept, y.kept))
        assert x.info == y.info and set(x.seconds) == set(y.seconds)


def _method(kind: str, cfg: dict, models: dict, settings: dict, hand, base=None):
    from tohgs.methods.predict import method_class

    cls = method_class(kind)
    return cls(kind, {"kind": kind, **cfg}, models, cls.Settings(**settings), torch.device("cpu"), hand, base)


@pytest.mark.parametrize("kind", ["grasp_tta", "contact_gen", "flex"])
def test_a_method_predicts_a_chunk_as_it_predicts_each_configuration(hand, kind):
    """predict_many on three configurations against predict on each: the same maps and grasps, so each
    configuration drew its samples from its own streams (a stream shared across the chunk would not)."""
    torch.manual_seed(0)
    small = {"object_mlp": [16], "hand_mlp": [16], "head": [16]}
    if kind == "grasp_tta":
        cfg = {"cvae": "cvae", "contact_net": "net", "contact": "none"}
        cvae = {"object_mlp": [16], "hand_mlp": [16], "encoder": [16], "decoder": [16], "latent": 4}
        models = {"cvae": build_component("grasp_cvae", cvae).eval(), "net": build_component("contact_net", small).eval()}
        settings = {"samples": 3, "tta": {"steps": 6}}
    elif kind == "contact_gen":
        cfg = {"model": "cg"}
        net = {"latent": 4, "hidden": [16], "pointnet": {"sa": [[32, 0.03, 8, [16]], [0, 0.0, 0, [32]]], "fp": [[32], [16]]}}
        models = {"cg": build_component("contact_gen", net).eval()}
        settings = {"samples": 3, "contactgen": {"global_steps": 4, "pose_steps": 8, "max_contact_points": 16}}
    else:
        cfg = {"prior": "prior"}
        models = {"prior": pose_prior(hand)}
        settings = {"samples": 2, "flex": {"steps": 8, "batch": 8, "drop_at": [3, 6], "hand_points": 64}}
    method = _method(kind, cfg, models, {**settings, "chunk": 3}, hand)
    together = method.predict_many(_requests(settings["samples"]))
    alone = [method.predict(r.batch, r.shard, r.row, r.generator, r.rng) for r in _requests(settings["samples"])]
    _same(together, alone)
    assert not np.array_equal(together[0].grasp, together[1].grasp)


def test_f_grasptta_filters_a_chunk_as_it_filters_each_configuration(hand):
    """The filter's ICP estimates and its kept flags, a chunk at once against one configuration at a time
    (each configuration's scene views split by the seed from its own stream)."""
    shard = _Shard()
    grasps = np.stack([near_object(hand, p, 4, 20 + c).numpy() for c, (p, _) in enumerate(_objects())])
    arrays = {"object_id": shard.object_id.astype(np.int32), "config_index": shard.config_index.astype(np.int32),
              "grasp_init": grasps.astype(np.float32), "kept": np.ones((3, 4), bool),
              "contact": np.zeros((3, 4, N), np.float32)}
    base = (arrays, {"objects": shard.attrs["objects"]})
    settings = {"samples": 4, "chunk": 3, "filter": {"icp": {"z_turns": 1, "max_iterations": 10}, "max_opp": 0.02}}
    method = _method("filtered", {"of": "grasptta"}, {}, settings, hand, base)
    together = method.predict_many(_requests(4))
    alone = [method.predict(r.batch, r.shard, r.row, r.generator, r.rng) for r in _requests(4)]
    _same(together, alone)
    assert all(np.isfinite(p.info["icp_rotation_deg"]) for p in together)
    shuffled = _requests(4)  # another configuration's stream splits the views differently
    shuffled[0] = replace(shuffled[0], rng=np.random.default_rng(99))
    assert method.predict_many(shuffled)[0].info != together[0].info
