"""Diffusion: the sampler against diffusers' own step, a sanity run that can fail, overfitting one batch,
and the grasp losses."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from tohgs.models.contact_diffuser import ContactDiffuser, ContactDiffuserConfig
from tohgs.models.diffusion import DiffusionConfig, _ddpm_with_noise, make_scheduler, sample, timestep_embedding
from tohgs.models.grasp_diffuser import GraspDiffuser, GraspDiffuserConfig, grasp_losses, vertex_normals

SMALL_PN = {"sa": [[32, 0.05, 8, [16, 32]], [8, 0.1, 8, [32, 32]], [0, 0.0, 0, [32, 48]]], "fp": [[32], [32], [32]]}


def test_our_ddpm_step_equals_diffusers_given_the_same_noise():
    for prediction in ("epsilon", "sample"):
        cfg = DiffusionConfig(prediction=prediction)
        sched = make_scheduler(cfg, "ddpm")
        sched.set_timesteps(50)
        x, out = torch.randn(4, 7), torch.randn(4, 7)
        for t in (int(sched.timesteps[0]), int(sched.timesteps[25]), 0):
            g = torch.Generator().manual_seed(t)
            ref = sched.step(out, t, x, generator=g).prev_sample
            noise = torch.randn(4, 7, generator=torch.Generator().manual_seed(t))
            torch.testing.assert_close(_ddpm_with_noise(sched, out, t, x, noise), ref, atol=1e-5, rtol=1e-5)


def test_timestep_embedding_distinguishes_steps():
    e = timestep_embedding(torch.tensor([0, 1, 500, 999]), 32)
    assert e.shape == (4, 32) and torch.cdist(e, e).fill_diagonal_(9).min() > 0.1


class _Denoiser(nn.Module):
    def __init__(self):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(2 + 16, 128), nn.SiLU(), nn.Linear(128, 128), nn.SiLU(), nn.Linear(128, 2))

    def forward(self, x, t):
        return self.net(torch.cat([x, timestep_embedding(t, 16)], -1))


def test_diffusion_learns_a_two_mode_distribution():
    """Data: x = (+-0.6, 0) + 0.05 noise. After training, DDIM and DDPM samples sit near the modes, both
    modes are used about equally, and an untrained network does not pass the same checks."""
    torch.manual_seed(0)
    cfg = DiffusionConfig(prediction="epsilon", clip=1.0)
    sched = make_scheduler(cfg)
    net = _Denoiser()
    g = torch.Generator().manual_seed(0)

    def data(n):
        sign = torch.randint(0, 2, (n, 1), generator=g) * 2 - 1
        return torch.cat([0.6 * sign, torch.zeros(n, 1)], 1) + 0.05 * torch.randn(n, 2, generator=g)

    def check(model, sampler, steps):
        x = sample(model, (400, 2), cfg, sampler, steps, torch.Generator().manual_seed(1))
        near = (x - torch.tensor([[0.6, 0.0]])).norm(dim=1).clamp(max=(x + torch.tensor([[0.6, 0.0]])).norm(dim=1))
        right = (x[:, 0] > 0).float().mean()
        return float((near < 0.2).float().mean()), float(right)

    untrained = check(net, "ddim", 50)
    opt = torch.optim.Adam(net.parameters(), lr=2e-3)
    for _ in range(2000):
        x0 = data(256)
        t = torch.randint(0, cfg.timesteps, (256,), generator=g)
        noise = torch.randn(256, 2, generator=g)
        loss = ((net(sched.add_noise(x0, noise, t), t) - noise) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    for sampler, steps in (("ddim", 50), ("ddpm", None)):  # DDIM 50 steps; full ancestral DDPM (T = 1000)
        close, right = check(net, sampler, steps)
        assert close > 0.85 and 0.3 < right < 0.7, (sampler, close, right)
    assert untrained[0] < 0.5, untrained


def _contact_batch(b=2, n=64):
    g = torch.Generator().manual_seed(0)
    pts = torch.rand(b, n, 3, generator=g) * 0.08
    return {"points": pts, "normals": torch.nn.functional.normalize(torch.randn(b, n, 3, generator=g), dim=-1),
            "d_init": torch.rand(b, n, generator=g), "d_goal": torch.rand(b, n, generator=g),
            "contact": (pts[..., 0] > 0.04).float()}


def test_contact_diffuser_overfits_one_batch_and_reloads_to_identical_samples(tmp_path):
    torch.manual_seed(0)
    model = ContactDiffuser(ContactDiffuserConfig(d_model=32, n_blocks=1, pointnet=SMALL_PN))
    batch = _contact_batch()
    sched = make_scheduler(model.diffusion)
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3)
    g = torch.Generator().manual_seed(0)
    x0 = 2 * batch["contact"] - 1
    t = torch.randint(0, 1000, (2,), generator=g)
    noise = torch.randn(x0.shape, generator=g)
    losses = []
    for _ in range(150):  # the same noise and steps every time: a pure memorisation test
        cond = model.condition(batch["points"], batch["normals"], batch["d_init"], batch["d_goal"])
        loss = ((model(sched.add_noise(x0, noise, t), t, cond) - noise) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.1 * losses[0], (losses[0], losses[-1])
    torch.save({"cfg": model.cfg, "state": model.state_dict()}, tmp_path / "m.pt")
    again = ContactDiffuser(torch.load(tmp_path / "m.pt", weights_only=False)["cfg"])
    again.load_state_dict(torch.load(tmp_path / "m.pt", weights_only=False)["state"])
    model.eval(), again.eval()
    outs = []
    for m in (model, again):
        with torch.no_grad():
            cond = m.condition(batch["points"], batch["normals"], batch["d_init"], batch["d_goal"])
        outs.append(sample(lambda x, tt: m(x, tt, cond), (2, 64), m.diffusion, "ddim", 10, torch.Generator().manual_seed(5)))
    torch.testing.assert_close(outs[0], outs[1])
    assert outs[0].shape == (2, 64) and outs[0].abs().max() <= 1.0 + 1e-6


@pytest.fixture(scope="module")
def hand():
    from tohgs.hand import load_hand

    return load_hand("anny")


def test_vertex_normals_point_out_of_the_closed_hand(hand):
    with torch.no_grad():
        v = hand(hand.preset("flat", 1)).vertices
    n = vertex_normals(v, hand.closed_faces)
    assert torch.allclose(n.norm(dim=-1), torch.ones(1, v.shape[1]), atol=1e-4)
    # Outward, and the same as trimesh's (area-weighted) vertex normals of the closed, watertight hand.
    import trimesh

    mesh = trimesh.Trimesh(v[0].numpy(), hand.closed_faces.numpy(), process=False)
    assert mesh.is_watertight and mesh.volume > 0
    assert (np.asarray(mesh.vertex_normals) * n[0].numpy()).sum(1).mean() > 0.98


def test_grasp_losses_vanish_for_the_truth_and_grow_with_error(hand):
    torch.manual_seed(0)
    model = GraspDiffuser(GraspDiffuserConfig(d_model=32, n_blocks=1, pointnet=SMALL_PN))
    grasp = hand.preset("relaxed", 2)
    model.set_normaliser(torch.cat([grasp, grasp + 0.1]))
    x0 = model.normalise(grasp)
    with torch.no_grad():
        hv = hand(grasp).vertices
    pts = hv[:, ::25] + 0.004 * vertex_normals(hv, hand.closed_faces)[:, ::25]  # points just outside the hand
    from tohgs.models.grasp_diffuser import contact_values

    contact, _ = contact_values(pts, hv, 100.0)
    exact = grasp_losses(model, hand, x0, x0, pts, contact, 100.0)
    assert exact["diff"] == 0 and exact["recon"] < 1e-12 and exact["cons"] < 1e-8
    shifted = grasp.clone()
    shifted[:, :3] += torch.tensor([0.0, -0.01, 0.0])  # the hand moves through the points
    off = grasp_losses(model, hand, model.normalise(shifted), x0, pts, contact, 100.0)
    assert off["diff"] > 0 and off["recon"] == pytest.approx(1e-4, rel=1e-3) and off["cons"] > 0
    # Points 4 mm outside the true hand are (nearly) all outside it; 1 cm deeper they are inside.
    assert off["pen"] > 5 * exact["pen"] and off["pen"] > 0.01
