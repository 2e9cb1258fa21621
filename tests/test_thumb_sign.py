"""Contact maps signed by the thumb's contact (beyond the paper): the sign, a GraspDiffuser that reads it
(its frame and moments still the paper's map's, its hand still turning with its input), the ground truth's
signed maps through the method, and the training jobs' params unchanged while the setting is off."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from helpers import SMALL_PN, prepared_component, train_steps
from tohgs.data.batch import Batch
from tohgs.geometry.contact_parts import thumb_signed
from tohgs.hand import load_hand
from tohgs.hand.layout import FINGERS
from tohgs.models.grasp_diffuser import GraspDiffuser, GraspDiffuserConfig


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


def test_thumb_signed_negates_the_points_the_thumb_touches_and_keeps_the_magnitude(hand):
    grasp = hand.preset("relaxed", 1)
    with torch.no_grad():
        v = hand(grasp).vertices
    normals = torch.nn.functional.normalize(v - v.mean(1, keepdim=True), dim=-1)
    points = v + 1e-4 * normals  # just off every vertex: its nearest vertex is itself
    contact = torch.rand(points.shape[:2], generator=torch.Generator().manual_seed(0)) + 0.1
    signed = thumb_signed(contact, points, v, hand.part_labels)
    thumb = torch.isin(hand.part_labels, torch.tensor(FINGERS["thumb"]))
    assert thumb.any() and (~thumb).any()
    assert (signed[0, thumb] < 0).all() and (signed[0, ~thumb] > 0).all()
    torch.testing.assert_close(signed.abs(), contact)


def _object(b: int = 2, n: int = 128, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    d = torch.nn.functional.normalize(torch.randn(b, n, 3, generator=g), dim=-1)
    pts = d * torch.tensor([0.06, 0.035, 0.025]) * (1 + 0.3 * d[..., :1] ** 2 + 0.2 * d[..., 1:2])
    pts = pts - pts.mean(1, keepdim=True)
    normals = torch.nn.functional.normalize(pts / torch.tensor([0.06, 0.035, 0.025]) ** 2, dim=-1)
    contact = torch.exp(-((pts - pts[:, :1]) ** 2).sum(-1) / 0.03**2)
    signed = torch.where(pts[..., 1] > pts[:, :1, 1], -contact, contact)  # one side of the patch is the thumb's
    return {"points": pts, "normals": normals, "contact": contact, "signed": signed}


def _model(hand, thumb: bool) -> GraspDiffuser:
    torch.manual_seed(0)
    model = GraspDiffuser(GraspDiffuserConfig(d_model=32, n_blocks=2, pointnet=SMALL_PN, thumb_sign=thumb)).eval()
    model.set_hand(hand)
    model.grasp_mean.normal_(0, 0.05)
    model.grasp_std.fill_(0.1)
    return model


def test_a_thumb_signed_grasp_diffuser_reads_the_sign_and_frames_by_the_papers_map(hand):
    obj = _object()
    model = _model(hand, thumb=True)
    with torch.no_grad():
        signed = model.condition(obj["points"], obj["normals"], obj["signed"])
        plain = model.condition(obj["points"], obj["normals"], obj["contact"])
        paper = _model(hand, thumb=False).condition(obj["points"], obj["normals"], obj["signed"])
    torch.testing.assert_close(signed.rotation, plain.rotation)
    torch.testing.assert_close(signed.origin, plain.origin)
    assert (signed.glob - plain.glob).abs().max() > 1e-3  # the sign reaches the network
    assert (paper.origin - plain.origin).abs().max() > 1e-3  # a model without it would frame the thumb away
    with pytest.raises(ValueError, match="thumb_sign"):
        GraspDiffuserConfig(thumb_sign=True, contact_input=False, frame="network", contact_features=False)


def test_a_thumb_signed_grasp_diffuser_turns_its_hand_with_its_input(hand):
    obj = _object(seed=3)
    model = _model(hand, thumb=True)

    def hands(o):
        b, n = o["points"].shape[:2]
        batch = Batch(o["points"], o["normals"], torch.zeros(b, n), torch.zeros(b, n), torch.zeros(b, 4, 3),
                      torch.zeros(b, 4, 3), torch.eye(4).expand(b, 4, 4), o["signed"])
        with torch.no_grad():
            return hand(model.sample_grasps(batch, "ddim", 5, torch.Generator().manual_seed(7))).vertices

    base = hands(obj)
    for R in Rotation.random(3, random_state=1).as_matrix():
        R = torch.as_tensor(R, dtype=torch.float32)
        turned = hands({**obj, "points": obj["points"] @ R.T, "normals": obj["normals"] @ R.T})
        assert float((turned - base @ R.T).norm(dim=-1).max()) < 1e-4


def test_training_signs_each_map_by_its_own_grasp_and_the_ground_truth_row_stores_the_papers_map(built, monkeypatch):
    """The wiring, with a stand-in sign (every point the thumb's: the tiny dataset's hand touches the cube with
    its fingers only): training reads each batch's maps signed, from the batch's own grasps; the ground-truth
    row gives the GraspDiffuser signed maps and stores the unsigned ones; a sampled map source is refused."""
    from types import SimpleNamespace

    import tohgs.geometry.contact_parts as contact_parts
    from tohgs.methods.contact_grasp import ContactGrasp, ContactGraspSettings
    from tohgs.models.checks import shuffled_condition_gap

    tmp, hand, shard, _, _ = built
    calls = []

    def all_thumb(contact, points, vertices, part_labels):
        calls.append((points.shape[0], vertices.shape))
        return -contact

    monkeypatch.setattr(contact_parts, "thumb_signed", all_thumb)  # what training and the method both sign with
    net = {"d_model": 16, "n_blocks": 1, "pointnet": SMALL_PN, "thumb_sign": True}
    model, data = prepared_component("grasp_diffuser", net, tmp / "shard-0.zarr", hand)
    seen = []
    original = model.condition
    model.condition = lambda points, normals, contact: seen.append(contact.detach()) or original(points, normals, contact)
    train_steps(model, data, 2, batch=3)
    assert len(seen) == 2 and all(bool((c <= 0).all()) and bool((c < 0).any()) for c in seen)
    assert calls == [(3, (3, hand.rest_vertices.shape[0], 3))] * 2  # each batch's own three hands
    model.condition = original
    method = ContactGrasp("g", {"contact": "ground_truth", "grasp": "gd"}, {"gd": model},
                          ContactGraspSettings(samples=2, grasp_sampler="ddim", grasp_steps=3), torch.device("cpu"), hand)
    gt = SimpleNamespace(**{k: getattr(shard, k) for k in ("contact", "grasp", "grasp_config", "object_id", "config_index",
                                                            "attrs", "alpha_contact")})
    row = int(shard.grasp_config[0])
    batch = Batch.collate([data[0]]).repeat(2)
    signed = method.source.maps(batch, gt, row, torch.Generator(), signed_by=hand)
    assert bool((signed <= 0).all()) and bool((signed < 0).any())
    pred = method.predict(batch, gt, row, torch.Generator().manual_seed(0), np.random.default_rng(0))
    np.testing.assert_allclose(pred.contact, -signed.numpy(), atol=1e-6)
    with pytest.raises(ValueError, match="thumb_sign"):
        ContactGrasp("g", {"contact": "cd", "grasp": "gd"}, {"gd": model, "cd": model}, ContactGraspSettings(),
                     torch.device("cpu"), hand)
    calls.clear()  # the model checks sign the maps as training does, with the hand
    with pytest.raises(ValueError, match="thumb_sign"):
        shuffled_condition_gap(model, data, n_samples=4)
    gap = shuffled_condition_gap(model, data, n_samples=4, hand=hand)
    assert calls and np.isfinite([v for v in gap.values() if isinstance(v, float)]).all()


def test_a_training_job_is_not_given_thumb_sign_while_it_is_off():
    from tohgs.config import job_network, load_schema

    schema = load_schema()
    component = {"kind": "grasp_diffuser", "network": {"d_model": 64, "thumb_sign": False, "recon_clamp": 1.0}}
    assert job_network(component, schema) == {"d_model": 64, "recon_clamp": 1.0}
    component["network"]["thumb_sign"] = True
    assert job_network(component, schema)["thumb_sign"] is True
