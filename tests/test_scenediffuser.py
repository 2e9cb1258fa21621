"""SceneDiffuser: GraspDiffuser reading the object alone (``contact_input: false``) learns grasps of the
object it is shown, and samples them without a contact map."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from helpers import prepared_component, train_steps
from tohgs.data.batch import Batch
from tohgs.models.grasp_diffuser import GraspDiffuserConfig

SCENE_DIFFUSER = {"d_model": 32, "n_blocks": 2, "mlp": [32, 64], "contact_input": False, "frame": "network",
                  "contact_features": False}


def _vertex_error(hand, grasps: torch.Tensor, truth: torch.Tensor) -> float:
    """Mean over (B, 51) grasps of the per-vertex distance (m) to the nearest of the (G, 51) true grasps."""
    with torch.no_grad():
        v, t = hand(grasps).vertices, hand(truth).vertices
        d = (v[:, None] - t[None]).norm(dim=-1).mean(-1)  # (B, G)
    return float(d.min(1).values.mean())


def test_a_trained_scene_diffuser_samples_its_training_grasps_without_a_map(built):  # noqa: F811
    """On one object (a cube: which object it is, is the workflow test's check, on the smoke models)."""
    tmp, hand, _, _, _ = built
    fresh, data = prepared_component("grasp_diffuser", SCENE_DIFFUSER, tmp / "shard-0.zarr", hand)
    trained, _ = prepared_component("grasp_diffuser", SCENE_DIFFUSER, tmp / "shard-0.zarr", hand)
    train_steps(trained, data, 150, batch=16)
    # Sampling needs no contact map; the samples land near the training grasps of that object, an
    # untrained copy's do not.
    items = [data.item(i, 0) for i in range(len(data))]
    truth = Batch.collate(items).grasp
    batch = dataclasses.replace(Batch.collate([items[0]] * 8), contact=None, grasp=None)
    errors = {}
    for name, model in (("trained", trained), ("fresh", fresh)):
        grasps = model.sample_grasps(batch, "ddim", 20, torch.Generator().manual_seed(0))
        assert grasps.shape == (8, 51) and torch.isfinite(grasps).all()
        errors[name] = _vertex_error(hand, grasps, truth)
    assert errors["trained"] < 0.5 * errors["fresh"], errors


def test_a_grasp_diffuser_that_reads_maps_refuses_a_batch_without_one_and_bad_settings_are_refused(built):  # noqa: F811
    tmp, hand, _, _, _ = built
    model, data = prepared_component("grasp_diffuser", {"d_model": 32, "n_blocks": 1, "mlp": [32]}, tmp / "shard-0.zarr", hand)
    batch = dataclasses.replace(Batch.collate([data.item(0, 0)]), contact=None)
    with pytest.raises(ValueError, match="contact maps"):
        model.eval().sample_grasps(batch, "ddim", 2, torch.Generator().manual_seed(0))
    with pytest.raises(ValueError, match="contact_input"):
        GraspDiffuserConfig(contact_input=False)  # the default frame is the contact frame
    with pytest.raises(ValueError, match="contact_input"):
        GraspDiffuserConfig(contact_input=False, frame="network", contact_features=True)
