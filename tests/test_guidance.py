"""Scene-aware guidance of diffusion sampling (tohgs.models.guidance, issue 20): each energy term against a
slow, obviously right reference (values and gradients); zero weights give exactly the unguided samples; a
hand that a sampler would put through a table at both poses comes out of it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from tohgs.data.batch import Batch
from tohgs.hand import load_hand
from tohgs.models.diffusion import DiffusionConfig, NoiseSchedule, sample
from tohgs.models.guidance import (GuidanceEnergy, GuidanceSettings, contact_guidance_step, guidance_step,
                                    near_scene_weights, select_diverse)


@pytest.fixture(scope="module")
def hand():
    return load_hand("anny").double()


def _plane(x: tuple[float, float], z: float, n: int, rng) -> tuple[torch.Tensor, torch.Tensor]:
    """n points of the horizontal square x, y in ``x`` at height z, normals +z."""
    p = np.column_stack([rng.uniform(*x, n), rng.uniform(-0.15, 0.15, n), np.full(n, z)])
    return torch.as_tensor(p), torch.as_tensor(np.tile([0.0, 0.0, 1.0], (n, 1)))


def _hand_z(hand, grasp: torch.Tensor) -> torch.Tensor:
    with torch.no_grad():
        return hand(grasp).vertices[..., 2]


def _rest_grasp(hand, b: int) -> torch.Tensor:
    g = torch.zeros(b, 51, dtype=torch.float64)
    g[:, 6:] = torch.as_tensor(hand.assets.prior_mean)
    return g


# --- each term against a reference -------------------------------------------------------------------------

def _reference_terms(hand, grasp, points, normals, scene, scene_normals, goal, contact, s: GuidanceSettings, sub):
    """The terms, one sample and one vertex at a time; nearest points by a Python argmin (no gradient)."""
    out = {k: [] for k in ("scene", "object", "contact", "joints")}
    verts = hand(grasp).vertices
    lim = hand.joint_limits.reshape(45, 2)
    for b in range(grasp.shape[0]):
        v = verts[b, sub]
        carried = [v, torch.stack([goal[b, :3, :3] @ x + goal[b, :3, 3] for x in v])]
        e_scene = 0.0
        for pts in carried:
            for x in pts:
                i = int(np.argmin([float(((x.detach() - c) ** 2).sum()) for c in scene[b]]))
                d = ((x - scene[b, i]) * scene_normals[b, i]).sum()
                if d > -s.max_depth:
                    e_scene = e_scene + torch.clamp(s.margin - d, min=0)
        e_obj = 0.0
        for x in v:
            i = int(np.argmin([float(((x.detach() - c) ** 2).sum()) for c in points[b]]))
            d = ((x - points[b, i]) * normals[b, i]).sum()
            if d > -s.max_depth:
                e_obj = e_obj + torch.clamp(-d, min=0)
        e_con = 0.0
        for i, p in enumerate(points[b]):
            dist = torch.sqrt(((verts[b] - p) ** 2).sum(-1)).min()
            c_hand = 1 - 2 * (torch.sigmoid(s.alpha * dist) - 0.5)
            e_con = e_con + (c_hand - contact[b, i]) ** 2
        e_joint = 0.0
        for j in range(45):
            q = grasp[b, 6 + j]
            e_joint = e_joint + torch.clamp(lim[j, 0] - q, min=0) + torch.clamp(q - lim[j, 1], min=0)
        for k, e in zip(out, (e_scene, e_obj, e_con, e_joint)):
            out[k].append(e)
    return {k: torch.stack([torch.as_tensor(e, dtype=torch.float64) for e in v]) for k, v in out.items()}


def test_every_term_and_its_gradient_equal_a_slow_reference(hand):
    rng = np.random.default_rng(0)
    g = torch.Generator().manual_seed(0)
    b = 2
    grasp = _rest_grasp(hand, b)
    grasp[:, 6:] += 0.6 * torch.randn(b, 45, generator=g, dtype=torch.float64)  # some joints past their limits
    grasp[:, 3:6] = 0.3 * torch.randn(b, 3, generator=g, dtype=torch.float64)
    z = _hand_z(hand, grasp)
    table, table_n = _plane((-0.3, 0.3), float(z.mean()), 150, rng)  # cuts through the hands
    obj = torch.as_tensor(rng.normal(0, 0.03, (60, 3))) + hand(grasp).vertices.detach()[0].mean(0)
    obj_n = torch.nn.functional.normalize(torch.as_tensor(rng.normal(size=(60, 3))), dim=-1)
    goal = torch.eye(4, dtype=torch.float64).repeat(b, 1, 1)
    goal[:, 2, 3] = -0.01  # carried down: deeper at the goal
    contact = torch.as_tensor(rng.uniform(0, 1, (b, 60)))
    s = GuidanceSettings(scale=1.0, w_scene=1.0, w_object=2.0, w_contact=0.5, w_joints=3.0, hand_points=40)
    e = GuidanceEnergy(hand, obj.expand(b, -1, -1), obj_n.expand(b, -1, -1), table.expand(b, -1, -1),
                    table_n.expand(b, -1, -1), goal, contact, s)
    x = grasp.clone().requires_grad_(True)
    terms = e.terms(x)
    x_ref = grasp.clone().requires_grad_(True)
    ref = _reference_terms(hand, x_ref, obj.expand(b, -1, -1), obj_n.expand(b, -1, -1), table.expand(b, -1, -1),
                           table_n.expand(b, -1, -1), goal, contact, s, e.sub)
    for k in terms:
        assert float(ref[k].detach().min()) > 0, (k, ref[k])  # every term is at work here
        torch.testing.assert_close(terms[k], ref[k], rtol=1e-6, atol=1e-9)
        (gk,) = torch.autograd.grad(terms[k].sum(), x, retain_graph=True)
        (gr,) = torch.autograd.grad(ref[k].sum(), x_ref, retain_graph=True)
        assert gr.abs().max() > 0, k
        torch.testing.assert_close(gk, gr, rtol=1e-5, atol=1e-8)
    total = e(grasp)
    torch.testing.assert_close(total, sum(s.weights[k] * ref[k] for k in ref).detach(), rtol=1e-6, atol=1e-9)


def test_settings_are_checked_and_zero_weights_or_scale_are_inactive():
    assert not GuidanceSettings().active  # the default: the faithful sampler
    assert not GuidanceSettings(scale=1.0, w_scene=0, w_object=0).active
    assert not GuidanceSettings(scale=1.0, start=0.0).active
    assert GuidanceSettings(scale=0.1).active
    for bad in ({"scale": -1}, {"start": 1.5}, {"w_scene": -1}, {"max_depth": 0}, {"contact_scale": -1},
                {"candidates": 0}, {"pool": 0.0}, {"near": 0.0}):
        with pytest.raises(ValueError):
            GuidanceSettings(**bad)


# --- zero weights: exactly the unguided samples -----------------------------------------------------------

def _batch(b: int, g: torch.Generator) -> Batch:
    pts = torch.randn(b, 64, 3, generator=g) * 0.03
    goal = torch.eye(4).repeat(b, 1, 1)
    return Batch(points=pts, normals=torch.nn.functional.normalize(torch.randn(b, 64, 3, generator=g), dim=-1),
                 d_init=torch.rand(b, 64, generator=g), d_goal=torch.rand(b, 64, generator=g),
                 scene=torch.randn(b, 128, 3, generator=g) * 0.1,
                 scene_normals=torch.nn.functional.normalize(torch.randn(b, 128, 3, generator=g), dim=-1),
                 goal_transform=goal, contact=torch.rand(b, 64, generator=g))


def test_zero_weights_give_exactly_the_unguided_samples_and_weights_change_them():
    from helpers import SMALL_PN
    from tohgs.models.grasp_diffuser import GraspDiffuser, GraspDiffuserConfig

    hand32 = load_hand("anny")
    torch.manual_seed(0)
    model = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN)).eval()
    model.set_hand(hand32)
    batch = _batch(3, torch.Generator().manual_seed(1))

    def draw(steer=None):
        return model.sample_grasps(batch, "ddim", 10, torch.Generator().manual_seed(2), steer=steer, hand=hand32)

    plain = draw()
    zero = draw(GuidanceSettings(scale=0.5, start=1.0, w_scene=0.0, w_object=0.0))
    off = draw(GuidanceSettings(scale=0.0, start=1.0))
    assert torch.equal(plain, zero) and torch.equal(plain, off)
    guided = draw(GuidanceSettings(scale=0.05, start=1.0, w_scene=1.0, w_object=1.0, w_contact=1.0))
    assert torch.isfinite(guided).all() and not torch.allclose(plain, guided)
    with pytest.raises(ValueError, match="hand model"):
        model.sample_grasps(batch, "ddim", 10, torch.Generator(), steer=GuidanceSettings(scale=0.1))

    assert guidance_step(lambda x: x, lambda g: g.sum(-1), GuidanceSettings(), 1000) is None


# --- a hand through a table at both poses comes out ---------------------------------------------------------

def test_guided_sampling_takes_a_hand_out_of_the_table_at_both_poses(hand):
    """The data, in normalised units as a GraspDiffuser sees them: x ~ N(0, I) decoding to hands 5 cm (and
    0.05 rad) per unit around one grasp whose fingers are in a table top at the initial pose; the goal
    carries the hand 0.5 m along x and 1 cm up, where a table top 3 cm higher makes it deeper. The exact
    denoiser of that data samples many hands in the tables; guided by the scene term, the same noise gives
    hands above both tables, and the samples stay within the data's spread."""
    rng = np.random.default_rng(0)
    c = _rest_grasp(hand, 1)[0]
    z = _hand_z(hand, c[None])[0]
    z0 = float(torch.quantile(z, 0.3))  # 30 % of the mean hand's vertices below the initial table top
    init_top, init_n = _plane((-0.3, 0.3), z0, 1500, rng)
    goal_top, goal_n = _plane((0.2, 0.8), z0 + 0.03, 1500, rng)
    scene, scene_n = torch.cat([init_top, goal_top]), torch.cat([init_n, goal_n])
    goal = torch.eye(4, dtype=torch.float64)
    goal[0, 3], goal[2, 3] = 0.5, 0.01
    b, unit = 16, 0.05
    cfg = DiffusionConfig(timesteps=1000, beta_end=0.01, prediction="sample", clip=0.0)
    ab = NoiseSchedule(cfg).alphas_cumprod.double()

    def denoise(x, t):
        """E[x0 | x_t] for x0 ~ N(0, I): the exact denoiser of the data."""
        return ab[t][:, None].sqrt() * x

    def decode(x):
        return c + unit * x

    def below(x):
        v = hand(decode(x)).vertices.detach()
        carried = v @ goal[:3, :3].T + goal[:3, 3]
        return float((v[..., 2] < z0).double().mean()), float((carried[..., 2] < z0 + 0.03).double().mean())

    s = GuidanceSettings(scale=0.1, start=0.5, w_scene=1.0, w_object=0.0, margin=0.003, max_depth=0.15)
    energy = GuidanceEnergy(hand, torch.zeros(b, 1, 3, dtype=torch.float64), torch.ones(b, 1, 3, dtype=torch.float64),
                         scene.expand(b, -1, -1), scene_n.expand(b, -1, -1), goal.expand(b, -1, -1), None, s)

    def run(steer: GuidanceSettings) -> torch.Tensor:
        guide = guidance_step(decode, energy, steer, cfg.timesteps)
        with torch.no_grad():
            return sample(denoise, (b, 51), cfg, "ddim", 50, torch.Generator().manual_seed(0), guide=guide).double()

    plain, guided = run(GuidanceSettings()), run(s)
    init0, goal0 = below(plain)
    init1, goal1 = below(guided)
    assert init0 > 0.15 and goal0 > init0, (init0, goal0)
    assert init1 < 0.02 and goal1 < 0.02, (init1, goal1)  # 0 and 0.004 here
    assert float(guided.abs().max()) < 6  # within the data's spread: moved out of the tables, not away


# --- guided contact sampling ---------------------------------------------------------------------------------

def test_near_scene_weights_fall_from_one_at_the_scene_to_zero_at_near():
    dist = torch.tensor([[0.0, 0.01, 0.02, 0.04]])
    dmap = 1 - 2 * (torch.sigmoid(30 * dist) - 0.5)  # the maps' own formula (alpha 30)
    far = 1 - 2 * (torch.sigmoid(30 * torch.full_like(dist, 0.1)) - 0.5)
    w = near_scene_weights(dmap, far, near=0.02)
    torch.testing.assert_close(w, torch.tensor([[1.0, float(w[0, 1]), 0.0, 0.0]]), atol=1e-6, rtol=0)
    assert 0.3 < float(w[0, 1]) < 0.7
    torch.testing.assert_close(near_scene_weights(far, dmap, near=0.02), w)  # either pose counts


def test_contact_guidance_moves_contact_off_the_points_near_the_scene_and_leaves_the_others():
    """The exact denoiser of N(0, I) maps (contact ``(x + 1) / 2``): guided, the near half's contact falls
    well below the unguided draw's; the far half is bit-identical (its weight, so its shift, is 0)."""
    b, n = 8, 64
    cfg = DiffusionConfig(timesteps=1000, beta_end=0.01, prediction="sample", clip=0.0)
    ab = NoiseSchedule(cfg).alphas_cumprod

    def denoise(x, t):
        return ab[t][:, None].sqrt() * x

    w = torch.zeros(b, n)
    w[:, : n // 2] = torch.linspace(0.2, 1.0, n // 2)

    def run(s: GuidanceSettings) -> torch.Tensor:
        guide = contact_guidance_step(w, s, cfg.timesteps)
        return (sample(denoise, (b, n), cfg, "ddim", 20, torch.Generator().manual_seed(3), guide=guide) + 1) / 2

    assert contact_guidance_step(w, GuidanceSettings(), 1000) is None
    plain, guided = run(GuidanceSettings()), run(GuidanceSettings(contact_scale=2.0, start=0.5))
    assert torch.equal(plain[:, n // 2:], guided[:, n // 2:])
    drop = (plain[:, : n // 2] - guided[:, : n // 2]).mean()
    assert drop > 0.1, float(drop)
    nearest, least = slice(n // 2 - 4, n // 2), slice(0, 4)
    assert (plain[:, nearest] - guided[:, nearest]).mean() > (plain[:, least] - guided[:, least]).mean()  # more where nearer


def test_the_contact_diffuser_samples_guided_only_when_asked():
    from helpers import SMALL_PN
    from tohgs.models.contact_diffuser import ContactDiffuser, ContactDiffuserConfig

    torch.manual_seed(0)
    model = ContactDiffuser(ContactDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN)).eval()
    batch = _batch(2, torch.Generator().manual_seed(1))

    def draw(steer=None):
        return model.sample_contact(batch, "ddim", 10, torch.Generator().manual_seed(2), steer=steer)

    plain = draw()
    assert torch.equal(plain, draw(GuidanceSettings(scale=1.0)))  # the grasp levers leave the maps be
    guided = draw(GuidanceSettings(contact_scale=3.0, start=1.0, near=0.05))
    near = near_scene_weights(batch.d_init, batch.d_goal, 0.05) > 0.5
    assert (plain - guided)[near].mean() > 0.05


# --- sample, score, keep --------------------------------------------------------------------------------------

def _reference_pick(energy: np.ndarray, verts: np.ndarray, keep: int, pool: float) -> list[int]:
    """Greedy farthest-point pick among the lowest-energy candidates, written plainly."""
    size = min(len(energy), max(keep, int(np.ceil(pool * len(energy)))))
    cand = sorted(range(len(energy)), key=lambda i: (energy[i], i))[:size]

    def dist(i, j):
        return sum(np.linalg.norm(verts[i][v] - verts[j][v]) for v in range(verts.shape[1]))

    picked = [cand[0]]
    while len(picked) < keep:
        best, best_d = None, -1.0
        for i in cand:
            if i in picked:
                continue
            d = min(dist(i, j) for j in picked)
            if d > best_d + 1e-12:
                best, best_d = i, d
        picked.append(best)
    return picked


def test_select_diverse_equals_a_plain_greedy_pick_and_spreads_more_than_the_lowest_energies():
    rng = np.random.default_rng(0)
    k, v, keep = 24, 5, 6
    centres = rng.normal(size=(k, 1, 3)) * np.where(np.arange(k) < 12, 0.01, 0.1)[:, None, None]
    verts = centres + rng.normal(size=(1, v, 3)) * 0.02
    energy = np.where(np.arange(k) < 12, 0.0, 1.0) + rng.uniform(0, 0.5, k)  # the tight cluster is better
    idx = select_diverse(torch.as_tensor(energy), torch.as_tensor(verts), keep, 0.75).tolist()
    assert idx == _reference_pick(energy, verts, keep, 0.75)
    assert idx[0] == int(np.argmin(energy))
    pool = set(np.argsort(energy, kind="stable")[:18].tolist())
    assert set(idx) <= pool

    def spread(ids):
        d = [np.linalg.norm(verts[i] - verts[j], axis=-1).sum() for a, i in enumerate(ids) for j in ids[a + 1:]]
        return np.mean(d)

    lowest = np.argsort(energy, kind="stable")[:keep].tolist()
    assert spread(idx) > 2 * spread(lowest)
    small = select_diverse(torch.as_tensor(energy), torch.as_tensor(verts), keep, 0.01).tolist()
    assert sorted(small) == sorted(lowest) and small[0] == lowest[0]  # a pool of S: the S lowest, reordered
    with pytest.raises(ValueError, match="cannot keep"):
        select_diverse(torch.as_tensor(energy), torch.as_tensor(verts), k + 1, 0.5)


def test_contact_grasp_samples_candidates_and_keeps_s_of_lower_energy(hand):
    from types import SimpleNamespace

    from helpers import SMALL_PN
    from tohgs.methods.contact_grasp import ContactGrasp, ContactGraspSettings
    from tohgs.models.contact_diffuser import ContactDiffuser, ContactDiffuserConfig
    from tohgs.models.grasp_diffuser import GraspDiffuser, GraspDiffuserConfig

    hand32 = load_hand("anny")
    torch.manual_seed(0)
    grasp = GraspDiffuser(GraspDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN)).eval()
    grasp.set_hand(hand32)
    contact = ContactDiffuser(ContactDiffuserConfig(d_model=16, n_blocks=1, pointnet=SMALL_PN)).eval()
    models = {"cd": contact, "gd": grasp}
    cfg = {"contact": "cd", "grasp": "gd"}
    shard = SimpleNamespace(alpha_contact=100.0, alpha_distance=30.0)
    batch = _batch(1, torch.Generator().manual_seed(1)).repeat(4)
    steer = {"candidates": 3, "pool": 0.5, "w_scene": 1.0, "w_object": 1.0, "hand_points": 100}
    method = ContactGrasp("g", cfg, models, ContactGraspSettings(samples=4, steps=5, steer=steer), torch.device("cpu"), hand32)
    pred = method.predict(batch, shard, 0, torch.Generator().manual_seed(0), np.random.default_rng(0))
    assert pred.grasp.shape == (4, 51) and pred.contact.shape == (4, 64) and "select" in pred.seconds
    assert pred.info["energy_kept"] <= pred.info["energy_candidates"]
    with pytest.raises(ValueError, match="hand model"):
        ContactGrasp("g", cfg, models, ContactGraspSettings(steer=steer), torch.device("cpu"), None)
    with pytest.raises(ValueError, match="contact_scale"):
        ContactGrasp("g", {"contact": "ground_truth", "grasp": "gd"}, models,
                     ContactGraspSettings(steer={"contact_scale": 1.0}), torch.device("cpu"), hand32)
