"""benchmarks/map_fidelity.py's measures of likeness between maps and of the rotation between two clouds."""

import numpy as np
import pandas as pd
import pytest
import torch

from helpers import load_benchmark
from tohgs.data.predictions import write_predictions

map_fidelity = load_benchmark("map_fidelity")


def test_map_alike_is_one_for_the_same_map_whatever_its_scale_and_about_zero_for_an_unrelated_one():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(4, 512, generator=g)
    same = map_fidelity.map_alike(a, 0.5 * a + 0.2)
    other = map_fidelity.map_alike(a, torch.rand(4, 512, generator=g))
    assert torch.allclose(same, torch.ones(4, dtype=same.dtype), atol=1e-6)
    assert other.abs().max() < 0.2
    assert torch.allclose(map_fidelity.map_alike(a, 1 - a), -torch.ones(4, dtype=same.dtype), atol=1e-6)


def test_kabsch_recovers_the_rotation_between_two_index_aligned_clouds():
    rng = np.random.default_rng(1)
    source = rng.normal(size=(200, 3)) * [0.05, 0.03, 0.02]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot = q * np.sign(np.linalg.det(q))  # a proper rotation
    target = source @ rot.T + [0.1, -0.2, 0.3]
    est = map_fidelity.kabsch(target, source)
    assert np.allclose(est, rot, atol=1e-9)
    assert np.isclose(np.linalg.det(est), 1.0)


def test_collisions_refuse_a_row_sampled_with_another_seed_than_the_dataset_row(tmp_path):
    """A seed replica's ground-truth rows read other task grasps than the seed-0 Dataset row
    (:func:`tohgs.methods.base.ground_truth_pick` draws them from the prediction seed): pairing them sample for
    sample would count unrelated grasps as turned hands."""
    rng = np.random.default_rng(0)
    folder = tmp_path / "predictions/placing"
    grasps = np.concatenate([rng.normal(0, 0.05, (2, 4, 3)), rng.normal(0, 1.0, (2, 4, 48))], -1)
    arrays = {"object_id": np.zeros(2, np.int32), "config_index": np.arange(2, dtype=np.int32),
              "contact": np.zeros((2, 4, 8), np.float32), "grasp_init": grasps, "grasp_goal": grasps,
              "kept": np.ones((2, 4), bool)}
    (tmp_path / "metrics/placing").mkdir(parents=True)
    for method, seed in (("dataset", 0), ("ours-gt-contact", 0), ("ours-gt-contact-seed1", 1)):
        write_predictions(arrays, {"task": "placing", "method": method, "objects": ["ycb-a"],
                                   "config": {"samples": 4, "seed": seed}}, folder / f"{method}.zarr")
        pd.DataFrame({"object": "ycb-a", "config_index": np.repeat(np.arange(2), 4), "sample": np.tile(np.arange(4), 2),
                      "init_opp": 0.01}).to_parquet(tmp_path / f"metrics/placing/{method}.parquet")
    same = map_fidelity.collisions(tmp_path, "placing", "ours-gt-contact")
    assert same["grasps"] == 8 and same["turned_pct"] == 0.0  # the same grasps: none turned
    with pytest.raises(SystemExit, match="seed 1, the dataset row with seed 0"):
        map_fidelity.collisions(tmp_path, "placing", "ours-gt-contact-seed1")
