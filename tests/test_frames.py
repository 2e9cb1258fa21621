"""Canonical frames (tohgs.geometry.frames) and the networks that read their inputs in them: a turned input
gives the turned hand (GraspDiffuser) and the same map (ContactDiffuser), whatever the turn; the z-only
contact frame and the network frame do not (the models trained before the canonical frames)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from helpers import SMALL_PN
from tohgs.data.batch import Batch
from tohgs.geometry.frames import contact_frame_3d, scene_frame
from tohgs.geometry.grasp import transform_grasp
from tohgs.hand import load_hand
from tohgs.models.contact_diffuser import ContactDiffuser, ContactDiffuserConfig
from tohgs.models.grasp_diffuser import GraspDiffuser, GraspDiffuserConfig, contact_moments

N = 256


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


def _object(seed: int, b: int = 3) -> dict[str, torch.Tensor]:
    """``b`` lumpy, asymmetric clouds (network frame), their normals, a contact patch and two distance maps."""
    g = torch.Generator().manual_seed(seed)
    d = torch.randn(b, N, 3, generator=g)
    d = d / d.norm(dim=-1, keepdim=True)
    pts = d * torch.tensor([0.06, 0.035, 0.025]) * (1 + 0.3 * d[..., :1] ** 2 + 0.2 * d[..., 1:2])
    pts = pts - pts.mean(1, keepdim=True)
    normals = torch.nn.functional.normalize(pts / torch.tensor([0.06, 0.035, 0.025]) ** 2, dim=-1)
    contact = torch.exp(-((pts - pts[:, :1]) ** 2).sum(-1) / 0.02**2)  # a patch around each cloud's first point
    d_init = torch.exp(-(pts[..., 2] - pts[..., 2].min(-1, keepdim=True).values) / 0.01)  # the support below
    d_goal = torch.exp(-(pts[..., 1] - pts[..., 1].min(-1, keepdim=True).values) / 0.02)  # an obstacle at -y
    return {"points": pts, "normals": normals, "contact": contact, "d_init": d_init, "d_goal": d_goal}


def _turned(obj: dict[str, torch.Tensor], R: torch.Tensor) -> dict[str, torch.Tensor]:
    return {**obj, "points": obj["points"] @ R.T, "normals": obj["normals"] @ R.T}


def _batch(obj: dict[str, torch.Tensor], contact: bool = True) -> Batch:
    b = obj["points"].shape[0]
    return Batch(obj["points"], obj["normals"], obj["d_init"], obj["d_goal"], torch.zeros(b, 4, 3),
                 torch.zeros(b, 4, 3), torch.eye(4).expand(b, 4, 4), obj["contact"] if contact else None)


def _rotations(n: int) -> list[torch.Tensor]:
    return [torch.as_tensor(Rotation.random(random_state=k).as_matrix(), dtype=torch.float32) for k in range(n)]


@pytest.mark.parametrize("which", ["contact", "scene"])
def test_frames_turn_with_their_input(which):
    obj = _object(0)
    frame = (lambda o: contact_frame_3d(o["points"], o["normals"], o["contact"])) if which == "contact" else \
        (lambda o: scene_frame(o["points"], o["d_init"], o["d_goal"]))
    F, o = frame(obj)
    torch.testing.assert_close(F.transpose(-1, -2) @ F, torch.eye(3).expand(3, 3, 3), atol=1e-5, rtol=0)
    assert torch.allclose(torch.linalg.det(F), torch.ones(3), atol=1e-5)
    for R in _rotations(4):
        F2, o2 = frame(_turned(obj, R))
        torch.testing.assert_close(F2, R @ F, atol=1e-4, rtol=0)
        torch.testing.assert_close(o2, o @ R.T, atol=1e-6, rtol=0)


def test_the_frames_point_where_the_inputs_say():
    obj = _object(1)
    F, origin = scene_frame(obj["points"], obj["d_init"], obj["d_goal"])
    assert (F[:, 2, 0] < -0.9).all()  # x towards the support below
    assert (F[:, 1, 1] < -0.5).all()  # y towards the obstacle at -y
    F, origin = contact_frame_3d(obj["points"], obj["normals"], obj["contact"])
    towards = obj["points"][:, 0] - obj["points"].mean(1)
    assert ((F[..., 0] * torch.nn.functional.normalize(towards, dim=-1)).sum(-1) > 0.8).all()  # x towards the patch
    assert (origin - obj["points"][:, 0]).norm(dim=-1).max() < 0.02  # at the patch
    _, surface = contact_frame_3d(obj["points"], obj["normals"], obj["contact"], origin="surface")
    assert ((surface[:, None] - obj["points"]).norm(dim=-1).min(-1).values < 1e-7).all()  # an object point


def test_contact_moments_do_not_depend_on_the_point_count():
    """The same map on 256 and on 128 of its points gives the same condition (the mass is a mean, not a sum)."""
    obj = _object(2)
    contact = torch.exp(-((obj["points"] - obj["points"][:, :1]) ** 2).sum(-1) / 0.04**2)  # a patch of many points
    full = contact_moments(obj["points"], obj["normals"], contact)
    half = contact_moments(obj["points"][:, ::2], obj["normals"][:, ::2], contact[:, ::2])
    torch.testing.assert_close(half[:, -1], full[:, -1], atol=0.15, rtol=0)  # a sum differs by log 2 = 0.69
    torch.testing.assert_close(half[:, :3], full[:, :3], atol=0.1, rtol=0)


def _hands_of(model, hand, obj, seed: int) -> torch.Tensor:
    model.eval()
    with torch.no_grad():
        grasp = model.sample_grasps(_batch(obj), "ddim", 5, torch.Generator().manual_seed(seed))
        return hand(grasp).vertices


@pytest.mark.parametrize("frame,equivariant", [("canonical", True), ("contact", False), ("network", False)])
def test_grasp_diffuser_turns_its_hand_with_its_input(hand, frame, equivariant):
    """A GraspDiffuser reading a turned object and map samples the turned hand (same random stream), within
    0.1 mm, with the canonical frame; the z-only contact frame and the network frame do not."""
    torch.manual_seed(0)
    model = GraspDiffuser(GraspDiffuserConfig(d_model=32, n_blocks=2, frame=frame, pointnet=SMALL_PN,
                                              contact_features=frame != "network"))
    model.set_hand(hand)
    model.grasp_mean.normal_(0, 0.05)  # a normaliser of plausible scale: the hands sit near the object
    model.grasp_std.fill_(0.1)
    obj = _object(3)
    base = _hands_of(model, hand, obj, 7)
    worst = 0.0
    for R in _rotations(3):
        turned = _hands_of(model, hand, _turned(obj, R), 7)
        worst = max(worst, float((turned - base @ R.T).norm(dim=-1).max()))
    if equivariant:
        assert worst < 1e-4
    else:
        assert worst > 1e-2


def test_grasp_frames_carry_grasps_exactly(hand):
    """The canonical frame's grasp vectors of a turned input equal those of the input (what the network
    learns is the same whatever the turn)."""
    model = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, frame="canonical", pointnet=SMALL_PN))
    model.set_hand(hand)
    obj = _object(4)
    g = torch.Generator().manual_seed(0)
    grasp = hand.preset("relaxed", 3) + torch.cat([0.05 * torch.randn(3, 6, generator=g), torch.zeros(3, 45)], 1)
    vec = model.in_frame(grasp, obj["points"], obj["contact"], obj["normals"])
    for R in _rotations(3):
        T = np.eye(4)
        T[:3, :3] = R.numpy()
        turned = torch.as_tensor(transform_grasp(grasp.numpy(), T, model.wrist.numpy()), dtype=torch.float32)
        t = _turned(obj, R)
        torch.testing.assert_close(model.in_frame(turned, t["points"], t["contact"], t["normals"]), vec, atol=2e-4, rtol=0)


@pytest.mark.parametrize("frame,invariant", [("canonical", True), ("network", False)])
def test_contact_diffuser_map_does_not_turn(frame, invariant):
    """A ContactDiffuser reading a turned object with the same distance maps samples the same map (same
    random stream) with the canonical frame; the network frame does not."""
    torch.manual_seed(0)
    model = ContactDiffuser(ContactDiffuserConfig(d_model=32, n_blocks=1, pointnet=SMALL_PN, frame=frame, local_k=8))
    model.eval()
    obj = _object(5)
    base = model.sample_contact(_batch(obj, False), "ddim", 5, torch.Generator().manual_seed(3))
    worst = 0.0
    for R in _rotations(3):
        turned = model.sample_contact(_batch(_turned(obj, R), False), "ddim", 5, torch.Generator().manual_seed(3))
        worst = max(worst, float((turned - base).abs().max()))
    if invariant:
        assert worst < 1e-3
    else:
        assert worst > 1e-2
