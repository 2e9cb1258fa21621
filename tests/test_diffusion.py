"""Diffusion: the sampler against diffusers' own step, a sanity run that can fail, overfitting one batch,
and the grasp losses."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest
import torch
from torch import nn

from helpers import SMALL_PN
from tohgs.models.contact_diffuser import ContactDiffuser, ContactDiffuserConfig
from tohgs.models.diffusion import DiffusionConfig, NoiseSchedule, sample, timestep_embedding
from tohgs.geometry.hand_object import contact_values, vertex_normals
from tohgs.models.grasp_diffuser import (GraspCondition, GraspDiffuser, GraspDiffuserConfig, grasp_losses,
                                        weighted_terms)
from tohgs.data.batch import Batch
from tohgs.models.train import EMA, cosine_with_warmup

def _diffusers_scheduler(cfg: DiffusionConfig, sampler: str):
    """diffusers' scheduler for ``cfg``: the reference our schedule is checked against (a test dependency)."""
    diffusers = pytest.importorskip("diffusers")
    cls = diffusers.DDPMScheduler if sampler == "ddpm" else diffusers.DDIMScheduler
    return cls(num_train_timesteps=cfg.timesteps, beta_start=cfg.beta_start, beta_end=cfg.beta_end,
               beta_schedule="linear", prediction_type=cfg.prediction, clip_sample=cfg.clip > 0,
               clip_sample_range=cfg.clip if cfg.clip > 0 else 1.0)


@pytest.mark.parametrize("prediction,clip", [("epsilon", 1.0), ("sample", 0.0)])
def test_schedule_and_steps_equal_diffusers(prediction, clip):
    """Our schedule, forward process, timestep spacing, DDPM step (given the same noise) and DDIM step
    (eta 0) against diffusers' DDPMScheduler and DDIMScheduler."""
    cfg = DiffusionConfig(prediction=prediction, clip=clip, beta_end=0.02 if prediction == "epsilon" else 0.01)
    ours = NoiseSchedule(cfg)
    torch.testing.assert_close(ours.alphas_cumprod, _diffusers_scheduler(cfg, "ddpm").alphas_cumprod, atol=1e-6, rtol=1e-5)
    x0, noise, t = torch.randn(5, 7), torch.randn(5, 7), torch.tensor([0, 1, 250, 998, 999])
    torch.testing.assert_close(ours.q_sample(x0, noise, t), _diffusers_scheduler(cfg, "ddpm").add_noise(x0, noise, t),
                               atol=1e-5, rtol=1e-5)
    for sampler, n in (("ddpm", 50), ("ddim", 20), ("ddim", 1)):
        ref = _diffusers_scheduler(cfg, sampler)
        ref.set_timesteps(n)
        steps = ours.inference_timesteps(n)
        assert steps == [int(t) for t in ref.timesteps]
        x, out = torch.randn(4, 7), torch.randn(4, 7)
        for i in (0, len(steps) // 2, len(steps) - 1):
            t, prev = steps[i], steps[i] - cfg.timesteps // n
            if sampler == "ddpm":
                want = ref.step(out, t, x, generator=torch.Generator().manual_seed(t)).prev_sample
                got = ours.ddpm_step(out, t, prev, x, torch.randn(4, 7, generator=torch.Generator().manual_seed(t)))
            else:
                want, got = ref.step(out, t, x, eta=0.0).prev_sample, ours.ddim_step(out, t, prev, x)
            torch.testing.assert_close(got, want, atol=1e-4, rtol=1e-4)
    with pytest.raises(ValueError, match="steps"):
        ours.inference_timesteps(0)
    with pytest.raises(ValueError, match="prediction"):
        NoiseSchedule(DiffusionConfig(prediction="v"))


def test_ema_and_cosine_schedule_equal_diffusers():
    """The training helpers against diffusers' EMAModel and get_cosine_schedule_with_warmup."""
    pytest.importorskip("diffusers")
    from diffusers.optimization import get_cosine_schedule_with_warmup
    from diffusers.training_utils import EMAModel

    torch.manual_seed(0)
    net = nn.Linear(3, 2)
    ours, ref = EMA(net.parameters(), 0.99), EMAModel(net.parameters(), decay=0.99)
    opt_a = torch.optim.SGD(net.parameters(), lr=0.1)
    opt_b = torch.optim.SGD(nn.Linear(3, 2).parameters(), lr=0.1)
    lr_a, lr_b = cosine_with_warmup(opt_a, 5, 40), get_cosine_schedule_with_warmup(opt_b, 5, 40)
    for _ in range(40):
        with torch.no_grad():
            for p in net.parameters():
                p.add_(torch.randn_like(p))
        ours.step(net.parameters())
        ref.step(net.parameters())
        opt_a.step()  # no gradients: only keeps the schedulers' call order
        opt_b.step()
        lr_a.step()
        lr_b.step()
        assert lr_a.get_last_lr() == pytest.approx(lr_b.get_last_lr(), abs=1e-12)
    for a, b in zip(ours.shadow, ref.shadow_params):
        torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)
    copy = EMA(net.parameters(), 0.5)
    copy.load_state_dict(ours.state_dict())
    copy.copy_to(net.parameters())
    torch.testing.assert_close(net.weight, ours.shadow[0])


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
    sched = NoiseSchedule(cfg)
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
        loss = ((net(sched.q_sample(x0, noise, t), t) - noise) ** 2).mean()
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
    sched = NoiseSchedule(model.diffusion)
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3)
    g = torch.Generator().manual_seed(0)
    x0 = 2 * batch["contact"] - 1
    t = torch.randint(0, 1000, (2,), generator=g)
    noise = torch.randn(x0.shape, generator=g)
    losses = []
    for _ in range(150):  # the same noise and steps every time: a pure memorisation test
        cond = model.condition(batch["points"], batch["normals"], batch["d_init"], batch["d_goal"])
        loss = ((model(sched.q_sample(x0, noise, t), t, cond) - noise) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.1 * losses[0], (losses[0], losses[-1])
    torch.save({"cfg": asdict(model.cfg), "state": model.state_dict()}, tmp_path / "m.pt")
    saved = torch.load(tmp_path / "m.pt", weights_only=True)
    again = ContactDiffuser(ContactDiffuserConfig.from_dict(saved["cfg"]))
    again.load_state_dict(saved["state"])
    model.eval(), again.eval()
    outs = []
    for m in (model, again):
        with torch.no_grad():
            cond = m.condition(batch["points"], batch["normals"], batch["d_init"], batch["d_goal"])
        outs.append(sample(lambda x, tt: m(x, tt, cond), (2, 64), m.diffusion, "ddim", 10, torch.Generator().manual_seed(5)))
    torch.testing.assert_close(outs[0], outs[1])
    assert outs[0].shape == (2, 64) and outs[0].abs().max() <= 1.0 + 1e-6


@pytest.mark.parametrize("prediction", ["epsilon", "sample"])
def test_contact_diffuser_trains_on_the_target_its_config_names(prediction):
    """``diffusion.prediction`` decides what the loss compares with: the noise or the clean map (x0)."""
    torch.manual_seed(0)
    diffusion = asdict(DiffusionConfig(beta_end=0.02, prediction=prediction))
    model = ContactDiffuser(ContactDiffuserConfig(d_model=32, n_blocks=1, pointnet=SMALL_PN, diffusion=diffusion)).eval()
    batch, sched = _contact_batch(), NoiseSchedule(model.diffusion)
    with torch.no_grad():
        typed = Batch(points=batch["points"], normals=batch["normals"], d_init=batch["d_init"], d_goal=batch["d_goal"],
                      scene=torch.zeros(2, 4, 3), scene_normals=torch.zeros(2, 4, 3),
                      goal_transform=torch.eye(4).expand(2, 4, 4), contact=batch["contact"])
        loss = model.loss(typed, torch.Generator().manual_seed(3))["loss"]
        g = torch.Generator().manual_seed(3)
        t = torch.randint(0, sched.timesteps, (2,), generator=g)
        x0 = 2 * batch["contact"] - 1
        noise = torch.randn(x0.shape, generator=g)
        pred = model(sched.q_sample(x0, noise, t), t,
                     model.condition(batch["points"], batch["normals"], batch["d_init"], batch["d_goal"]))
    losses = {"epsilon": ((pred - noise) ** 2).mean(), "sample": ((pred - x0) ** 2).mean()}
    torch.testing.assert_close(loss, losses[prediction])
    other = "sample" if prediction == "epsilon" else "epsilon"
    assert abs(float(loss - losses[other])) > 1e-3


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
    model = GraspDiffuser(GraspDiffuserConfig(d_model=32, n_blocks=1, pointnet=SMALL_PN, frame="network",
                                              representation="axis_angle"))
    grasp = hand.preset("relaxed", 2)
    model.set_normaliser(torch.cat([grasp, grasp + 0.1]))
    x0 = model.normalise(grasp)
    with torch.no_grad():
        hv = hand(grasp).vertices
    pts = hv[:, ::25] + 0.004 * vertex_normals(hv, hand.closed_faces)[:, ::25]  # points just outside the hand
    contact, _ = contact_values(pts, hv, 100.0)
    with torch.no_grad():
        cond = model.condition(pts, torch.zeros_like(pts), contact)
    assert torch.equal(cond.points, pts)  # the network frame is the shards' frame
    exact = grasp_losses(model, hand, x0, x0, cond, contact, 100.0)
    assert (exact["diff"] == 0).all() and (exact["recon"] < 1e-9).all() and (exact["cons"] < 1e-6).all()
    shifted = grasp.clone()
    shifted[:, :3] += torch.tensor([0.0, -0.01, 0.0])  # the hand moves through the points
    off = grasp_losses(model, hand, model.normalise(shifted), x0, cond, contact, 100.0)
    # L_recon sums the squared vertex error over the vertices (1 cm on each of V vertices: V x 1e-4 m^2).
    assert (off["diff"] > 0).all() and off["recon"] == pytest.approx(torch.full((2,), hand.n_vertices * 1e-4), rel=1e-3)
    assert (off["cons"] > 0).all()
    # Points 4 mm outside the true hand are (nearly) all outside it; 1 cm deeper they are inside.
    assert (off["pen"] > 5 * exact["pen"]).all() and (off["pen"] > 0.01).all()
    # The point sums are scaled to the paper's 2048 points: half the points, the same loss per point.
    half = GraspCondition(cond.glob, None, cond.rotation, cond.origin, pts[:, ::2])
    off_half = grasp_losses(model, hand, model.normalise(shifted), x0, half, contact[:, ::2], 100.0)
    assert off_half["cons"] == pytest.approx(off["cons"], rel=0.3)


def test_recon_clamp_caps_each_samples_reconstruction_term_and_0_leaves_it_whole():
    terms = {k: torch.tensor(v) for k, v in dict(diff=[1.0, 1.0], recon=[0.5, 4.0], pen=[0.2, 3.0],
                                                 cons=[1.0, 2.0]).items()}
    weights = (15.0, 2.0, 5.0, 0.002)
    official = weighted_terms(terms, weights)  # the official clamp at 1 (per sample)
    assert official["recon"] == pytest.approx(2.0 * (0.5 + 1.0) / 2)
    assert weighted_terms(terms, weights, 0.0)["recon"] == pytest.approx(2.0 * (0.5 + 4.0) / 2)
    assert weighted_terms(terms, weights, 2.0)["recon"] == pytest.approx(2.0 * (0.5 + 2.0) / 2)
    # the other terms do not depend on it: L_pen keeps its clamp at 1
    assert weighted_terms(terms, weights, 0.0)["pen"] == pytest.approx(5.0 * (0.2 + 1.0) / 2)
    with pytest.raises(ValueError, match="recon_clamp"):
        GraspDiffuserConfig(recon_clamp=-1.0)


def test_the_contact_frame_turns_about_z_and_grasps_go_there_and_back(hand):
    from tohgs.models.grasp_diffuser import contact_frame, grasp_from_frame, grasp_to_frame

    g = torch.Generator().manual_seed(0)
    pts = torch.randn(3, 64, 3, generator=g) * 0.03
    contact = (pts[..., 0] > 0.02).float()  # contact on the +x side
    rot, origin = contact_frame(pts, contact)
    assert torch.allclose(rot @ rot.transpose(-1, -2), torch.eye(3).expand(3, 3, 3), atol=1e-6)
    assert torch.allclose(rot[:, :, 2], torch.tensor([0.0, 0.0, 1.0]).expand(3, 3))  # up stays up
    assert (rot[:, 0, 0] > 0.5).all()  # x towards the contact
    wrist = hand.rest_joints[0]
    grasp = hand.preset("relaxed", 3) + torch.cat([0.02 * torch.randn(3, 6, generator=g), torch.zeros(3, 45)], 1)
    there = grasp_to_frame(grasp, rot, origin, wrist)
    torch.testing.assert_close(grasp_from_frame(there, rot, origin, wrist), grasp, atol=1e-5, rtol=0)
    # The hand in the frame is the world hand moved by x' = R^T (x - o).
    with torch.no_grad():
        world, local = hand(grasp).vertices, hand(there).vertices
    torch.testing.assert_close(local, (world - origin[:, None]) @ rot, atol=1e-5, rtol=0)
    # An upright turn of the input turns the frame with it: the grasp in the frame does not change.
    a = torch.tensor(0.7)
    turn = torch.tensor([[a.cos(), -a.sin(), 0.0], [a.sin(), a.cos(), 0.0], [0.0, 0.0, 1.0]])
    rot2, origin2 = contact_frame(pts @ turn.T, contact)
    from tohgs.geometry.grasp import transform_grasp

    T = np.eye(4)
    T[:3, :3] = turn.numpy()
    turned = torch.as_tensor(transform_grasp(grasp.numpy(), T, wrist.numpy()), dtype=torch.float32)
    torch.testing.assert_close(grasp_to_frame(turned, rot2, origin2, wrist), there, atol=1e-4, rtol=0)


def test_the_skip_parameterisation_returns_its_input_at_t_0():
    model = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN, skip=True))
    g = torch.Generator().manual_seed(1)
    pts, nrm = torch.randn(2, 64, 3, generator=g) * 0.03, torch.randn(2, 64, 3, generator=g)
    contact = torch.rand(2, 64, generator=g)
    x = torch.randn(2, model.dim, generator=g)
    with torch.no_grad():
        cond = model.condition(pts, nrm, contact)
        out0 = model(x, torch.zeros(2, dtype=torch.long), cond)
    assert (out0 - x).abs().max() < 0.05  # sqrt(1 - a_0) = 0.01: the residual barely moves it


def test_normaliser_of_a_single_grasp_is_finite():
    """A training split with one task grasp (small runs have them) must not give a NaN std."""
    model = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN, representation="axis_angle"))
    grasp = torch.randn(1, 51, generator=torch.Generator().manual_seed(0))
    model.set_normaliser(grasp)
    assert torch.isfinite(model.grasp_std).all() and (model.grasp_std == 1e-3).all()
    assert torch.isfinite(model.normalise(grasp)).all()
    with pytest.raises(ValueError, match="set_normaliser"):
        model.set_normaliser(torch.zeros(0, 51))


def test_the_palm_rot6d_representation_round_trips_and_places_the_palm(hand):
    model = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN, representation="palm_rot6d"))
    model.set_hand(hand)
    g = torch.Generator().manual_seed(2)
    grasp = hand.preset("relaxed", 4) + torch.cat([0.05 * torch.randn(4, 3, generator=g), 1.5 * torch.randn(4, 3, generator=g),
                                                    torch.zeros(4, 45)], 1)
    vec = model.vector_of(grasp)
    assert vec.shape == (4, 54) and model.dim == 54
    torch.testing.assert_close(hand(model.grasp_of(vec)).vertices, hand(grasp).vertices, atol=1e-5, rtol=0)
    # the first three numbers are where the rest palm centre goes when the hand is posed
    flat = torch.cat([grasp[:, :6], torch.zeros(4, 45)], 1)
    with torch.no_grad():
        palm = hand(flat).vertices[:, torch.as_tensor(hand.assets.palm_ids)].mean(1)
    rest_palm = hand.rest_vertices[torch.as_tensor(hand.assets.palm_ids)].mean(0)
    assert torch.allclose(rest_palm, model.palm)
    torch.testing.assert_close(vec[:, :3], palm, atol=2e-3, rtol=0)  # flat fingers move the palm vertices a little


def test_guidance_needs_an_unconditional_model_and_scale_1_is_the_conditional_one():
    g = torch.Generator().manual_seed(3)
    pts, nrm = torch.randn(2, 64, 3, generator=g) * 0.03, torch.randn(2, 64, 3, generator=g)
    contact = torch.rand(2, 64, generator=g)
    x, t = torch.randn(2, 54, generator=g), torch.full((2,), 500)
    plain = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN))
    with torch.no_grad():
        cond = plain.condition(pts, nrm, contact)
        torch.testing.assert_close(plain.guided(x, t, cond, 1.0), plain(x, t, cond))
        with pytest.raises(ValueError, match="without cond_dropout"):
            plain.guided(x, t, cond, 2.0)
        cfg = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN, cond_dropout=0.1))
        torch.nn.init.normal_(cfg.null_glob, generator=g)
        cond = cfg.condition(pts, nrm, contact)
        c, u = cfg(x, t, cond), cfg(x, t, cfg.drop_context(cond, torch.ones(2, dtype=torch.bool)))
        torch.testing.assert_close(cfg.guided(x, t, cond, 2.0), u + 2.0 * (c - u))


def test_contact_smoothing_averages_over_neighbours_and_keeps_regions():
    from tohgs.methods.contact_grasp import smooth_contact

    g = torch.Generator().manual_seed(0)
    pts = torch.rand(400, 3, generator=g) * 0.1
    region = (pts[:, 0] < 0.05).float()  # a coherent half, 1 inside and 0 outside
    noisy = (region + (torch.rand(400, generator=g) < 0.2).float() * (1 - 2 * region)).clamp(0, 1)[None]  # 20 % flipped
    torch.testing.assert_close(smooth_contact(pts, noisy, 0), noisy)
    torch.testing.assert_close(smooth_contact(pts, noisy, 1), noisy)
    smooth = smooth_contact(pts, noisy, 8)
    assert smooth.shape == noisy.shape and float(smooth.min()) >= 0 and float(smooth.max()) <= 1
    # the flipped points are mostly restored, the region kept: fewer points on the wrong side of 0.5
    wrong = lambda m: float(((m > 0.5).float() != region).float().mean())  # noqa: E731
    assert wrong(smooth) < 0.5 * wrong(noisy[0]), (wrong(noisy[0]), wrong(smooth))
    ones = torch.ones(2, 400)
    torch.testing.assert_close(smooth_contact(pts, ones, 8), ones)


def test_neighbour_mean_and_max_equal_the_gathered_reduction():
    """ContactDiffuser's local mixing (embedding bags with autograd, one neighbour at a time without): the same
    values (and, with distinct neighbours, gradients) as gathering every neighbour and reducing, with and
    without autograd."""
    from tohgs.models.contact_diffuser import neighbour_mean_max
    from tohgs.models.pointnet2 import gather

    g = torch.Generator().manual_seed(0)
    x = torch.randn(3, 40, 8, generator=g, requires_grad=True)
    idx = torch.rand(3, 40, 40, generator=g).topk(6, dim=-1).indices
    w = torch.randn(3, 40, 8, generator=g)
    nb = gather(x, idx)
    ref_mean, ref_max = nb.mean(2), nb.max(2).values
    ((ref_mean * w).sum() + (ref_max * w).sum()).backward()
    ref_grad, x.grad = x.grad.clone(), None
    mean, top = neighbour_mean_max(x, idx)
    ((mean * w).sum() + (top * w).sum()).backward()
    torch.testing.assert_close(mean, ref_mean, atol=1e-6, rtol=0)
    torch.testing.assert_close(top, ref_max, atol=0, rtol=0)
    torch.testing.assert_close(x.grad, ref_grad, atol=1e-5, rtol=0)
    with torch.no_grad():
        mean, top = neighbour_mean_max(x, idx)
    torch.testing.assert_close(mean, ref_mean.detach(), atol=1e-6, rtol=0)
    torch.testing.assert_close(top, ref_max.detach(), atol=0, rtol=0)


def test_point_attention_equals_torch_transformer_layer_bit_for_bit():
    """ContactDiffuser's batch-first attention layer loads torch's TransformerEncoderLayer's weights and gives
    its outputs and gradients exactly (a faster layout of the same computation), training and evaluating."""
    from tohgs.models.contact_diffuser import PointAttention

    torch.manual_seed(0)
    ref = torch.nn.TransformerEncoderLayer(32, 4, 64, 0.0, activation="gelu", batch_first=True, norm_first=True)
    ours = PointAttention(32, 4, 64, 0.0)
    ours.load_state_dict(ref.state_dict())  # strict: the same parameter names
    x = torch.randn(3, 50, 32, requires_grad=True)
    w = torch.randn(3, 50, 32)
    ref_out = ref(x)
    (ref_grad,) = torch.autograd.grad((ref_out * w).sum(), x)
    out = ours(x)
    (grad,) = torch.autograd.grad((out * w).sum(), x)
    assert torch.equal(out, ref_out) and torch.equal(grad, ref_grad)
    fast = torch.backends.mha.get_fastpath_enabled()
    torch.backends.mha.set_fastpath_enabled(False)
    try:
        with torch.no_grad():
            assert torch.equal(ours.eval()(x), ref.eval()(x))
    finally:
        torch.backends.mha.set_fastpath_enabled(fast)
    # the weights are used: another layer's differ
    other = PointAttention(32, 4, 64, 0.0).eval()
    with torch.no_grad():
        assert (other(x) - ours(x)).abs().max() > 1e-3


def test_grasp_diffuser_attention_with_cached_keys_equals_multihead_attention():
    """The grasp token's cross-attention, its keys and values projected once per condition, gives
    torch.nn.MultiheadAttention's result with the same weights."""
    from tohgs.models.grasp_diffuser import _Block

    torch.manual_seed(0)
    block = _Block(32, 2, 0.0, 4, tokens=True).eval()
    h, c, tokens = torch.randn(5, 32), torch.randn(5, 32), torch.randn(5, 40, 32)
    with torch.no_grad():
        ours = block(h, c, block.keys_values(tokens))
        mid = h + block.mlp(h + c)
        ref = mid + block.attn(block.norm(mid)[:, None], tokens, tokens, need_weights=False)[0][:, 0]
    torch.testing.assert_close(ours, ref, atol=1e-5, rtol=1e-5)
