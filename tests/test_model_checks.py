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
