"""ContactGen's object-centric representation: contact, part and direction maps of a known hand pose."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from tohgs.geometry.contact_parts import N_PARTS, directions_to_world, part_contact
from tohgs.geometry.hand_object import contact_values
from tohgs.hand import load_hand


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


def _posed(hand, seed: int = 0) -> tuple[torch.Tensor, object]:
    """A grasping pose (the ``power`` preset) turned and moved at random, and the posed hand."""
    rng = np.random.default_rng(seed)
    pose = hand.preset("power").clone()
    pose[0, 3:6] = torch.as_tensor(Rotation.random(random_state=seed).as_rotvec(), dtype=pose.dtype)
    pose[0, :3] = torch.as_tensor(rng.uniform(-0.2, 0.2, 3), dtype=pose.dtype)
    return pose, hand(pose)


def test_the_part_and_direction_of_rigidly_skinned_vertices_are_recovered_exactly(hand):
    """Object points on the hand's rigidly skinned vertices (one joint's weight above 0.999): the part is
    that joint, and the direction is the vertex's rest offset from the joint, whatever the pose: the
    posed frames (the forward pass's rotations) are checked against the rest geometry, not against
    themselves."""
    weights, labels = hand.weights, hand.part_labels
    rigid = torch.nonzero(weights.max(-1).values > 0.999)[:, 0]
    parts_present = set(labels[rigid].tolist())
    assert len(parts_present) >= 10, f"only {len(parts_present)} parts have rigid vertices"
    expected = hand.rest_vertices[rigid] - hand.rest_joints[labels[rigid]]
    expected = expected / expected.norm(dim=-1, keepdim=True)
    for seed in range(3):
        _, out = _posed(hand, seed)
        points = out.vertices[:, rigid]  # (1, R, 3) object points exactly on those vertices
        rep = part_contact(points, out.vertices, out.joints, out.rotations, labels, alpha=100.0)
        assert torch.equal(rep.part[0], labels[rigid]), "each point's part is its vertex's joint"
        err = (rep.direction[0] - expected).norm(dim=-1)
        assert float(err.max()) < 1e-4, f"seed {seed}: direction error up to {float(err.max()):.2e}"
        assert float(rep.contact.min()) > 0.999, "a point on the hand is in full contact"


def test_directions_go_back_to_the_world_and_the_contact_is_the_shards_map(hand):
    torch.manual_seed(0)
    _, out = _posed(hand, 5)
    centre = out.vertices[0].mean(0)
    points = centre + 0.06 * torch.randn(1, 300, 3)
    rep = part_contact(points, out.vertices, out.joints, out.rotations, hand.part_labels, alpha=100.0)
    assert rep.part.min() >= 0 and rep.part.max() < N_PARTS
    assert torch.allclose(rep.direction.norm(dim=-1), torch.ones(1, 300), atol=1e-5)
    world = directions_to_world(rep.part, rep.direction, out.rotations)
    origin = out.joints[0, rep.part[0]]
    offset = points[0] - origin
    assert float((world[0] - offset / offset.norm(dim=-1, keepdim=True)).norm(dim=-1).max()) < 1e-4
    expected, _ = contact_values(points, out.vertices, 100.0)
    assert torch.allclose(rep.contact, expected)
    near = rep.contact > 0.5
    assert 0 < int(near.sum()) < 300, "some points near the hand, some away"
    with pytest.raises(ValueError, match="rotations must have shape"):
        part_contact(points, out.vertices, out.joints, out.rotations[:, :15], hand.part_labels, 100.0)


# ---------------------------------------------------------------------------------------------------------
# The sequential CVAE (ContactGen) and its contact-only reduction (ContactCVAE) learn their targets.

from helpers import prepared_component, train_steps  # noqa: E402
from tohgs.data.batch import Batch  # noqa: E402

CONTACT_GEN = {"latent": 8, "hidden": [32, 32], "kl_anneal_steps": 50,
               "pointnet": {"sa": [[64, 0.03, 16, [32, 32]], [0, 0.0, 0, [64]]], "fp": [[64], [32]]}}


@pytest.mark.parametrize("parts", [True, False])
def test_a_trained_contact_gen_reconstructs_its_targets_better_than_an_untrained_one(built, parts):  # noqa: F811
    tmp, hand, _, _, _ = built
    net = {**CONTACT_GEN, "parts": parts}
    fresh, data = prepared_component("contact_gen", net, tmp / "shard-0.zarr", hand)
    trained, _ = prepared_component("contact_gen", net, tmp / "shard-0.zarr", hand)
    train_steps(trained, data, 80)
    batch = Batch.collate([data.item(i, 0) for i in range(len(data))])
    truth = trained.targets(batch) if parts else None
    w = 1.0 + 5.0 * batch.contact

    def errors(model):
        rep = model.eval().reconstruct(batch)
        out = {"contact": float((w * (rep.contact - batch.contact).abs()).mean())}
        if parts:
            out["part"] = float((w * (rep.part != truth.part)).mean())
            out["direction"] = float((w * (1 - (rep.direction * truth.direction).sum(-1))).mean())
        return out

    e_fresh, e_trained = errors(fresh), errors(trained)
    for k in e_fresh:
        assert e_trained[k] < 0.5 * e_fresh[k], (k, e_trained, e_fresh)
    gen = torch.Generator().manual_seed(0)
    maps = trained.sample_contact(batch, "ddim", 1, gen)
    assert maps.shape == batch.contact.shape and float(maps.min()) >= 0 and float(maps.max()) <= 1
    if parts:
        rep = trained.sample_representation(batch, gen)
        assert rep.part.shape == batch.contact.shape and int(rep.part.max()) < N_PARTS
        assert torch.allclose(rep.direction.norm(dim=-1), torch.ones_like(batch.contact), atol=1e-5)
        # the sampled map puts contact where the training maps have it: on the cube's top, under the hand
        top = batch.points[..., 2] > batch.points[..., 2].max() - 0.01
        assert float(maps[top].mean()) > float(maps[~top].mean()) + 0.1


# ---------------------------------------------------------------------------------------------------------
# The solver brings a perturbed ground-truth hand back toward the representation it made.

from tohgs.grasps.contactgen_solver import SolverSettings, default_start, representation_of, solve  # noqa: E402
from tohgs.models.contact_net import perturb_grasps  # noqa: E402
from tohgs.data.maps import MapDataset  # noqa: E402


def test_the_solver_brings_a_perturbed_hand_back_to_its_representation(built):  # noqa: F811
    tmp, hand, _, _, _ = built
    data = MapDataset([tmp / "shard-0.zarr"], per="grasp")
    batch = Batch.collate([data.item(i, 0) for i in range(len(data))])
    alpha = data.shards[0].alpha_contact
    target = representation_of(hand, batch.grasp, batch.points, alpha)
    start = perturb_grasps(batch.grasp, (0.015, 0.15, 0.15), torch.Generator().manual_seed(3))
    settings = SolverSettings(global_steps=40, pose_steps=120)
    grasp, history = solve(hand, batch.points, target, settings, start=start)
    with torch.no_grad():
        true_v = hand(batch.grasp).vertices
        err_start = (hand(start).vertices - true_v).norm(dim=-1).mean().item()
        err_end = (hand(grasp).vertices - true_v).norm(dim=-1).mean().item()
    e_start = history["energy"][settings.global_steps]  # the first pose-stage energy (every term)
    assert history["energy"][-1] < 0.5 * e_start, (history["energy"][-1], e_start)
    assert err_end < 0.6 * err_start, (err_end, err_start)
    lim = hand.joint_limits.reshape(45, 2)
    assert ((grasp[:, 6:] >= lim[:, 0] - 1e-6) & (grasp[:, 6:] <= lim[:, 1] + 1e-6)).all()
    # from the default start too, the contact energy falls (the global stage finds the contact side)
    _, hist = solve(hand, batch.points, target, SolverSettings(global_steps=60, pose_steps=0))
    assert hist["contact"][-1] < 0.7 * hist["contact"][0]
    assert default_start(hand, 2).shape == (2, 51)


def test_the_part_search_finds_the_nearest_vertex_of_the_assigned_part(hand):
    """The padded per-part search against the brute-force masked minimum over every vertex."""
    from tohgs.grasps.contactgen_solver import nearest_part_vertex, part_table

    _, out = _posed(hand, seed=4)
    verts = out.vertices.expand(3, -1, -1)
    gen = torch.Generator().manual_seed(0)
    points = verts[:, :1].detach() + 0.05 * torch.randn(3, 200, 3, generator=gen)
    part = torch.randint(0, N_PARTS, (3, 200), generator=gen)
    idx = nearest_part_vertex(points, part, verts, part_table(hand.part_labels))
    d = torch.cdist(points, verts).masked_fill(hand.part_labels[None, None] != part[..., None], float("inf"))
    assert torch.equal(hand.part_labels[idx], part)
    assert torch.allclose(torch.gather(d, 2, idx[..., None])[..., 0], d.min(-1).values)


def test_kept_correspondences_solve_as_well_as_searching_every_step(built):  # noqa: F811
    """``search_every`` 10 (the default) ends within 15 % of the exact search's energy, from the same start."""
    tmp, hand, _, _, _ = built
    data = MapDataset([tmp / "shard-0.zarr"], per="grasp")
    batch = Batch.collate([data.item(i, 0) for i in range(len(data))])
    target = representation_of(hand, batch.grasp, batch.points, 100.0)
    start = perturb_grasps(batch.grasp, (0.015, 0.15, 0.15), torch.Generator().manual_seed(3))
    ends = {}
    for every in (1, 10):
        _, hist = solve(hand, batch.points, target, SolverSettings(global_steps=20, pose_steps=60, search_every=every),
                        start=start)
        ends[every] = hist["energy"][-1]
    assert ends[10] < 1.15 * ends[1], ends
    with pytest.raises(ValueError, match="search_every"):
        SolverSettings(search_every=0)


def test_the_surface_terms_on_their_counting_points_equal_the_terms_over_every_point(built):  # noqa: F811
    """The solver measures the contact term's distances only for entries of non-zero weight and the
    penetration depths only for points near the hand; the energies and their gradients are those of the
    same terms over every point (the dense form, written out here), bit for bit."""
    from tohgs.geometry.hand_object import distance_to_vertices, nearest_index, vertex_normals
    from tohgs.geometry.surface_distance import closest_faces, corner_normals, distance_to_faces
    from tohgs.geometry.surface_distance import vertex_rings
    from tohgs.grasps.contactgen_solver import (CONTACTGEN_POINTS, NEAR_HAND, RING_WIDTH, contact_points,
                                                nearest_part_vertex, part_table, solver_energy)

    tmp, hand, _, _, _ = built
    data = MapDataset([tmp / "shard-0.zarr"], per="grasp")
    batch = Batch.collate([data.item(i, 0) for i in range(len(data))])
    target = representation_of(hand, batch.grasp, batch.points, 100.0)
    s = SolverSettings(min_contact=0.3, max_contact_points=64)
    sel = contact_points(target.contact, s)
    assert (sel[1] == 0).any() and (sel[1] > 0).any()  # both kinds of entries
    grasp = perturb_grasps(batch.grasp, (0.01, 0.1, 0.1), torch.Generator().manual_seed(5)).requires_grad_(True)
    terms = solver_energy(hand, grasp, batch.points, target, s, "pose", sel)
    # the dense form: every selected entry's and every point's distance, the ones that do not count times 0
    idx, weight = sel
    out = hand(grasp)
    pts = batch.points
    scale = CONTACTGEN_POINTS / pts.shape[1]
    rings = vertex_rings(hand.closed_faces, hand.rest_vertices.shape[0], RING_WIDTH)
    sel_pts = torch.gather(pts, 1, idx[..., None].expand(-1, -1, 3))
    part = nearest_part_vertex(sel_pts, torch.gather(target.part, 1, idx), out.vertices, part_table(hand.part_labels))
    d_part = distance_to_faces(sel_pts, out.vertices, closest_faces(sel_pts, out.vertices, hand.closed_faces, rings, part))
    contact = s.w_contact * scale * (weight * d_part).sum(-1)
    idx_h = nearest_index(pts, out.vertices)
    near = distance_to_vertices(pts, out.vertices, idx_h) < NEAR_HAND
    assert near.any() and not near.all()
    faces = closest_faces(pts, out.vertices, hand.closed_faces, rings, idx_h, near)
    normals = corner_normals(vertex_normals(out.vertices.detach(), hand.closed_faces), faces)
    sd = distance_to_faces(pts, out.vertices, faces, normals)
    penetration = s.w_penetration * scale * (near.to(pts.dtype) * (-sd - 1e-3).clamp_min(0)).sum(-1)
    assert (terms["penetration"] > 0).any()  # the perturbed hands press into their objects
    for name, dense in (("contact", contact), ("penetration", penetration)):
        assert torch.equal(terms[name], dense), name
        (g_sparse,) = torch.autograd.grad(terms[name].sum(), grasp, retain_graph=True)
        (g_dense,) = torch.autograd.grad(dense.sum(), grasp, retain_graph=True)
        assert torch.equal(g_sparse, g_dense), name


def test_the_ground_truth_gate_solves_the_representation_of_the_datasets_own_grasps(built):  # noqa: F811
    """``model: ground_truth`` (the solver's gate): per configuration the representation of the grasps the
    Dataset row evaluates (ground_truth_pick), solved from the default start; the hands come back near those
    grasps (closer than the start), and a configuration without task grasps is not predicted."""
    from tohgs.data.maps import read_map_shard
    from tohgs.methods.base import Request, ground_truth_pick
    from tohgs.methods.contact_gen import ContactGenMethod, ContactGenSettings
    from tohgs.settings import settings_from

    tmp, hand, _, _, _ = built
    shard = read_map_shard(tmp / "shard-0.zarr")
    data = MapDataset([tmp / "shard-0.zarr"], per="config")
    cpu = torch.device("cpu")
    s = settings_from(ContactGenSettings, {"samples": 3, "seed": 1, "device": "cpu",
                                            "contactgen": {"global_steps": 40, "pose_steps": 100}})
    gate = ContactGenMethod("contactgen-gt", {"kind": "contact_gen", "model": "ground_truth"}, {}, s, cpu, hand)
    requests = [Request(Batch.collate([data[row]], cpu).repeat(3), shard, row, torch.Generator().manual_seed(0),
                        np.random.default_rng(0)) for row in range(shard.n_configs)]
    preds = gate.predict_many(requests)
    assert len(preds) == shard.n_configs
    for row, pred in enumerate(preds):
        ids = ground_truth_pick(shard, row, 3, 1)
        truth = torch.as_tensor(shard.grasp[ids], dtype=torch.float32)
        with torch.no_grad():
            v_true = hand(truth).vertices
            err = (hand(torch.as_tensor(pred.grasp, dtype=torch.float32)).vertices - v_true).norm(dim=-1).mean()
            start = default_start(hand, 3)
            err_start = (hand(start).vertices - v_true).norm(dim=-1).mean()
        assert float(err) < 0.3 * float(err_start), (row, float(err), float(err_start))
        np.testing.assert_allclose(pred.contact, representation_of(
            hand, truth, requests[row].batch.points, shard.alpha_contact).contact.numpy(), atol=1e-6)
    # no task grasps: no prediction (the tables count the configuration as missing)
    empty = type(shard)({**shard.arrays, "grasp_config": np.full_like(shard.grasp_config, -1)}, shard.attrs)
    assert gate.predict_many([Request(requests[0].batch, empty, 0, requests[0].generator, requests[0].rng)]) == [None]
    with pytest.raises(ValueError, match="not among the trained components"):
        ContactGenMethod("contactgen", {"kind": "contact_gen", "model": "contact_gen"}, {}, s, cpu, hand)


def test_the_representation_check_sees_a_collapsed_contact_latent(built):  # noqa: F811
    """model_checks' representation_fit: a ContactGen whose contact decoder ignores its latent (a collapsed
    posterior) draws one map for every sample (sample IoU 1); the same network reading its latent does not;
    the part histogram is compared where there is contact, and the curve's last KLs are reported."""
    from tohgs.models.checks import representation_fit

    tmp, hand, _, _, _ = built
    model, _ = prepared_component("contact_gen", CONTACT_GEN, tmp / "shard-0.zarr", hand)
    model.eval()
    data = MapDataset([tmp / "shard-0.zarr"], per="grasp")
    with torch.no_grad():  # a contact map of about half the points, varying with the latent
        model.contact_stage.decoder[-1].bias.fill_(0.0)
        model.contact_stage.decoder[-1].weight.mul_(20.0)
    curve = [{"kl_contact": 0.5, "kl_part": 1.0, "kl_direction": 2.0}]
    reads = representation_fit(model, hand, data, curve, samples=4)
    assert 0.05 < reads["contact_fraction"] < 0.95 and reads["sample_iou_median"] < 0.9, reads
    assert 0 <= reads["part_tv"] <= 1 and reads["kl_direction"] == 2.0
    first = model.contact_stage.decoder[0]
    with torch.no_grad():  # the decoder's first layer reads [features, z]: cut the latent's columns
        first.weight[:, -model.cfg.latent:] = 0
    collapsed = representation_fit(model, hand, data, curve, samples=4)
    assert collapsed["sample_iou_median"] == 1.0, collapsed


def test_the_representation_check_measures_the_contact_stage_s_reconstruction(built):  # noqa: F811
    """representation_fit's reconstruction IoU is each true map against the contact stage's posterior-mean
    reconstruction of it: 1 for a stage that gives the map back, 0 for one that gives nothing back; the
    sampled values' 99th percentile is reported beside the truth's."""
    from tohgs.models.checks import representation_fit

    tmp, hand, _, _, _ = built
    model, _ = prepared_component("contact_gen", CONTACT_GEN, tmp / "shard-0.zarr", hand)
    model.eval()
    data = MapDataset([tmp / "shard-0.zarr"], per="grasp")
    plain = representation_fit(model, hand, data, samples=2)
    assert 0 <= plain["reconstruction_iou_median"] <= 1 and 0 < plain["contact_p99"] < 1
    assert 0.5 < plain["true_contact_p99"] <= 1
    model.reconstruct_contact = lambda batch: batch.contact  # a perfect reconstruction
    assert representation_fit(model, hand, data, samples=2)["reconstruction_iou_median"] == 1.0
    model.reconstruct_contact = lambda batch: torch.zeros_like(batch.contact)  # none
    assert representation_fit(model, hand, data, samples=2)["reconstruction_iou_median"] == 0.0
