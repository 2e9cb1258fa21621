"""Force-closure grasp synthesis: the energy terms and the annealing optimiser."""

from __future__ import annotations

import pytest
import torch

from tohgs.assets.bricks import make_brick
from tohgs.geometry.sdf import SDFGrid
from tohgs.grasps.synthesis import (GraspEnergy, SynthesisSettings, initial_grasps, support_planes, synthesize,
                                    vertex_subset, wrench_energy)
from tohgs.hand import load_hand


@pytest.fixture(scope="module")
def setup():
    hand = load_hand("anny")
    cube = make_brick("cube")
    cube.apply_translation(-cube.center_mass)
    return hand, cube, SDFGrid.build(cube, spacing=0.002, padding=0.05)


def test_wrench_energy_known_cases():
    x = torch.tensor([[[0.02, 0, 0], [-0.02, 0, 0]]])
    balanced = torch.tensor([[[1.0, 0, 0], [-1.0, 0, 0]]])
    assert wrench_energy(x, balanced).item() == pytest.approx(0.0)
    single = torch.tensor([[[1.0, 0, 0], [1.0, 0, 0]]])
    assert wrench_energy(x, single).item() == pytest.approx(4.0)  # |2 n|^2, no torque (x parallel to n)
    twist = torch.tensor([[[0, 1.0, 0], [0, -1.0, 0]]])  # a couple: no net force, torque 2 * 0.02
    assert wrench_energy(x, twist).item() == pytest.approx((2 * 0.02) ** 2)


def test_initial_hands_face_the_object_from_outside(setup):
    hand, cube, sdf = setup
    s = SynthesisSettings(batch=16, init_jitter=0.0)
    pose, contact = initial_grasps(hand, cube.vertices, s, torch.Generator().manual_seed(0))
    assert pose.shape == (16, 51) and contact.shape == (16, s.n_contact)
    with torch.no_grad():
        v = hand(pose).vertices
    palm = v[:, hand.assets.palm_ids].mean(1)
    d = sdf(palm)
    assert (d > 0).all() and (d < 0.04 + 0.03).all()  # outside, within the initial distance (plus the cube's corners)
    # The palm normal (the hand's -y turned by the global rotation) points at the object.
    from tohgs.hand.rotations import axis_angle_to_matrix

    palm_normal = axis_angle_to_matrix(pose[:, 3:6]) @ torch.tensor([0.0, -1.0, 0.0])
    toward = -palm / palm.norm(dim=-1, keepdim=True)
    assert ((palm_normal * toward).sum(-1) > 0.9).all()


def test_the_optimiser_lowers_the_energy(setup):
    hand, cube, sdf = setup
    s = SynthesisSettings(batch=8, iterations=60, refine_iterations=20, step_decay_every=8, temperature_decay_every=2)
    r = synthesize(hand, sdf, cube.vertices, s, seed=0)
    assert len(r.history) == 81
    assert r.history[-1] < 0.6 * r.history[0], r.history[::10]
    polish = r.history[61:]  # the annealing's entries are on its vertex subset, the polishing's on every vertex
    assert all(b <= a + 1e-6 for a, b in zip(polish, polish[1:])), "refinement keeps each grasp's best pose"
    e0 = GraspEnergy(hand, sdf, s)(*initial_grasps(hand, cube.vertices, s, torch.Generator().manual_seed(0)))
    assert r.energies.dis.mean() < e0.dis.mean().detach()
    again = synthesize(hand, sdf, cube.vertices, s, seed=0)
    assert torch.equal(again.pose, r.pose), "the same seed must give the same grasps"


def test_support_planes_touch_the_object_and_the_plane_energy_pushes_hands_out(setup):
    hand, cube, sdf = setup
    for direction in ("random", "down"):
        s = SynthesisSettings(batch=8, plane_fraction=0.5, plane_direction=direction)
        planes = support_planes(cube.vertices, s, torch.Generator().manual_seed(1))
        assert (planes[4:] == 0).all() and (planes[:4, :3].norm(dim=-1) - 1).abs().max() < 1e-6
        side = torch.as_tensor(cube.vertices, dtype=torch.float32) @ planes[:4, :3].T - planes[:4, 3]
        assert side.min() > -1e-6 and side.min(0).values.abs().max() < 1e-6  # tangent: touches, no cut
        if direction == "down":
            assert torch.allclose(planes[:4, :3], torch.tensor([0.0, 0.0, 1.0]).expand(4, 3))
    s = SynthesisSettings(batch=2, plane_fraction=1.0, plane_direction="down")
    planes = support_planes(cube.vertices, s, torch.Generator().manual_seed(0))
    pose, contact = initial_grasps(hand, cube.vertices, s, torch.Generator().manual_seed(0), planes)
    energy = GraspEnergy(hand, sdf, s, planes)
    with torch.no_grad():
        floor = planes[0, 3].item()
        lowest = hand(pose).vertices[..., 2].min(1).values
        above, below = pose.clone(), pose.clone()
        above[:, 2] += floor + 0.01 - lowest
        below[:, 2] += floor - 0.02 - lowest
        assert (energy(above, contact).plane == 0).all()
        assert (energy(below, contact).plane > 0).all()


def test_energy_terms_equal_their_dense_definitions(setup):
    """The fast paths (coordinate-major vertices, sparse penetration, plane rows, one SDF lookup for the
    contacts and their normals, a matmul for the keypoint pairs) against the terms written out densely."""
    hand, cube, sdf = setup
    s = SynthesisSettings(batch=12, plane_fraction=0.5)
    g = torch.Generator().manual_seed(3)
    planes = support_planes(cube.vertices, s, g)
    pose, contact = initial_grasps(hand, cube.vertices, s, g, planes)
    centre = torch.as_tensor(cube.vertices.mean(0), dtype=pose.dtype)
    pose[:, :3] += 0.6 * (centre - hand(pose).vertices.detach().mean(1))  # sink half of each hand in
    pose = pose.requires_grad_(True)
    e = GraspEnergy(hand, sdf, s, planes)(pose, contact)
    v = hand(pose).vertices.contiguous()
    x = v[torch.arange(12)[:, None], hand.contact_ids[contact]]
    ref_pen = torch.relu(-sdf(v)).sum(-1)
    ref_dis = sdf(x).abs().sum(-1)
    n, offset = planes[:, None, :3], planes[:, 3:4]
    ref_plane = (torch.relu(offset - (v * n).sum(-1)) * (n.norm(dim=-1) > 0)).sum(-1)
    kp = hand(pose).joints[:, GraspEnergy(hand, sdf, s).kp_idx]
    pairs = GraspEnergy(hand, sdf, s).pairs
    ref_spen = torch.relu(s.spen_threshold - (kp[:, pairs[:, 0]] - kp[:, pairs[:, 1]]).norm(dim=-1)).sum(-1)
    assert (ref_pen > 0).sum() >= 6 and (ref_plane > 0).any()  # the terms are exercised
    for got, ref in ((e.pen, ref_pen), (e.dis, ref_dis), (e.plane, ref_plane), (e.spen, ref_spen)):
        torch.testing.assert_close(got, ref, rtol=1e-5, atol=1e-7)
        g_got, g_ref = (torch.autograd.grad(t.sum(), pose, retain_graph=True)[0] for t in (got, ref))
        torch.testing.assert_close(g_got, g_ref, rtol=1e-4, atol=1e-5)


def test_refinement_adam_matches_torch_optim(setup):
    """The written-out Adam and cosine schedule of the polishing phase follow torch.optim's."""
    from tohgs.grasps.synthesis import _refine

    hand, cube, sdf = setup
    s = SynthesisSettings(batch=6, refine_iterations=7, refine_lr=0.002)
    pose, contact = initial_grasps(hand, cube.vertices, s, torch.Generator().manual_seed(5))
    energy = GraspEnergy(hand, sdf, s)
    with torch.no_grad():
        e0 = energy(pose, contact)
    history: list[float] = []
    best_pose, best = _refine(energy, pose, contact, e0, s, history, progress=False)
    # The reference: torch.optim.Adam and CosineAnnealingLR, keeping each grasp's best pose.
    x = pose.clone().requires_grad_(True)
    opt = torch.optim.Adam([x], lr=s.refine_lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, s.refine_iterations)
    ref_pose, ref_total = pose.clone(), e0.total.clone()
    for _ in range(s.refine_iterations):
        cur = energy(x, contact)
        better = cur.total.detach() < ref_total
        ref_pose = torch.where(better[:, None], x.detach(), ref_pose)
        ref_total = torch.where(better, cur.total.detach(), ref_total)
        opt.zero_grad()
        cur.total.sum().backward()
        opt.step()
        sched.step()
    torch.testing.assert_close(best_pose, ref_pose, rtol=0, atol=1e-6)
    torch.testing.assert_close(best.total, ref_total, rtol=1e-5, atol=1e-6)
    assert len(history) == s.refine_iterations and best.total.mean() < e0.total.mean()


def test_the_annealing_vertex_subset(setup):
    """The subset spreads over the hand and holds the contacts and tips; the energy on it equals the dense
    definitions on those vertices (values, gradients), on all of them the full energy; a synthesis that
    anneals on it returns the energies on every vertex, and with the fraction 1 it is the full optimiser."""
    hand, cube, sdf = setup
    ids = vertex_subset(hand, 0.33)
    assert vertex_subset(hand, 1.0) is None
    assert set(hand.contact_ids.tolist()) | set(hand.tip_ids.tolist()) <= set(ids.tolist())
    assert 0.33 * hand.n_vertices <= len(ids) <= 0.33 * hand.n_vertices + len(hand.contact_ids) + 5
    assert bool((ids[1:] > ids[:-1]).all())
    with pytest.raises(ValueError, match="must be in"):
        vertex_subset(hand, 0.0)
    s = SynthesisSettings(batch=12, plane_fraction=0.5)
    g = torch.Generator().manual_seed(4)
    planes = support_planes(cube.vertices, s, g)
    pose, contact = initial_grasps(hand, cube.vertices, s, g, planes)
    centre = torch.as_tensor(cube.vertices.mean(0), dtype=pose.dtype)
    pose[:, :3] += 0.6 * (centre - hand(pose).vertices.detach().mean(1))  # sink half of each hand in
    pose = pose.requires_grad_(True)
    sub = GraspEnergy(hand, sdf, s, planes, ids)(pose, contact)
    full = GraspEnergy(hand, sdf, s, planes)(pose, contact)
    every = GraspEnergy(hand, sdf, s, planes, torch.arange(hand.n_vertices))(pose, contact)
    v = hand(pose).vertices[:, ids]
    n, offset = planes[:, None, :3], planes[:, 3:4]
    ref_pen = torch.relu(-sdf(v)).sum(-1)
    ref_plane = (torch.relu(offset - (v * n).sum(-1)) * (n.norm(dim=-1) > 0)).sum(-1)
    assert (ref_pen > 0).sum() >= 6 and (sub.pen < full.pen).any()  # fewer vertices see less depth
    for got, ref in ((sub.pen, ref_pen), (sub.plane, ref_plane), (sub.fc, full.fc), (sub.dis, full.dis),
                     (sub.spen, full.spen), (every.total, full.total)):
        torch.testing.assert_close(got, ref, rtol=1e-5, atol=1e-7)
        g_got, g_ref = (torch.autograd.grad(t.sum(), pose, retain_graph=True)[0] for t in (got, ref))
        torch.testing.assert_close(g_got, g_ref, rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="fingertip"):
        GraspEnergy(hand, sdf, s, planes, ids[ids != hand.tip_ids[0]])
    s = SynthesisSettings(batch=8, iterations=30, refine_iterations=0, anneal_vertices=0.33)
    r = synthesize(hand, sdf, cube.vertices, s, seed=1)
    with torch.no_grad():
        e = GraspEnergy(hand, sdf, s, r.planes)(r.pose, r.contact_idx)
    for k in e.__dict__:
        torch.testing.assert_close(getattr(r.energies, k), getattr(e, k), rtol=0, atol=0)
    r1 = synthesize(hand, sdf, cube.vertices, SynthesisSettings(batch=8, iterations=30, refine_iterations=0,
                                                                anneal_vertices=1.0), seed=1)
    assert not torch.equal(r1.pose, r.pose)  # the subset changes the path
