"""The optimisers' fast per-hand paths against their slow, obviously right references: the vertex normals,
the nearest-vertex and nearest-cloud-point searches, ContactNet's cached first layer, and GraspTTA's
energy (each reference is the computation as it was written before the speed work)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from tohgs.geometry.cloud import CloudIndex
from tohgs.geometry.hand_object import contact_values, inside_hand, nearest_index, nearest_vertex, vertex_normals
from tohgs.geometry.maps import sample_surface
from tohgs.grasps.starts import near_object
from tohgs.grasps.tta import OFFICIAL_POINTS, TTASettings, object_caches, tta_energy
from tohgs.hand import load_hand
from tohgs.models.component import build_component


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


@pytest.fixture(scope="module")
def problem(hand):
    """Six hands near a 512-point capsule (random turns, the palm on the surface, some inside it)."""
    p, n = sample_surface(trimesh.creation.capsule(height=0.08, radius=0.03), 512, np.random.default_rng(0))
    points = torch.as_tensor(p - p.mean(0), dtype=torch.float32)
    return near_object(hand, points, 6, 0), points[None].expand(6, -1, -1)


def reference_vertex_normals(verts: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """(B, V, 3) area-weighted unit vertex normals, accumulated along the vertex axis of (B, V, 3)."""
    tri = verts[:, faces]
    fn = torch.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0], dim=-1)
    vn = torch.zeros_like(verts)
    for k in range(3):
        vn = vn.index_add(1, faces[:, k], fn)
    return vn / vn.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def test_vertex_major_normals_are_bit_for_bit_the_reference(hand, problem):
    grasp, _ = problem
    with torch.no_grad():
        verts = hand(grasp).vertices
        fast = vertex_normals(verts, hand.closed_faces)  # the vertex-major path (no gradient)
    assert torch.equal(fast, reference_vertex_normals(verts, hand.closed_faces)), "the same normals, bit for bit"
    g = grasp.clone().requires_grad_(True)  # with gradient: the reference layout, deterministic on any thread count
    assert torch.equal(vertex_normals(hand(g).vertices, hand.closed_faces).detach(), fast)


def test_the_tuned_trees_find_the_brute_force_nearest_point(hand, problem):
    grasp, points = problem
    with torch.no_grad():
        verts = hand(grasp).vertices
    brute = ((points.double()[:, :, None] - verts.double()[:, None]) ** 2).sum(-1).argmin(-1)
    assert verts.shape[1] > 256, "the tree path (large clouds)"
    assert torch.equal(nearest_index(points, verts), brute)
    scene = verts[0]  # a fixed cloud asked by the other hands' vertices
    index = CloudIndex(scene, torch.nn.functional.normalize(scene, dim=-1))
    query = verts[1:, ::3]
    brute_cloud = ((query.double()[..., None, :] - scene.double()) ** 2).sum(-1).argmin(-1)
    assert torch.equal(index.nearest(query), brute_cloud)


@pytest.fixture(scope="module")
def contact_net():
    torch.manual_seed(0)
    return build_component("contact_net", {"object_mlp": [64, 128], "hand_mlp": [64, 128], "head": [128, 64]}).eval()


def test_the_cached_first_layer_gives_contact_net_s_map_to_float_rounding(hand, problem, contact_net):
    grasp, points = problem
    with torch.no_grad():
        verts = hand(grasp).vertices
        current, _ = contact_values(points, verts, 100.0)
        ref = contact_net.predict_map(points, verts, current)
        cache = contact_net.object_cache(points)
        fast = contact_net.predict_map_cached(cache, verts, current)
        assert ref.shape == fast.shape
        assert float((fast - ref).abs().max()) < 2e-6, "float32 rounding of the reordered first layer"
        assert not torch.equal(fast, contact_net.predict_map_cached(cache, verts, 1 - current)), "the current map enters"
        # a hand's map depends on its own numbers only: other hands in its chunk changed, its map is the same
        other = verts.clone()
        other[1:] += 0.01
        assert torch.equal(contact_net.predict_map_cached(cache, other, current)[0], fast[0])


def reference_tta_energy(hand, grasp, points, contact_net, alpha, settings):
    """GraspTTA's energy as written before the speed work (ContactNet's full first layer, normals with
    gradient): the three weighted terms' sum (B,) and the nearest vertices (B, N)."""
    scale = OFFICIAL_POINTS / points.shape[1]
    verts = hand(grasp).vertices
    c_hand, idx = contact_values(points, verts, alpha)
    with torch.no_grad():
        c_target = contact_net.predict_map(points, verts, c_hand.detach(), contact_net.object_features(points))
    consistency = 1e-4 * scale * ((c_hand - c_target) ** 2).sum(-1)
    inside, offset = inside_hand(points, verts, reference_vertex_normals(verts, hand.closed_faces), idx)
    penetration = 120.0 * scale * (inside * (offset**2).sum(-1)).sum(-1)
    d_candidates, _ = nearest_vertex(points, verts[:, hand.contact_ids])
    with torch.no_grad():
        close = (c_hand > 1.0 - 2.0 * (torch.sigmoid(torch.tensor(alpha * settings.contact_radius)) - 0.5)).float()
    contact = 7500.0 * (close * d_candidates**2).sum(-1) / close.sum(-1).clamp_min(1.0)
    energy = settings.w_contact * contact + settings.w_consistency * consistency + settings.w_penetration * penetration
    return energy, idx


def test_the_adaptation_energy_and_its_gradient_match_the_reference(hand, problem, contact_net):
    grasp, points = problem
    settings = TTASettings()
    g_ref = grasp.clone().requires_grad_(True)
    e_ref, idx_ref = reference_tta_energy(hand, g_ref, points, contact_net, 100.0, settings)
    e_ref.sum().backward()
    g_new = grasp.clone().requires_grad_(True)
    terms = tta_energy(hand, g_new, points, contact_net, 100.0, settings, object_caches(contact_net, points))
    terms["energy"].sum().backward()
    assert torch.equal(terms["nearest"], idx_ref), "the same nearest vertices"
    assert float(terms["penetration"].max()) > 0, "some hands enter the object: every term is exercised"
    assert torch.allclose(terms["energy"], e_ref, rtol=1e-5, atol=1e-7)
    assert torch.allclose(g_new.grad, g_ref.grad, rtol=1e-4, atol=1e-4 * float(g_ref.grad.abs().max()))
