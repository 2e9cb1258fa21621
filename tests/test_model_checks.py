"""ContactDiffuser's permuted-map check (tohgs.models.checks.permuted_map_gap): a denoiser that reads only each
point's own value (per-point marginals) scores the same on true and permuted maps, whatever its skill; the
trained smoke models are held to it in tests/test_workflow.py."""

from __future__ import annotations

import torch

from helpers import SMALL_PN
from tohgs.data.maps import MapDataset
from tohgs.models.checks import permuted_map_gap
from tohgs.models.contact_diffuser import ContactDiffuser, ContactDiffuserConfig


class PerPoint(ContactDiffuser):
    """A denoiser of per-point marginals: each point's noise estimated from its own noisy value alone, the
    best such estimate for values of +-1 (x_t = sqrt(a) x0 + sqrt(1 - a) eps, x0 = sign(x_t))."""

    def forward(self, x_t, t, cond):
        a = self.schedule.alphas_cumprod[t].reshape(-1, 1)
        x0 = torch.tanh(x_t * a.sqrt() / (1 - a).clamp_min(1e-6))  # E[x0 | x_t] for x0 = +-1 equally likely
        return self.target(x_t, x0, a)

    def target(self, x_t, x0, a):
        """What the network predicts (its config's ``prediction``) for the clean map ``x0``."""
        return x0 if self.schedule.cfg.prediction == "sample" else (x_t - a.sqrt() * x0) / (1 - a).sqrt()


def test_a_per_point_denoiser_scores_true_and_permuted_maps_alike(built):
    tmp = built[0]
    data = MapDataset([tmp / "shard-0.zarr"], per="grasp")
    per_point = PerPoint(ContactDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN)).eval()
    r = permuted_map_gap(per_point, data, n_samples=256)
    assert set(r) == {"true", "permuted", "gap"}
    assert abs(r["gap"]) < 0.02, r
    # a denoiser that knows where the contact lies (here: the map itself, an oracle) does far worse on
    # permuted maps
    oracle_maps = {}

    class Oracle(PerPoint):
        def forward(self, x_t, t, cond):
            return self.target(x_t, oracle_maps["x0"], self.schedule.alphas_cumprod[t].reshape(-1, 1))

    oracle = Oracle(ContactDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN)).eval()
    from tohgs.data.batch import Batch

    g = torch.Generator().manual_seed(0)
    idx = torch.randint(0, len(data), (64,), generator=g).tolist()  # the draw permuted_map_gap makes
    oracle_maps["x0"] = 2 * Batch.collate([data[i] for i in idx]).contact - 1
    r = permuted_map_gap(oracle, data, n_samples=64)
    assert r["gap"] > 1.0, r


def test_roughness_tells_regions_from_salt_and_pepper(built):
    from tohgs.models.checks import map_roughness

    tmp = built[0]
    item = MapDataset([tmp / "shard-0.zarr"], per="grasp")[0]
    points = torch.as_tensor(item["points"])
    true = torch.as_tensor(item["contact"])[None]
    g = torch.Generator().manual_seed(0)
    shuffled = true[:, torch.randperm(true.shape[1], generator=g)]  # the same values, anywhere
    assert map_roughness(true, points).item() * 2 < map_roughness(shuffled, points).item()
    assert map_roughness(torch.full_like(true, 0.7), points).item() < 1e-6


def test_local_mixing_reads_the_neighbours_values(built):
    """With ``local_k`` a point's output depends on its nearest points' noisy values (and not on far ones
    through that path); without it, a network whose attention is switched off reads only its own."""
    from tohgs.data.batch import Batch
    from tohgs.geometry.neighbours import nearest_neighbours

    tmp = built[0]
    batch = Batch.collate([MapDataset([tmp / "shard-0.zarr"], per="grasp")[0]])
    torch.manual_seed(0)
    model = ContactDiffuser(ContactDiffuserConfig(d_model=16, n_blocks=1, local_k=8, pointnet=SMALL_PN)).eval()
    cond = model.batch_condition(batch)
    assert cond.neighbours is not None and cond.neighbours.shape == (1, batch.points.shape[1], 8)
    assert torch.equal(cond.neighbours, nearest_neighbours(batch.points, 8))
    assert not (cond.neighbours == torch.arange(batch.points.shape[1])[None, :, None]).any()  # itself excluded
    for layer in model.attn:  # only the local path connects the points
        layer.forward = lambda h, *a, **k: h
    x = torch.zeros(1, batch.points.shape[1])
    t = torch.tensor([10])
    base = model(x, t, cond)
    i, j = 0, int(cond.neighbours[0, 0, 0])
    far = int(torch.cdist(batch.points[0, :1], batch.points[0]).argmax())
    nudged = x.clone(); nudged[0, j] = 1.0
    assert (model(nudged, t, cond)[0, i] - base[0, i]).abs() > 1e-6  # a neighbour's value reaches it
    moved = x.clone(); moved[0, far] = 1.0
    if far not in cond.neighbours[0, 0].tolist():
        assert torch.equal(model(moved, t, cond)[0, i], base[0, i])  # a far point's does not
    plain = ContactDiffuser(ContactDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN)).eval()
    for layer in plain.attn:
        layer.forward = lambda h, *a, **k: h
    pc = plain.batch_condition(batch)
    assert pc.neighbours is None
    assert torch.equal(plain(nudged, t, pc)[0, i], plain(x, t, pc)[0, i])


def test_the_other_configurations_comparison_leaves_out_copies_of_the_own_maps():
    """Two configurations of one object that share a prior grasp share its map: the plain comparison scores
    that copy 1, the distinct one leaves it out; the held-out one scores each own map against the others."""
    from types import SimpleNamespace

    import numpy as np

    from tohgs.models.checks import _configurations, _held_out_ious, _other_config_ious

    n = 12
    maps = {p: np.zeros(n, np.float32) for p in (0, 1, 2)}  # prior grasp -> its map on the object's points
    maps[0][0:4] = 1.0
    maps[1][2:6] = 1.0   # IoU with grasp 0's: 2 / 6
    maps[2][3:9] = 1.0   # IoU with grasp 1's: 3 / 7
    shard = SimpleNamespace(object_id=np.array([5, 5]), grasp_config=np.array([0, 0, 1, 1]),
                            grasp_prior_index=np.array([0, 1, 1, 2]), attrs={"objects": ["a"]})

    class Maps(SimpleNamespace):  # the MapDataset attributes the comparison reads, per grasp
        def __getitem__(self, i):
            return {"contact": maps[int(shard.grasp_prior_index[self.index[i][1]])]}

    data = Maps(shards=[shard], index=[(0, r) for r in range(4)])
    by_config, keys = _configurations(data, 24)
    assert keys == [(0, 0), (0, 1)]
    true = torch.as_tensor(np.stack([maps[0], maps[1]])) > 0.5
    every, distinct = _other_config_ious(data, by_config, (0, 0), true, 0.5)
    assert np.allclose(every, [1.0, 3 / 7])  # grasp 1's copy, grasp 2's map
    assert np.allclose(distinct, [3 / 7])
    assert np.allclose(_held_out_ious(true), [2 / 6, 2 / 6])
    assert _held_out_ious(true[:1]) == []
