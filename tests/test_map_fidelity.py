"""benchmarks/map_fidelity.py's measures of likeness between maps and of the rotation between two clouds."""

import importlib.util
from pathlib import Path

import numpy as np
import torch

BENCH = Path(__file__).resolve().parent.parent / "benchmarks" / "map_fidelity.py"
spec = importlib.util.spec_from_file_location("map_fidelity", BENCH)
map_fidelity = importlib.util.module_from_spec(spec)
spec.loader.exec_module(map_fidelity)


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
