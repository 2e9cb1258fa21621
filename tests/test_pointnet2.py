"""Pure-torch PointNet++: sampling and grouping against brute force, shapes, gradients, invariances."""

from __future__ import annotations

import torch

from tohgs.models.pointnet2 import PointNet2, PointNet2Config, ball_query, farthest_point_sample, gather


def test_farthest_point_sampling_picks_spread_distinct_points():
    g = torch.Generator().manual_seed(0)
    xyz = torch.rand(2, 500, 3, generator=g)
    idx = farthest_point_sample(xyz, 32)
    assert idx.shape == (2, 32) and all(len(set(r.tolist())) == 32 for r in idx)
    # Each new point is the farthest from those chosen before it (brute force check).
    p = xyz[0]
    for i in range(1, 32):
        d = torch.cdist(p, p[idx[0, :i]]).min(1).values
        assert d[idx[0, i]] == d.max()


def test_ball_query_returns_only_neighbours_within_the_radius():
    g = torch.Generator().manual_seed(1)
    xyz = torch.rand(1, 400, 3, generator=g)
    centres = xyz[:, :10]
    idx = ball_query(0.15, 8, xyz, centres)
    assert idx.shape == (1, 10, 8)
    d = (gather(xyz, idx) - centres[:, :, None]).norm(dim=-1)
    assert (d <= 0.15 + 1e-6).all()
    far = torch.tensor([[[5.0, 5.0, 5.0]]])  # no neighbour: falls back to the nearest point
    assert ball_query(0.1, 4, xyz, far).unique().numel() == 1


def test_ball_query_takes_the_lowest_indices_within_the_radius_in_order():
    # brute force: each centre's in-radius indices ascending, the first nsample, a short list padded with its
    # first entry, an empty one with the nearest point
    g = torch.Generator().manual_seed(2)
    xyz = torch.rand(2, 300, 3, generator=g)
    centres = torch.cat([xyz[:, :20], torch.full((2, 1, 3), 3.0)], 1)
    for radius, k in ((0.05, 16), (0.12, 8), (0.3, 32)):
        idx = ball_query(radius, k, xyz, centres)
        d2 = torch.cdist(centres, xyz) ** 2
        for b in range(2):
            for s in range(centres.shape[1]):
                inside = torch.nonzero(d2[b, s] <= radius**2).flatten()[:k].tolist()
                inside = inside or [int(d2[b, s].argmin())]
                assert idx[b, s].tolist() == inside + [inside[0]] * (k - len(inside))


def test_backbone_shapes_gradients_and_translation_invariance():
    torch.manual_seed(0)
    cfg = PointNet2Config(in_channels=2, sa=((64, 0.05, 8, (16, 32)), (16, 0.1, 8, (32, 64)), (0, 0.0, 0, (64, 96))),
                          fp=((64,), (64,), (48,)))
    net = PointNet2(cfg)
    xyz = torch.rand(3, 256, 3) * 0.1
    feats = torch.rand(3, 256, 2, requires_grad=True)
    local, glob = net(xyz, feats)
    assert local.shape == (3, 256, 48) and glob.shape == (3, 96)
    (local.sum() + glob.sum()).backward()
    assert feats.grad is not None and feats.grad.abs().sum() > 0
    # Relative coordinates only: moving the cloud changes nothing (up to rounding at ball boundaries).
    with torch.no_grad():
        l2, g2 = net(xyz + torch.tensor([0.3, -0.2, 0.1]), feats)
        l1, g1 = net(xyz, feats)
        other, _ = net(torch.rand(3, 256, 3) * 0.1, feats)
    assert (l1 - l2).abs().median() < 1e-5 < (l1 - other).abs().median()
    torch.testing.assert_close(g1, g2, atol=1e-2, rtol=1e-2)


def test_a_prefix_of_a_farthest_point_order_samples_to_itself_and_the_backbone_skips_the_loop():
    """Farthest-point sampling from index 0 of the first m points of a farthest-point order returns them in
    order, so the levels after the first take their centres as a prefix: the same outputs as sampling anew,
    bit for bit."""
    g = torch.Generator().manual_seed(3)
    for n, m, k in ((500, 128, 32), (300, 64, 64), (1000, 256, 17)):
        xyz = torch.rand(4, n, 3, generator=g)
        first = gather(xyz, farthest_point_sample(xyz, m))
        assert torch.equal(farthest_point_sample(first, k), torch.arange(k).expand(4, k))
    torch.manual_seed(0)
    cfg = PointNet2Config(in_channels=2, sa=((64, 0.05, 8, (16, 32)), (16, 0.1, 8, (32, 64)), (0, 0.0, 0, (64, 96))),
                          fp=((64,), (64,), (48,)))
    net = PointNet2(cfg).eval()
    xyz, feats = torch.rand(3, 256, 3, generator=g) * 0.1, torch.rand(3, 256, 2, generator=g)
    with torch.no_grad():
        local, glob = net(xyz, feats)
        x1, f1 = net.sa[0](xyz, feats)
        x2, f2 = net.sa[1](x1, f1, ordered=False)  # sampled anew
        x2o, f2o = net.sa[1](x1, f1, ordered=True)
    assert torch.equal(x2, x2o) and torch.equal(f2, f2o)
    with torch.no_grad():  # more centres asked than points: the loop, as before
        xs, _ = net.sa[0](xyz[:, :40], feats[:, :40], ordered=True)
    assert xs.shape == (3, 64, 3)
