"""Refining a contact-map method's sampled hands against their own maps (beyond the paper): GraspTTA's
adaptation with a fixed map as the consistency target, and the method setting that runs it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from helpers import SMALL_PN, prepared_component
from tohgs.data.batch import Batch
from tohgs.geometry.hand_object import contact_values
from tohgs.grasps.tta import FixedMaps, RefineSettings, refine_to_maps
from tohgs.hand import load_hand


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny")


def test_refining_against_a_hands_own_map_lowers_the_energy_and_zero_steps_keep_the_hands(hand):
    true = hand.preset("relaxed", 2)
    with torch.no_grad():
        v = hand(true).vertices
    g = torch.Generator().manual_seed(0)
    points = v[:, torch.randperm(v.shape[1], generator=g)[:256]] + 0.004 * torch.randn(2, 256, 3, generator=g)
    maps, _ = contact_values(points, v, 100.0)
    start = true.clone()
    start[:, :3] += torch.tensor([0.01, -0.005, 0.0])  # the hand 1.1 cm off the grasp whose map it is given
    refined, history = refine_to_maps(hand, start, points, maps, 100.0, RefineSettings(steps=30))
    # The energy falls (19.1 -> 15.5 on an Intel Xeon); its consistency term alone need not: the hand trades
    # it against the penetration of these points (the hand's own surface, noisy), and on an Intel Xeon it
    # rose (1.60 -> 2.34) where an AMD EPYC saw it fall, so the test holds the sum, with a margin.
    assert history["energy"][-1] < 0.95 * history["energy"][0]
    assert not torch.equal(refined, start)
    kept, _ = refine_to_maps(hand, start, points, maps, 100.0, RefineSettings(steps=0))
    torch.testing.assert_close(kept, start)
    with pytest.raises(ValueError, match="FixedMaps"):
        FixedMaps(maps).object_cache(points[:1])


def test_a_contact_map_method_refines_its_hands_when_asked_and_needs_the_hand_for_it(built):
    from tohgs.methods.contact_grasp import ContactGrasp, ContactGraspSettings

    tmp, hand, shard, _, _ = built
    model, data = prepared_component("grasp_diffuser", {"d_model": 16, "n_blocks": 1, "pointnet": SMALL_PN},
                                     tmp / "shard-0.zarr", hand)
    model.eval()
    cfg = {"contact": "ground_truth", "grasp": "gd"}
    gt = SimpleNamespace(**{k: getattr(shard, k) for k in ("contact", "grasp", "grasp_config", "object_id", "config_index",
                                                            "attrs", "alpha_contact")})
    row = int(shard.grasp_config[0])
    batch = Batch.collate([data[0]]).repeat(2)
    preds = {}
    for steps in (0, 5):
        settings = ContactGraspSettings(samples=2, grasp_sampler="ddim", grasp_steps=3, refine={"steps": steps})
        method = ContactGrasp("g", cfg, {"gd": model}, settings, torch.device("cpu"), hand)
        preds[steps] = method.predict(batch, gt, row, torch.Generator().manual_seed(0), np.random.default_rng(0))
    assert "refine" in preds[5].seconds and "refine" not in preds[0].seconds
    assert not np.allclose(preds[5].grasp, preds[0].grasp)  # the same sampled hands, then refined
    np.testing.assert_allclose(preds[5].contact, preds[0].contact)  # the maps as given
    with pytest.raises(ValueError, match="refine"):
        ContactGrasp("g", cfg, {"gd": model}, ContactGraspSettings(refine={"steps": 5}), torch.device("cpu"), None)
