"""Signed point-to-surface distances of a posed hand (tohgs.geometry.surface_distance) against a slow
reference (open3d's exact signed distance of the closed mesh), and what they change in ContactGen's solver."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh

from tohgs.geometry.hand_object import nearest_index, vertex_normals
from tohgs.geometry.raycast import exact_signed_distance
from tohgs.geometry.surface_distance import (closest_point_on_triangles, distance_to_faces, signed_surface_distance,
                                             vertex_rings)
from tohgs.hand import load_hand


@pytest.fixture(scope="module")
def posed():
    """The hand in its relaxed preset (no self-intersection, so that inside and outside are defined), its
    trimesh and points within 5 mm of its surface along the face normals, with their exact signed distances."""
    hand = load_hand("anny")
    v = hand(hand.preset("relaxed")).vertices[0].detach()
    mesh = trimesh.Trimesh(v.numpy(), hand.closed_faces.numpy(), process=False)
    assert mesh.is_watertight
    pts, fid = trimesh.sample.sample_surface(mesh, 3000, seed=0)
    off = np.random.default_rng(0).uniform(-0.005, 0.005, (len(pts), 1))
    pts = pts + off * mesh.face_normals[fid]
    return hand, v, pts, exact_signed_distance(mesh, pts)


def test_the_one_ring_distance_matches_the_exact_signed_distance_near_the_surface(posed):
    hand, v, pts, ref = posed
    p = torch.as_tensor(pts, dtype=v.dtype)[None]
    idx = nearest_index(p, v[None])
    rings = vertex_rings(hand.closed_faces, len(v), 32)
    sd = signed_surface_distance(p, v[None], hand.closed_faces, rings, idx)[0].numpy().astype(np.float64)
    near = np.abs(ref) < 0.002
    err = np.abs(sd - ref)
    assert np.mean(err[near] < 5e-5) > 0.99, np.quantile(err[near], [0.5, 0.99])
    # where they differ, the ring's closest point is farther than the surface's: never nearer
    assert (np.abs(sd) >= np.abs(ref) - 2e-5).all()
    sure = np.abs(ref) > 2e-4
    assert np.mean(np.sign(sd[sure & near]) == np.sign(ref[sure & near])) > 0.995
    # the nearest vertex alone, the proxy it replaces, is millimetres off for points on the surface
    nv = np.linalg.norm(pts - v.numpy()[idx[0].numpy()], axis=1)
    assert np.median(np.abs(nv - np.abs(ref))[near]) > 5e-4


def test_the_closest_point_on_a_triangle_is_the_nearest_of_a_dense_sample_of_it():
    gen = torch.Generator().manual_seed(0)
    a, b, c = (torch.randn(200, 3, generator=gen, dtype=torch.float64) for _ in range(3))
    p = 2 * torch.randn(200, 3, generator=gen, dtype=torch.float64)
    q = closest_point_on_triangles(p, a, b, c)
    u = torch.linspace(0, 1, 201, dtype=torch.float64)
    uu, vv = torch.meshgrid(u, u, indexing="ij")
    keep = (uu + vv) <= 1
    uu, vv = uu[keep], vv[keep]  # (S,) barycentric samples covering the triangle
    samples = a[:, None] + uu[None, :, None] * (b - a)[:, None] + vv[None, :, None] * (c - a)[:, None]
    brute = (samples - p[:, None]).norm(dim=-1).min(-1).values
    exact = (q - p).norm(dim=-1)
    assert (exact <= brute + 1e-12).all()  # never farther than any sample of the triangle
    assert torch.allclose(exact, brute, atol=0.02 * float((b - a).norm(dim=-1).max()))


def test_rings_hold_every_face_of_a_vertex_and_gradients_follow_the_offset(posed):
    hand, v, _, _ = posed
    faces = hand.closed_faces
    one = vertex_rings(faces, len(v), depth=1)
    two = vertex_rings(faces, len(v), 32)
    for f in (0, 17, len(faces) - 1):
        for corner in faces[f].tolist():
            assert f in one[corner].tolist() and f in two[corner].tolist()
    for vert in (0, 500, len(v) - 1):  # the one-ring leads the two-ring
        n1 = len(set(one[vert].tolist()))
        assert set(two[vert, :n1].tolist()) == set(one[vert].tolist())
    assert two.shape == (len(v), 32)
    with pytest.raises(ValueError, match="no face"):
        vertex_rings(faces, len(v) + 1)
    # d(distance)/d(point) is the unit offset from the closest point (finite differences agree)
    corners = faces[:4][None]  # (1, 4, 3): four points, each against one face
    verts = v[None].double()
    x = (verts[0, faces[:4]].mean(1) + 0.003 * torch.randn(4, 3, generator=torch.Generator().manual_seed(1),
                                                           dtype=torch.float64))[None].requires_grad_(True)
    d = distance_to_faces(x, verts, corners)
    (g,) = torch.autograd.grad(d.sum(), x)
    eps = 1e-7
    for k in range(3):
        dx = torch.zeros_like(x)
        dx[..., k] = eps
        fd = (distance_to_faces(x + dx, verts, corners) - distance_to_faces(x - dx, verts, corners)) / (2 * eps)
        assert torch.allclose(g[..., k], fd, atol=1e-5)


def test_points_resting_on_the_hand_are_not_penetration_for_the_surface_distance(posed):
    """The solver's penetration term (beyond 1 mm): object points lying 0.5 mm outside the surface count
    nothing with the surface distance, and something with the nearest-vertex proxy (the ContactGen row's
    grazing hands)."""
    hand, v, _, _ = posed
    mesh = trimesh.Trimesh(v.numpy(), hand.closed_faces.numpy(), process=False)
    pts, fid = trimesh.sample.sample_surface(mesh, 2000, seed=1)
    pts = pts + 0.0005 * mesh.face_normals[fid]
    p = torch.as_tensor(pts, dtype=v.dtype)[None]
    idx = nearest_index(p, v[None])
    rings = vertex_rings(hand.closed_faces, len(v), 32)
    sd = signed_surface_distance(p, v[None], hand.closed_faces, rings, idx)[0]
    assert float((-sd - 1e-3).clamp_min(0).sum()) < 1e-3 * 0.01 * len(pts)  # at most 1 % of one mm per point
    normals = vertex_normals(v[None], hand.closed_faces)
    offset = p - v[None, idx[0]]
    inside = (offset * normals[0, idx[0]]).sum(-1) < 0
    proxy = (inside * (offset.norm(dim=-1) - 1e-3).clamp_min(0)).sum()
    assert float(proxy) > 20 * max(float((-sd - 1e-3).clamp_min(0).sum()), 1e-6)


def test_the_blocked_face_search_equals_one_block(posed, monkeypatch):
    """closest_faces searches its points in blocks (SEARCH_CHUNK): blocks of 7 points, a block of them all
    and the default give the same faces, with a mask that skips some points."""
    import tohgs.geometry.surface_distance as sdist

    hand, v, pts, _ = posed
    p = torch.as_tensor(pts, dtype=v.dtype).reshape(2, -1, 3)
    verts = torch.stack([v, v + 0.001])
    idx = nearest_index(p, verts)
    rings = vertex_rings(hand.closed_faces, len(v), 32)
    where = torch.arange(p.shape[1])[None].expand(2, -1) % 3 != 0
    faces = {}
    for chunk in (7, 10**9, sdist.SEARCH_CHUNK):
        monkeypatch.setattr(sdist, "SEARCH_CHUNK", chunk)
        faces[chunk] = sdist.closest_faces(p, verts, hand.closed_faces, rings, idx, where)
    assert torch.equal(faces[7], faces[10**9]) and torch.equal(faces[sdist.SEARCH_CHUNK], faces[10**9])
    # a search happened: some searched points' faces are not their ring's first
    first = hand.closed_faces[rings[idx, 0]]
    assert not torch.equal(faces[7][where], first[where])
